"""The executor abstraction: serial and local-process executors, worker set-up, progress,
errors, dead workers, the factory, and sharding."""

from __future__ import annotations

import functools
import importlib.util
import os

import pytest
from executor_cases import (
    count_in_worker,
    die_on,
    fail_on_three,
    square,
    start_counting,
    stop_counting,
    unit_bytes,
    write_unit,
    written_units,
)
from hypothesis import given
from hypothesis import strategies as st

from roft_sim.errors import ConfigError, DatasetFormatError
from roft_sim.executors import (
    Executor,
    LocalProcessExecutor,
    RayExecutor,
    SerialExecutor,
    Shard,
    WorkerSetup,
    WorkUnitError,
    make_executor,
    select_shard,
    shard_positions,
)


def _raise_roft_sim_error(x: int) -> int:
    raise DatasetFormatError(f"bad file {x}")


# ------------------------------------------------------------------------------- serial
def test_serial_executor_runs_setup_units_teardown_and_forwards_progress():
    seen: list[int] = []
    setup = WorkerSetup(start_counting, ("serial",), teardown=stop_counting)
    executor = SerialExecutor()
    run = executor.map_unordered(count_in_worker, [5, 6, 7], setup=setup, on_progress=seen.append)
    out = [result for _, result in run]
    assert [(x, tag, calls) for x, tag, _, calls in out] == [
        (5, "serial", 1),
        (6, "serial", 2),
        (7, "serial", 3),
    ]
    assert {pid for _, _, pid, _ in out} == {os.getpid()}
    assert seen == [2, 2, 2]
    # teardown ran: the state is gone, and a unit run outside the executor fails
    with pytest.raises(RuntimeError, match="not initialised"):
        count_in_worker(1)


def test_serial_executor_errors_name_the_unit_and_keep_roft_sim_errors():
    with pytest.raises(WorkUnitError, match=r"work unit 3 failed: ValueError: three") as info:
        list(SerialExecutor().map_unordered(fail_on_three, [1, 2, 3, 4]))
    assert info.value.unit == 3 and isinstance(info.value.cause, ValueError)
    assert not info.value.worker_died
    with pytest.raises(DatasetFormatError, match="bad file 1"):
        list(SerialExecutor().map_unordered(_raise_roft_sim_error, [1]))


# -------------------------------------------------------------------------------- local
@pytest.mark.parametrize("workers", [1, 2])
def test_local_processes_keep_worker_state_and_report_progress(workers):
    """Each worker process runs the initializer once and keeps its state for all its units;
    every unit runs exactly once; progress counts reach the driver."""
    seen: list[int] = []
    executor = LocalProcessExecutor(workers)
    setup = WorkerSetup(start_counting, ("local",))
    units = list(range(8))
    run = executor.map_unordered(count_in_worker, units, setup=setup, on_progress=seen.append)
    out = [result for _, result in run]
    assert sorted(x for x, *_ in out) == units
    assert {tag for _, tag, _, _ in out} == {"local"}
    pids = {pid for _, _, pid, _ in out}
    assert os.getpid() not in pids and 1 <= len(pids) <= workers
    for pid in pids:  # calls count up 1, 2, ... in each worker: the state survived
        calls = sorted(c for _, _, p, c in out if p == pid)
        assert calls == list(range(1, len(calls) + 1))
    assert sum(seen) == 2 * len(units)


def test_started_workers_are_spawned_before_the_map_and_run_its_setup_before_their_units():
    """start() spawns the processes at once (each runs the executor's initializer); the map
    then runs on those processes, its own set-up once per worker before the first unit."""
    seen: list[int] = []
    executor = LocalProcessExecutor(2, initializer=start_counting, initargs=("early",))
    executor.start()
    started = executor._started  # the spawned pool, before any unit exists
    assert started is not None and len(started[0]._processes) == 2
    early_pids = {p.pid for p in started[0]._processes.values()}
    setup = WorkerSetup(start_counting, ("map",))
    units = list(range(8))
    run = executor.map_unordered(count_in_worker, units, setup=setup, on_progress=seen.append)
    out = [result for _, result in run]
    assert sorted(x for x, *_ in out) == units and {tag for _, tag, _, _ in out} == {"map"}
    assert {pid for _, _, pid, _ in out} <= early_pids
    for pid in {pid for _, _, pid, _ in out}:  # the map's set-up ran once per worker
        calls = sorted(c for _, _, p, c in out if p == pid)
        assert calls == list(range(1, len(calls) + 1))
    assert sum(seen) == 2 * len(units) and executor._started is None


def test_started_workers_that_no_map_uses_are_stopped_by_close():
    executor = LocalProcessExecutor(2)
    executor.start()
    assert executor._started is not None
    processes = list(executor._started[0]._processes.values())
    executor.close()
    executor.close()  # idempotent
    assert executor._started is None and not any(p.is_alive() for p in processes)
    assert dict(executor.map_unordered(square, [2, 3])) == {2: 4, 3: 9}  # still usable


def test_local_process_errors_name_the_unit():
    executor = LocalProcessExecutor(2)
    with pytest.raises(WorkUnitError, match=r"work unit 3 failed: ValueError: three") as info:
        list(executor.map_unordered(fail_on_three, [1, 2, 3, 4, 5]))
    assert isinstance(info.value.cause, ValueError)
    with pytest.raises(DatasetFormatError, match="bad file 1"):
        list(executor.map_unordered(_raise_roft_sim_error, [1]))
    assert dict(executor.map_unordered(square, [2, 3])) == {2: 4, 3: 9}


def test_a_worker_that_dies_mid_unit_loses_nothing_and_a_rerun_completes(tmp_path):
    """Unit 4's worker hard-exits half-way through writing its file. The run stops with a
    WorkUnitError that says a worker died; every file that exists is complete and correct (the
    half-written one is a temp file); running the same units again writes exactly the missing
    ones, and the result equals an uninterrupted run's bytes."""
    units = [(str(tmp_path), i) for i in range(10)]
    with pytest.raises(WorkUnitError, match="a worker process died") as info:
        list(LocalProcessExecutor(2).map_unordered(functools.partial(die_on, 4), units))
    assert info.value.worker_died
    first = written_units(tmp_path)
    finished = {n for n in first if n.endswith(".bin") and not n.startswith(".")}
    assert "4.bin" not in finished and any(n.startswith(".4.bin.") for n in first)
    for name in finished:
        assert first[name] == unit_bytes(int(name.split(".")[0]))  # no corrupt result
    rerun = dict(SerialExecutor().map_unordered(write_unit, units))
    assert {u[1] for u, n in rerun.items() if n > 0} == set(range(10)) - {
        int(n.split(".")[0]) for n in finished
    }
    final = {n: b for n, b in written_units(tmp_path).items() if not n.startswith(".")}
    assert final == {f"{i}.bin": unit_bytes(i) for i in range(10)}


# ------------------------------------------------------------------------------ factory
def test_make_executor_builds_what_the_flags_ask_for():
    assert isinstance(make_executor(1), SerialExecutor)
    assert isinstance(make_executor(None), SerialExecutor)
    local = make_executor(3)
    assert isinstance(local, LocalProcessExecutor) and local.workers == 3
    assert isinstance(local, Executor) and isinstance(SerialExecutor(), Executor)
    for bad, message in [
        ({"workers": 0}, "--workers must be >= 1, got 0"),
        ({"kind": "slurm"}, "unknown --executor 'slurm'; expected one of local, ray"),
        ({"address": "head:6379"}, "--address 'head:6379' is the address of a Ray cluster"),
    ]:
        with pytest.raises(ConfigError, match=message):
            make_executor(**bad)
    with pytest.raises(ConfigError, match="never 'fork'"):
        LocalProcessExecutor(2, start_method="fork")  # type: ignore[arg-type]


def test_the_ray_executor_says_what_to_install_when_ray_is_missing(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "ray" else real(name, *a)
    )
    with pytest.raises(ConfigError, match=r"needs Ray.*pip install 'roft-sim\[ray\]'"):
        make_executor(2, kind="ray")
    with pytest.raises(ConfigError, match="needs Ray"):
        RayExecutor()


# ----------------------------------------------------------------------------- sharding
def test_shard_parsing_is_one_based_with_clear_errors():
    assert Shard.parse("1/4") == Shard(0, 4) and Shard.parse(" 4 / 4 ") == Shard(3, 4)
    assert str(Shard(1, 3)) == "2/3"
    for bad, message in [
        ("0/4", r"must be in 1\.\.4 \(1-based"),
        ("5/4", r"must be in 1\.\.4"),
        ("1/0", "N must be >= 1"),
        ("a/b", "expected i/N"),
        ("3", "expected i/N"),
        ("1/2/3", "expected i/N"),
        ("1.5/2", "expected i/N"),
    ]:
        with pytest.raises(ConfigError, match=message):
            Shard.parse(bad)
    with pytest.raises(ConfigError, match="0 <= index < count"):
        Shard(2, 2)


@given(st.integers(0, 60), st.integers(1, 9), st.sampled_from(["blocks", "round-robin"]))
def test_shards_are_disjoint_balanced_and_cover_everything(total, count, layout):
    shards = [shard_positions(total, Shard(i, count), layout) for i in range(count)]
    assert sorted(p for s in shards for p in s) == list(range(total))
    sizes = [len(s) for s in shards]
    assert max(sizes) - min(sizes) <= 1
    if layout == "blocks":  # contiguous runs, in shard order
        flat = [p for s in shards for p in s]
        assert flat == list(range(total))


@given(st.permutations(list(range(12))), st.integers(1, 5))
def test_shard_assignment_depends_on_the_keys_not_on_the_order_given(order, count):
    """Each job of an array builds its unit list itself: the assignment must not depend on
    the order it happens to list them in."""
    units = [f"cell-{i:02d}" for i in range(12)]
    shuffled = [units[i] for i in order]
    for i in range(count):
        for layout in ("blocks", "round-robin"):
            a = select_shard(units, Shard(i, count), key=str, layout=layout)
            b = select_shard(shuffled, Shard(i, count), key=str, layout=layout)
            assert sorted(a) == sorted(b)


def test_shard_assignment_is_pinned():
    """The documented rule, by hand: 10 units sorted by key; blocks give unit p to shard
    p * 4 // 10, round-robin to p mod 4."""
    units = [f"u{i}" for i in range(10)]
    blocks = [select_shard(units, Shard(i, 4), key=str) for i in range(4)]
    assert blocks == [["u0", "u1", "u2"], ["u3", "u4"], ["u5", "u6", "u7"], ["u8", "u9"]]
    rr = [select_shard(units, Shard(i, 4), key=str, layout="round-robin") for i in range(4)]
    assert rr == [["u0", "u4", "u8"], ["u1", "u5", "u9"], ["u2", "u6"], ["u3", "u7"]]
    with pytest.raises(ValueError, match="unique"):
        select_shard(["a", "a"], Shard(0, 2), key=str)
    assert select_shard(units, None, key=str) == units


def test_unit_result_is_the_one_dispatch_rule():
    from roft_sim.errors import ConfigError
    from roft_sim.executors.base import WorkUnitError, unit_result

    assert unit_result("u", lambda: 3) == 3

    def user_error() -> None:
        raise ConfigError("bad option")

    with pytest.raises(ConfigError, match="bad option"):  # passes through unwrapped
        unit_result("u", user_error)
    with pytest.raises(WorkUnitError, match="work unit 'u' failed: ZeroDivisionError") as info:
        unit_result("u", lambda: 1 / 0)
    assert info.value.unit == "u" and not info.value.worker_died
    with pytest.raises(WorkUnitError, match="a worker process died") as info:
        unit_result("u", lambda: 1 / 0, worker_death=(ZeroDivisionError,))
    assert info.value.worker_died
