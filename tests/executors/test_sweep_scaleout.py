"""Sweeps on any executor and in shards give the same bytes; shards are stable across reruns
and leave each other's work alone; killed workers and drivers lose nothing."""

from __future__ import annotations

import functools
import json
import os
import re
import signal
import subprocess
import sys
import time

import pytest
from executor_cases import sweep_hashes, write_box_dataset

from roft_sim.cli import main
from roft_sim.executors import LocalProcessExecutor, SerialExecutor, Shard, WorkUnitError
from roft_sim.harness.cells import CELL_FILE, CELLS_DIR, finished_cells, shard_cells
from roft_sim.harness.sweep import SweepConfig, SweptParameter, plan_sweep, run_sweep

SUMMARY_FILES = ("summary.md", "summary.csv", "summary.tex", "cells.csv", "timing.csv")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_box_dataset(tmp_path_factory.mktemp("data"))


def _config(dataset, **kw) -> SweepConfig:
    base = {
        "name": "scaleout",
        "datasets": (dataset,),
        "trackers": ("detector-hold", "naive-delay"),
        "parameter": SweptParameter(name="delay", values=(0.0, 3.0)),
        "flow": "none",
        "masks": "none",
        "include_rgb": False,
    }
    return SweepConfig(**(base | kw))


@pytest.fixture(scope="module")
def reference(dataset, tmp_path_factory):
    """An uninterrupted in-process sweep: deterministic hashes of every file."""
    out = tmp_path_factory.mktemp("reference") / "sweep"
    run_sweep(_config(dataset), out, plots=False)
    return sweep_hashes(out)


def _cli_args(dataset, out, *extra):
    return ["sweep", str(dataset), "--trackers", "detector-hold,naive-delay", "--flow", "none",
            "--masks", "none", "--no-rgb", "--param", "delay=0:3:3", "--no-plots",
            "--no-progress", "--out", str(out), *extra]  # fmt: skip


def test_two_local_workers_give_the_serial_bytes(dataset, reference, tmp_path):
    result = run_sweep(
        _config(dataset), tmp_path / "sweep", executor=LocalProcessExecutor(2), plots=False
    )
    assert len(result.records) == 8
    assert sweep_hashes(tmp_path / "sweep") == reference


def test_cli_shards_then_a_final_run_give_the_serial_bytes(dataset, tmp_path, capsys):
    """Three shards through the CLI into one folder (no summary yet), then the same command
    with --resume and no --shard writes the summary without running a cell: the bytes equal an
    unsharded run's."""
    ref = tmp_path / "ref" / "sweep"
    assert main(_cli_args(dataset, ref)) == 0
    out = tmp_path / "sharded" / "sweep"
    for i in (1, 2, 3):
        assert main(_cli_args(dataset, out, "--shard", f"{i}/3")) == 0
        assert f"shard {i}/3: " in capsys.readouterr().err
        assert not any((out / name).exists() for name in SUMMARY_FILES)
    assert len(finished_cells(out / CELLS_DIR)) == 8
    stamps = {p: p.stat().st_mtime_ns for p in (out / CELLS_DIR).glob(f"*/{CELL_FILE}")}
    assert main([*_cli_args(dataset, out, "--resume"), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["cells"] == 8
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps  # no cell ran again
    assert sweep_hashes(out) == sweep_hashes(ref)
    # a shard run again after everything finished does nothing and changes nothing
    assert main([*_cli_args(dataset, out, "--shard", "2/3"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["shard"] == "2/3" and report["shard_cells_finished"] == report["shard_cells"]
    assert sweep_hashes(out) == sweep_hashes(ref)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--shard", "0/2"], r"--shard '0/2': the shard number i must be in 1\.\.2"),
        (["--shard", "3/2"], r"must be in 1\.\.2"),
        (["--shard", "two"], "expected i/N"),
        (["--shard", "1/2", "--overwrite"], "--shard 1/2 with --overwrite"),
        (["--address", "head:6379"], "add --executor ray"),
        (["--executor", "slurm"], "unknown --executor 'slurm'"),
        (["--workers", "0"], "--workers must be >= 1"),
    ],
)
def test_cli_rejects_bad_executor_and_shard_flags(dataset, tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    assert main(_cli_args(dataset, out, *extra)) == 2
    err = capsys.readouterr().err
    assert "roft-sim sweep: error:" in err
    assert re.search(message, err), err
    assert not out.exists()


class _StopAfter:
    """An executor that runs ``limit`` units, then raises as if the job were killed."""

    workers = 1

    def __init__(self, limit: int) -> None:
        self.limit = limit

    def map_unordered(self, fn, units, **kwargs):
        for i, unit in enumerate(units):
            if i == self.limit:
                raise KeyboardInterrupt
            yield unit, fn(unit)


def test_shard_assignment_is_stable_when_a_shard_is_rerun(dataset, reference, tmp_path):
    """Shard 1/2 is killed after one cell, shard 2/2 completes, shard 1/2 runs again: it runs
    exactly its remaining cells (the assignment does not depend on what is on disk), every cell
    runs once, and the result equals an unsharded run."""
    config = _config(dataset)
    out = tmp_path / "sweep"
    cells = plan_sweep(config)
    first, second = shard_cells(cells, Shard(0, 2)), shard_cells(cells, Shard(1, 2))
    assert len(first) == len(second) == 4 and not {c.cell_id for c in first} & {
        c.cell_id for c in second
    }
    ran: list[str] = []

    class Recording(SerialExecutor):
        def map_unordered(self, fn, units, **kwargs):
            for unit, result in super().map_unordered(fn, units, **kwargs):
                ran.append(unit.cell_id)
                yield unit, result

    with pytest.raises(KeyboardInterrupt):
        run_sweep(config, out, executor=_StopAfter(1), plots=False, shard=Shard(0, 2))
    assert len(finished_cells(out / CELLS_DIR)) == 1
    run_sweep(config, out, executor=Recording(), plots=False, shard=Shard(1, 2))
    assert sorted(ran) == sorted(c.cell_id for c in second)
    ran.clear()
    result = run_sweep(config, out, executor=Recording(), plots=False, shard=Shard(0, 2))
    assert sorted(ran) == sorted(c.cell_id for c in first[1:])
    assert result.summary_rows == [] and len(result.records) == 8
    ran.clear()
    run_sweep(config, out, executor=Recording(), plots=False)
    assert ran == []
    assert sweep_hashes(out) == reference


def test_a_shard_removes_only_its_own_leftovers(dataset, tmp_path):
    """Shards share cells/: a shard starting must not delete the temporary folder of a cell
    another shard is writing, but does clear its own cells' leftovers."""
    config = _config(dataset)
    cells = plan_sweep(config)
    mine, theirs = shard_cells(cells, Shard(0, 2)), shard_cells(cells, Shard(1, 2))
    cells_dir = tmp_path / "sweep" / CELLS_DIR
    cells_dir.mkdir(parents=True)
    their_tmp = cells_dir / f".{theirs[0].cell_id}.4242.tmp"
    my_tmp = cells_dir / f".{mine[0].cell_id}.4242.tmp"
    my_broken = cells_dir / mine[1].cell_id
    for folder in (their_tmp, my_tmp, my_broken):
        folder.mkdir()
        (folder / "pose_estimate.txt").write_text("half\n")
    run_sweep(config, tmp_path / "sweep", plots=False, shard=Shard(0, 2))
    assert their_tmp.is_dir() and not my_tmp.exists()
    assert (my_broken / CELL_FILE).is_file()
    assert set(finished_cells(cells_dir)) == {c.cell_id for c in mine}


def test_a_worker_killed_mid_sweep_loses_nothing(dataset, reference, tmp_path):
    """A worker process hard-exits while running a cell: the run stops with a dead-worker
    error; the finished cells are intact; a rerun runs the rest and the bytes match."""
    cells = plan_sweep(_config(dataset))
    victim = sorted(c.cell_id for c in cells)[5]

    class DyingOn(LocalProcessExecutor):
        def map_unordered(self, fn, units, **kwargs):
            from executor_cases import run_or_die

            return super().map_unordered(functools.partial(run_or_die, victim, fn), units)

    out = tmp_path / "sweep"
    with pytest.raises(WorkUnitError, match="a worker process died") as info:
        run_sweep(_config(dataset), out, executor=DyingOn(2), plots=False)
    assert info.value.worker_died
    done = finished_cells(out / CELLS_DIR)
    assert victim not in done and len(done) < 8
    partial = sweep_hashes(out)
    assert any(path.startswith(f"{CELLS_DIR}/.{victim}.") for path in partial)  # half-written
    for path, digest in partial.items():
        if path.startswith(CELLS_DIR) and not path.startswith(f"{CELLS_DIR}/."):
            assert reference[path] == digest, path  # what exists is complete and correct
    run_sweep(_config(dataset), out, plots=False)
    assert sweep_hashes(out) == reference


@pytest.mark.slow  # a 48-cell sweep in a subprocess, killed, and resumed (~20 s)
def test_a_killed_sweep_driver_resumes_to_the_same_bytes(dataset, tmp_path):
    """SIGKILL to the whole process group of `roft-sim sweep --workers 2` mid-run, then the same
    command with --resume: the folder equals an uninterrupted run's (timing left out)."""
    grid = ["--seeds", "0,1,2,3,4,5"]
    reference = tmp_path / "reference" / "sweep"
    assert main([*_cli_args(dataset, reference), *grid]) == 0
    out = tmp_path / "killed" / "sweep"
    cmd = [sys.executable, "-m", "roft_sim", *_cli_args(dataset, out), *grid, "--workers", "2"]
    proc = subprocess.Popen(cmd, start_new_session=True, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240
    try:
        while len(list((out / CELLS_DIR).glob(f"*/{CELL_FILE}"))) < 3:
            assert proc.poll() is None, "the sweep ended before it could be killed"
            assert time.monotonic() < deadline, "no progress within 240 s"
            time.sleep(0.02)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    done = len(finished_cells(out / CELLS_DIR))
    assert 3 <= done < 48
    assert main([*_cli_args(dataset, out, "--resume"), *grid]) == 0
    assert sweep_hashes(out) == sweep_hashes(reference)
