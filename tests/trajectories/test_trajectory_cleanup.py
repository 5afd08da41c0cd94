"""Clean-up of sampled poses: resampling, drift removal, low-pass, windows, speed scaling."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy import signal

from roft_sim.errors import ConfigError
from roft_sim.geometry import matrix_from_rotvec, rotation_angle, transform_from_rt
from roft_sim.testing import assert_pose_close
from roft_sim.trajectories import PoseSamples, SplinePoseTrajectory
from roft_sim.trajectories.samples import (
    LOWPASS_ORDER,
    find_gaps,
    lowpass_poses,
    remove_position_drift,
    resample_uniform,
    scale_speed,
    window_samples,
)

RATE_HZ = 120.0
AXIS = np.array([1.0, 2.0, 2.0]) / 3.0


def single_axis_samples(angle_rad: np.ndarray, p_m: np.ndarray | None = None) -> PoseSamples:
    """Rotation ``Exp(angle * AXIS)`` and position ``p_m`` (N, 3) at 120 Hz."""
    n = angle_rad.size
    p = np.zeros((n, 3)) if p_m is None else p_m
    T = transform_from_rt(matrix_from_rotvec(angle_rad[:, None] * AXIS), p)
    return PoseSamples(t_s=np.arange(n) / RATE_HZ, T_ref_obj=T, source="test")


def butterworth(x: np.ndarray, cutoff_hz: float) -> np.ndarray:
    sos = signal.butter(LOWPASS_ORDER, cutoff_hz, fs=RATE_HZ, output="sos")
    return signal.sosfiltfilt(sos, x, axis=0)


def test_lowpass_equals_angle_filter_about_a_fixed_axis() -> None:
    """Oracle: about a fixed axis the tangent-space filter is the filter of the angle."""
    rng = np.random.default_rng(0)
    t = np.arange(480) / RATE_HZ
    angle = np.sin(2 * np.pi * 1.0 * t) + 0.01 * rng.normal(size=t.size)
    p = np.column_stack([0.1 * np.sin(2 * np.pi * t), 0.01 * rng.normal(size=t.size), 0 * t])
    out = lowpass_poses(single_axis_samples(angle, p), 10.0)
    expected = matrix_from_rotvec(butterworth(angle, 10.0)[:, None] * AXIS)
    interior = slice(60, -60)
    err_rad = rotation_angle(out.T_ref_obj[interior, :3, :3], expected[interior])
    assert err_rad.max() < 1e-4
    np.testing.assert_allclose(out.T_ref_obj[:, :3, 3], butterworth(p, 10.0), atol=1e-15)


def test_lowpass_removes_jitter_and_keeps_slow_motion() -> None:
    """0.6 deg RMS jitter (CMU wrists) shrinks below half; a 1 Hz swing stays put."""
    rng = np.random.default_rng(1)
    t = np.arange(1200) / RATE_HZ
    truth = 0.8 * np.sin(2 * np.pi * 0.7 * t)
    noisy = np.column_stack([truth, 0 * t, 0 * t]) + rng.normal(
        0, np.radians(0.6) / 3**0.5, (t.size, 3)
    )
    samples = PoseSamples(
        t_s=t,
        T_ref_obj=transform_from_rt(matrix_from_rotvec(noisy), np.zeros((t.size, 3))),
        source="x",
    )
    out = lowpass_poses(samples, 10.0)
    truth_R = matrix_from_rotvec(np.column_stack([truth, 0 * t, 0 * t]))
    before = rotation_angle(samples.T_ref_obj[:, :3, :3], truth_R)
    after = rotation_angle(out.T_ref_obj[:, :3, :3], truth_R)
    assert np.sqrt(np.mean(after**2)) < 0.5 * np.sqrt(np.mean(before**2))
    assert np.sqrt(np.mean(after[100:-100] ** 2)) < np.radians(0.3)


def test_lowpass_does_not_depend_on_quaternion_signs() -> None:
    """Rotations are stored as matrices, but the filter works on quaternions; a motion that turns
    more than 360 deg crosses every sign convention."""
    t = np.arange(600) / RATE_HZ
    angle = 2.5 * np.pi * t  # 1.25 turns per second
    samples = single_axis_samples(angle)
    out = lowpass_poses(samples, 10.0)
    interior = slice(60, -60)
    err = rotation_angle(out.T_ref_obj[interior, :3, :3], samples.T_ref_obj[interior, :3, :3])
    assert err.max() < 1e-6


def test_lowpass_errors() -> None:
    samples = single_axis_samples(np.zeros(200))
    with pytest.raises(ConfigError, match="Nyquist"):
        lowpass_poses(samples, 70.0)
    irregular = PoseSamples(
        t_s=np.cumsum(np.linspace(0.01, 0.02, 200)), T_ref_obj=samples.T_ref_obj, source="x"
    )
    with pytest.raises(ValueError, match="resample_uniform"):
        lowpass_poses(irregular, 10.0)


def test_drift_removal_removes_walking_and_keeps_hand_motion() -> None:
    t = np.arange(int(10 * RATE_HZ)) / RATE_HZ
    walk = np.column_stack([1.2 * t, 0.3 * t, 0 * t])
    hand = np.column_stack(
        [0.05 * np.sin(2 * np.pi * 2 * t), 0 * t, 0.03 * np.cos(2 * np.pi * 3 * t)]
    )
    out = remove_position_drift(single_axis_samples(0 * t, walk + hand), 2.0)
    interior = slice(int(1.5 * RATE_HZ), -int(1.5 * RATE_HZ))
    np.testing.assert_allclose(out.T_ref_obj[interior, :3, 3], hand[interior], atol=1e-3)
    with pytest.raises(ConfigError, match="fewer than 3 samples"):
        remove_position_drift(single_axis_samples(0 * t), 0.01)


def test_resample_uniform_bridges_gaps_on_the_spline(caplog: pytest.LogCaptureFixture) -> None:
    t = np.concatenate([np.arange(50), np.arange(80, 130)]) / RATE_HZ
    angle = np.sin(t)
    samples = PoseSamples(t_s=t, T_ref_obj=single_axis_samples(angle).T_ref_obj, source="gappy")
    assert find_gaps(t) == [(pytest.approx(49 / RATE_HZ), pytest.approx(31 / RATE_HZ))]
    with caplog.at_level(logging.INFO):
        out = resample_uniform(samples)
    assert "1 gaps" in caplog.text
    np.testing.assert_allclose(out.t_s, np.arange(130) / RATE_HZ, atol=1e-12)
    spline = SplinePoseTrajectory(t, samples.T_ref_obj)
    assert_pose_close(out.T_ref_obj, spline.sample(out.t_s).T_ref_obj, atol_m=1e-15, atol_rad=1e-12)


def test_window_keeps_the_span_and_restarts_time() -> None:
    samples = single_axis_samples(np.linspace(0, 1, 240))
    out = window_samples(samples, 0.5, 1.0)
    assert out.t_s[0] == 0.0 and out.t_s[-1] == pytest.approx(0.5)
    assert len(out) == 61
    assert_pose_close(out.T_ref_obj, samples.T_ref_obj[60:121])
    with pytest.raises(ConfigError, match="keeps 0 samples"):
        window_samples(samples, 5.0, 6.0)


def test_speed_scale_scales_velocities_and_accelerations() -> None:
    rng = np.random.default_rng(2)
    t = np.arange(40) / 30.0
    rotvec = np.cumsum(rng.normal(0, 0.1, (40, 3)), axis=0)
    p = np.cumsum(rng.normal(0, 0.02, (40, 3)), axis=0)
    samples = PoseSamples(
        t_s=t, T_ref_obj=transform_from_rt(matrix_from_rotvec(rotvec), p), source="x"
    )
    base = SplinePoseTrajectory(samples.t_s, samples.T_ref_obj)
    half = scale_speed(samples, 0.5)
    slow = SplinePoseTrajectory(half.t_s, half.T_ref_obj)
    assert slow.end_s == pytest.approx(2 * base.end_s)
    tm = np.linspace(0.1, 1.2, 17)
    a, b = base.sample(tm), slow.sample(tm / 0.5)
    assert_pose_close(b.T_ref_obj, a.T_ref_obj, atol_m=1e-12, atol_rad=1e-9)
    np.testing.assert_allclose(b.v_mps, 0.5 * a.v_mps, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.w_radps, 0.5 * a.w_radps, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.a_mps2, 0.25 * a.a_mps2, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(b.alpha_radps2, 0.25 * a.alpha_radps2, rtol=1e-9, atol=1e-12)
    with pytest.raises(ConfigError, match="speed_scale"):
        scale_speed(samples, 0.0)
