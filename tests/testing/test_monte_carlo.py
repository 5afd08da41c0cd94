"""The Monte-Carlo pose scenarios draw from exactly the stated model (sample statistics against
the formulas), reproducibly, and match a PoseUKFConfig."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.errors import ConfigError
from roft_sim.faults import load_faults
from roft_sim.geometry import rotvec_from_matrix
from roft_sim.testing import (
    ConstantVelocityPoseModel,
    check_error_consistency,
    draw_pose_scenario,
    run_pose_monte_carlo,
    tracker_for,
)
from roft_sim.testing.monte_carlo import POSE_SET
from roft_sim.trackers.roft import PoseUKFConfig

MODEL = ConstantVelocityPoseModel(
    accel_psd_m2ps3=(1.0, 2.0, 0.5),
    angular_rw_var_radps2=(0.01, 0.02, 0.04),
    position_noise_var_m2=(1e-4, 4e-4, 9e-4),
    rotation_noise_var_rad2=(1e-3, 4e-3, 9e-3),
)


def _relative(sample_var, expected):
    return np.abs(np.asarray(sample_var) / np.asarray(expected) - 1.0)


def test_truth_increments_and_detector_noise_have_the_model_covariances():
    n, fps = 20000, 30
    scenario = draw_pose_scenario(MODEL, n_frames=n, rng=np.random.default_rng(0), fps=fps)
    truth, dt = scenario.truth, 1.0 / fps
    dv = np.diff(truth.v_obj_mps, axis=0)
    dw = np.diff(truth.w_radps, axis=0)
    p = truth.T_cam_obj[:, :3, 3]
    dp = p[1:] - p[:-1] - truth.v_obj_mps[:-1] * dt
    tol = 4 * np.sqrt(2 / n)  # 4 standard errors of a sample variance
    S = np.asarray(MODEL.accel_psd_m2ps3)
    assert _relative(dv.var(axis=0), S * dt).max() < tol
    assert _relative(dp.var(axis=0), S * dt**3 / 3).max() < tol
    np.testing.assert_allclose(np.mean(dp * dv, axis=0), S * dt**2 / 2, rtol=tol)
    assert _relative(dw.var(axis=0), MODEL.angular_rw_var_radps2).max() < tol
    # orientation integrates the angular velocity of the previous frame, camera frame
    R = truth.T_cam_obj[:, :3, :3]
    step = rotvec_from_matrix(R[1:] @ np.swapaxes(R[:-1], 1, 2))
    np.testing.assert_allclose(step, truth.w_radps[:-1] * dt, atol=1e-12)
    detected = scenario.sequence.detector_poses(POSE_SET).T_cam_obj
    assert _relative((detected[:, :3, 3] - p).var(axis=0), MODEL.position_noise_var_m2).max() < tol
    n_q = rotvec_from_matrix(detected[:, :3, :3] @ np.swapaxes(R, 1, 2))  # left perturbation
    assert _relative(n_q.var(axis=0), MODEL.rotation_noise_var_rad2).max() < tol


def test_the_first_frame_is_drawn_around_the_prior_with_its_covariance():
    rng = np.random.default_rng(1)
    errors = []
    for _ in range(400):
        s = draw_pose_scenario(MODEL, n_frames=1, rng=rng)
        T0, T = s.initial.T_cam_obj, s.truth.T_cam_obj[0]
        r = rotvec_from_matrix(T[:3, :3] @ T0[:3, :3].T)
        errors.append(np.concatenate([T[:3, 3] - T0[:3, 3], r, s.truth.v_obj_mps[0],
                                      s.truth.w_radps[0]]))  # fmt: skip
    P0 = MODEL.initial_covariance()
    e = np.array(errors)[:, None]
    assert check_error_consistency(e, np.broadcast_to(P0, e.shape[:2] + P0.shape)).passed
    assert s.initial.k == 0 and np.array_equal(s.initial.covariance, P0)
    assert np.all(s.initial.v_obj_mps == 0) and np.all(s.initial.w_radps == 0)


def test_matching_copies_a_pose_ukf_config():
    cfg = PoseUKFConfig(sigma_linear=(2.0, 2.0, 2.0), meas_cov_x=(1e-2, 1e-2, 1e-2))
    model = ConstantVelocityPoseModel.matching(cfg, start_position_m=(0.1, 0.0, 0.8))
    assert model.accel_psd_m2ps3 == cfg.sigma_linear
    assert model.angular_rw_var_radps2 == cfg.sigma_angular
    assert model.position_noise_var_m2 == cfg.meas_cov_x
    assert model.rotation_noise_var_rad2 == cfg.meas_cov_q
    assert model.initial_velocity_var_m2ps2 == cfg.cov_v0
    assert model.start_position_m == (0.1, 0.0, 0.8)


def test_bad_settings_are_config_errors():
    with pytest.raises(ConfigError, match="position_noise_var_m2 must be > 0"):
        ConstantVelocityPoseModel(position_noise_var_m2=(0.0, 1.0, 1.0))
    with pytest.raises(ConfigError, match="accel_psd_m2ps3 must be three finite values >= 0"):
        ConstantVelocityPoseModel(accel_psd_m2ps3=(-1.0, 1.0, 1.0))
    with pytest.raises(ConfigError, match="runs must be >= 1"):
        run_pose_monte_carlo(lambda s: None, MODEL, load_faults("none"), runs=0, n_frames=3,
                             seed=0)  # fmt: skip


def test_runs_are_independent_and_reproducible():
    make = lambda seq: tracker_for("pose-only-ukf", seq)  # noqa: E731
    a = run_pose_monte_carlo(make, MODEL, load_faults("paper"), runs=3, n_frames=20, seed=5)
    b = run_pose_monte_carlo(make, MODEL, load_faults("paper"), runs=3, n_frames=20, seed=5)
    assert len(a.estimates) == 3 and all(len(run) == 20 for run in a.estimates)
    for x, y in zip(a.estimates, b.estimates, strict=True):
        assert all(np.array_equal(e.T_cam_obj, f.T_cam_obj) for e, f in zip(x, y, strict=True))
    first = [t.T_cam_obj[5, 0, 3] for t in a.truths]
    assert len(set(first)) == 3  # each run draws its own truth
