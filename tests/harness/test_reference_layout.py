"""`roft-sim run --layout reference`: the tree the reference ROFT evaluation scores unchanged.

The tree is checked file by file against what hsp-iit/roft ``evaluation/data_loader.py``,
``metrics.py`` and ``evaluate.py`` open (names, columns, frames, no all-zero rows), and the
reference's numbers are recomputed here from its formulas (docs/metrics.md;
shared/reference/metrics_faults_flow.md), independently of roft_sim.metrics, and compared with
ours. The reference's DOPE row (``load_dope`` with ``simulate_inference``) is transcribed too and
compared with detector-hold under ``--invalid hold``.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from harness_cases import box_sequence

from roft_sim.cli import main
from roft_sim.datasets import write_sequence
from roft_sim.datasets.base import DetectorPoses
from roft_sim.harness.reference_layout import (
    REFERENCE_EXPERIMENTS,
    REFERENCE_OBJECTS,
    REFERENCE_RESULT_FILES,
    REFERENCE_ROFT_CONFIG,
    ReferenceTree,
    reference_config_name,
)
from roft_sim.trackers.roft import ablation_config

N_FRAMES = 30
CONFIG = "full_mask_mrcnn_of_none_pose_dope_detector_hold"


# --------------------------------------------------------- the reference's formulas, transcribed
def _load_generic(path: Path) -> np.ndarray:
    """``DataLoader.load_generic``: rows of space-separated floats."""
    rows = []
    with open(path, newline="") as f:
        for row in f:
            rows.append([float(x.rstrip()) for x in row.rstrip().split(sep=" ") if x != ""])
    return np.array(rows)


def _rotation_from_axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """pyquaternion ``Quaternion(axis=..., angle=...).rotation_matrix`` (axis normalised: a
    zero axis is the ZeroDivisionError the reference hits on all-zero rows)."""
    norm = float(np.linalg.norm(axis))
    if norm == 0.0:
        raise ZeroDivisionError("zero axis")
    x, y, z = np.sin(angle / 2) * np.asarray(axis) / norm
    w = np.cos(angle / 2)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _log_norm(R: np.ndarray) -> float:
    """``r_to_log``: the rotation angle of R [rad]."""
    return float(np.arccos(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))


def _vocap(distances: np.ndarray) -> float:
    """``Metric.auc`` + ``bop_pose_error.VOCap``, percent."""
    d = distances.copy()
    d[d > 0.1] = np.inf
    rec = np.sort(d)
    n = len(rec)
    prec = np.cumsum(np.ones(n, np.float32)) / n
    keep = np.isfinite(rec)
    rec, prec = rec[keep], prec[keep]
    if len(rec) == 0:
        return 0.0
    mrec = np.append(np.insert(rec, 0, 0), 0.1)
    mpre = np.append(np.insert(prec, 0, 0), prec[-1])
    for i in range(1, len(mpre)):
        mpre[i] = max(mpre[i], mpre[i - 1])
    i = np.where(mrec[1:] != mrec[:-1])[0] + 1
    return float(np.sum((mrec[i] - mrec[i - 1]) * mpre[i]) * 10 * 100)


def _reference_errors(gt: np.ndarray, est: np.ndarray, points: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame ADD [m], position error [cm] and rotation error [deg] of (N, 7) rows."""
    add, t_err, a_err = [], [], []
    for g, e in zip(gt, est, strict=True):
        R_g = _rotation_from_axis_angle(g[3:6], g[6])
        R_e = _rotation_from_axis_angle(e[3:6], e[6])
        add.append(
            np.linalg.norm((points @ R_e.T + e[:3]) - (points @ R_g.T + g[:3]), axis=1).mean()
        )
        t_err.append(np.linalg.norm((g[:3] - e[:3]) * 100.0))
        a_err.append(_log_norm(R_g @ R_e.T) * 180.0 / np.pi)
    return {"add": np.array(add), "t": np.array(t_err), "a": np.array(a_err)}


def _rmse(x: np.ndarray) -> float:
    return float(np.linalg.norm(x) / np.sqrt(x.shape[0]))


# ------------------------------------------------------------------------------------ fixtures
def _object_sequence(
    obj: str, seed: int, valid: np.ndarray | None = None, *, n_frames: int = N_FRAMES
):
    seq = box_sequence(n_frames=n_frames, name=obj, seed=seed)
    if valid is not None:
        poses = seq.detector_pose_sets["dope"]
        T = poses.T_cam_obj.copy()
        T[~valid] = np.eye(4)
        seq = dataclasses.replace(
            seq, detector_pose_sets={"dope": DetectorPoses(T_cam_obj=T, valid=valid)}
        )
    return dataclasses.replace(seq, object_name=obj)


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory):
    data = tmp_path_factory.mktemp("data")
    for i, obj in enumerate(REFERENCE_OBJECTS):
        write_sequence(_object_sequence(obj, seed=20 + i), "fast-ycb", data)
    out = tmp_path_factory.mktemp("run") / "out"
    code = main(
        [
            "run",
            str(data),
            "--tracker",
            "detector-hold",
            "--flow",
            "none",
            "--masks",
            "mrcnn",
            "--layout",
            "reference",
            "--out",
            str(out),
            "--no-progress",
        ]
    )
    assert code == 0
    return data, out


def test_the_tree_holds_every_file_the_reference_opens(reference_run):
    data, out = reference_run
    assert sorted(p.name for p in (out / "results" / "ROFT_results" / "fastycb").iterdir()) == [
        CONFIG
    ]
    for obj in REFERENCE_OBJECTS:
        results = out / "results" / "ROFT_results" / "fastycb" / CONFIG / obj
        assert sorted(p.name for p in results.iterdir()) == sorted(REFERENCE_RESULT_FILES)
        columns = {
            "pose_estimate_ycb.txt": 13,
            "velocity_estimate.txt": 6,
            "execution_times.txt": 2,
            "pose_measurements.txt": 7,
            "velocity_measurements.txt": 6,
        }
        for name, width in columns.items():
            rows = _load_generic(results / name)
            assert rows.shape == (N_FRAMES, width), name
            assert np.isfinite(rows).all(), name
        for name in ("pose_estimate_ycb.txt", "pose_measurements.txt"):
            rows = _load_generic(results / name)
            assert not np.all(rows[:, -7:] == 0.0, axis=1).any(), f"all-zero row in {name}"
            assert np.allclose(np.linalg.norm(rows[:, -4:-1], axis=1), 1.0), name
        dataset = out / "dataset" / "fast-ycb" / obj
        cam = json.loads((dataset / "cam_K.json").read_text())
        assert {"fx", "fy", "cx", "cy", "width", "height"} <= set(cam)
        ours = data / obj
        # the reference's frames are ours: poses_ycb.txt and points.xyz are in the object frame
        # of our poses (reference_layout docstring), so gt/poses_ycb.txt is our gt/poses.txt
        # (rows pass through a rotation matrix: equal to 1e-12)
        for rel, source in (
            ("gt/poses.txt", "gt/poses.txt"),
            ("gt/poses_ycb.txt", "gt/poses.txt"),
            ("gt/velocities.txt", "gt/velocities.txt"),
            ("dope/poses.txt", "dope/poses.txt"),
            ("dope/poses_ycb.txt", "dope/poses.txt"),
        ):
            np.testing.assert_allclose(
                _load_generic(dataset / rel), _load_generic(ours / source), rtol=0, atol=1e-12
            )
        points = _load_generic(out / "YCB_Video_Models" / "models" / obj / "points.xyz")
        np.testing.assert_array_equal(points, _load_generic(ours / "models" / obj / "points.xyz"))
    run = json.loads((out / "run.json").read_text())
    assert run["layout"] == "reference" and run["reference_config"] == CONFIG


def _assert_reference_numbers(out: Path, config: str, objects: tuple[str, ...], n: int) -> None:
    """evaluate.py for 'ours' on the tree: every row scored (velocity rows included, frame 0
    too), v = v_o + w x t_gt, ALL pools every frame; equal to our metrics.json."""
    metrics = json.loads((out / "metrics.json").read_text())
    pooled: dict[str, list[np.ndarray]] = {"add": [], "t": [], "a": [], "v": [], "w": []}
    for obj in objects:
        results = out / "results" / "ROFT_results" / "fastycb" / config / obj
        gt = _load_generic(out / "dataset" / "fast-ycb" / obj / "gt" / "poses_ycb.txt")
        gt_vel = _load_generic(out / "dataset" / "fast-ycb" / obj / "gt" / "velocities.txt")
        pose = _load_generic(results / "pose_estimate_ycb.txt")[:, 6:]
        vel = _load_generic(results / "velocity_estimate.txt")
        for i in range(gt_vel.shape[0]):
            vel[i, 0:3] = vel[i, 0:3] + np.cross(vel[i, 3:6], gt[i, 0:3])
        points = _load_generic(out / "YCB_Video_Models" / "models" / obj / "points.xyz")
        errors = _reference_errors(gt, pose, points)
        errors["v"] = np.linalg.norm((gt_vel[:, :3] - vel[:, :3]) * 100.0, axis=1)
        errors["w"] = np.linalg.norm((gt_vel[:, 3:] - vel[:, 3:]) * 180.0 / np.pi, axis=1)
        ours = metrics[obj]
        assert ours["frames"] == n and ours["frames_invalid"] == 0
        assert ours["frames_velocity"] == n  # the reference scores every velocity row
        assert _vocap(errors["add"]) == pytest.approx(ours["add_auc_pct"], rel=1e-12)
        assert _rmse(errors["t"]) == pytest.approx(ours["rmse_t_cm"], rel=1e-9)
        assert _rmse(errors["a"]) == pytest.approx(ours["rmse_a_deg"], rel=1e-7)
        assert _rmse(errors["v"]) == pytest.approx(ours["rmse_v_cmps"], rel=1e-9)
        assert _rmse(errors["w"]) == pytest.approx(ours["rmse_w_dps"], rel=1e-9)
        for key in pooled:
            pooled[key].append(errors[key])
    every = {key: np.concatenate(values) for key, values in pooled.items()}
    assert _vocap(every["add"]) == pytest.approx(metrics["ALL"]["add_auc_pct"], rel=1e-12)
    assert _rmse(every["t"]) == pytest.approx(metrics["ALL"]["rmse_t_cm"], rel=1e-9)
    assert _rmse(every["v"]) == pytest.approx(metrics["ALL"]["rmse_v_cmps"], rel=1e-9)
    assert _rmse(every["w"]) == pytest.approx(metrics["ALL"]["rmse_w_dps"], rel=1e-9)
    assert 0.0 < metrics["ALL"]["add_auc_pct"] < 100.0  # the numbers compared are not trivial


def test_the_reference_numbers_equal_ours(reference_run):
    _, out = reference_run
    _assert_reference_numbers(out, CONFIG, REFERENCE_OBJECTS, N_FRAMES)


ROFT_OBJECTS = REFERENCE_OBJECTS[:2]
ROFT_FRAMES = 15


@pytest.fixture(scope="module")
def roft_reference_run(tmp_path_factory):
    data = tmp_path_factory.mktemp("roft_data")
    for i, obj in enumerate(ROFT_OBJECTS):
        write_sequence(_object_sequence(obj, seed=40 + i, n_frames=ROFT_FRAMES), "fast-ycb", data)
    out = tmp_path_factory.mktemp("roft_run") / "out"
    args = ["run", str(data), "--tracker", "roft", "--flow", "gt", "--masks", "mrcnn"]
    args += ["--layout", "reference", "--reference-config", REFERENCE_ROFT_CONFIG]
    assert main([*args, "--out", str(out), "--no-progress"]) == 0
    return out


def test_roft_reference_numbers_equal_ours_velocity_rows_included(roft_reference_run, capsys):
    """ROFT has no spatial twist on frame 0 (its velocity filter has seen no flow yet): the tree's
    row there holds its zero velocity, which the reference scores against a moving object's
    ground truth, and so do we."""
    out = roft_reference_run
    for obj in ROFT_OBJECTS:
        estimates = np.load(out / obj / "estimates.npz")
        assert not estimates["has_spatial_twist"][0] and estimates["has_spatial_twist"][1:].all()
        gt_vel = _load_generic(out / "dataset" / "fast-ycb" / obj / "gt" / "velocities.txt")
        assert np.linalg.norm(gt_vel[0, :3]) > 0.05  # frame 0's row weighs in
    _assert_reference_numbers(out, REFERENCE_ROFT_CONFIG, ROFT_OBJECTS, ROFT_FRAMES)
    run = json.loads((out / "run.json").read_text())
    assert run["reference_experiments"] == [
        "exp_fastycb_roft",
        "exp_fastycb_velocities",
        "exp_fastycb_ablation",
    ]


def test_the_run_says_which_reference_experiment_reads_its_tree(reference_run, capsys):
    """evaluate.py opens execution_times.txt first in the folder its experiment names, so a tree
    whose <config> no experiment reads (detector-hold's own name) fails there with
    FileNotFoundError: the run says so and how to be scored as the reference's ROFT row."""
    from roft_sim.cli.run import _print_reference_note

    _, out = reference_run
    assert REFERENCE_RESULT_FILES[0] == "execution_times.txt"
    run = json.loads((out / "run.json").read_text())
    assert run["reference_experiments"] == []
    tree = ReferenceTree(root=out, config_name=CONFIG, objects=REFERENCE_OBJECTS)
    _print_reference_note(tree)
    err = capsys.readouterr().err
    assert "no experiment" in err and f"--reference-config {REFERENCE_ROFT_CONFIG}" in err
    gt_inputs = REFERENCE_EXPERIMENTS["exp_fastycb_ablation"][0]
    ablation = dataclasses.replace(tree, config_name=gt_inputs)
    assert ablation.experiments == ("exp_fastycb_ablation",)
    _print_reference_note(ablation)
    err = capsys.readouterr().err
    assert "exp_fastycb_ablation" in err and f"{REFERENCE_ROFT_CONFIG}_no_pose" in err
    _print_reference_note(dataclasses.replace(tree, config_name=REFERENCE_ROFT_CONFIG))
    assert "--experiment-name exp_fastycb_roft" in capsys.readouterr().err


def _reference_dope_row(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``DataLoader.load_dope`` with ``simulate_inference`` (5 fps, 200 ms at 30 fps)."""
    skip = int((1.0 / 5) / (1 / 30.0))
    data = np.pad(rows, ((skip, 0), (0, 0)), "edge")[: rows.shape[0], :]
    data = np.repeat(data[::skip, :], skip, axis=0)[: rows.shape[0], :]
    i_0 = 0
    for i in range(data.shape[0]):
        if data[i, 0] != 0.0 and data[i, 1] != 0.0 and data[i, 2] != 0.0:
            i_0 = i
            break
    indexes = np.arange(i_0, data.shape[0])
    data = data[i_0:, :]
    for i in range(1, data.shape[0]):
        if data[i, 0] == 0.0 and data[i, 1] == 0.0 and data[i, 2] == 0.0:
            data[i, :] = data[i - 1, :]
    return data, indexes


def test_detector_hold_under_hold_is_the_reference_dope_row(tmp_path):
    """The reference's DOPE row, from the dope/poses_ycb.txt we write, equals detector-hold
    under the paper faults scored with --invalid hold (here frame 0 and frame 12 are misses, so
    the first pose arrives at frame 12 and the miss at 12 is held over)."""
    valid = np.ones(N_FRAMES, dtype=bool)
    valid[[0, 12]] = False
    obj = "004_sugar_box"
    write_sequence(_object_sequence(obj, seed=5, valid=valid), "fast-ycb", tmp_path / "data")
    out = tmp_path / "out"
    args = ["run", str(tmp_path / "data"), "--tracker", "detector-hold", "--flow", "none"]
    assert main([*args, "--masks", "none", "--layout", "reference", "--out", str(out)]) == 0
    ours = json.loads((out / "metrics.json").read_text())[obj]
    dataset = out / "dataset" / "fast-ycb" / obj
    dope, indexes = _reference_dope_row(_load_generic(dataset / "dope" / "poses_ycb.txt"))
    assert indexes[0] == 12
    gt = _load_generic(dataset / "gt" / "poses_ycb.txt")[indexes]
    points = _load_generic(out / "YCB_Video_Models" / "models" / obj / "points.xyz")
    errors = _reference_errors(gt, dope, points)
    assert ours["frames"] == len(indexes) and ours["frames_invalid"] == 12
    assert _vocap(errors["add"]) == pytest.approx(ours["add_auc_pct"], rel=1e-12)
    assert _rmse(errors["t"]) == pytest.approx(ours["rmse_t_cm"], rel=1e-9)
    assert _rmse(errors["a"]) == pytest.approx(ours["rmse_a_deg"], rel=1e-7)
    # the tracker's rows in the tree start with its first pose, back-filled (no zero rows)
    rows = _load_generic(
        out
        / "results/ROFT_results/fastycb"
        / "full_mask_none_of_none_pose_dope_detector_hold"
        / obj
        / "pose_estimate_ycb.txt"
    )
    np.testing.assert_array_equal(rows[:12, 6:], np.repeat(rows[12:13, 6:], 12, axis=0))


def test_config_names_follow_the_reference():
    inputs = {"masks": "mrcnn_ycbv_bop_pbr", "flow": "stored:nvof_1_slow", "poses": "dope"}
    base = "full_mask_mrcnn_ycbv_bop_pbr_of_nvof_1_slow_pose_dope"
    assert reference_config_name(inputs, "roft", ablation_config("full")) == base
    assert reference_config_name(inputs, "roft", ablation_config("no_outlier_rejection")) == (
        base + "_no_outrej"
    )
    assert reference_config_name(inputs, "roft", ablation_config("no_mask_sync")) == (
        base + "_no_flowaid"
    )
    gt = {"masks": "gt", "flow": "dis:medium", "poses": "gt"}
    assert (
        reference_config_name(gt, "naive-delay") == "full_mask_gt_of_dis_medium_pose_gt_naive_delay"
    )


def test_one_sequence_per_object(tmp_path, capsys):
    data = tmp_path / "data"
    for name in ("a", "b"):
        seq = dataclasses.replace(_object_sequence("003_cracker_box", 1), name=name)
        write_sequence(seq, "fast-ycb", data)
    args = ["run", str(data), "--tracker", "detector-hold", "--flow", "none", "--masks", "none"]
    assert main([*args, "--layout", "reference", "--out", str(tmp_path / "out")]) == 2
    assert "more than one sequence" in capsys.readouterr().err
