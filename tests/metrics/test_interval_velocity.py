"""Velocity from the exact interval motion: closed forms for uniform and uniformly accelerated
motion, scipy for the rotations, and the fitted predictor never worse than the other two."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from roft_sim.geometry import transform_from_rt
from roft_sim.metrics.interval_velocity import interval_mean_twists, interval_velocity_errors
from roft_sim.records import PoseTrack

AXIS = np.array([1.0, 2.0, -2.0]) / 3.0  # a fixed unit axis


def _fixed_axis_track(t_s, angle, rate, position, velocity) -> PoseTrack:
    """Rotation by ``angle(t)`` about AXIS (rate ``rate(t)`` [rad/s]) and translation
    ``position(t)`` (velocity ``velocity(t)``), sampled at ``t_s`` with scipy's rotations."""
    t = np.asarray(t_s, dtype=np.float64)
    R = Rotation.from_rotvec(angle(t)[:, None] * AXIS).as_matrix()
    return PoseTrack(
        t_s=t,
        T_cam_obj=transform_from_rt(R, position(t)),
        v_obj_mps=velocity(t),
        w_radps=rate(t)[:, None] * AXIS,
    )


def _uniformly_accelerated(t_s, alpha=30.0, accel=(2.0, -1.0, 0.5)) -> PoseTrack:
    a = np.asarray(accel)
    return _fixed_axis_track(
        t_s,
        angle=lambda t: 0.5 * alpha * t**2 + 0.3 * t,
        rate=lambda t: alpha * t + 0.3,
        position=lambda t: 0.5 * t[:, None] ** 2 * a + [0.0, 0.0, 0.7],
        velocity=lambda t: t[:, None] * a,
    )


def test_uniform_motion_is_known_exactly_from_its_intervals():
    t = np.arange(40) / 30.0
    track = _fixed_axis_track(
        t,
        angle=lambda s: 2.0 * s,
        rate=lambda s: np.full_like(s, 2.0),
        position=lambda s: s[:, None] * [0.1, -0.2, 0.05] + [0.0, 0.0, 0.7],
        velocity=lambda s: np.tile([0.1, -0.2, 0.05], (s.size, 1)),
    )
    v, w = interval_mean_twists(track)
    np.testing.assert_allclose(v, np.tile([0.1, -0.2, 0.05], (39, 1)), atol=1e-12)
    np.testing.assert_allclose(w, np.tile(2.0 * AXIS, (39, 1)), atol=1e-9)
    errors = interval_velocity_errors(track)
    assert errors.frames == 37
    for name in ("held", "extrapolated", "fitted"):
        assert getattr(errors, f"{name}_v_cmps") == pytest.approx(0.0, abs=1e-9)
        assert getattr(errors, f"{name}_w_dps") == pytest.approx(0.0, abs=1e-6)


def test_uniform_acceleration_holds_half_an_interval_behind_and_extrapolates_exactly():
    """The interval mean of a linearly changing velocity is its value at the interval's
    middle: held lags by a dt / 2, a linear extrapolation is exact."""
    dt = 1.0 / 30.0
    alpha, accel = 30.0, np.array([2.0, -1.0, 0.5])
    errors = interval_velocity_errors(_uniformly_accelerated(np.arange(50) * dt, alpha, accel))
    assert errors.held_w_dps == pytest.approx(np.rad2deg(alpha * dt / 2), rel=1e-6)
    assert errors.held_v_cmps == pytest.approx(100 * np.linalg.norm(accel) * dt / 2, rel=1e-9)
    assert errors.extrapolated_w_dps == pytest.approx(0.0, abs=1e-6)
    assert errors.extrapolated_v_cmps == pytest.approx(0.0, abs=1e-9)
    assert errors.fitted_v_cmps == pytest.approx(0.0, abs=1e-6)


def test_dropped_frames_use_the_time_stamps():
    """Frames 10 and 11 missing: the intervals around the gap are longer, and the
    extrapolation spans the distance between the two intervals' middles."""
    t = np.delete(np.arange(50), [10, 11]) / 30.0
    errors = interval_velocity_errors(_uniformly_accelerated(t))
    assert errors.extrapolated_w_dps == pytest.approx(0.0, abs=1e-6)
    assert errors.extrapolated_v_cmps == pytest.approx(0.0, abs=1e-9)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**16), frequency_hz=st.floats(0.5, 8.0))
def test_the_fitted_predictor_is_never_worse_than_held_or_extrapolated(seed, frequency_hz):
    """Both are linear combinations of the last three interval means (weights (1, 0, 0) and
    (1.5, -0.5, 0) at a steady rate); ``fitted`` is the least-squares best one."""
    rng = np.random.default_rng(seed)
    phase, amplitude = rng.uniform(0, 2 * np.pi, 2), rng.uniform(0.2, 1.5, 2)
    omega = 2 * np.pi * frequency_hz
    track = _fixed_axis_track(
        np.arange(60) / 30.0,
        angle=lambda t: amplitude[0] * np.sin(omega * t + phase[0]),
        rate=lambda t: amplitude[0] * omega * np.cos(omega * t + phase[0]),
        position=lambda t: (
            np.outer(np.sin(omega * t + phase[1]), [0.1, 0.0, 0.02]) * amplitude[1]
            + [0.0, 0.0, 0.7]
        ),
        velocity=lambda t: (
            np.outer(np.cos(omega * t + phase[1]), [0.1, 0.0, 0.02]) * amplitude[1] * omega
        ),
    )
    e = interval_velocity_errors(track)
    assert e.fitted_w_dps <= min(e.held_w_dps, e.extrapolated_w_dps) + 1e-9
    assert e.fitted_v_cmps <= min(e.held_v_cmps, e.extrapolated_v_cmps) + 1e-9


def test_too_short_a_track_scores_no_frame():
    errors = interval_velocity_errors(_uniformly_accelerated(np.arange(3) / 30.0))
    assert errors.frames == 0 and np.isnan(errors.held_v_cmps)
    assert errors.summary()["held_w_dps"] is None and errors.summary()["frames"] == 0


def test_time_stamps_must_increase():
    track = _uniformly_accelerated(np.array([0.0, 0.1, 0.1, 0.2, 0.3]))
    with pytest.raises(ValueError, match="must increase"):
        interval_mean_twists(track)
