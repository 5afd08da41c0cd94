"""Spline replay, rigid maps, samples and speed statistics: exact derivatives, oracles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation, RotationSpline

from roft_sim.geometry import (
    matrix_from_rotvec,
    quat_from_matrix,
    rotvec_from_matrix,
    transform_from_rt,
)
from roft_sim.records import PoseTrack
from roft_sim.testing import assert_pose_close
from roft_sim.testing.strategies import transforms
from roft_sim.testing.trajectory_strategies import finite_difference_errors
from roft_sim.trajectories import (
    RigidlyMappedTrajectory,
    SplinePoseTrajectory,
    Trajectory,
    TrajectorySample,
    sample_at_rate,
    speed_statistics,
)


def random_poses(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Irregular times (N,) [s] and smooth-ish random poses (N, 4, 4) [m]."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.02, 0.06, n))
    rotvec = np.cumsum(rng.normal(0.0, 0.2, (n, 3)), axis=0)
    p = np.cumsum(rng.normal(0.0, 0.01, (n, 3)), axis=0)
    return t, transform_from_rt(matrix_from_rotvec(rotvec), p)


def interior_times(knots: np.ndarray, fraction: float = 0.37) -> np.ndarray:
    """One time inside each knot interval except the first and last, away from the knots."""
    return knots[1:-2] + fraction * np.diff(knots)[1:-1]


def test_scipy_rotation_spline_rate_is_body_frame() -> None:
    """The premise of SplinePoseTrajectory: scipy's rate satisfies dR/dt = R [w_body]x."""
    t, T = random_poses(12, seed=1)
    spline = RotationSpline(t, Rotation.from_matrix(T[:, :3, :3]))
    tm, h = interior_times(t), 1e-6
    R_minus, R_plus = spline(tm - h).as_matrix(), spline(tm + h).as_matrix()
    body_fd = rotvec_from_matrix(np.swapaxes(R_minus, 1, 2) @ R_plus) / (2 * h)
    space_fd = rotvec_from_matrix(R_plus @ np.swapaxes(R_minus, 1, 2)) / (2 * h)
    rate = spline(tm, 1)
    np.testing.assert_allclose(rate, body_fd, rtol=0, atol=1e-6)
    assert np.abs(rate - space_fd).max() > 1e-2  # genuinely different frames


def test_spline_passes_through_samples_and_is_a_trajectory() -> None:
    t, T = random_poses(20, seed=2)
    traj = SplinePoseTrajectory(t, T)
    assert isinstance(traj, Trajectory)
    assert (traj.start_s, traj.end_s) == (t[0], t[-1])
    assert_pose_close(traj.sample(t).T_ref_obj, T, atol_m=1e-12, atol_rad=1e-9)


def test_spline_derivatives_match_finite_differences() -> None:
    t, T = random_poses(40, seed=3)
    traj = SplinePoseTrajectory(t, T)
    errors = finite_difference_errors(traj, interior_times(t), h_s=1e-6)
    for name, err in errors.items():
        assert err.max() < 1e-6, (name, err.max())


@pytest.mark.parametrize(
    ("t", "message"),
    [
        (np.array([0.0, 1.0, 1.0, 2.0]), "increase strictly"),
        (np.array([0.0, 1.0, 2.0]), "at least 4 samples"),
    ],
)
def test_spline_rejects_bad_times(t: np.ndarray, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        SplinePoseTrajectory(t, np.broadcast_to(np.eye(4), (t.size, 4, 4)))


def test_sample_outside_interval_raises() -> None:
    t, T = random_poses(10, seed=4)
    traj = SplinePoseTrajectory(t, T)
    with pytest.raises(ValueError, match="outside the trajectory"):
        traj.sample([t[-1] + 1e-3])
    with pytest.raises(ValueError, match="NaN"):
        traj.sample([np.nan])
    # within the documented 1e-9 s tolerance the time is clamped
    assert traj.sample([t[-1] + 5e-10]).t_s[0] == t[-1]


def test_sample_as_pose_track_keeps_camera_frame_quantities() -> None:
    t, T = random_poses(10, seed=5)
    sample = SplinePoseTrajectory(t, T).sample(interior_times(t))
    track = sample.as_pose_track()
    assert isinstance(track, PoseTrack)
    np.testing.assert_array_equal(track.T_cam_obj, sample.T_ref_obj)
    np.testing.assert_array_equal(track.v_obj_mps, sample.v_mps)
    np.testing.assert_array_equal(track.w_radps, sample.w_radps)


def test_trajectory_sample_checks_shapes() -> None:
    with pytest.raises(ValueError, match="v_mps must have shape"):
        TrajectorySample(
            t_s=np.zeros(2),
            T_ref_obj=np.zeros((2, 4, 4)),
            v_mps=np.zeros((3, 3)),
            w_radps=np.zeros((2, 3)),
            a_mps2=np.zeros((2, 3)),
            alpha_radps2=np.zeros((2, 3)),
        )


@given(left=transforms(max_abs_m=1.0), right=transforms(max_abs_m=0.3))
def test_rigid_map_transforms_velocities_exactly(left: np.ndarray, right: np.ndarray) -> None:
    """Against the closed form and against finite differences of the mapped poses."""
    t, T = random_poses(16, seed=6)
    inner = SplinePoseTrajectory(t, T)
    mapped = RigidlyMappedTrajectory(inner, T_left=left, T_right=right)
    tm = interior_times(t)
    s, m = inner.sample(tm), mapped.sample(tm)
    R_A = left[:3, :3]
    d = s.T_ref_obj[:, :3, :3] @ right[:3, 3]
    np.testing.assert_allclose(m.T_ref_obj, left @ s.T_ref_obj @ right, atol=1e-12)
    np.testing.assert_allclose(m.w_radps, s.w_radps @ R_A.T, atol=1e-12)
    np.testing.assert_allclose(m.v_mps, (s.v_mps + np.cross(s.w_radps, d)) @ R_A.T, atol=1e-12)
    errors = finite_difference_errors(mapped, tm, h_s=1e-6)
    assert max(e.max() for e in errors.values()) < 1e-6
    # rigid maps with an identity grasp keep speeds
    ident = RigidlyMappedTrajectory(inner, T_left=left).sample(tm)
    np.testing.assert_allclose(ident.linear_speed_mps, s.linear_speed_mps, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(ident.angular_speed_radps, s.angular_speed_radps, rtol=1e-12)


def test_rigid_map_rejects_non_rigid_transform() -> None:
    t, T = random_poses(8, seed=7)
    with pytest.raises(ValueError, match="orthonormal"):
        RigidlyMappedTrajectory(SplinePoseTrajectory(t, T), T_left=np.diag([2.0, 1, 1, 1]))


def constant_twist_trajectory(v: np.ndarray, w: np.ndarray) -> SplinePoseTrajectory:
    """Poses of uniform motion ``p = v t``, ``R = Exp(w t)`` sampled at 100 Hz over 1 s."""
    t = np.arange(101) / 100.0
    return SplinePoseTrajectory(
        t, transform_from_rt(matrix_from_rotvec(np.outer(t, w)), np.outer(t, v))
    )


def test_speed_statistics_of_uniform_motion() -> None:
    """Hand-computed: a constant twist has constant speeds (the cubic reproduces them)."""
    traj = constant_twist_trajectory(np.array([0.3, 0.0, 0.4]), np.array([0.0, np.pi / 2, 0.0]))
    stats = speed_statistics(sample_at_rate(traj, 50.0))
    assert stats.num_samples == 51
    assert stats.duration_s == pytest.approx(1.0)
    assert stats.rate_hz == pytest.approx(50.0)
    for summary in (stats.linear_speed_mps,):
        assert summary.peak == pytest.approx(0.5, rel=1e-9)
        assert summary.median == pytest.approx(0.5, rel=1e-9)
    assert stats.angular_speed_dps.p95 == pytest.approx(90.0, rel=1e-6)
    report = stats.report()
    assert set(report["angular_speed_dps"]) == {"peak", "p95", "median"}


def test_speed_statistics_percentiles_and_exclusion() -> None:
    t = np.arange(101) / 100.0
    speed = t.copy()  # linear speed equal to t: v = (t, 0, 0)
    sample = TrajectorySample(
        t_s=t,
        T_ref_obj=np.broadcast_to(np.eye(4), (101, 4, 4)).copy(),
        v_mps=np.column_stack([speed, 0 * t, 0 * t]),
        w_radps=np.zeros((101, 3)),
        a_mps2=np.zeros((101, 3)),
        alpha_radps2=np.zeros((101, 3)),
    )
    stats = speed_statistics(sample)
    assert (stats.linear_speed_mps.peak, stats.linear_speed_mps.median) == (1.0, 0.5)
    assert stats.linear_speed_mps.p95 == pytest.approx(0.95)
    cut = speed_statistics(sample, exclude_intervals_s=[(0.805, 2.0)])
    assert cut.linear_speed_mps.peak == pytest.approx(0.8)
    assert cut.excluded_samples == 20 and cut.num_samples == 101
    with pytest.raises(ValueError, match="excluded"):
        speed_statistics(sample, exclude_intervals_s=[(-1.0, 2.0)])


@given(rate=st.floats(1.0, 500.0))
def test_sample_at_rate_stays_inside(rate: float) -> None:
    traj = constant_twist_trajectory(np.array([0.1, 0.0, 0.0]), np.zeros(3))
    sample = sample_at_rate(traj, rate)
    assert sample.t_s[0] == 0.0 and sample.t_s[-1] <= traj.end_s
    assert traj.end_s - sample.t_s[-1] < 1.0 / rate
    np.testing.assert_allclose(np.diff(sample.t_s), 1.0 / rate, rtol=1e-9)


def test_from_pq_matches_matrix_construction() -> None:
    t, T = random_poses(10, seed=8)
    a = SplinePoseTrajectory(t, T)
    b = SplinePoseTrajectory.from_pq(t, T[:, :3, 3], quat_from_matrix(T[:, :3, :3]))
    tm = interior_times(t)
    assert_pose_close(a.sample(tm).T_ref_obj, b.sample(tm).T_ref_obj, atol_m=1e-12, atol_rad=1e-9)
