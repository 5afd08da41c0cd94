"""Camera ego-motion with exact velocities: the camera's pose in the world over time.

The world frame is the OpenCV optical frame of the camera at rest; a static camera has
``T_world_cam = I``. Two models: a sinusoidal sway, and captured motion replayed from a file
(TUM, BVH joint, CSV) that starts at the rest pose. MuJoCo is not involved: the scene moves its
camera body to these poses.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry import invert_transform, matrix_from_rotvec, so3_left_jacobian
from roft_sim.scene.config import CameraFileMotionConfig, CameraMotionConfig, CameraSwayConfig
from roft_sim.trajectories.captured import read_pose_samples
from roft_sim.trajectories.rigid_map import RigidlyMappedTrajectory
from roft_sim.trajectories.samples import clean_samples
from roft_sim.trajectories.spline import SplinePoseTrajectory

F64 = NDArray[np.float64]

__all__ = ["CameraPoses", "camera_poses", "file_camera_trajectory"]

_PHASE_T = np.array([0.0, 2.0, 4.0]) * np.pi / 3.0
_PHASE_R = np.pi / 2.0 + _PHASE_T


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraPoses:
    """Camera poses and velocities at N times, world frame."""

    T_world_cam: F64
    """(N, 4, 4) camera pose (OpenCV optical frame) in the world [m]."""
    v_world_mps: F64
    """(N, 3) velocity of the camera origin, world frame [m/s]."""
    w_world_radps: F64
    """(N, 3) camera angular velocity, world frame [rad/s] (``dR/dt = [w]x R``)."""


def camera_poses(config: CameraMotionConfig | None, t_s: ArrayLike) -> CameraPoses:
    """Camera poses at times ``t_s`` ``(N,)`` [s]; None = a static camera at the world origin.

    Raises:
        ConfigError: a captured camera motion (``kind = "file"``) ends before a time asked for.
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
    n = t.shape[0]
    if config is None:
        return CameraPoses(
            T_world_cam=np.broadcast_to(np.eye(4), (n, 4, 4)).copy(),
            v_world_mps=np.zeros((n, 3)),
            w_world_radps=np.zeros((n, 3)),
        )
    if isinstance(config, CameraFileMotionConfig):
        return _file_camera_poses(config, t)
    if not isinstance(config, CameraSwayConfig):
        raise TypeError(f"unsupported camera motion {config!r}")
    omega = 2.0 * np.pi * config.frequency_hz
    a_p = np.asarray(config.amplitude_m, dtype=np.float64)
    a_r = np.asarray(config.amplitude_rad, dtype=np.float64)
    phase_p = omega * t[:, None] + _PHASE_T
    phase_r = omega * t[:, None] + _PHASE_R
    p = a_p * np.sin(phase_p)
    v = a_p * omega * np.cos(phase_p)
    r = a_r * np.sin(phase_r)
    r_dot = a_r * omega * np.cos(phase_r)
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, :3, :3] = matrix_from_rotvec(r)
    T[:, :3, 3] = p
    w = np.einsum("nij,nj->ni", so3_left_jacobian(r), r_dot)
    return CameraPoses(T_world_cam=T, v_world_mps=v, w_world_radps=w)


@functools.lru_cache(maxsize=8)
def file_camera_trajectory(config: CameraFileMotionConfig) -> RigidlyMappedTrajectory:
    """The captured camera motion as a trajectory ``T_world_cam(t)`` (cached per config: the
    renderer asks for one time per frame).

    The file is read with :func:`roft_sim.trajectories.captured.read_pose_samples`, cleaned as
    captured object motion is (:func:`roft_sim.trajectories.samples.clean_samples`) and
    replayed by a :class:`SplinePoseTrajectory` (exact derivatives); the anchoring is the rigid
    map of :class:`CameraFileMotionConfig`.

    Raises:
        DatasetFormatError: a malformed file.
        ConfigError: a missing joint or bad settings.
    """
    samples = read_pose_samples(
        config.path,
        config.format,
        joint=config.joint,
        relative_to=config.relative_to,
        bvh_unit=config.bvh_unit,
    )
    samples, _ = clean_samples(
        samples,
        lowpass_hz=config.lowpass_hz,
        remove_drift_window_s=config.remove_drift_window_s,
        window_s=config.window_s,
        speed_scale=config.speed_scale,
    )
    spline = SplinePoseTrajectory(samples.t_s, samples.T_ref_obj)
    T_body_cam = config.camera_in_body.T_hand_obj
    T_ref_cam0 = spline.sample(np.array([spline.start_s])).T_ref_obj[0] @ T_body_cam
    return RigidlyMappedTrajectory(spline, T_left=invert_transform(T_ref_cam0), T_right=T_body_cam)


def _file_camera_poses(config: CameraFileMotionConfig, t: F64) -> CameraPoses:
    trajectory = file_camera_trajectory(config)
    t_traj = float(trajectory.start_s) + t
    if t.size and float(t_traj.max()) > float(trajectory.end_s) + 1e-9:
        raise ConfigError(
            f"camera motion {str(config.path)!r} lasts {trajectory.end_s - trajectory.start_s:.3f}"
            f" s but the scenario needs {float(t.max()):.3f} s; shorten the scenario, pick a "
            "longer window_s, or lower speed_scale"
        )
    sample = trajectory.sample(t_traj)
    return CameraPoses(
        T_world_cam=sample.T_ref_obj, v_world_mps=sample.v_mps, w_world_radps=sample.w_radps
    )
