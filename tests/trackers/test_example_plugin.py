"""The example external plugin (examples/tracker_plugin) found through the entry-point registry.

One test pip-installs the package (from a copy, into a temporary folder: ``pip install
--no-deps --target``; pip builds it locally, or in an isolated environment when the local
setuptools cannot, which needs the package index) and runs it with ``roft-sim run`` on a tiny
dataset on disk, as a user would. The other registers the same entry point by hand (a
``.dist-info`` folder with the ``entry_points.txt`` pip would write) and checks the tracker's
output exactly.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
import tomllib
from importlib import invalidate_caches
from pathlib import Path

import numpy as np
import pytest
from observation_schedules import build_observations, make_context, paper_schedule

from roft_sim.cli import main
from roft_sim.datasets import write_sequence
from roft_sim.geometry import matrix_from_rotvec, rotvec_from_matrix
from roft_sim.trackers import create_tracker, discover_trackers, load_tracker_config, run_tracker

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "tracker_plugin"
NAME = "extrapolate-latest"


@pytest.fixture
def clean_plugin_modules():
    yield
    for mod in [m for m in sys.modules if m.startswith("roft_sim_example_tracker")]:
        del sys.modules[mod]
    invalidate_caches()


def _run_plugin(seq):
    specs = discover_trackers()
    assert NAME in specs, f"plugin not discovered; found {sorted(specs)}"
    spec = specs[NAME]
    config = load_tracker_config(spec, {"max_extrapolation_frames": 9})
    tracker = create_tracker(spec, make_context(seq, renderer=False), config)
    est = run_tracker(tracker, build_observations(seq, poses=paper_schedule(len(seq))))
    assert [e.k for e in est] == list(range(len(seq)))
    return est


def test_example_plugin_registered_by_its_entry_point(
    tmp_path, monkeypatch, tiny_seq, capsys, clean_plugin_modules
):
    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())
    table = project["project"]["entry-points"]["roft_sim.trackers"]
    assert table == {NAME: "roft_sim_example_tracker:SPEC"}
    dist = tmp_path / "roft_sim_example_tracker-0.1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: roft-sim-example-tracker\nVersion: 0.1.0\n"
    )
    lines = "".join(f"{k} = {v}\n" for k, v in table.items())
    (dist / "entry_points.txt").write_text(f"[roft_sim.trackers]\n{lines}")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.syspath_prepend(str(EXAMPLE))
    invalidate_caches()
    est = _run_plugin(tiny_seq)
    assert all(e.valid for e in est)
    # at frame 14 the newest poses are those of frames 0 and 6: extrapolate 8 frames
    T0, T6 = tiny_seq.gt.T_cam_obj[[0, 6]]
    dt = 6 / tiny_seq.fps
    w = rotvec_from_matrix(T6[:3, :3] @ T0[:3, :3].T) / dt
    expected = np.eye(4)
    expected[:3, :3] = matrix_from_rotvec(w * 8 / tiny_seq.fps) @ T6[:3, :3]
    expected[:3, 3] = T6[:3, 3] + (T6[:3, 3] - T0[:3, 3]) / dt * 8 / tiny_seq.fps
    np.testing.assert_allclose(est[14].T_cam_obj, expected, atol=1e-12)
    assert main(["trackers"]) == 0
    assert NAME in capsys.readouterr().out


@pytest.mark.slow  # pip-installs the example plugin
def test_example_plugin_pip_installs_and_runs_through_roft_sim_run(
    tmp_path, monkeypatch, tiny_seq, clean_plugin_modules, capsys
):
    source = tmp_path / "src"
    shutil.copytree(EXAMPLE, source, ignore=shutil.ignore_patterns("build", "*.egg-info"))
    target = tmp_path / "site"
    base = [sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(target)]
    errors = []
    for extra in (["--no-build-isolation"], []):  # local build first, then an isolated one
        done = subprocess.run(
            [*base, *extra, str(source)], capture_output=True, text=True, timeout=300
        )
        if done.returncode == 0:
            break
        errors.append(done.stderr.strip().splitlines()[-1:] if done.stderr else "")
    else:
        pytest.skip(f"pip could not build the example plugin here (no index access?): {errors}")
    monkeypatch.syspath_prepend(str(target))
    invalidate_caches()
    est = _run_plugin(tiny_seq)
    assert est[-1].valid and np.isfinite(est[-1].T_cam_obj).all()
    # the same plugin through the harness and the CLI, on a dataset written to disk
    # the analytic sequence's perfect detections are its "gt" pose set, a name files reserve
    as_detector = dataclasses.replace(
        tiny_seq, detector_pose_sets={"dope": tiny_seq.detector_poses("gt")}
    )
    dataset = write_sequence(as_detector, "fast-ycb", tmp_path / "data")
    out = tmp_path / "run"
    argv = ["run", str(dataset), "--tracker", NAME, "--faults", "paper", "--flow", "none",
            "--masks", "none", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics[tiny_seq.name]["frames"] == len(tiny_seq)
    assert np.isfinite(metrics["ALL"]["rmse_t_cm"])
    assert NAME in capsys.readouterr().out or (out / "run.json").is_file()
