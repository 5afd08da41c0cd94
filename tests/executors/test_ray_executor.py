"""The Ray executor in local mode on this machine (``ray.init(num_cpus=2)``): worker set-up,
progress, errors, dead workers restarted or reported, and the same bytes as the serial executor
for a sweep and a generated dataset. Skipped when Ray (the optional extra) is not installed."""

from __future__ import annotations

import functools
import os
from pathlib import Path

import pytest

ray = pytest.importorskip(
    "ray", reason="Ray is not installed (optional extra: pip install 'roft-sim[ray]')"
)

from executor_cases import (  # noqa: E402
    count_in_worker,
    die_on,
    die_once,
    fail_on_three,
    start_counting,
    sweep_hashes,
    tiny_ci_scenario,
    tree_hashes,
    unit_bytes,
    write_box_dataset,
    write_unit,
    written_units,
)

from roft_sim.errors import DatasetFormatError  # noqa: E402
from roft_sim.executors import RayExecutor, SerialExecutor, WorkerSetup, WorkUnitError  # noqa: E402

HERE = Path(__file__).resolve().parent


def _raise_roft_sim_error(x: int) -> int:
    raise DatasetFormatError(f"bad file {x}")


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray instance (2 CPUs) for the module; actors can import executor_cases."""
    path = os.pathsep.join(p for p in (str(HERE), os.environ.get("PYTHONPATH")) if p)
    try:
        ray.init(
            num_cpus=2,
            include_dashboard=False,
            log_to_driver=False,
            runtime_env={"env_vars": {"PYTHONPATH": path}},
        )
    except Exception as e:  # Ray installed but its processes cannot start in this sandbox
        pytest.skip(f"Ray is installed but cannot start a local instance here: {e}")
    yield
    ray.shutdown()


@pytest.mark.slow  # the default run keeps one Ray sweep (the CLI's) and the error paths
def test_ray_actors_keep_worker_state_and_report_progress(local_ray):
    seen: list[int] = []
    executor = RayExecutor()
    assert executor.workers == 2  # one per CPU of the cluster
    setup = WorkerSetup(start_counting, ("ray",))
    units = list(range(8))
    run = executor.map_unordered(count_in_worker, units, setup=setup, on_progress=seen.append)
    out = [result for _, result in run]
    assert sorted(x for x, *_ in out) == units
    assert {tag for _, tag, _, _ in out} == {"ray"}
    pids = {pid for _, _, pid, _ in out}
    assert os.getpid() not in pids and 1 <= len(pids) <= 2
    for pid in pids:  # the actor's state survives across its units
        calls = sorted(c for _, _, p, c in out if p == pid)
        assert calls == list(range(1, len(calls) + 1))
    assert sum(seen) == 2 * len(units)
    assert ray.is_initialized()  # an existing connection is left open


def test_ray_errors_name_the_unit_and_keep_roft_sim_errors(local_ray):
    executor = RayExecutor(2)
    with pytest.raises(WorkUnitError, match=r"work unit 3 failed: ValueError: three") as info:
        list(executor.map_unordered(fail_on_three, [1, 2, 3, 4]))
    assert isinstance(info.value.cause, ValueError) and not info.value.worker_died
    with pytest.raises(DatasetFormatError, match="bad file 1"):
        list(executor.map_unordered(_raise_roft_sim_error, [1]))


@pytest.mark.slow  # the default run keeps one Ray sweep (the CLI's) and the error paths
def test_a_dead_ray_worker_is_restarted_and_its_unit_retried(local_ray, tmp_path):
    """Unit 2's actor process hard-exits on the first attempt: Ray restarts the actor, retries
    the unit, and the run completes with every file correct."""
    out, markers = tmp_path / "out", tmp_path / "markers"
    out.mkdir()
    markers.mkdir()
    units = [(str(out), i) for i in range(6)]
    done = dict(
        RayExecutor(2, max_restarts=1).map_unordered(
            functools.partial(die_once, str(markers)), units
        )
    )
    assert sorted(u[1] for u in done) == list(range(6))
    assert (markers / "died_2").exists()
    final = {n: b for n, b in written_units(out).items() if not n.startswith(".")}
    assert final == {f"{i}.bin": unit_bytes(i) for i in range(6)}


def test_a_ray_worker_that_keeps_dying_stops_the_run_and_a_rerun_completes(local_ray, tmp_path):
    units = [(str(tmp_path), i) for i in range(6)]
    with pytest.raises(WorkUnitError, match="a worker process died") as info:
        list(RayExecutor(2, max_restarts=0).map_unordered(functools.partial(die_on, 3), units))
    assert info.value.worker_died
    for name, data in written_units(tmp_path).items():
        if not name.startswith("."):
            assert data == unit_bytes(int(name.split(".")[0]))
    list(SerialExecutor().map_unordered(write_unit, units))
    final = {n: b for n, b in written_units(tmp_path).items() if not n.startswith(".")}
    assert final == {f"{i}.bin": unit_bytes(i) for i in range(6)}


@pytest.mark.slow  # the default run keeps one Ray sweep (the CLI's) and the error paths
def test_a_sweep_on_ray_gives_the_serial_bytes(local_ray, tmp_path):
    from roft_sim.harness.sweep import SweepConfig, SweptParameter, run_sweep

    data = write_box_dataset(tmp_path / "data")
    config = SweepConfig(
        name="ray",
        datasets=(data,),
        trackers=("detector-hold", "naive-delay"),
        parameter=SweptParameter(name="delay", values=(0.0, 3.0)),
        flow="none",
        masks="none",
        include_rgb=False,
    )
    serial = run_sweep(config, tmp_path / "serial", plots=False)
    on_ray = run_sweep(config, tmp_path / "ray", executor=RayExecutor(2), plots=False)
    assert len(on_ray.records) == len(serial.cells) == 8
    a, b = sweep_hashes(tmp_path / "serial"), sweep_hashes(tmp_path / "ray")
    assert len(a) > 8 * 5 and a == b


@pytest.mark.render
@pytest.mark.slow  # each actor imports MuJoCo and builds the scene (~10 s on 2 cores)
def test_a_dataset_generated_on_ray_gives_the_serial_bytes(local_ray, tmp_path):
    from roft_sim.generation import GenerationOptions, generate_dataset

    scenarios = [
        tiny_ci_scenario("cracker_box", frames=5),
        tiny_ci_scenario("mustard_hand_moving_camera", frames=4),
    ]
    options = GenerationOptions(chunk_frames=2, progress=False)
    generate_dataset(scenarios, tmp_path / "serial", options)
    seen: list[int] = []
    summary = generate_dataset(
        scenarios, tmp_path / "ray", options, executor=RayExecutor(2), on_frames=seen.append
    )
    assert summary.finished and summary.workers == 2 and sum(seen) == 9
    assert tree_hashes(tmp_path / "ray") == tree_hashes(tmp_path / "serial")


def test_sweep_cli_with_executor_ray_gives_the_serial_bytes(local_ray, tmp_path, capsys):
    """`roft-sim sweep --executor ray` (here joining the module's Ray instance) writes the same
    folder as the in-process CLI run, and --workers defaults to the cluster's CPUs."""
    from roft_sim.cli import main

    data = write_box_dataset(tmp_path / "data")
    args = ["sweep", str(data), "--trackers", "detector-hold", "--flow", "none", "--masks", "none",
            "--no-rgb", "--param", "dropout=0,0.5", "--no-plots", "--no-progress"]  # fmt: skip
    assert main([*args, "--out", str(tmp_path / "serial" / "s")]) == 0
    assert main([*args, "--out", str(tmp_path / "ray" / "s"), "--executor", "ray", "--json"]) == 0
    assert '"cells": 4' in capsys.readouterr().out
    assert sweep_hashes(tmp_path / "ray" / "s") == sweep_hashes(tmp_path / "serial" / "s")
    assert ray.is_initialized()
