"""The velocity KF: flow Jacobian, measurement construction, robust weights, batched update."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.linalg import expm

from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics, project_points, v_o_from_v_obj
from roft_sim.geometry.camera import backproject_pixels
from roft_sim.geometry.rigid_flow import rigid_flow
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import matrix_from_rotvec, skew
from roft_sim.records import FlowField
from roft_sim.shipped_files import scenarios_dir
from roft_sim.testing.analytic_scene import AnalyticMotion
from roft_sim.trackers import get_tracker_spec, load_tracker_config
from roft_sim.trackers.roft.config import RoftConfig, VelocityKFConfig
from roft_sim.trackers.roft.mask_sync import PixelSet
from roft_sim.trackers.roft.velocity_kf import (
    FlowMeasurement,
    VelocityKF,
    _depth_rate_weights,
    _edge_pixel_labels,
    depth_rate_rows,
    finite_motion_flow,
    flow_jacobian,
    flow_measurement,
    laplacian_likelihood,
    occluder_free,
)

CAM = CameraIntrinsics(
    fx_px=600.0, fy_px=580.0, cx_px=319.5, cy_px=241.0, width_px=640, height_px=480
)


def test_jacobian_is_the_derivative_of_the_projection_of_a_moving_body_point():
    rng = np.random.default_rng(1)
    P = rng.uniform([-0.2, -0.15, 0.4], [0.2, 0.15, 1.2], (50, 3))
    twist = rng.normal(size=6)
    uv = project_points(CAM, P)
    J = flow_jacobian(CAM, uv[:, 0], uv[:, 1], P[:, 2], dt_s=1.0)
    eps = 1e-7
    P_dot = twist[:3] + np.cross(twist[3:], P)  # dP/dt = v_o + w x P
    uv_dot = (project_points(CAM, P + eps * P_dot) - project_points(CAM, P - eps * P_dot)) / (
        2 * eps
    )
    np.testing.assert_allclose(J @ twist, uv_dot, rtol=1e-6, atol=1e-6)


def test_jacobian_rows_are_the_papers_equation_9():
    u, v, z, dt = 400.0, 100.0, 0.7, 1 / 30
    up, vp, fx, fy = u - CAM.cx_px, v - CAM.cy_px, CAM.fx_px, CAM.fy_px
    expected = dt * np.array(
        [
            [fx / z, 0, -up / z, -up * vp / fy, (fx**2 + up**2) / fx, -vp * fx / fy],
            [0, fy / z, -vp / z, (-(fy**2) - vp**2) / fy, up * vp / fx, up * fy / fx],
        ]
    )
    np.testing.assert_allclose(flow_jacobian(CAM, u, v, z, dt), expected, rtol=1e-12)


def test_small_rigid_motion_flow_matches_the_linear_model():
    """The exact motion field of a short step ~ dt * J * twist (ties GT flow and the model)."""
    cam = CameraIntrinsics(
        fx_px=300.0, fy_px=300.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120
    )
    v, u = np.mgrid[0:120, 0:160]
    depth = (0.6 + 0.001 * u + 0.0005 * v).astype(np.float32)  # a slanted plane
    twist = np.array([0.3, -0.2, 0.1, 0.8, -0.5, 1.2])
    dt = 1e-4
    M = transform_from_rt(matrix_from_rotvec(twist[3:] * dt), twist[:3] * dt)  # ~ exp(dt xi)
    flow, valid = rigid_flow(cam, depth, np.zeros((120, 160), int), M[None])
    J = flow_jacobian(cam, u[valid], v[valid], depth[valid], dt)
    # first order in dt: the error relative to the flow is O(dt |twist|) ~ 1e-4
    np.testing.assert_allclose(J @ twist, flow[valid], atol=1e-3 * np.abs(flow[valid]).max())


def _exp_twist(twist, dt):
    """(4, 4) ``exp(dt xi)`` of the spatial twist ``(v_o, w)`` (6,) by scipy's expm."""
    xi = np.zeros((4, 4))
    xi[:3, :3] = skew(twist[3:])
    xi[:3, 3] = twist[:3]
    return expm(xi * dt)


def _exact_frame(twist, depth, dt, window):
    """The 160x120 camera, the mask of ``window`` (rows, columns) where the exact flow is valid,
    and that flow of a 1/30 s step of the constant ``twist`` (6,) of the surface ``depth``."""
    cam = CameraIntrinsics(
        fx_px=300.0, fy_px=300.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120
    )
    flow, valid = rigid_flow(cam, depth, np.zeros(depth.shape, int), _exp_twist(twist, dt)[None])
    mask = np.zeros_like(valid)
    mask[window] = valid[window]
    return cam, mask, FlowField(flow_px=flow.astype(np.float32), from_k=0, to_k=1)


@pytest.mark.parametrize(
    "twist",
    [[0.5, -0.3, -0.4, 1.5, -1.0, 2.0], [0.6, -0.4, -0.4, 0.8, -0.6, 0.5]],
    ids=["fast-spin", "fast-shift"],
)
def test_midpoint_jacobian_fits_the_finite_flow_of_a_fast_frame_better(twist):
    """The exact flow of one 1/30 s frame of a constant twist (the motion exp(dt xi), 16-24 px
    on an 80x60 px patch of a slanted plane at 0.6 m): the least-squares twist of the linear
    model evaluated half the median displacement further is closer to the truth than with the
    Jacobian at the pixel of frame k-1 (the reference's first-order model): the linear part by
    at least 1/0.65, the angular part by at least 1/0.9."""
    twist = np.asarray(twist)
    v, u = np.mgrid[0:120, 0:160]
    depth = (0.6 + 0.001 * u + 0.0005 * v).astype(np.float32)
    dt = 1 / 30
    cam, mask, field = _exact_frame(twist, depth, dt, (slice(30, 90), slice(40, 120)))
    errors = {}
    for midpoint in (False, True):
        cfg = VelocityKFConfig(
            midpoint_jacobian=midpoint,
            subsampling_stride=1,
            depth_band_m=None,
            finite_motion_correction=False,
        )
        m = flow_measurement(PixelSet.from_mask(mask), depth, field, cam, dt, cfg)
        est = np.linalg.lstsq(m.J.reshape(-1, 6), m.y_px.reshape(-1), rcond=None)[0]
        errors[midpoint] = np.array(
            [np.linalg.norm(est[:3] - twist[:3]), np.linalg.norm(est[3:] - twist[3:])]
        )
    assert (errors[True] < errors[False] * [0.65, 0.9]).all(), errors


def test_finite_motion_flow_is_the_projection_of_the_se3_exponential():
    """Against scipy's matrix exponential of the twist and an explicit projection, and the
    linear model's limit for a short step."""
    rng = np.random.default_rng(3)
    P = rng.uniform([-0.2, -0.15, 0.4], [0.2, 0.15, 1.2], (60, 3))
    uv = project_points(CAM, P)
    for twist, dt in ((rng.normal(size=6), 1 / 30), (np.array([0.4, 0, -0.2, 0, 4.0, 1.0]), 0.1)):
        motion = _exp_twist(twist, dt)
        moved = P @ motion[:3, :3].T + motion[:3, 3]
        expected = project_points(CAM, moved) - uv
        got = finite_motion_flow(CAM, uv[:, 0], uv[:, 1], P[:, 2], twist, dt)
        np.testing.assert_allclose(got, expected, atol=1e-9)
    twist, dt = rng.normal(size=6), 1e-6
    J = flow_jacobian(CAM, uv[:, 0], uv[:, 1], P[:, 2], dt)
    np.testing.assert_allclose(
        finite_motion_flow(CAM, uv[:, 0], uv[:, 1], P[:, 2], twist, dt), J @ twist, rtol=1e-4
    )


@pytest.mark.parametrize(
    "twist",
    [[0.5, -0.3, -0.4, 1.5, -1.0, 2.0], [0.1, 0.05, 0.0, 3.7, 1.0, -0.6]],
    ids=["fast-spin", "out-of-plane-210-dps"],
)
def test_the_finite_motion_correction_recovers_a_fast_twist_from_exact_flow(twist):
    """The exact flow of one 1/30 s frame (motion exp(dt xi)) of a small tilted patch at 0.6 m:
    corrected at the pixels' own twist (the first update: within 0.2 deg/s and 2 mm/s), or by
    a filter whose interval mean is 20 % off (corrected at that, then twice at the filter's own
    estimate: iterated-EKF steps; within 0.5 deg/s and 5 mm/s), the least-squares twist of the
    pixels is the true one; the linear model alone (the reference, even with the midpoint
    Jacobian) misses the rotation by degrees per second."""
    twist = np.asarray(twist)
    v, u = np.mgrid[0:120, 0:160]
    depth = (0.6 + 0.0008 * (u - 80) + 0.0004 * (v - 60)).astype(np.float32)
    dt = 1 / 30
    cam, mask, field = _exact_frame(twist, depth, dt, (slice(35, 85), slice(50, 110)))
    errors = {}
    for name, correct, at in (
        ("linear", False, None),
        ("own fit", True, None),
        ("filter", True, 0.8 * twist),
    ):
        cfg = VelocityKFConfig(
            subsampling_stride=1,
            depth_band_m=None,
            finite_motion_correction=correct,
            motion_model="constant",
            cov_v0=(1.0, 1.0, 1.0),
            cov_w0=(1.0, 1.0, 1.0),
        )
        m = flow_measurement(
            PixelSet.from_mask(mask), depth, field, cam, dt, cfg, linearization_twist=at
        )
        kf = VelocityKF(cfg)
        if at is not None:  # a filter that has run: its interval mean is 20 % off this one
            kf.x, kf.updates = at.copy(), 1
        assert kf.step(m, t_s=dt, dt_s=dt) and kf.fit is not None
        est = kf.fit[0]  # the pixels' own twist, after the filter's relinearisation
        errors[name] = (
            100 * np.linalg.norm(est[:3] - twist[:3]),
            np.rad2deg(np.linalg.norm(est[3:] - twist[3:])),
        )
    assert errors["own fit"][0] < 0.2 and errors["own fit"][1] < 0.2, errors
    assert errors["filter"][0] < 0.5 and errors["filter"][1] < 0.5, errors
    assert errors["linear"][1] > 1.5, errors


def _mask_with_depth(n_rows=6):
    mask = np.zeros((CAM.height_px, CAM.width_px), bool)
    mask[200 : 200 + n_rows, 300:340] = True
    depth = np.full(mask.shape, 0.8, np.float32)
    return mask, depth


def test_stride_is_over_the_row_major_pixel_list_before_validity_filtering():
    mask, depth = _mask_with_depth()
    idx = np.flatnonzero(mask)
    depth.reshape(-1)[idx[35]] = 0.0  # invalid depth on the 2nd sampled pixel
    depth.reshape(-1)[idx[70]] = 2.5  # beyond depth_maximum_m
    flow = FlowField(flow_px=np.ones(mask.shape + (2,), np.float32), from_k=0, to_k=1)
    flow.flow_px.reshape(-1, 2)[idx[105]] = np.nan
    m = flow_measurement(PixelSet.from_mask(mask), depth, flow, CAM, 1 / 30, VelocityKFConfig())
    kept = idx[::35][[0, 4, 5, 6]]
    np.testing.assert_array_equal(m.v_px * CAM.width_px + m.u_px, kept)


def test_laplacian_likelihood_by_hand():
    e = np.array([[3.0, 4.0], [0.0, 1.0], [6.0, 8.0], [0.0, 2.0]])  # norms 5, 1, 10, 2
    mu, b = 3.5, np.mean([1.5, 2.5, 6.5, 1.5])  # median, mean absolute deviation
    lik = np.exp(-np.abs(np.array([5, 1, 10, 2]) - mu) / b)
    np.testing.assert_allclose(laplacian_likelihood(e), lik / lik.max(), rtol=1e-12)
    # the reference pairs element r with r + N of (du0, dv0, du1, dv1, ...): other mu and b
    flat = e.reshape(-1)
    mis = np.hypot(flat[:4], flat[4:])
    mu_r = np.median(mis)
    b_r = np.mean(np.abs(mis - mu_r))
    lik_r = np.exp(-np.abs(np.array([5, 1, 10, 2]) - mu_r) / b_r)
    np.testing.assert_allclose(laplacian_likelihood(e, "reference"), lik_r / lik_r.max())
    assert not np.allclose(lik_r / lik_r.max(), lik / lik.max())
    np.testing.assert_array_equal(laplacian_likelihood(np.ones((5, 2))), np.ones(5))  # b = 0


def _random_measurement(rng, n):
    mask, depth = _mask_with_depth()
    u = rng.integers(0, CAM.width_px, n)
    v = rng.integers(0, CAM.height_px, n)
    z = rng.uniform(0.4, 1.5, n)
    J = flow_jacobian(CAM, u, v, z, 1 / 30)
    y = J @ rng.normal(size=6) + rng.standard_t(2, (n, 2))  # heavy-tailed noise
    return FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v)


@pytest.mark.parametrize(
    "weight_flow, pairs", [(True, "correct"), (True, "reference"), (False, "correct")]
)
def test_batched_update_equals_the_references_sequential_per_pixel_update(weight_flow, pairs):
    rng = np.random.default_rng(7)
    cfg = VelocityKFConfig(
        weight_flow=weight_flow,
        cov_flow=(1.0, 2.0),
        reweighting_pairs=pairs,
        adapt_flow_noise=False,
    )
    kf = VelocityKF(cfg)
    kf.x = rng.normal(size=6)
    for _ in range(3):
        m = _random_measurement(rng, 40)
        x, P = kf.x.copy(), kf.P + np.diag(cfg.sigma_linear + cfg.sigma_angular)
        lik = laplacian_likelihood(m.y_px - m.J @ x, pairs) if weight_flow else np.ones(len(m))
        for j in range(len(m)):  # the reference: one 2x2 block per pixel, in list order
            Hj = m.J[j]
            R = np.diag(cfg.cov_flow) / lik[j]
            S = Hj @ P @ Hj.T + R
            K = P @ Hj.T @ np.linalg.inv(S)
            x = x + K @ (m.y_px[j] - Hj @ x)
            P = (np.eye(6) - K @ Hj) @ P
        assert kf.step(m)
        np.testing.assert_allclose(kf.x, x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(kf.P, P, rtol=1e-9, atol=1e-15)


def test_too_few_pixels_keep_the_previous_corrected_belief():
    rng = np.random.default_rng(2)
    kf = VelocityKF(VelocityKFConfig())
    assert kf.step(_random_measurement(rng, 30))
    x, P = kf.x.copy(), kf.P.copy()
    few = _random_measurement(rng, 2)
    assert not kf.step(few) and not kf.step(None)
    np.testing.assert_array_equal(kf.x, x)
    np.testing.assert_array_equal(kf.P, P)  # the prediction's Q is undone too


def test_noise_free_flow_of_a_constant_twist_is_recovered_exactly():
    rng = np.random.default_rng(4)
    truth = np.array([0.2, -0.1, 0.3, 1.5, -2.0, 0.7])
    kf = VelocityKF(VelocityKFConfig())
    for _ in range(6):
        m = _random_measurement(rng, 60)
        m = dataclasses.replace(m, y_px=m.J @ truth)
        kf.step(m)
    np.testing.assert_allclose(kf.x, truth, atol=1e-6)


def test_velocity_kf_alone_recovers_the_gt_spatial_twist(medium_seq):
    """GT flow and GT masks of frame k-1, 320x240, fast motion (RMS |v_o| 1.37 m/s, |w| 2.9 rad/s).

    The flow F_k spans (k-1, k], so the twist it measures is the one at k - 1/2. Flow noise is
    set to (320/1280)^2 px^2 (R = 1 px^2 at Fast-YCB's 1280 px width, the same angular noise) and
    the stride to 5 (the pixel count of a 1280x720 image with stride 35). Measured RMS errors
    against the mid-interval twist: 0.099 m/s, 0.19 rad/s (against frame k: 0.18 m/s, 0.38 rad/s).
    """
    seq = medium_seq
    s = (seq.intrinsics.width_px / 1280) ** 2
    cfg = VelocityKFConfig(cov_flow=(s, s), subsampling_stride=5)
    mid = AnalyticMotion().track((np.arange(len(seq)) - 0.5) / seq.fps)
    kf = VelocityKF(cfg)
    errors = []
    for k in range(1, len(seq)):
        m = flow_measurement(
            PixelSet.from_mask(seq.mask(k - 1, "gt")),
            seq.depth(k - 1),
            seq.flow(k, "gt"),
            seq.intrinsics,
            1 / seq.fps,
            cfg,
        )
        assert kf.step(m)
        v_o = v_o_from_v_obj(mid.v_obj_mps[k], mid.w_radps[k], mid.T_cam_obj[k, :3, 3])
        errors.append(kf.x - np.r_[v_o, mid.w_radps[k]])
    e = np.array(errors)[3:]
    rms_v = np.sqrt(np.mean(np.sum(e[:, :3] ** 2, 1)))
    rms_w = np.sqrt(np.mean(np.sum(e[:, 3:] ** 2, 1)))
    assert rms_v < 0.13 and rms_w < 0.25  # < 10 % of the motion's RMS


def test_adapted_flow_noise_recovers_the_true_spread():
    """With Gaussian flow noise of 0.8 px on (du, dv) the robust residual spread gives R of
    about 0.8^2 (the configured 0.1^2 is only a floor)."""
    rng = np.random.default_rng(3)
    cfg = VelocityKFConfig(cov_flow=(0.01, 0.01), weight_flow=False, noise_reference_width_px=None)
    kf = VelocityKF(cfg)
    n = 2000
    u = rng.integers(0, CAM.width_px, n)
    v = rng.integers(0, CAM.height_px, n)
    J = flow_jacobian(CAM, u, v, rng.uniform(0.4, 1.5, n), 1 / 30)
    y = J @ np.r_[0.1, -0.2, 0.05, 1.0, -0.5, 0.3] + rng.normal(0.0, 0.8, (n, 2))
    assert kf.step(FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v))
    np.testing.assert_allclose(kf.flow_sigma_px, [0.8, 0.8], rtol=0.08)


@pytest.mark.parametrize("noise_px", [0.0, 0.1])
def test_constant_acceleration_model_reports_the_twist_at_the_frame(noise_px):
    """A twist with a constant rate, flow measured with (or without) pixel noise: with
    the constant-acceleration model (``motion_model = "auto"``'s second model) the twist
    reported at k (``x_frame``) is the
    truth at k within a quarter of the half-frame lag ``|rate| dt / 2`` after 15 frames, and
    the interval mean handed to the UKF (``x``) is the truth at k - 1/2; the constant model
    reports the interval mean as the twist at k (the lag)."""
    rng = np.random.default_rng(7)
    n, dt = 400, 1 / 30
    u = rng.integers(0, CAM.width_px, n)
    v = rng.integers(0, CAM.height_px, n)
    J = flow_jacobian(CAM, u, v, rng.uniform(0.4, 1.5, n), dt)
    rate = np.r_[1.5, -1.0, 0.8, 12.0, -8.0, 6.0]  # [m/s^2, rad/s^2]
    lag = np.abs(rate) * dt / 2  # (6,) the interval mean's lag behind the twist at k

    def twist(t):
        return np.r_[0.1, 0.0, -0.1, 0.5, 1.0, -0.5] + rate * t

    errors = {}
    for model in ("constant", "constant_acceleration"):
        kf = VelocityKF(VelocityKFConfig(), CAM.width_px, model)
        err_at_k = []
        for k in range(1, 31):
            y = J @ twist((k - 0.5) * dt) + rng.normal(0.0, noise_px, (n, 2))
            assert kf.step(FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v), t_s=k * dt, dt_s=dt)
            if k >= 15:
                err_at_k.append(np.abs(kf.x_frame - twist(k * dt)))
                if model == "constant_acceleration":
                    assert (np.abs(kf.x - twist((k - 0.5) * dt)) < 0.25 * lag).all()
        errors[model] = np.max(err_at_k, axis=0)
    assert (errors["constant_acceleration"] < 0.25 * lag).all(), errors
    assert (errors["constant"] > 0.7 * lag).all(), errors


def test_constant_acceleration_model_needs_the_frame_times():
    kf = VelocityKF(VelocityKFConfig(), None, "constant_acceleration")
    J = flow_jacobian(CAM, [100, 200, 300], [100, 200, 150], [1.0, 1.0, 1.0], 1 / 30)
    zeros = np.zeros(3, np.int64)
    meas = FlowMeasurement(y_px=np.zeros((3, 2)), J=J, u_px=zeros, v_px=zeros)
    with pytest.raises(ValueError, match="needs the frame time"):
        kf.step(meas)
    with pytest.raises(ConfigError, match="motion_model must be 'constant' or 'auto'"):
        VelocityKFConfig(motion_model="constant_acceleration")  # type: ignore[arg-type]


def _rms_w_error_on_a_turning_small_object(
    config: VelocityKFConfig, flow_noise_px: float = 0.05, kf: VelocityKF | None = None
) -> float:
    """RMS error of w [rad/s] over frames 10-59 of a velocity KF (at ``CAM``'s 640 px width) on
    flow with ``flow_noise_px`` of noise, from 150 pixels of a 40 x 60 px patch at 0.65 m with
    +-1.5 cm of relief turning about its centre at up to 2 rad/s: a small object, whose
    out-of-plane rotation shows only through its depth differences."""
    rng = np.random.default_rng(11)
    kf = kf if kf is not None else VelocityKF(config, width_px=CAM.width_px)
    n = 150
    u = CAM.cx_px + rng.uniform(-20.0, 20.0, n)
    v = CAM.cy_px + rng.uniform(-30.0, 30.0, n)
    J = flow_jacobian(CAM, u, v, 0.65 + rng.uniform(-0.015, 0.015, n), 1 / 30)
    errors = []
    for k in range(60):
        t = k / 30
        w = 2.0 * np.array([np.sin(2.0 * t), np.cos(1.5 * t), 0.3 * np.sin(t)])
        twist = np.r_[-np.cross(w, [0.0, 0.0, 0.65]), w]
        y = J @ twist + rng.normal(0.0, flow_noise_px, (n, 2))
        assert kf.step(FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v))
        errors.append(kf.x[3:] - w)
    return float(np.sqrt(np.mean(np.sum(np.square(errors[10:]), axis=1))))


def test_the_shipped_exact_flow_config_follows_flow_the_default_weighs_as_nvof():
    """``scenarios/trackers/roft_exact_flow.toml`` changes only ``velocity.cov_flow`` (and fixes
    it: no ``exact_flow_spread_px``); on nearly exact flow (0.05 px, above what the default
    recognises as exact) the default's NVOF-level flow noise (0.5 px at 640 px, a floor of the
    residual-spread estimate) makes the filter trail the weakly observed w_x / w_y, while the
    shipped config's lets the residual spread set the noise (GT
    inputs, TUM room2 at 640x360, e_w 15.7 -> 6.0 deg/s)."""
    path = scenarios_dir() / "trackers" / "roft_exact_flow.toml"
    exact = load_tracker_config(get_tracker_spec("roft"), path)
    default = RoftConfig()
    assert exact.velocity.cov_flow == (0.01, 0.01)
    assert exact.velocity.exact_flow_spread_px is None
    assert dataclasses.replace(
        exact.velocity,
        cov_flow=default.velocity.cov_flow,
        exact_flow_spread_px=default.velocity.exact_flow_spread_px,
    ) == (default.velocity)
    assert dataclasses.replace(exact, velocity=default.velocity) == default
    rms_default = _rms_w_error_on_a_turning_small_object(default.velocity)
    rms_exact = _rms_w_error_on_a_turning_small_object(exact.velocity)
    assert rms_exact < 0.06  # 0.041 rad/s
    assert rms_default > 0.09  # 0.110 rad/s: the lag


def test_flow_that_fits_to_a_hundredth_of_a_pixel_is_weighed_as_exact():
    """``exact_flow_spread_px`` (default 0.01 px): on flow with 0.001 px of noise (what exact
    flow leaves after the fit) the default lowers its noise to the shipped exact-flow
    configuration's and follows the turns as that configuration does (0.0015 rad/s RMS), where
    without it the NVOF-level noise makes it trail them (0.079); on 0.05 px flow (an
    estimator's) its noise stays the configured one, to the bit."""
    default = VelocityKFConfig()
    assert default.exact_flow_spread_px == 0.01
    off = dataclasses.replace(default, exact_flow_spread_px=None)
    exact_config = dataclasses.replace(default, cov_flow=(0.01, 0.01), exact_flow_spread_px=None)
    rms = _rms_w_error_on_a_turning_small_object(default, flow_noise_px=0.001)
    rms_off = _rms_w_error_on_a_turning_small_object(off, flow_noise_px=0.001)
    rms_exact = _rms_w_error_on_a_turning_small_object(exact_config, flow_noise_px=0.001)
    assert rms < 0.01 and abs(rms - rms_exact) < 0.002, (rms, rms_exact)
    assert rms_off > 0.07, rms_off
    kf = VelocityKF(default, width_px=CAM.width_px)
    kf_off = VelocityKF(off, width_px=CAM.width_px)
    estimated = _rms_w_error_on_a_turning_small_object(default, kf=kf)
    assert estimated == _rms_w_error_on_a_turning_small_object(off, kf=kf_off)
    np.testing.assert_array_equal(kf.flow_sigma_px, np.sqrt(default.flow_variance_px2(640)))
    with pytest.raises(ConfigError, match="exact_flow_spread_px"):
        VelocityKFConfig(exact_flow_spread_px=0.0)


def test_only_dense_flow_of_distinct_vectors_counts_as_exact():
    """Noise-free flow lowers R to a hundredth when it is dense with distinct vectors; the same
    values read from a 4x4 grid (NVOF's: a small object's few distinct vectors fit six
    parameters without residual whatever their error), or a dense flow of a few repeated
    vectors (a still object's quantised flow), leave R the configured one."""
    rng = np.random.default_rng(3)
    n = 150
    u = CAM.cx_px + rng.uniform(-20.0, 20.0, n)
    v = CAM.cy_px + rng.uniform(-30.0, 30.0, n)
    J = flow_jacobian(CAM, u, v, 0.65 + rng.uniform(-0.015, 0.015, n), 1 / 30)
    y = J @ np.array([0.05, -0.02, 0.01, 0.5, -0.3, 0.2])
    R = np.asarray(VelocityKFConfig().flow_variance_px2(CAM.width_px))
    repeated = np.repeat(y[:6], n // 6, axis=0)
    cases = [
        (FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v), 0.01),
        (FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v, grid_px=4), 1.0),
        (FlowMeasurement(y_px=repeated, J=J[: len(repeated)], u_px=u, v_px=v), 1.0),
    ]
    for measurement, ratio in cases:
        kf = VelocityKF(VelocityKFConfig(), width_px=CAM.width_px)
        assert kf.step(measurement)
        np.testing.assert_allclose(kf.flow_sigma_px**2, R * ratio, rtol=1e-12)


def test_distinct_vectors_counts_as_np_unique():
    """The count of distinct flow rows (a sort and a count) equals ``np.unique``'s on rows with
    repeats, rows equal in one component only, signed zeros (equal), NaNs (one value to
    np.unique) and no rows at all."""
    rng = np.random.default_rng(5)
    base = rng.integers(-3, 4, size=(200, 2)).astype(np.float64) / 4.0
    signed = base.copy()
    signed[::7] = -0.0
    with_nan = base.copy()
    with_nan[3, 0] = with_nan[9, 1] = np.nan
    for y in (base, signed, with_nan, np.zeros((0, 2)), rng.normal(size=(50, 2))):
        m = FlowMeasurement(
            y_px=y, J=np.zeros((len(y), 2, 6)), u_px=np.zeros(len(y)), v_px=np.zeros(len(y))
        )
        expected = np.unique(np.ascontiguousarray(y).view(np.complex128)).size
        assert m.distinct_vectors() == expected


def _object_and_hand(hand_twist, hand_in_front=True):
    """An 80 x 80 px tilted patch at 0.65 m (the object, turning with ``_OBJECT_TWIST``) and a
    50 x 30 px patch 5 cm in front of it or 5 cm behind it (the hand), one mask over both, exact
    flow. Returns (pixels, depth (H, W) [m], u, v, z, y (N, 2) [px], J (N, 2, 6), is_hand (N,))."""
    H, W = CAM.height_px, CAM.width_px
    depth = np.zeros((H, W))
    mask = np.zeros((H, W), bool)
    vv, uu = np.mgrid[200:280, 280:360]
    depth[vv, uu] = 0.65 + 0.0005 * (uu - 320)  # a 4 cm tilt, 0.5 mm between neighbours
    mask[vv, uu] = True
    hand = np.zeros((H, W), bool)
    hand[230:260, 250:300] = True
    depth[hand] = 0.60 if hand_in_front else 0.70
    mask |= hand
    pixels = PixelSet.from_mask(mask)
    u, v = pixels.u, pixels.v
    z = depth[v, u]
    J = flow_jacobian(CAM, u, v, z, 1 / 30)
    is_hand = hand[v, u]
    y = np.where(is_hand[:, None], J @ hand_twist, J @ _OBJECT_TWIST)
    return pixels, depth, u, v, z, y, J, is_hand


_OBJECT_TWIST = np.array([0.1, -0.05, 0.02, 1.0, -1.5, 0.4])


def test_a_part_in_front_that_moves_otherwise_is_dropped_and_the_rest_kept():
    """The hand 5 cm in front, turning otherwise: all its pixels dropped, none of the object's;
    the object's twist is then exact. Rigidly attached (same twist), in front or behind: kept."""
    cfg = VelocityKFConfig()
    other = _OBJECT_TWIST + np.array([0.05, 0.0, 0.0, 0.0, 1.0, 0.0])
    pixels, depth, u, v, z, y, J, is_hand = _object_and_hand(other)
    keep = occluder_free(pixels, depth, u, v, z, y, J, cfg)
    assert not keep[is_hand].any() and keep[~is_hand].all()
    fit = np.linalg.lstsq(J[keep].reshape(-1, 6), y[keep].reshape(-1), rcond=None)[0]
    np.testing.assert_allclose(fit, _OBJECT_TWIST, atol=1e-9)
    bent = np.linalg.lstsq(J.reshape(-1, 6), y.reshape(-1), rcond=None)[0]
    assert np.linalg.norm(bent[3:] - _OBJECT_TWIST[3:]) > 0.05  # what the hand did to the fit
    for twist, in_front in ((_OBJECT_TWIST, True), (other, False)):
        pixels, depth, u, v, z, y, J, is_hand = _object_and_hand(twist, in_front)
        assert occluder_free(pixels, depth, u, v, z, y, J, cfg).all()


def test_a_hand_whose_flow_is_smoothed_towards_the_object_is_kept():
    """Dense flow smooths a hand towards the object: a part that disagrees by less than one
    pixel's noise is not an occluder to drop."""
    rng = np.random.default_rng(5)
    pixels, depth, u, v, z, y, J, is_hand = _object_and_hand(_OBJECT_TWIST)
    y = y + rng.normal(0.0, 0.3, y.shape)
    y[is_hand] += 0.2  # a slight, smoothed-away disagreement [px]
    assert occluder_free(pixels, depth, u, v, z, y, J, VelocityKFConfig()).all()


def test_flow_measurement_leaves_out_the_hand_and_the_reference_reads_it():
    """Through ``flow_measurement``: the default leaves the hand's pixels out; the reference
    configuration (no occluder test) reads every pixel of the mask."""
    other = _OBJECT_TWIST + np.array([0.05, 0.0, 0.0, 0.0, 1.0, 0.0])
    pixels, depth, u, v, z, y, J, is_hand = _object_and_hand(other)
    field = np.zeros((CAM.height_px, CAM.width_px, 2), np.float32)
    field[v, u] = y
    flow = FlowField(flow_px=field, from_k=0, to_k=1)
    default = flow_measurement(pixels, depth, flow, CAM, 1 / 30, VelocityKFConfig(), stride=1)
    reference = flow_measurement(
        pixels, depth, flow, CAM, 1 / 30, VelocityKFConfig(occluder_depth_jump_m=None), stride=1
    )
    assert len(reference) == len(u) and len(default) == int((~is_hand).sum())


def _plane_depth(cam: CameraIntrinsics, normal, offset_m: float) -> np.ndarray:
    """(H, W) z-depth [m] of the plane ``normal . P = offset_m`` (camera frame) at every pixel."""
    v, u = np.mgrid[0 : cam.height_px, 0 : cam.width_px]
    ray = np.stack([(u - cam.cx_px) / cam.fx_px, (v - cam.cy_px) / cam.fy_px, np.ones(u.shape)])
    return offset_m / np.tensordot(np.asarray(normal, dtype=np.float64), ray, axes=1)


def _moving_plane(twist, dt, window, normal=(0.3, -0.2, 1.0), offset_m=0.6):
    """A plane at about 0.6 m moved for ``dt`` [s] by the constant spatial ``twist`` (6,): the
    camera, the mask of ``window``, the exact flow (``rigid_flow``), the depth of both frames
    and the motion (4, 4) (scipy's expm)."""
    cam = CameraIntrinsics(
        fx_px=300.0, fy_px=300.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120
    )
    n = np.asarray(normal, dtype=np.float64)
    depth0 = _plane_depth(cam, n, offset_m)
    motion = _exp_twist(np.asarray(twist, dtype=np.float64), dt)
    n1 = motion[:3, :3] @ n
    depth1 = _plane_depth(cam, n1, offset_m + n1 @ motion[:3, 3])
    flow, valid = rigid_flow(
        cam, depth0.astype(np.float32), np.zeros(depth0.shape, int), motion[None]
    )
    mask = np.zeros_like(valid)
    mask[window] = valid[window]
    field = FlowField(flow_px=flow.astype(np.float32), from_k=0, to_k=1)
    return cam, mask, field, depth0, depth1, motion


@pytest.mark.parametrize(
    "twist",
    [[0.0, 0.0, 0.4, 0.0, 0.0, 0.0], [0.3, -0.2, -0.4, 1.5, -1.0, 2.0]],
    ids=["recession", "fast-spin"],
)
def test_depth_rate_rows_are_the_depth_change_of_each_point(twist):
    """A slanted plane moved for 1/30 s by a constant twist, exact flow: each row's measured
    depth change is the z change of that body point under the motion (scipy's expm, then the
    point's own coordinates: an oracle independent of the rows' bilinear read), and the row's
    linear model at the point's mean position reproduces it to second order in the motion."""
    dt = 1 / 30
    cam, mask, field, depth0, depth1, motion = _moving_plane(
        twist, dt, (slice(30, 90), slice(40, 120))
    )
    cfg = VelocityKFConfig(subsampling_stride=1, depth_band_m=None, finite_motion_correction=False)
    m = flow_measurement(PixelSet.from_mask(mask), depth0, field, cam, dt, cfg, next_depth_m=depth1)
    rows = m.depth_rate
    assert rows is not None and len(rows) > 0.9 * len(m)
    uv = np.stack([rows.u_px, rows.v_px], -1).astype(np.float64)
    P = backproject_pixels(cam, uv, depth0[rows.v_px, rows.u_px])
    moved = P @ motion[:3, :3].T + motion[:3, 3]
    np.testing.assert_allclose(rows.dz_m, moved[:, 2] - P[:, 2], atol=2e-6)
    np.testing.assert_allclose(rows.J @ np.asarray(twist), rows.dz_m, atol=2e-5)


def test_the_depth_change_measures_the_recession_a_small_patch_hides_from_the_flow():
    """A 12x8 px patch of a plane receding at 0.3 m/s while it turns, flow with 1.5 px of
    Gaussian noise and depth with 1 mm: the flow alone barely sees the recession (the patch's
    image shrinks by 0.05 px a frame); the depth change of its points measures it. RMS error of
    v_z over 8 seeds of one update from a wide prior: with the depth change under a third of
    the flow's alone."""
    dt = 1 / 30
    twist = np.array([0.05, -0.1, 0.3, 0.4, -0.6, 0.3])
    cam, mask, field, depth0, depth1, _ = _moving_plane(twist, dt, (slice(56, 64), slice(74, 86)))
    errors = {True: [], False: []}
    for seed in range(8):
        rng = np.random.default_rng(seed)
        noisy = FlowField(
            flow_px=field.flow_px + rng.normal(0, 1.5, field.flow_px.shape).astype(np.float32),
            from_k=0,
            to_k=1,
        )
        d0 = depth0 + rng.normal(0, 0.001, depth0.shape)
        d1 = depth1 + rng.normal(0, 0.001, depth1.shape)
        for depth_rate in (True, False):
            cfg = VelocityKFConfig(
                subsampling_stride=1,
                depth_band_m=None,
                finite_motion_correction=False,
                motion_model="constant",
                cov_v0=(1.0, 1.0, 1.0),
                cov_w0=(10.0, 10.0, 10.0),
                depth_rate=depth_rate,
            )
            m = flow_measurement(PixelSet.from_mask(mask), d0, noisy, cam, dt, cfg, next_depth_m=d1)
            assert (m.depth_rate is not None) == depth_rate
            kf = VelocityKF(cfg)
            assert kf.step(m, t_s=dt, dt_s=dt)
            errors[depth_rate].append(kf.x[2] - twist[2])
    rms = {key: float(np.sqrt(np.mean(np.square(e)))) for key, e in errors.items()}
    assert rms[True] < rms[False] / 3, rms
    assert rms[True] < 0.1, rms  # m/s


def test_depth_rate_rows_skip_points_carried_onto_a_depth_edge_or_out_of_the_image():
    """A point whose flow carries it across a 10 cm depth step, or out of the image, gives no
    row; the rest do."""
    cam = CameraIntrinsics(
        fx_px=300.0, fy_px=300.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120
    )
    depth0 = np.full((120, 160), 0.6)
    depth1 = depth0.copy()
    depth1[:, 100:] = 0.7  # an edge between columns 99 and 100
    u = np.array([10, 20, 30, 40, 50, 60, 70, 80, 98, 150])
    v = np.full(10, 60)
    flow = np.zeros((10, 2))
    flow[8, 0] = 1.5  # 98 -> 99.5: its four neighbours straddle the edge
    flow[9, 0] = 20.0  # 150 -> 170: out of the image
    rows = depth_rate_rows(cam, u, v, depth0[v, u], flow, depth1, 1 / 30, VelocityKFConfig())
    assert rows is not None
    np.testing.assert_array_equal(rows.u_px, u[:8])
    np.testing.assert_allclose(rows.dz_m, 0.0)


def test_depth_rate_rows_on_a_steep_flank_weigh_less():
    """Each row carries the depth gradient where it was read (a tilted plane: the analytic
    gradient's norm, by central differences of the exact depth), and its variance adds the
    flow's error carried through that gradient: with a 1 px flow noise, rows read where the
    plane is 4 times steeper weigh less, equal residuals or not."""
    cam = CameraIntrinsics(
        fx_px=300.0, fy_px=300.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120
    )
    depth = 0.6 + 0.002 * np.mgrid[0:120, 0:160][1].astype(np.float64)  # 2 mm per column
    depth[:, 80:] = 0.6 + 0.16 + 0.008 * (np.arange(80, 160) - 80)  # 8 mm per column
    u = np.array([20, 30, 40, 50, 60, 100, 110, 120, 130, 140])
    v = np.full(10, 60)
    flow = np.full((10, 2), 0.25)
    cfg = VelocityKFConfig(depth_band_m=None)
    rows = depth_rate_rows(cam, u, v, depth[v, u], flow, depth, 1 / 30, cfg)
    assert rows is not None
    np.testing.assert_allclose(rows.slope_m_per_px, np.where(u < 80, 0.002, 0.008), rtol=1e-9)
    _, weight = _depth_rate_weights(rows, np.zeros(6), 1.0, cfg)
    assert (weight[u < 80] > 4 * weight[u >= 80]).all(), weight


def test_edge_pixel_labels_match_a_search_of_each_pixels_neighbours():
    """Each edge pixel joins its 8-neighbour nearest in depth among the labelled ones within
    the jump (the first in the scan order on a tie), against a per-pixel loop."""
    rng = np.random.default_rng(5)
    h, w, jump = 20, 30, 0.03
    labels = rng.integers(0, 4, (h, w)).astype(np.int32)
    z = rng.uniform(0.5, 0.6, (h, w)).astype(np.float32)
    z[rng.random((h, w)) < 0.1] = 0.52  # ties
    rows, cols = np.nonzero(labels == 0)
    got = _edge_pixel_labels(labels, z, rows, cols, jump)
    for i, (r, c) in enumerate(zip(rows, cols, strict=True)):
        best, expected = np.inf, 0
        for dv in (-1, 0, 1):
            for du in (-1, 0, 1):
                rr, cc = r + dv, c + du
                if (dv, du) == (0, 0) or not (0 <= rr < h and 0 <= cc < w) or labels[rr, cc] <= 0:
                    continue
                gap = abs(float(z[rr, cc]) - float(z[r, c]))
                if gap <= jump and gap < best:
                    best, expected = gap, labels[rr, cc]
        assert got[i] == expected, (r, c)
