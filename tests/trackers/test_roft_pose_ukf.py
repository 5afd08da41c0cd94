"""The pose UKF: quaternion helpers, unscented transform, KF oracle, well-formedness."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from observation_schedules import scaled_examples
from scipy.spatial.transform import Rotation

from roft_sim.errors import ConfigError
from roft_sim.geometry import (
    matrix_from_quat,
    quat_angle,
    quat_from_rotvec,
    quat_multiply,
    rotvec_from_matrix,
    rotvec_from_quat,
    skew,
)
from roft_sim.testing.strategies import rotation_vectors, small_rotation_vectors, unit_quaternions
from roft_sim.trackers.roft.config import PoseUKFConfig
from roft_sim.trackers.roft.pose_ukf import (
    PoseBelief,
    PoseUKF,
    _qexp,
    _qlog,
    _qmul,
    markley_mean,
    psd_sqrt,
    unscented_weights,
)


@given(unit_quaternions(), unit_quaternions())
def test_hot_path_product_equals_geometry(a, b):
    np.testing.assert_allclose(_qmul(a, b), quat_multiply(a, b), atol=1e-15)
    batch = np.stack([a, b, quat_multiply(a, b)])  # (N, 4) with (N, 4) and with (4,)
    np.testing.assert_allclose(
        _qmul(batch, batch[::-1]), quat_multiply(batch, batch[::-1]), atol=1e-15
    )
    np.testing.assert_allclose(_qmul(batch, b), quat_multiply(batch, b), atol=1e-15)


@given(st.one_of(rotation_vectors(), small_rotation_vectors()))
def test_hot_path_exp_and_log_equal_geometry(r):
    np.testing.assert_allclose(_qexp(r[None])[0], quat_from_rotvec(r), atol=1e-15)
    q = quat_from_rotvec(r)
    np.testing.assert_allclose(_qlog(q[None])[0], rotvec_from_quat(q), atol=1e-14)
    np.testing.assert_allclose(_qlog(-q[None])[0], rotvec_from_quat(q), atol=1e-14)


def test_reference_unscented_weights():
    c, wm, wc = unscented_weights(21, 1.0, 2.0, 0.0)
    assert c == 21 and wm[0] == 0.0 and wc[0] == 2.0
    np.testing.assert_allclose(wm[1:], 1 / 42)
    assert wm.sum() == pytest.approx(1.0)
    c, wm, wc = unscented_weights(6, 0.5, 2.0, 1.0)
    assert wm.sum() == pytest.approx(1.0) and c == pytest.approx(0.25 * 7)


def test_psd_square_root():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(12, 5))
    M = A @ A.T  # rank 5: zero eigenvalues are clipped, not NaN
    S = psd_sqrt(M)
    np.testing.assert_allclose(S @ S.T, M, atol=1e-12)


def test_markley_mean_equals_scipy_mean_and_ignores_signs():
    rng = np.random.default_rng(5)
    base = Rotation.from_rotvec([0.3, -1.0, 2.0])
    rots = Rotation.from_rotvec(rng.normal(scale=0.2, size=(9, 3))) * base
    w = rng.uniform(0.1, 1.0, 9)
    q = rots.as_quat()[:, [3, 0, 1, 2]]
    q[::2] *= -1
    mean = markley_mean(q, w / w.sum())
    expected = rots.mean(weights=w).as_quat()[[3, 0, 1, 2]]
    assert quat_angle(mean, expected) < 1e-12 and mean[0] >= 0


def test_prediction_mean_follows_the_constant_velocity_model():
    cfg = PoseUKFConfig(sigma_linear=(0.0,) * 3, sigma_angular=(0.0,) * 3)
    ukf = PoseUKF(cfg)
    q0 = quat_from_rotvec([0.2, 0.1, -0.4])
    b = PoseBelief(
        x=np.r_[0.1, -0.2, 0.3, 0.5, 1.0, -2.0, 0.0, 0.1, 0.6],
        q=q0,
        P=np.diag(np.full(12, 1e-14)),  # ~ a point: the UT mean is the model's image
    )
    dt = 0.04
    out = ukf.predict(b, dt)
    np.testing.assert_allclose(out.x[6:9], b.x[6:9] + dt * b.x[0:3], atol=1e-12)
    np.testing.assert_allclose(out.x[:6], b.x[:6], atol=1e-12)
    # w is in the camera frame: the rotation is composed on the LEFT
    expected_q = quat_multiply(quat_from_rotvec(dt * b.x[3:6]), q0)
    assert quat_angle(out.q, expected_q) < 1e-10


@pytest.mark.parametrize("interval", [True, False])
def test_coasting_prediction_follows_the_gaussian_velocity_autocorrelation(interval):
    """``coast_s`` seconds without a velocity measurement: one step multiplies v and w by
    rho(t) / rho(t - dt), rho(t) = exp(-t^2 / (2 sigma^2)), and the pose integrates the decayed
    velocities; their covariance is kept. Steps from the last measured velocity compose to
    rho(t) of the whole coast."""
    cfg = PoseUKFConfig(
        sigma_linear=(0.0,) * 3,
        sigma_angular=(0.0,) * 3,
        coast_correlation_time_v_s=0.2,
        coast_correlation_time_w_s=0.11,
        integrate_interval_velocity=interval,
    )
    ukf = PoseUKF(cfg)
    q0 = quat_from_rotvec([0.2, 0.1, -0.4])
    x = np.r_[0.1, -0.2, 0.3, 0.5, 1.0, -2.0, 0.0, 0.1, 0.6]
    dt = 1 / 30

    def rho(t, sigma):
        return np.exp(-(t**2) / (2 * sigma**2))

    def point(state):
        return PoseBelief(x=state, q=q0, P=np.diag(np.full(12, 1e-14)))

    t = 3 * dt  # the third frame without a velocity measurement
    a_v, a_w = rho(t, 0.2) / rho(t - dt, 0.2), rho(t, 0.11) / rho(t - dt, 0.11)
    out = ukf.predict(point(x), dt, coast_s=t)
    np.testing.assert_allclose(out.x[0:3], a_v * x[0:3], atol=1e-12)
    np.testing.assert_allclose(out.x[3:6], a_w * x[3:6], atol=1e-12)
    if interval:  # the pose integrates the (decayed) new velocities
        np.testing.assert_allclose(out.x[6:9], x[6:9] + dt * a_v * x[0:3], atol=1e-12)
        expected_q = quat_multiply(quat_from_rotvec(dt * a_w * x[3:6]), q0)
        assert quat_angle(out.q, expected_q) < 1e-10
    spread = ukf.predict(PoseBelief(x=x, q=q0, P=np.diag(np.full(12, 1e-4))), dt, coast_s=t)
    np.testing.assert_allclose(spread.x[0:3], a_v * x[0:3], atol=1e-12)
    np.testing.assert_allclose(np.diag(spread.P)[0:6], 1e-4, rtol=1e-9)  # spread kept
    belief = point(x)  # five coasting steps leave rho(5 dt) of the last measured velocity
    for step in range(1, 6):
        belief = ukf.predict(belief, dt, coast_s=step * dt)
    np.testing.assert_allclose(belief.x[0:3], rho(5 * dt, 0.2) * x[0:3], atol=1e-12)
    np.testing.assert_allclose(belief.x[3:6], rho(5 * dt, 0.11) * x[3:6], atol=1e-12)
    # a measured frame, and the reference (no correlation times), keep a constant velocity
    reference = dataclasses.replace(
        cfg, coast_correlation_time_v_s=None, coast_correlation_time_w_s=None
    )
    for model, coast_s in ((ukf, 0.0), (PoseUKF(reference), t)):
        out = model.predict(point(x), dt, coast_s=coast_s)
        np.testing.assert_allclose(out.x[0:6], x[0:6], atol=1e-12)


@pytest.mark.parametrize("sigma", [0.0, -0.1, float("nan")])
def test_coast_correlation_times_must_be_positive(sigma):
    with pytest.raises(ConfigError, match="coast_correlation_time_w_s must be > 0 seconds"):
        PoseUKFConfig(coast_correlation_time_w_s=sigma)


def _exact_kf(x, P, steps, cfg, w, dt):
    """The linear KF on z = (v, p) when w is known exactly: v_o = v - w x p is linear in z.

    With ``integrate_interval_velocity`` the position integrates the NEW velocity
    (p' = p + dt (v + n_v) + n_p), so n_v also enters the position."""
    S = np.diag(cfg.sigma_linear)
    F = np.block([[np.eye(3), np.zeros((3, 3))], [dt * np.eye(3), np.eye(3)]])
    Q = np.block([[S * dt, S * dt**2 / 2], [S * dt**2 / 2, S * dt**3 / 3]])
    if cfg.integrate_interval_velocity:
        G = np.block([[np.eye(3), np.zeros((3, 3))], [dt * np.eye(3), np.eye(3)]])
        Q = G @ Q @ G.T
    H_vo = np.hstack([np.eye(3), -skew(w)])
    H_p = np.hstack([np.zeros((3, 3)), np.eye(3)])
    for kind, y in steps:
        x, P = F @ x, F @ P @ F.T + Q
        Hs, ys, Rs = [], [], []
        if kind in ("vel", "pose+vel"):
            Hs.append(H_vo)
            ys.append(y["v_o"])
            Rs.append(np.diag(cfg.meas_cov_v))
        if kind in ("pose", "pose+vel"):
            Hs.append(H_p)
            ys.append(y["p"])
            Rs.append(np.diag(cfg.meas_cov_x))
        H, yv = np.vstack(Hs), np.concatenate(ys)
        R = np.zeros((len(yv), len(yv)))
        i = 0
        for r in Rs:
            R[i : i + 3, i : i + 3] = r
            i += 3
        K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
        x = x + K @ (yv - H @ x)
        P = P - K @ H @ P
    return x, P


@pytest.mark.parametrize("interval", [True, False])
def test_ukf_equals_the_exact_kf_on_its_linear_gaussian_special_case(interval):
    """With w known exactly (zero variance, no w process noise) the translational model and the
    spatial-velocity and position measurements are linear in (v, p), and the unscented transform
    (augmented noise, SVD square root, alpha=1, beta=2, kappa=0) must reproduce the KF, in both
    prediction orders (``integrate_interval_velocity``; False is the reference's)."""
    cfg = PoseUKFConfig(
        sigma_angular=(0.0,) * 3,
        sigma_linear=(0.7, 1.0, 1.3),
        integrate_interval_velocity=interval,
    )
    ukf = PoseUKF(cfg)
    rng = np.random.default_rng(11)
    w = np.array([0.8, -1.5, 0.4])
    A = rng.normal(size=(6, 6)) * 0.03
    P_vp = A @ A.T + 1e-3 * np.eye(6)  # correlated initial covariance over (v, p)
    P = np.zeros((12, 12))
    idx = np.r_[0:3, 6:9]
    P[np.ix_(idx, idx)] = P_vp
    P[9:12, 9:12] = 1e-3 * np.eye(3)
    x0 = np.r_[0.2, -0.1, 0.05, w, 0.03, -0.02, 0.7]
    belief = PoseBelief(x=x0, q=quat_from_rotvec([0.1, 0.2, 0.3]), P=P)
    dt = 1 / 30
    steps = []
    for k in range(12):
        y = {"v_o": rng.normal(size=3) * 0.3, "w": w, "p": x0[6:9] + rng.normal(size=3) * 0.02}
        steps.append(("pose+vel" if k % 6 == 0 else "vel", y))
    steps.append(("pose", {"p": np.r_[0.0, 0.0, 0.69]}))
    for kind, y in steps:
        belief = ukf.predict(belief, dt)
        twist = np.r_[y["v_o"], y["w"]] if kind != "pose" else None
        pose = {}
        if kind != "vel":
            pose = {"p_meas_m": y["p"], "q_meas_wxyz": belief.q}
        belief = ukf.correct(belief, twist=twist, **pose)
    z, Pz = _exact_kf(x0[idx], P_vp, steps, cfg, w, dt)
    np.testing.assert_allclose(belief.x[idx], z, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(belief.P[np.ix_(idx, idx)], Pz, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(belief.x[3:6], w, atol=1e-12)  # w never moves


def test_orientation_update_is_a_left_perturbation_towards_the_measurement():
    ukf = PoseUKF(PoseUKFConfig())
    q = quat_from_rotvec([0.4, -0.3, 1.0])
    b = ukf.initial_belief(np.r_[0, 0, 0.6], q)
    delta = np.array([0.0, 0.05, 0.0])  # measured = exp(delta) R  (camera-frame offset)
    q_meas = quat_multiply(quat_from_rotvec(delta), q)
    out = ukf.correct(b, p_meas_m=np.r_[0, 0, 0.6], q_meas_wxyz=q_meas)
    step = rotvec_from_matrix(matrix_from_quat(out.q) @ matrix_from_quat(q).T)
    gain = 1e-3 / (1e-3 + 1e-4)  # P0 / (P0 + R_q), the linear KF gain
    np.testing.assert_allclose(step, gain * delta, atol=2e-4)


def _check_well_formed(b: PoseBelief) -> None:
    assert np.isfinite(b.x).all() and np.isfinite(b.q).all() and np.isfinite(b.P).all()
    assert abs(np.linalg.norm(b.q) - 1.0) < 1e-12
    np.testing.assert_array_equal(b.P, b.P.T)
    assert np.linalg.eigvalsh(b.P).min() > 0


@settings(max_examples=scaled_examples(30))
@given(
    st.lists(
        st.tuples(
            st.sampled_from(["vel", "pose", "pose+vel", "none"]),
            st.floats(-5, 5),
            rotation_vectors(),
            st.floats(1e-3, 0.5),
        ),
        min_size=1,
        max_size=25,
    )
)
def test_belief_stays_well_formed_under_wild_measurements(steps):
    ukf = PoseUKF(PoseUKFConfig())
    b = ukf.initial_belief(np.r_[0.0, 0.0, 0.6], np.r_[1.0, 0, 0, 0])
    for kind, scale, r, dt in steps:
        b = ukf.predict(b, dt)
        twist = np.r_[scale, -scale, 0.5 * scale, r] if "vel" in kind else None
        pose = {}
        if "pose" in kind:
            pose = {"p_meas_m": np.r_[scale, 0.1, 0.6 + scale], "q_meas_wxyz": quat_from_rotvec(r)}
        b = ukf.correct(b, twist=twist, **pose)
        _check_well_formed(b)


def test_correct_needs_both_parts_of_a_pose():
    ukf = PoseUKF(PoseUKFConfig())
    b = ukf.initial_belief(np.zeros(3), np.r_[1.0, 0, 0, 0])
    with pytest.raises(ValueError, match="both p_meas_m and q_meas_wxyz"):
        ukf.correct(b, p_meas_m=np.zeros(3))
    assert ukf.correct(b) is b
