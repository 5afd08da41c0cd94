"""The ``fast-ycb`` preset moved along a Fast-YCB dataset's own motion (``roft-sim paper
--motion``): the scenarios replay each object's ``gt/poses.txt`` pose for pose."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from roft_sim.assets import FAST_YCB_OBJECTS
from roft_sim.cli import main
from roft_sim.errors import ConfigError
from roft_sim.generation import preset_scenario_paths, with_fast_ycb_motion
from roft_sim.scenario import load_scenario
from roft_sim.trajectories import CapturedMotionConfig, build_trajectory

OBJECTS = FAST_YCB_OBJECTS


def _motion_rows(n: int, phase: float) -> np.ndarray:
    """(n, 7) Fast-YCB pose rows ``x y z ax ay az angle`` [m, unit axis, rad]: a smooth motion
    0.6 m in front of the camera."""
    k = np.arange(n, dtype=np.float64)
    t = np.stack(
        [0.05 * np.sin(k / 9 + phase), 0.03 * np.cos(k / 7), 0.6 + 0.04 * np.sin(k / 13)], axis=1
    )
    rotvec = np.stack([0.4 + 0.01 * k, 0.2 * np.sin(k / 11 + phase), 0.1 + 0.0 * k], axis=1)
    angle = np.linalg.norm(rotvec, axis=1, keepdims=True)
    return np.hstack([t, rotvec / angle, angle])


def _write_motion(root: Path, n: int = 40, objects: tuple[str, ...] = OBJECTS) -> Path:
    for i, name in enumerate(objects):
        gt = root / name / "gt"
        gt.mkdir(parents=True)
        rows = _motion_rows(n, phase=0.5 * i)
        (gt / "poses.txt").write_text("".join(" ".join(f"{v:.9f}" for v in r) + "\n" for r in rows))
    return root


def test_each_preset_scenario_replays_its_objects_poses(tmp_path):
    root = _write_motion(tmp_path / "fast-ycb", n=40)
    for i, path in enumerate(preset_scenario_paths("fast-ycb")):
        preset = load_scenario(path)
        scenario = with_fast_ycb_motion(preset, root)
        name = preset.object.name_or_path
        assert name == OBJECTS[i]
        assert isinstance(scenario.trajectory, CapturedMotionConfig)
        assert scenario.trajectory.path == (root / name).resolve()
        # 40 poses where the preset asks for 880 frames: the file's length
        assert preset.n_frames == 880 and scenario.n_frames == 40
        assert (scenario.object, scenario.camera, scenario.seed) == (
            preset.object,
            preset.camera,
            preset.seed,
        )
        trajectory = build_trajectory(scenario.trajectory, scenario.intrinsics)
        sample = trajectory.sample(np.arange(scenario.n_frames) / scenario.fps)
        rows = _motion_rows(40, phase=0.5 * i)
        np.testing.assert_allclose(sample.T_ref_obj[:, :3, 3], rows[:, :3], atol=1e-7)
        R = Rotation.from_rotvec(rows[:, 3:6] * rows[:, 6:7]).as_matrix()
        np.testing.assert_allclose(sample.T_ref_obj[:, :3, :3], R, atol=1e-7)


def test_a_longer_motion_keeps_the_scenarios_frames(tmp_path):
    root = _write_motion(tmp_path, n=900, objects=("003_cracker_box",))
    preset = load_scenario(preset_scenario_paths("fast-ycb")[0])
    assert with_fast_ycb_motion(preset, root).n_frames == 880


def test_a_missing_object_or_a_mesh_file_is_refused_with_the_fix(tmp_path):
    root = _write_motion(tmp_path, objects=("003_cracker_box",))
    second = load_scenario(preset_scenario_paths("fast-ycb")[1])
    with pytest.raises(ConfigError, match=r"no Fast-YCB motion for 004_sugar_box: .*gt/poses.txt"):
        with_fast_ycb_motion(second, root)
    as_file = dataclasses.replace(
        second, object=dataclasses.replace(second.object, name=None, mesh=tmp_path / "m.obj")
    )
    with pytest.raises(ConfigError, match="looked up by object name"):
        with_fast_ycb_motion(as_file, root)


def test_paper_cli_checks_the_motion_before_touching_the_output(tmp_path, capsys):
    out = tmp_path / "paper"
    out.mkdir()
    (out / "keep.txt").write_text("earlier results")
    partial = _write_motion(tmp_path / "partial", objects=OBJECTS[:5])
    bad_rows = _write_motion(tmp_path / "bad", objects=OBJECTS)
    (bad_rows / OBJECTS[2] / "gt" / "poses.txt").write_text("1 2 3\n")
    base = ["paper", "--out", str(out), "--overwrite", "--no-plugins", "--rows", "detector"]
    for extra, message in (
        (["--motion", str(tmp_path / "nowhere")], "is not a folder"),
        (["--motion", str(partial)], "no Fast-YCB motion for 010_potted_meat_can"),
        (["--motion", str(bad_rows)], "--motion: .*3 fields, expected 7"),
        (["--motion", str(partial), "--reuse", str(partial)], "drop one of them"),
    ):
        assert main([*base, *extra]) == 2, extra
        err = capsys.readouterr().err
        assert re.search(message, err), (message, err)
        assert (out / "keep.txt").exists(), extra


@pytest.mark.render
def test_paper_generates_the_sequences_on_the_given_motion(tmp_path, capsys):
    """The generated sequences' ground truth is the motion file's poses, frame for frame."""
    from roft_sim.datasets import open_sequence

    root = _write_motion(tmp_path / "fast-ycb", n=40)
    out = tmp_path / "paper"
    args = ["paper", "--out", str(out), "--motion", str(root), "--resolution", "64x36"]
    args += ["--frames", "3", "--rows", "detector", "--no-plugins", "--no-progress", "--json"]
    assert main(args) == 0
    capsys.readouterr()
    record = json.loads((out / "paper.json").read_text())
    assert record["dataset"]["motion"] == str(root)
    for i, name in enumerate(OBJECTS):
        gt = open_sequence(out / "dataset" / name).ground_truth()
        rows = _motion_rows(3, phase=0.5 * i)
        np.testing.assert_allclose(gt.T_cam_obj[:, :3, 3], rows[:, :3], atol=1e-6)
        R = Rotation.from_rotvec(rows[:, 3:6] * rows[:, 6:7]).as_matrix()
        np.testing.assert_allclose(gt.T_cam_obj[:, :3, :3], R, atol=1e-6)
