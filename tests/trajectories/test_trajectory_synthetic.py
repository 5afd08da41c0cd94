"""Synthetic minimum-jerk motion: speed targets, in view, exact derivatives, determinism."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.testing.trajectory_strategies import (
    finite_difference_errors,
    sample_times,
    synthetic_motion_configs,
    synthetic_trajectories,
)
from roft_sim.trajectories import (
    FAST_YCB_CAMERA,
    MinimumJerkTrajectory,
    SyntheticMotionConfig,
    Trajectory,
    ViewRegion,
    build_trajectory,
    sample_at_rate,
    speed_statistics,
)
from roft_sim.trajectories.synthetic import _profile

SMALL_CAMERA = CameraIntrinsics(
    fx_px=140.0, fy_px=140.0, cx_px=79.5, cy_px=59.5, width_px=160, height_px=120
)


def away_from_segment_ends(traj: MinimumJerkTrajectory, t: np.ndarray, gap_s: float) -> np.ndarray:
    ends = np.concatenate([traj.segment_start_times_s, [traj.end_s]])
    return t[np.min(np.abs(t[:, None] - ends[None, :]), axis=1) > gap_s]


def test_minimum_jerk_profile_against_its_polynomial() -> None:
    tau = np.linspace(0, 1, 11)
    s, ds, dds = _profile(tau)
    np.testing.assert_allclose(s, 10 * tau**3 - 15 * tau**4 + 6 * tau**5, atol=1e-15)
    np.testing.assert_allclose(ds, 30 * tau**2 - 60 * tau**3 + 30 * tau**4, atol=1e-13)
    np.testing.assert_allclose(dds, 60 * tau - 180 * tau**2 + 120 * tau**3, atol=1e-12)
    assert (s[0], s[-1], ds[0], ds[-1], dds[0], dds[-1]) == (0, 1, 0, 0, 0, 0)
    assert ds[5] == pytest.approx(1.875)


def test_default_synthetic_motion_hits_the_fast_ycb_speed_targets() -> None:
    """Peaks within 10 % of 0.6 m/s and 266 deg/s, for the default seed and a few others."""
    for seed in (0, 1, 2, 3, 4):
        config = SyntheticMotionConfig(seed=seed)
        traj = build_trajectory(config, FAST_YCB_CAMERA)
        assert isinstance(traj, Trajectory)
        assert (traj.start_s, traj.end_s) == (0.0, pytest.approx(10.0, abs=1e-12))
        stats = speed_statistics(sample_at_rate(traj, 30.0))
        assert stats.linear_speed_mps.peak == pytest.approx(0.6, rel=0.1)
        assert stats.angular_speed_dps.peak == pytest.approx(266.0, rel=0.1)
        # the exact segment peaks equal the targets
        v_peak, w_peak = traj.segment_peak_speeds()
        assert v_peak.max() == pytest.approx(0.6, rel=1e-12)
        assert np.degrees(w_peak.max()) == pytest.approx(266.0, rel=1e-12)


def _peak_accelerations(traj: Trajectory) -> tuple[float, float, float]:
    """(max linear [m/s^2], max angular [deg/s^2], p95 angular [deg/s^2]) sampled at 1 kHz."""
    sample = sample_at_rate(traj, 1000.0)
    a = np.linalg.norm(sample.a_mps2, axis=1)
    alpha = np.degrees(np.linalg.norm(sample.alpha_radps2, axis=1))
    return float(a.max()), float(alpha.max()), float(np.percentile(alpha, 95))


def test_accelerations_stay_within_the_human_like_bounds() -> None:
    """Every primitive respects the bounds; the p95 matches captured hand motion (TUM VI rooms:
    830-990 deg/s^2), while the peak speeds stay at the Fast-YCB targets."""
    for seed in (0, 1, 2):
        config = SyntheticMotionConfig(seed=seed, duration_s=20.0)
        a_max, alpha_max, alpha_p95 = _peak_accelerations(build_trajectory(config, FAST_YCB_CAMERA))
        assert a_max <= config.peak_linear_acceleration_mps2 * (1 + 1e-6)
        assert alpha_max <= config.peak_angular_acceleration_dps2 * (1 + 1e-6)
        assert 700.0 < alpha_p95 <= 1000.0
    # without the bound the same primitives accelerate far harder (the bound has an effect)
    loose = SyntheticMotionConfig(
        seed=0,
        duration_s=20.0,
        peak_linear_acceleration_mps2=1e6,
        peak_angular_acceleration_dps2=1e9,
    )
    assert _peak_accelerations(build_trajectory(loose, FAST_YCB_CAMERA))[1] > 3000.0


def test_synthetic_motion_stays_in_view_at_the_working_distance() -> None:
    for camera, radius in ((FAST_YCB_CAMERA, 0.1), (SMALL_CAMERA, 0.05)):
        traj = build_trajectory(SyntheticMotionConfig(seed=7), camera, object_radius_m=radius)
        region = ViewRegion.from_config(camera, (0.4, 0.9), 0.5, radius)
        p = sample_at_rate(traj, 200.0).T_ref_obj[:, :3, 3]
        assert region.contains(p, tol_m=1e-9).all()
        assert p[:, 2].min() >= 0.4 - 1e-9 and p[:, 2].max() <= 0.9 + 1e-9


def test_synthetic_derivatives_match_finite_differences() -> None:
    traj = build_trajectory(SyntheticMotionConfig(seed=11), FAST_YCB_CAMERA)
    rng = np.random.default_rng(0)
    t = away_from_segment_ends(traj, np.sort(rng.uniform(0.0, traj.end_s, 600)), 1e-3)
    errors = finite_difference_errors(traj, t, h_s=1e-6)
    for name, err in errors.items():
        assert err.max() < 1e-6, (name, err.max())


def test_synthetic_motion_is_c2_across_segments() -> None:
    """Across every segment boundary, +-1 ns apart, nothing jumps (jerk ~1e3 m/s^3 at most, so
    accelerations may differ by ~1e-6)."""
    traj = build_trajectory(SyntheticMotionConfig(seed=5), FAST_YCB_CAMERA)
    for t in traj.segment_start_times_s[1:]:
        before, after = traj.sample([t - 1e-9]), traj.sample([t + 1e-9])
        for name in ("v_mps", "w_radps", "a_mps2", "alpha_radps2"):
            np.testing.assert_allclose(getattr(before, name), getattr(after, name), atol=1e-5)
        np.testing.assert_allclose(before.T_ref_obj, after.T_ref_obj, atol=1e-8)


def test_same_seed_same_motion_other_seed_other_motion() -> None:
    t = np.linspace(0, 10, 301)
    a = build_trajectory(SyntheticMotionConfig(seed=42), FAST_YCB_CAMERA).sample(t)
    b = build_trajectory(SyntheticMotionConfig(seed=42), FAST_YCB_CAMERA).sample(t)
    c = build_trajectory(SyntheticMotionConfig(seed=43), FAST_YCB_CAMERA).sample(t)
    np.testing.assert_array_equal(a.T_ref_obj, b.T_ref_obj)
    np.testing.assert_array_equal(a.w_radps, b.w_radps)
    assert np.abs(a.T_ref_obj - c.T_ref_obj).max() > 1e-3


def test_configured_targets_are_hit() -> None:
    config = SyntheticMotionConfig(
        seed=3, duration_s=6.0, peak_linear_speed_mps=0.25, peak_angular_speed_dps=90.0
    )
    stats = speed_statistics(sample_at_rate(build_trajectory(config, FAST_YCB_CAMERA), 100.0))
    assert stats.linear_speed_mps.peak == pytest.approx(0.25, rel=0.02)
    assert stats.angular_speed_dps.peak == pytest.approx(90.0, rel=0.02)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"duration_s": 1.0}, r"too short .* use at least 1.80 s"),
        ({"peak_angular_acceleration_dps2": 0.0}, "peak_angular_acceleration_dps2 must be a posi"),
        (
            {"duration_s": 3.0, "peak_linear_acceleration_mps2": 0.5},
            r"too short .* use at least 7.39 s .*acceleration bounds",
        ),
        ({"peak_linear_speed_mps": 0.0}, "peak_linear_speed_mps must be a positive number"),
        ({"working_distance_m": (0.9, 0.4)}, "0 < near < far"),
        (
            {"reach_weight": 0, "twist_weight": 0, "shake_weight": 0, "hold_weight": 0},
            "positive sum",
        ),
        ({"shake_half_cycles": (0, 3)}, "shake_half_cycles"),
        ({"min_speed_fraction": 1.5}, r"min_speed_fraction must lie in \(0, 1\]"),
    ],
)
def test_synthetic_config_errors(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        SyntheticMotionConfig(**kwargs)


def test_region_too_narrow_for_the_margin() -> None:
    with pytest.raises(ConfigError, match="no object centre fits in view"):
        build_trajectory(SyntheticMotionConfig(), SMALL_CAMERA, object_radius_m=2.0)


@settings(max_examples=15)
@given(
    config=synthetic_motion_configs(max_linear_speed_mps=0.8, max_angular_speed_dps=300),
)
def test_property_any_config_hits_its_targets_and_stays_in_view(
    config: SyntheticMotionConfig,
) -> None:
    traj = build_trajectory(config, SMALL_CAMERA, object_radius_m=0.05)
    v_peak, w_peak = traj.segment_peak_speeds()
    assert v_peak.max() == pytest.approx(config.peak_linear_speed_mps, rel=1e-9)
    assert w_peak.max() == pytest.approx(config.peak_angular_speed_radps, rel=1e-9)
    assert traj.end_s == pytest.approx(config.duration_s, abs=1e-9)
    region = ViewRegion.from_config(
        SMALL_CAMERA, config.working_distance_m, config.in_view_margin, 0.05
    )
    assert region.contains(sample_at_rate(traj, 60.0).T_ref_obj[:, :3, 3], tol_m=1e-9).all()


@settings(max_examples=10)
@given(data=st.data())
def test_strategies_respect_speed_bounds(data: st.DataObject) -> None:
    traj = data.draw(synthetic_trajectories(max_linear_speed_mps=0.3, max_angular_speed_dps=100))
    t = data.draw(sample_times(traj))
    sample = traj.sample(t)
    assert sample.linear_speed_mps.max() <= 0.3 * (1 + 1e-9)
    assert np.degrees(sample.angular_speed_radps.max()) <= 100 * (1 + 1e-9)
