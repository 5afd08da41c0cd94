"""The reference's held "DOPE" scoring policy and the start-of-sequence miss stretch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from roft_sim.datasets.base import DetectorPoses
from roft_sim.errors import ConfigError
from roft_sim.records import PoseTrack
from roft_sim.sensors.dope_calibration import held_detection_estimates
from roft_sim.sensors.pose_estimator import PoseEstimatorConfig, sample_pose_detections


def _reference_load_dope(values: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, int]:
    """The reference ``data_loader.load_dope`` (simulated inference) written out step by step on
    one scalar per frame: shift by 6 with edge padding, keep every 6th, repeat each 6 times,
    replace a missing value by the last valid one, drop the frames before the first valid."""
    n = len(values)
    shifted = np.concatenate([np.repeat(values[:1], 6), values])[:n]
    shifted_ok = np.concatenate([np.repeat(valid[:1], 6), valid])[:n]
    kept, kept_ok = shifted[::6], shifted_ok[::6]
    held = np.repeat(kept, 6)[:n].astype(float)
    held_ok = np.repeat(kept_ok, 6)[:n]
    last = np.nan
    for k in range(n):
        if held_ok[k]:
            last = held[k]
        held[k] = last
    first = int(np.flatnonzero(~np.isnan(held))[0])
    return held, first


@pytest.mark.parametrize("seed", range(5))
def test_held_detections_match_the_reference_policy(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 120))
    valid = rng.random(n) < 0.6
    valid[int(rng.integers(0, n // 2)) // 6 * 6] = True  # at least one usable frame
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, 0, 3] = np.arange(n)  # the frame index, to see which detection is held
    T_held, ok = held_detection_estimates(DetectorPoses(T_cam_obj=T, valid=valid))
    expected, first = _reference_load_dope(np.arange(n, dtype=float), valid)
    assert not ok[:first].any() and ok[first:].all()
    np.testing.assert_array_equal(T_held[first:, 0, 3], expected[first:])


def test_held_detections_reject_bad_timing():
    det = DetectorPoses(T_cam_obj=np.broadcast_to(np.eye(4), (3, 4, 4)), valid=np.ones(3, bool))
    with pytest.raises(ConfigError, match="period_frames"):
        held_detection_estimates(det, period_frames=0)


def _track(n: int) -> PoseTrack:
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, 2, 3] = 0.6
    return PoseTrack(
        t_s=np.arange(n) / 30, T_cam_obj=T, v_obj_mps=np.zeros((n, 3)), w_radps=np.zeros((n, 3))
    )


def test_start_miss_stretch_has_the_configured_rate_and_mean_length():
    config = PoseEstimatorConfig(
        miss_probability=0.0, start_miss_probability=0.3, start_miss_mean_frames=40.0
    )
    lengths = []
    for seed in range(600):
        valid = sample_pose_detections(_track(400), config, np.random.default_rng(seed)).valid
        lengths.append(int(np.argmax(valid)))
    lengths_arr = np.array(lengths)
    stretched = lengths_arr[lengths_arr > 0]
    assert abs(len(stretched) / 600 - 0.3) < 0.06
    assert abs(stretched.mean() - 40.0) < 6.0


def test_start_miss_stretch_leaves_the_other_draws_unchanged():
    base = PoseEstimatorConfig()
    with_stretch = dataclasses.replace(base, start_miss_probability=1.0, start_miss_mean_frames=5)
    a = sample_pose_detections(_track(60), base, np.random.default_rng(3))
    b = sample_pose_detections(_track(60), with_stretch, np.random.default_rng(3))
    first = int(np.argmax(b.valid))
    assert first >= 1 and not b.valid[:first].any()
    np.testing.assert_array_equal(a.valid[first:], b.valid[first:])
    np.testing.assert_array_equal(a.T_cam_obj[first:], b.T_cam_obj[first:])


def test_start_miss_config_is_checked():
    with pytest.raises(ConfigError, match="start_miss_mean_frames"):
        PoseEstimatorConfig(start_miss_mean_frames=0.5)
    with pytest.raises(ConfigError, match="start_miss_probability"):
        PoseEstimatorConfig(start_miss_probability=1.5)


# ------------------------------------------------------- the per-object Table I calibration
def test_fast_ycb_objects_get_their_own_fit_unless_an_estimator_is_given():
    from roft_sim.sensors.networks import PoseSetConfig
    from roft_sim.sensors.pose_estimator import FAST_YCB_DOPE

    assert len(FAST_YCB_DOPE) == 6
    default = PoseSetConfig()
    for name, config in FAST_YCB_DOPE.items():
        assert default.estimator_for(name) == config != PoseEstimatorConfig()
    assert default.estimator_for("021_bleach_cleanser") == PoseEstimatorConfig()
    custom = PoseSetConfig(estimator=PoseEstimatorConfig(rotation_sigma_rad=0.2))
    assert custom.estimator_for("009_gelatin_box").rotation_sigma_rad == 0.2
    pooled = PoseSetConfig(calibration="none")
    assert pooled.estimator_for("009_gelatin_box") == PoseEstimatorConfig()
    with pytest.raises(ConfigError, match="calibration"):
        PoseSetConfig(calibration="paper")  # type: ignore[arg-type]


TABLE1_AUC_TOLERANCE = 3.0
"""Issue 15's goal: each object within 3 ADD-AUC points of Table I's DOPE column."""
ALL_AUC_TOLERANCE = 2.0
"""... and ALL within 2 points of 58.83 %."""


@pytest.mark.slow
@pytest.mark.shared_data
def test_held_dope_reproduces_table1_per_object_on_the_report_seeds(shared_ycb_dir):
    """The fit used trajectory seeds 0-9 of the fast-ycb preset's motion; this scores seeds
    100-109 (the EVALUATION split) with the real meshes' model points."""
    from roft_sim.assets import load_object
    from roft_sim.generation import preset_scenario_paths
    from roft_sim.report.paper_reference import paper_tables
    from roft_sim.sensors.dope_calibration import REPORT_SEEDS, scenario_motion_tracks, score_dope
    from roft_sim.sensors.pose_estimator import FAST_YCB_DOPE

    paths = {p.stem: p for p in preset_scenario_paths("fast-ycb")}
    tracks = {n: scenario_motion_tracks(p, REPORT_SEEDS) for n, p in paths.items()}
    points = {
        n: load_object(n, assets_dir=shared_ycb_dir, prefer="ycb").model.model_points_m
        for n in paths
    }
    held = score_dope(FAST_YCB_DOPE, tracks, points).held
    paper = paper_tables().table1["DOPE"]["add_auc_pct"]
    reached = {n: round(held[n].add_auc_pct, 2) for n in [*paths, "ALL"]}
    print("held DOPE ADD-AUC, seeds 100-109:", reached)
    for name in paths:
        assert abs(reached[name] - paper[name]) <= TABLE1_AUC_TOLERANCE, (name, reached, paper)
    assert abs(reached["ALL"] - paper["ALL"]) <= ALL_AUC_TOLERANCE
    # gelatin box: the heavy outliers behind Table I's 34.4 cm
    assert held["009_gelatin_box"].rmse_t_cm > 20.0
