"""One entry point from a trajectory config to a placed trajectory ``T_cam_obj(t)``."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.trajectories.base import Trajectory
from roft_sim.trajectories.captured import CapturedMotionConfig, build_captured_trajectory
from roft_sim.trajectories.continuous import ContinuousMotionConfig, generate_continuous_motion
from roft_sim.trajectories.hand_motion import HandMotionConfig, resolve_hand_motion
from roft_sim.trajectories.placement import ViewRegion
from roft_sim.trajectories.synthetic import SyntheticMotionConfig, generate_synthetic_motion

__all__ = ["TrajectoryConfig", "build_trajectory", "FAST_YCB_CAMERA"]

_log = logging.getLogger(__name__)

TrajectoryConfig = (
    SyntheticMotionConfig | ContinuousMotionConfig | CapturedMotionConfig | HandMotionConfig
)
"""A trajectory in a scenario file; the ``kind`` key (``synthetic``, ``continuous``, ``file`` or
``hand-motion``) picks one."""

FAST_YCB_CAMERA = CameraIntrinsics(
    fx_px=1229.4285612615463,
    fy_px=1229.4285612615463,
    cx_px=640.0,
    cy_px=360.0,
    width_px=1280,
    height_px=720,
)
"""The Fast-YCB reference camera (1280x720, 55 deg horizontal field of view)."""


def build_trajectory(
    config: TrajectoryConfig,
    intrinsics: CameraIntrinsics,
    *,
    base_dir: Path | None = None,
    object_radius_m: float = 0.1,
) -> Trajectory:
    """The object's trajectory ``T_cam_obj(t)`` for a static camera at the world origin.

    Synthetic motion (bursty :class:`SyntheticMotionConfig` or continuous
    :class:`ContinuousMotionConfig`) is drawn with ``np.random.default_rng(config.seed)`` inside
    the view region; a :class:`HandMotionConfig` becomes the config it stands for
    (:func:`~roft_sim.trajectories.hand_motion.resolve_hand_motion`); captured motion is read,
    cleaned, replayed and placed (:func:`roft_sim.trajectories.captured.build_captured_trajectory`).

    Args:
        config: a :class:`SyntheticMotionConfig`, :class:`ContinuousMotionConfig` or
            :class:`CapturedMotionConfig` or :class:`HandMotionConfig`.
        intrinsics: the camera (OpenCV frame) the motion must stay in view of.
        base_dir: folder that relative file paths are resolved against (the scenario file's).
        object_radius_m: radius of the object's bounding sphere [m] (in-view margin).

    Raises:
        ConfigError: invalid settings or a motion that cannot be placed in view.
        DatasetFormatError: a malformed trajectory file.
    """
    if isinstance(config, HandMotionConfig):
        resolved, reason = resolve_hand_motion(config)
        _log.info("hand-motion trajectory: %s", reason)
        return build_trajectory(
            resolved, intrinsics, base_dir=base_dir, object_radius_m=object_radius_m
        )
    if isinstance(config, SyntheticMotionConfig):
        region = ViewRegion.from_config(
            intrinsics, config.working_distance_m, config.in_view_margin, object_radius_m
        )
        return generate_synthetic_motion(config, region, np.random.default_rng(config.seed))
    if isinstance(config, ContinuousMotionConfig):
        region = ViewRegion.from_config(
            intrinsics, config.working_distance_m, config.in_view_margin, object_radius_m
        )
        return generate_continuous_motion(config, region, np.random.default_rng(config.seed))
    if isinstance(config, CapturedMotionConfig):
        return build_captured_trajectory(
            config, intrinsics, base_dir=base_dir, object_radius_m=object_radius_m
        )
    raise TypeError(
        "expected a SyntheticMotionConfig, ContinuousMotionConfig, CapturedMotionConfig or "
        "HandMotionConfig, got "
        f"{config!r}"
    )
