"""Hypothesis strategies for object trajectories with speed bounds, and a derivative check.

For property tests of trackers and filters (and of trajectories themselves)::

    from roft_sim.testing.trajectory_strategies import synthetic_trajectories

    @given(synthetic_trajectories(max_linear_speed_mps=0.3, max_angular_speed_dps=120))
    def test_my_tracker_follows_slow_motion(trajectory):
        track = sample_at_rate(trajectory, 30.0).as_pose_track()
        ...

Every drawn trajectory is a seeded :class:`roft_sim.trajectories.MinimumJerkTrajectory` in the
camera frame: its peak linear and angular speeds equal the drawn targets (which lie inside the
given bounds), and the object centre stays in the view region of the camera.
"""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.so3 import rotvec_from_matrix
from roft_sim.testing.strategies import FiniteFloats
from roft_sim.trajectories.base import Trajectory
from roft_sim.trajectories.build import FAST_YCB_CAMERA, build_trajectory
from roft_sim.trajectories.synthetic import SyntheticMotionConfig

F64 = NDArray[np.float64]

__all__ = [
    "synthetic_motion_configs",
    "synthetic_trajectories",
    "sample_times",
    "finite_difference_errors",
]


@st.composite
def synthetic_motion_configs(
    draw: st.DrawFn,
    *,
    min_linear_speed_mps: float = 0.05,
    max_linear_speed_mps: float = 1.0,
    min_angular_speed_dps: float = 10.0,
    max_angular_speed_dps: float = 400.0,
    min_duration_s: float = 2.0,
    max_duration_s: float = 8.0,
) -> SyntheticMotionConfig:
    """Synthetic-motion configs whose peak speeds lie in the given bounds.

    The seed, duration, peak speeds, slowest-primitive fraction and primitive mix are drawn;
    the durations of submovements stay at most half the total duration.
    """
    if not (0 < min_linear_speed_mps <= max_linear_speed_mps):
        raise ValueError("need 0 < min_linear_speed_mps <= max_linear_speed_mps")
    if not (0 < min_angular_speed_dps <= max_angular_speed_dps):
        raise ValueError("need 0 < min_angular_speed_dps <= max_angular_speed_dps")
    if not (1.0 <= min_duration_s <= max_duration_s):
        raise ValueError("need 1 <= min_duration_s <= max_duration_s")
    finite: FiniteFloats = {"allow_nan": False, "allow_infinity": False}
    duration = draw(st.floats(min_duration_s, max_duration_s, **finite))
    longest = min(0.9, 0.5 * duration)
    weights = draw(st.lists(st.floats(0.0, 1.0, **finite), min_size=4, max_size=4))
    if sum(weights) == 0:
        weights[0] = 1.0
    return SyntheticMotionConfig(
        seed=draw(st.integers(0, 2**32 - 1)),
        duration_s=duration,
        peak_linear_speed_mps=draw(st.floats(min_linear_speed_mps, max_linear_speed_mps, **finite)),
        peak_angular_speed_dps=draw(
            st.floats(min_angular_speed_dps, max_angular_speed_dps, **finite)
        ),
        min_speed_fraction=draw(st.floats(0.1, 1.0, **finite)),
        reach_weight=weights[0],
        twist_weight=weights[1],
        shake_weight=weights[2],
        hold_weight=weights[3],
        submovement_duration_s=(min(0.3, longest), longest),
    )


@st.composite
def synthetic_trajectories(
    draw: st.DrawFn,
    /,
    *,
    intrinsics: CameraIntrinsics = FAST_YCB_CAMERA,
    object_radius_m: float = 0.1,
    **bounds: float,
) -> Trajectory:
    """Placed synthetic trajectories ``T_cam_obj(t)`` whose peak speeds lie in ``bounds``.

    Args:
        intrinsics: camera the object stays in view of.
        object_radius_m: object radius for the in-view margin [m].
        **bounds: keyword arguments of :func:`synthetic_motion_configs` (speed and duration
            bounds).
    """
    config = draw(synthetic_motion_configs(**bounds))
    return build_trajectory(config, intrinsics, object_radius_m=object_radius_m)


@st.composite
def sample_times(draw: st.DrawFn, trajectory: Trajectory, *, max_size: int = 32) -> F64:
    """Sorted ``(N,)`` times [s] inside ``[start_s, end_s]`` of ``trajectory``, N >= 1."""
    finite: FiniteFloats = {"allow_nan": False, "allow_infinity": False}
    times = draw(
        st.lists(
            st.floats(trajectory.start_s, trajectory.end_s, **finite),
            min_size=1,
            max_size=max_size,
        )
    )
    return np.sort(np.array(times, dtype=np.float64))


def finite_difference_errors(
    trajectory: Trajectory,
    t_s: ArrayLike,
    *,
    h_s: float = 1e-6,
    floor_mps: float = 1e-3,
    floor_radps: float = 1e-3,
    floor_mps2: float = 1e-2,
    floor_radps2: float = 1e-2,
) -> dict[str, F64]:
    """Relative disagreement between a trajectory's derivatives and central differences.

    At each time ``t`` (which needs ``t +- h_s`` inside the trajectory), compares
    ``v`` with ``(p(t+h) - p(t-h)) / 2h``, ``w`` with ``Log(R(t+h) R(t-h)^T) / 2h``, ``a`` with
    the difference of ``v`` and ``alpha`` with the difference of ``w``. Each error is
    ``|analytic - fd| / max(|analytic|, floor)``, the floor keeping the ratio finite at rest.

    Returns:
        ``{"v": (N,), "w": (N,), "a": (N,), "alpha": (N,)}`` relative errors.
    """
    t = np.asarray(t_s, dtype=np.float64)
    mid, plus, minus = trajectory.sample(t), trajectory.sample(t + h_s), trajectory.sample(t - h_s)
    v_fd = (plus.T_ref_obj[:, :3, 3] - minus.T_ref_obj[:, :3, 3]) / (2 * h_s)
    dR = plus.T_ref_obj[:, :3, :3] @ np.swapaxes(minus.T_ref_obj[:, :3, :3], -1, -2)
    w_fd = rotvec_from_matrix(dR) / (2 * h_s)
    a_fd = (plus.v_mps - minus.v_mps) / (2 * h_s)
    alpha_fd = (plus.w_radps - minus.w_radps) / (2 * h_s)

    def rel(analytic: F64, fd: F64, floor: float) -> F64:
        size = np.maximum(np.linalg.norm(analytic, axis=-1), floor)
        err: F64 = np.linalg.norm(analytic - fd, axis=-1) / size
        return err

    return {
        "v": rel(mid.v_mps, v_fd, floor_mps),
        "w": rel(mid.w_radps, w_fd, floor_radps),
        "a": rel(mid.a_mps2, a_fd, floor_mps2),
        "alpha": rel(mid.alpha_radps2, alpha_fd, floor_radps2),
    }
