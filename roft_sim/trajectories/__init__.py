"""Object trajectories with exact velocities: captured (TUM, BVH, Fast-YCB, BOP, CSV) and
synthetic, placed in front of a static camera.

A :class:`Trajectory` gives, for any array of times, ``T_cam_obj`` with the object-origin
velocity, the angular velocity (camera frame, ``dR/dt = [w]x R``) and both accelerations, all
analytic derivatives of the poses returned. Build one from a scenario config with
:func:`build_trajectory`. See docs/trajectories.md.
"""

from roft_sim.trajectories.base import (
    SpeedStatistics,
    SpeedSummary,
    Trajectory,
    TrajectorySample,
    sample_at_rate,
    speed_statistics,
)
from roft_sim.trajectories.bop import read_bop_scene_gt
from roft_sim.trajectories.build import FAST_YCB_CAMERA, TrajectoryConfig, build_trajectory
from roft_sim.trajectories.bvh import BvhMotion, bvh_pose_samples, read_bvh
from roft_sim.trajectories.captured import (
    TRAJECTORY_FILE_FORMATS,
    CapturedMotionConfig,
    CapturedTrajectory,
    build_captured_trajectory,
    read_pose_samples,
)
from roft_sim.trajectories.continuous import (
    ContinuousHandMotion,
    ContinuousMotionConfig,
    generate_continuous_motion,
)
from roft_sim.trajectories.fast_ycb import read_fast_ycb_poses
from roft_sim.trajectories.hand_motion import (
    HandMotionConfig,
    default_trajectories_dir,
    resolve_hand_motion,
)
from roft_sim.trajectories.placement import GraspOffset, PlacementConfig, ViewRegion
from roft_sim.trajectories.rigid_map import RigidlyMappedTrajectory
from roft_sim.trajectories.samples import (
    PoseSamples,
    lowpass_poses,
    remove_position_drift,
    resample_uniform,
)
from roft_sim.trajectories.spline import SplinePoseTrajectory
from roft_sim.trajectories.synthetic import (
    MinimumJerkTrajectory,
    SyntheticMotionConfig,
    generate_synthetic_motion,
)
from roft_sim.trajectories.trajectory_csv import (
    CSV_COLUMNS,
    read_trajectory_csv,
    write_trajectory_csv,
)
from roft_sim.trajectories.tum import read_tum

__all__ = [
    "CSV_COLUMNS",
    "FAST_YCB_CAMERA",
    "TRAJECTORY_FILE_FORMATS",
    "BvhMotion",
    "CapturedMotionConfig",
    "CapturedTrajectory",
    "ContinuousHandMotion",
    "ContinuousMotionConfig",
    "GraspOffset",
    "HandMotionConfig",
    "MinimumJerkTrajectory",
    "PlacementConfig",
    "PoseSamples",
    "RigidlyMappedTrajectory",
    "SpeedStatistics",
    "SpeedSummary",
    "SplinePoseTrajectory",
    "SyntheticMotionConfig",
    "Trajectory",
    "TrajectoryConfig",
    "TrajectorySample",
    "ViewRegion",
    "build_captured_trajectory",
    "build_trajectory",
    "bvh_pose_samples",
    "default_trajectories_dir",
    "generate_continuous_motion",
    "generate_synthetic_motion",
    "lowpass_poses",
    "read_bop_scene_gt",
    "read_bvh",
    "read_fast_ycb_poses",
    "read_pose_samples",
    "read_trajectory_csv",
    "read_tum",
    "remove_position_drift",
    "resample_uniform",
    "resolve_hand_motion",
    "sample_at_rate",
    "speed_statistics",
    "write_trajectory_csv",
]
