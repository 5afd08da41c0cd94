"""``velocity.motion_model = "auto"``: the prequential choice between the constant and the
constant-acceleration velocity KF, and the constant-acceleration KF's start."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.trackers.roft.config import VelocityKFConfig
from roft_sim.trackers.roft.velocity_kf import FlowMeasurement, VelocityKF, flow_jacobian
from roft_sim.trackers.roft.velocity_selector import SelectingVelocityKF, make_velocity_filter

CAM = CameraIntrinsics(
    fx_px=600.0, fy_px=580.0, cx_px=319.5, cy_px=241.0, width_px=640, height_px=480
)
DT_S = 1 / 30
RATE = np.r_[1.5, -1.0, 0.8, 12.0, -8.0, 6.0]
"""(6,) constant rate of the clean stream's twist [m/s^2, rad/s^2]."""


def _pixels(rng: np.random.Generator, n: int = 400):
    u = rng.integers(0, CAM.width_px, n)
    v = rng.integers(0, CAM.height_px, n)
    return u, v, flow_jacobian(CAM, u, v, rng.uniform(0.4, 1.5, n), DT_S)


def _run(kfs, twist_mean, frames, rng, noise_px):
    """Feeds every filter in ``kfs`` the flow of the interval means ``twist_mean(k)`` (6,)
    [m/s, rad/s] of frames 1..frames, plus white pixel noise [px]; returns the per-frame
    ``x_frame`` (frames, 6) of each filter."""
    u, v, J = _pixels(rng)
    out = [[] for _ in kfs]
    for k in range(1, frames + 1):
        y = J @ twist_mean(k) + rng.normal(0.0, noise_px, (len(u), 2))
        meas = FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v)
        for kf, rows in zip(kfs, out, strict=True):
            assert kf.step(meas, t_s=k * DT_S, dt_s=DT_S)
            rows.append(kf.x_frame.copy())
    return [np.array(rows) for rows in out]


def _twist(t_s: float):
    return np.r_[0.1, 0.0, -0.1, 0.5, 1.0, -0.5] + RATE * t_s


def test_auto_weights_the_acceleration_model_on_a_clean_accelerating_stream():
    """A twist with a constant rate and nearly exact flow (0.05 px): after 60 frames the
    constant-acceleration model has (almost) all the weight, the reported twist
    is the truth at k within a quarter of the half-frame lag, and the pose UKF's measurement
    (``x``, ``P``) is exactly a plain constant KF's on the same stream (the oracle)."""
    rng = np.random.default_rng(3)
    auto = SelectingVelocityKF(VelocityKFConfig(motion_model="auto"), CAM.width_px)
    plain = VelocityKF(VelocityKFConfig(motion_model="constant"), CAM.width_px)
    reported, _ = _run([auto, plain], lambda k: _twist((k - 0.5) * DT_S), 60, rng, 0.05)
    assert (auto.weights_accel > 0.85).all()
    lag = np.abs(RATE) * DT_S / 2
    assert (np.abs(reported[-1] - _twist(60 * DT_S)) < 0.25 * lag).all()
    np.testing.assert_array_equal(auto.x, plain.x)
    np.testing.assert_array_equal(auto.P, plain.P)


def test_auto_keeps_the_constant_model_when_the_flow_errors_are_coloured():
    """The flow of a constant twist whose interval means carry an error that all pixels share
    and that persists from frame to frame (AR(1), correlation 0.8: a stale mask, flow smoothed
    across the silhouette) plus 0.5 px of pixel noise: the constant-acceleration model reads
    the error's changes as acceleration, predicts the flow worse, and keeps a small weight."""
    rng = np.random.default_rng(5)
    base = np.r_[0.2, -0.1, 0.05, 0.5, -0.3, 0.2]
    sigma = np.r_[0.05, 0.05, 0.05, 0.3, 0.3, 0.3]  # [m/s, rad/s]
    error = np.zeros(6)
    errors = []
    for _ in range(80):
        error = 0.8 * error + np.sqrt(1 - 0.8**2) * sigma * rng.normal(size=6)
        errors.append(error.copy())
    auto = SelectingVelocityKF(VelocityKFConfig(motion_model="auto"), CAM.width_px)
    _run([auto], lambda k: base + errors[k - 1], 80, rng, 0.5)
    assert (auto.weights_accel < 0.15).all()
    # the reported twist is the constant model's but for that small share
    gap = np.abs(auto.accel.x_frame - auto.constant.x_frame)
    assert (np.abs(auto.x_frame - auto.constant.x_frame) <= 0.15 * gap + 1e-12).all()


def test_auto_waits_for_evidence_before_weighting_the_acceleration_model():
    """One score is noise: after the second update (the first both models predicted) the
    confidence stays below one half however clean the stream (the prior's pseudo-updates of "no
    difference"); a consistent advantage is trusted within ten updates."""
    confidence = {}
    for frames in (2, 10):
        auto = SelectingVelocityKF(VelocityKFConfig(motion_model="auto"), CAM.width_px)
        _run([auto], lambda k: _twist((k - 0.5) * DT_S), frames, np.random.default_rng(4), 0.0)
        confidence[frames] = auto.confidence
        assert (auto.weights_accel <= auto.confidence + 1e-12).all()
    assert confidence[2] < 0.5 < 0.99 < confidence[10]


def test_a_sudden_stop_takes_the_weight_from_the_acceleration_model_at_once():
    """A clean accelerating stream gives the constant-acceleration model the weight; when the
    motion stops holding its last twist, the constant model predicts the next flow exactly and
    the other one is off by its rate: the current update's scores move the weights below 0.1
    in that same update (the running means alone would keep them above 0.85 for many more)."""
    rng = np.random.default_rng(9)
    auto = SelectingVelocityKF(VelocityKFConfig(motion_model="auto"), CAM.width_px)
    stop = 40
    _run([auto], lambda k: _twist((min(k, stop) - 0.5) * DT_S), stop, rng, 0.05)
    assert (auto.weights_accel > 0.85).all()
    u, v, J = _pixels(np.random.default_rng(10))
    y = J @ _twist((stop - 0.5) * DT_S) + rng.normal(0.0, 0.05, (len(u), 2))
    auto.step(FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v), t_s=(stop + 1) * DT_S, dt_s=DT_S)
    assert (auto.weights_accel < 0.1).all(), auto.weights_accel
    assert (auto.score[1] < auto.score[0]).all()  # the running means still favour it


def test_the_twist_is_mixed_per_part_at_the_decoupling_point():
    """The pixels all at 1 m depth around the optical axis: the fit's decoupling point is on
    the axis near that depth (the linear velocity there does not depend on ``w``). With one
    model's weights set per part, the reported twist has the constant-acceleration model's
    velocity at that point and the constant model's angular velocity (the oracle: both models'
    twists moved to the point by ``v + w x c`` by hand)."""
    rng = np.random.default_rng(8)
    n = 400
    u = rng.uniform(220, 420, n).astype(np.int64)
    v = rng.uniform(140, 340, n).astype(np.int64)
    J = flow_jacobian(CAM, u, v, np.ones(n), DT_S)
    auto = SelectingVelocityKF(VelocityKFConfig(motion_model="auto"), CAM.width_px)
    for k in range(1, 6):
        y = J @ _twist((k - 0.5) * DT_S) + rng.normal(0.0, 0.2, (n, 2))
        auto.step(FlowMeasurement(y_px=y, J=J, u_px=u, v_px=v), t_s=k * DT_S, dt_s=DT_S)
    c = auto.decoupling_point_m
    assert abs(c[2] - 1.0) < 0.05 and np.hypot(c[0], c[1]) < 0.05
    auto.weights_accel = np.array([1.0, 0.0])
    auto._combine()
    at_c = [
        np.r_[x[:3] + np.cross(x[3:], c), x[3:]]
        for x in (auto.constant.x_frame, auto.accel.x_frame)
    ]
    reported = np.r_[auto.x_frame[:3] + np.cross(auto.x_frame[3:], c), auto.x_frame[3:]]
    np.testing.assert_allclose(reported[:3], at_c[1][:3], atol=1e-12)
    np.testing.assert_allclose(reported[3:], at_c[0][3:], atol=1e-12)


def test_constant_acceleration_starts_from_the_first_flow():
    """An object already moving fast (1.2 m/s, 4 rad/s, no acceleration) when the first flow
    arrives: the first update takes the pixels' interval mean as the twist (the rate at its
    prior), so no frame's twist is off by more than 1 cm/s and 0.02 rad/s. A Bayesian update
    of the zero prior put most of the first twist into the rate and inflated the adaptive twist
    noise with it (91 cm/s on frame 1 of TUM room1 at 640x360, docs/roft.md)."""
    rng = np.random.default_rng(6)
    truth = np.r_[0.9, -0.8, 0.1, 2.0, -3.0, 1.5]
    kf = VelocityKF(VelocityKFConfig(), CAM.width_px, "constant_acceleration")
    (reported,) = _run([kf], lambda k: truth, 12, rng, 0.05)
    err = np.abs(reported - truth)
    assert (err[:, :3] < 0.01).all(), err[:, :3].max(axis=0)
    assert (err[:, 3:] < 0.02).all(), err[:, 3:].max(axis=0)


def test_make_velocity_filter_and_the_auto_settings():
    assert isinstance(make_velocity_filter(VelocityKFConfig()), SelectingVelocityKF)
    kf = make_velocity_filter(VelocityKFConfig(motion_model="constant"))
    assert isinstance(kf, VelocityKF)
    auto = SelectingVelocityKF(VelocityKFConfig(motion_model="auto"))
    J = flow_jacobian(CAM, [100, 200, 300], [100, 200, 150], [1.0, 1.0, 1.0], DT_S)
    zeros = np.zeros(3, np.int64)
    with pytest.raises(ValueError, match="needs the frame time"):
        auto.step(FlowMeasurement(y_px=np.zeros((3, 2)), J=J, u_px=zeros, v_px=zeros))
    with pytest.raises(ConfigError, match="selection"):
        VelocityKFConfig(selection_margin=0.0)
    with pytest.raises(ConfigError, match="selection_memory"):
        VelocityKFConfig(selection_memory=0.5)
    with pytest.raises(ConfigError, match="selection_prior_updates"):
        VelocityKFConfig(selection_prior_updates=0.0)
    with pytest.raises(ConfigError, match="selection"):
        VelocityKFConfig(selection_log_ratio_clip=-1.0)
