"""Generation on any executor and in shards gives the same bytes; shard assignment is stable
across reruns; killed workers and drivers lose nothing."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import threading
import time

import pytest
from executor_cases import ci_scenario_file, tiny_ci_scenario, tree_hashes

from roft_sim.cli import main
from roft_sim.datasets.fast_ycb import PARTS_DIR_NAME
from roft_sim.executors import LocalProcessExecutor, SerialExecutor, Shard
from roft_sim.generation import (
    GenerationError,
    GenerationOptions,
    generate_dataset,
    plan_shard_units,
    plan_work_units,
)

NAMES = ("cracker_box", "mustard_hand_moving_camera")
FRAMES = {"cracker_box": 5, "mustard_hand_moving_camera": 4}
"""Two tiny CI scenarios: 9 frames in 5 units of 2 frames (3 + 2)."""
COMMON = ["--resolution", "96x72", "--chunk-frames", "2", "--no-progress"]


def _scenarios():
    return [tiny_ci_scenario(n, frames=FRAMES[n]) for n in NAMES]


def _options(**kw) -> GenerationOptions:
    return GenerationOptions(**({"chunk_frames": 2, "progress": False} | kw))


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted in-process run of both scenarios: path -> SHA-256."""
    out = tmp_path_factory.mktemp("reference")
    generate_dataset(_scenarios(), out, _options())
    return tree_hashes(out)


# ------------------------------------------------------------------ shard plan (no render)
def test_shard_plans_cover_every_frame_once_whatever_is_already_written():
    n_frames, names = [5, 4, 7], ["b_seq", "a_seq", "c_seq"]
    written = [{0, 3}, set(), {1, 2, 3, 4, 5, 6}]
    missing = [sorted(set(range(n)) - w) for n, w in zip(n_frames, written, strict=True)]
    for count in (1, 2, 3, 7):
        shards = [
            plan_shard_units(n_frames, names, missing, chunk_frames=2, shard=Shard(i, count))
            for i in range(count)
        ]
        frames = sorted((u.sequence, k) for s in shards for u in s for k in range(u.start, u.stop))
        assert frames == sorted((s, k) for s, m in enumerate(missing) for k in m)
        # every unit lies within one chunk of the full plan: [2j, 2j + 2)
        assert all(u.start // 2 == (u.stop - 1) // 2 for s in shards for u in s)
    # blocks by sequence NAME: shard 1/3 of the full plan is a_seq's two chunks and b_seq's first
    full = [range(n) for n in n_frames]
    first = plan_shard_units(n_frames, names, full, chunk_frames=2, shard=Shard(0, 3))
    assert [(names[u.sequence], u.start, u.stop) for u in first] == [
        ("b_seq", 0, 2),
        ("a_seq", 0, 2),
        ("a_seq", 2, 4),
    ]
    # the written frames do not move chunks to other shards
    again = plan_shard_units(n_frames, names, missing, chunk_frames=2, shard=Shard(0, 3))
    assert [(u.sequence, u.start, u.stop) for u in again] == [(0, 1, 2), (1, 0, 2), (1, 2, 4)]
    assert plan_shard_units([4], ["s"], [range(4)], chunk_frames=2, shard=Shard(0, 1)) == (
        plan_work_units([range(4)], chunk_frames=2)
    )


# ----------------------------------------------------------------------------- renders
@pytest.mark.render
def test_shards_then_a_final_resume_give_the_bytes_of_one_run(reference, tmp_path):
    """Shard 1/2 interrupted after 2 frames, shard 2/2, shard 1/2 again, then a run without
    shards: every frame is generated exactly once (the assignment does not change as frames get
    written), shards finalize nothing, and the dataset equals the one-process run's bytes."""
    out = tmp_path / "sharded"
    one = _options(shard=Shard(0, 2))
    first = generate_dataset(_scenarios(), out, _options(shard=Shard(0, 2), stop_after_frames=2))
    assert first.frames_generated == 2 and not first.finished
    second = generate_dataset(_scenarios(), out, _options(shard=Shard(1, 2)))
    third = generate_dataset(_scenarios(), out, one)
    assert first.frames_generated + second.frames_generated + third.frames_generated == 9
    assert not third.finished and third.shard == Shard(0, 2)
    for name in NAMES:  # complete but not finalized: the parts folder is still there
        assert (out / f"ci_{name}" / PARTS_DIR_NAME).is_dir()
    assert generate_dataset(_scenarios(), out, one).frames_generated == 0
    final = generate_dataset(_scenarios(), out, _options(resume=True))
    assert final.finished and final.frames_generated == 0
    assert tree_hashes(out) == reference


@pytest.mark.render
def test_cli_shards_then_resume_give_the_bytes_of_one_run(tmp_path, capsys):
    """`--shard 2/2`, `--shard 1/2`, then `--resume` without --shard: the CLI's dataset equals
    an unsharded CLI run's (5 frames in chunks [0, 2), [2, 4), [4, 5): shard 2/2 gets the last)."""
    out = tmp_path / "out"
    scenario = str(ci_scenario_file())
    args = ["generate", scenario, "--frames", "5", "--out", str(out), *COMMON]
    ref = tmp_path / "ref"
    assert main(["generate", scenario, "--frames", "5", "--out", str(ref), *COMMON]) == 0
    capsys.readouterr()
    assert main([*args, "--shard", "2/2", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["shard"] == "2/2" and not report["finished"]
    assert report["frames_generated"] == 1  # frame 4: the last of the 3 chunks
    assert main([*args, "--shard", "1/2"]) == 0
    assert "run the same command without --shard and with --resume" in capsys.readouterr().err
    assert main([*args, "--resume", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["finished"] and report["frames_generated"] == 0
    assert tree_hashes(out) == tree_hashes(ref)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--shard", "0/2"], r"the shard number i must be in 1\.\.2 \(1-based"),
        (["--shard", "3/2"], r"must be in 1\.\.2"),
        (["--shard", "1/x"], "expected i/N"),
        (["--shard", "1/2", "--overwrite"], "--shard 1/2 with --overwrite"),
        (["--address", "head:6379"], "add --executor ray"),
        (["--executor", "dask"], "unknown --executor 'dask'; expected one of local, ray"),
        (["--executor", "ray", "--workers", "0"], "--workers must be >= 1"),
    ],
)
def test_cli_rejects_bad_executor_and_shard_flags(tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    code = main(["generate", str(ci_scenario_file()), "--out", str(out), *COMMON, *extra])
    assert code == 2
    err = capsys.readouterr().err
    assert "roft-sim generate: error:" in err and re.search(message, err), err
    assert not out.exists()


@pytest.mark.render
@pytest.mark.slow  # two spawned workers start in ~10 s (imports, assets)
def test_two_local_workers_give_the_same_bytes(reference, tmp_path):
    summary = generate_dataset(
        _scenarios(), tmp_path / "two", _options(), executor=LocalProcessExecutor(2)
    )
    assert summary.finished and summary.workers == 2
    assert tree_hashes(tmp_path / "two") == reference


@pytest.mark.render
@pytest.mark.slow  # two spawned workers, one killed, then a resume (~30 s)
def test_a_worker_killed_mid_run_loses_nothing_and_resume_completes(reference, tmp_path):
    """os.kill(SIGKILL) of one worker process once a few frames are written: the run stops with
    a GenerationError naming a dead worker, what is written stays valid, and a resumed run
    gives the bytes of an uninterrupted one."""
    import multiprocessing

    out = tmp_path / "out"
    parts = [out / f"ci_{n}" / PARTS_DIR_NAME for n in NAMES]
    killed: list[int] = []

    def kill_a_worker() -> None:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            if sum(len(list(p.glob("frame_*.json"))) for p in parts if p.is_dir()) >= 2:
                children = multiprocessing.active_children()
                if children:
                    os.kill(children[0].pid, signal.SIGKILL)
                    killed.append(children[0].pid)
                    return
            time.sleep(0.01)

    killer = threading.Thread(target=kill_a_worker)
    killer.start()
    try:
        with pytest.raises(GenerationError, match="a worker process died"):
            generate_dataset(_scenarios(), out, _options(), executor=LocalProcessExecutor(2))
    finally:
        killer.join()
    assert killed
    summary = generate_dataset(_scenarios(), out, _options(resume=True))
    assert summary.finished and 0 < summary.frames_generated < 9
    assert tree_hashes(out) == reference


@pytest.mark.render
@pytest.mark.slow  # a local Ray instance in a subprocess, killed, then a resume (~60 s)
def test_a_killed_ray_driver_resumes_to_the_same_bytes(tmp_path):
    """SIGKILL to the process group of `roft-sim generate --executor ray` (the driver, its local
    Ray instance and the actors) once a few frames are written; `--resume` (on local processes)
    completes the dataset with the bytes of an uninterrupted run."""
    pytest.importorskip("ray", reason="Ray is not installed (pip install 'roft-sim[ray]')")
    common = ["--frames", "12", *COMMON]
    reference = tmp_path / "reference"
    assert main(["generate", str(ci_scenario_file()), "--out", str(reference), *common]) == 0
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "roft_sim", "generate", str(ci_scenario_file()), "--out",
           str(out), "--executor", "ray", "--workers", "2", *common]  # fmt: skip
    proc = subprocess.Popen(cmd, start_new_session=True, stderr=subprocess.DEVNULL)
    parts = out / "003_cracker_box" / PARTS_DIR_NAME  # generate names a folder by its object
    deadline = time.monotonic() + 300
    try:
        while len(list(parts.glob("frame_*.json"))) < 3:
            assert proc.poll() is None, "the run ended before it could be killed"
            assert time.monotonic() < deadline, "no progress within 300 s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    written = len(list(parts.glob("frame_*.json")))
    assert 3 <= written < 12
    assert main(["generate", str(ci_scenario_file()), "--out", str(out), "--resume", *common]) == 0
    assert tree_hashes(out) == tree_hashes(reference)


def test_serial_executor_is_the_default_for_one_worker(tmp_path):
    """Without an executor, one worker (or one unit) runs in this process."""
    from roft_sim.generation.runner import _default_executor

    assert isinstance(_default_executor(_options(), 5), SerialExecutor)
    assert isinstance(_default_executor(_options(workers=2), 1), SerialExecutor)
    local = _default_executor(_options(workers=2), 5)
    assert isinstance(local, LocalProcessExecutor) and local.workers == 2
