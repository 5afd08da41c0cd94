"""DOPE-like pose estimator: each error term against its configured statistics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from roft_sim.datasets.base import DetectorPoses
from roft_sim.errors import ConfigError
from roft_sim.geometry import transform_from_rt
from roft_sim.metrics import pose_error_tangent
from roft_sim.records import PoseTrack
from roft_sim.sensors.pose_estimator import (
    OUTLIER_FLIP,
    OUTLIER_JUMP,
    OUTLIER_NONE,
    PoseEstimatorConfig,
    sample_pose_detections,
    simulate_pose_detections,
)

NOTHING = PoseEstimatorConfig(
    lateral_sigma_per_m=0.0,
    ray_sigma_per_m=0.0,
    ray_bias_per_m=0.0,
    rotation_sigma_rad=0.0,
    outlier_fraction=0.0,
    miss_probability=0.0,
    occlusion_miss_gain=0.0,
)


def _static_track(n: int, t_m=(0.1, -0.05, 0.6), seed: int = 0) -> PoseTrack:
    R = Rotation.random(random_state=seed).as_matrix()
    T = np.broadcast_to(transform_from_rt(R, t_m), (n, 4, 4)).copy()
    return PoseTrack(
        t_s=np.arange(n) / 30, T_cam_obj=T, v_obj_mps=np.zeros((n, 3)), w_radps=np.zeros((n, 3))
    )


def test_zero_error_config_returns_ground_truth():
    gt = _static_track(50)
    det = simulate_pose_detections(gt, NOTHING, np.random.default_rng(0))
    assert isinstance(det, DetectorPoses) and det.valid.all()
    np.testing.assert_allclose(det.T_cam_obj, gt.T_cam_obj, atol=1e-15)


def test_core_translation_errors_scale_with_distance_along_and_across_the_ray():
    cfg = dataclasses.replace(
        NOTHING,
        lateral_sigma_per_m=0.01,
        ray_sigma_per_m=0.03,
        ray_bias_per_m=0.02,
        error_correlation=0.0,
    )
    for dist in (0.5, 1.0):
        t = np.array([0.3, -0.2, 1.0])
        t = t / np.linalg.norm(t) * dist
        gt = _static_track(20000, t)
        det = simulate_pose_detections(gt, cfg, np.random.default_rng(1))
        err = det.T_cam_obj[:, :3, 3] - t
        u = t / dist
        along = err @ u
        across = err - along[:, None] * u
        assert along.mean() == pytest.approx(0.02 * dist, abs=4 * 0.03 * dist / np.sqrt(20000))
        assert along.std() == pytest.approx(0.03 * dist, rel=0.03)
        assert np.sqrt((across**2).sum(1).mean() / 2) == pytest.approx(0.01 * dist, rel=0.03)


def test_rotation_error_is_a_left_perturbation_with_the_configured_std_and_correlation():
    cfg = dataclasses.replace(NOTHING, rotation_sigma_rad=0.05, error_correlation=0.8)
    gt = _static_track(20000)
    det = simulate_pose_detections(gt, cfg, np.random.default_rng(2))
    r = pose_error_tangent(gt.T_cam_obj, det.T_cam_obj)[:, 3:]  # R_est = exp(r) R_gt
    assert r.std(axis=0) == pytest.approx([0.05] * 3, rel=0.06)
    lag1 = [np.corrcoef(r[:-1, i], r[1:, i])[0, 1] for i in range(3)]
    assert lag1 == pytest.approx([0.8] * 3, abs=0.02)


def test_visibility_scales_errors_and_misses():
    cfg = dataclasses.replace(
        NOTHING,
        rotation_sigma_rad=0.05,
        error_correlation=0.0,
        visibility_error_gain=2.0,
        occlusion_miss_gain=0.5,
        min_visible_fraction=0.1,
    )
    n = 20000
    gt = _static_track(n)
    vis = np.where(np.arange(n) < n // 2, 1.0, 0.5)
    sample = sample_pose_detections(gt, cfg, np.random.default_rng(3), visible_fraction=vis)
    r = pose_error_tangent(gt.T_cam_obj, sample.T_cam_obj)[:, 3:]
    full, half = sample.valid & (vis == 1.0), sample.valid & (vis == 0.5)
    assert r[full].std() == pytest.approx(0.05, rel=0.05)
    assert r[half].std() == pytest.approx(0.05 * 2.0, rel=0.05)  # 1 + 2 (1 - 0.5)
    assert sample.valid[: n // 2].all()
    misses = int((~sample.valid[n // 2 :]).sum())  # p = 0.5 * 0.5 = 0.25
    lo, hi = stats.binom.interval(0.999, n // 2, 0.25)
    assert lo <= misses <= hi
    hidden = sample_pose_detections(
        gt, cfg, np.random.default_rng(3), visible_fraction=np.full(n, 0.05)
    )
    assert not hidden.valid.any()
    assert (hidden.T_cam_obj == np.eye(4)).all()


def test_outlier_episodes_fraction_duration_and_kinds():
    cfg = dataclasses.replace(
        NOTHING,
        outlier_fraction=0.05,
        outlier_mean_duration_frames=3.0,
        outlier_flip_share=0.4,
        jump_min_m=0.2,
        jump_max_m=0.5,
    )
    n = 60000
    gt = _static_track(n)
    s = sample_pose_detections(gt, cfg, np.random.default_rng(4))
    out = s.outlier_kind != OUTLIER_NONE
    assert out.mean() == pytest.approx(0.05, abs=0.006)
    starts = np.flatnonzero(out[1:] & ~out[:-1])
    assert out.sum() / max(len(starts), 1) == pytest.approx(3.0, rel=0.1)  # mean episode length
    flips = s.outlier_kind == OUTLIER_FLIP
    assert flips.sum() / out.sum() == pytest.approx(0.4, abs=0.06)
    # A flip is a rotation by pi about one of the OBJECT's axes, position untouched.
    R_rel = np.einsum("nji,njk->nik", gt.T_cam_obj[flips, :3, :3], s.T_cam_obj[flips, :3, :3])
    rv = Rotation.from_matrix(R_rel).as_rotvec()
    assert np.allclose(np.linalg.norm(rv, axis=1), np.pi)
    assert np.allclose(np.sort(np.abs(rv), axis=1)[:, :2], 0, atol=1e-9)
    np.testing.assert_allclose(s.T_cam_obj[flips, :3, 3], gt.T_cam_obj[flips, :3, 3])
    jumps = s.outlier_kind == OUTLIER_JUMP
    d = np.linalg.norm(s.T_cam_obj[jumps, :3, 3] - gt.T_cam_obj[jumps, :3, 3], axis=1)
    assert d.min() >= 0.2 - 1e-12 and d.max() <= 0.5 + 1e-12
    angle = Rotation.from_matrix(
        np.einsum("nij,nkj->nik", s.T_cam_obj[jumps, :3, :3], gt.T_cam_obj[jumps, :3, :3])
    ).magnitude()
    assert angle.max() <= np.pi / 2 + 1e-9 and angle.mean() == pytest.approx(np.pi / 4, rel=0.1)


def test_deterministic_per_seed():
    gt = _static_track(500)
    a = simulate_pose_detections(gt, PoseEstimatorConfig(), np.random.default_rng(9))
    b = simulate_pose_detections(gt, PoseEstimatorConfig(), np.random.default_rng(9))
    c = simulate_pose_detections(gt, PoseEstimatorConfig(), np.random.default_rng(10))
    np.testing.assert_array_equal(a.T_cam_obj, b.T_cam_obj)
    np.testing.assert_array_equal(a.valid, b.valid)
    assert not np.array_equal(a.T_cam_obj, c.T_cam_obj)


def test_config_validation_and_toml(tmp_path):
    from roft_sim.config_files import load_dataclass_toml

    with pytest.raises(ConfigError, match="outlier_fraction must be in"):
        PoseEstimatorConfig(outlier_fraction=1.0)
    with pytest.raises(ConfigError, match="jump_max_m"):
        PoseEstimatorConfig(jump_min_m=0.5, jump_max_m=0.1)
    path = tmp_path / "dope.toml"
    path.write_text("outlier_fraction = 0.0\nrotation_sigma_rad = 0.1\n")
    cfg = load_dataclass_toml(PoseEstimatorConfig, path)
    assert cfg.outlier_fraction == 0.0 and cfg.rotation_sigma_rad == 0.1
    with pytest.raises(ValueError, match="visible_fraction"):
        simulate_pose_detections(
            _static_track(3), cfg, np.random.default_rng(0), visible_fraction=[1.0, 2.0, 1.0]
        )
