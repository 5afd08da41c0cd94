"""Captured motion from a file, cleaned up, replayed and placed in front of the camera.

The pipeline of :func:`build_captured_trajectory`:

1. read the file (:func:`read_pose_samples`: TUM, BVH, Fast-YCB, BOP or CSV);
2. when drift removal or low-pass filtering is asked for, resample the poses uniformly at
   their median rate (the spline bridges tracking gaps), then remove drift and low-pass;
3. keep the time window (times restart at 0) and scale the speed;
4. replay with :class:`SplinePoseTrajectory` (exact derivatives);
5. apply the grasp offset and the placement (:class:`RigidlyMappedTrajectory`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.trajectories.base import TrajectorySample
from roft_sim.trajectories.bop import read_bop_scene_gt
from roft_sim.trajectories.bvh import BvhUnit, bvh_pose_samples, read_bvh
from roft_sim.trajectories.fast_ycb import FAST_YCB_RATE_HZ, read_fast_ycb_poses
from roft_sim.trajectories.placement import (
    GraspOffset,
    PlacementConfig,
    ViewRegion,
    camera_rotation_from_up,
    fit_camera_anchor,
    up_vector,
)
from roft_sim.trajectories.rigid_map import RigidlyMappedTrajectory
from roft_sim.trajectories.samples import PoseSamples, clean_samples, find_gaps
from roft_sim.trajectories.spline import SplinePoseTrajectory
from roft_sim.trajectories.trajectory_csv import csv_pose_samples
from roft_sim.trajectories.tum import read_tum

F64 = NDArray[np.float64]

__all__ = [
    "TrajectoryFileFormat",
    "TRAJECTORY_FILE_FORMATS",
    "CapturedMotionConfig",
    "CapturedTrajectory",
    "read_pose_samples",
    "build_captured_trajectory",
]

_log = logging.getLogger(__name__)

TrajectoryFileFormat = Literal["tum", "bvh", "fast-ycb", "bop", "csv"]
TRAJECTORY_FILE_FORMATS: tuple[str, ...] = ("tum", "bvh", "fast-ycb", "bop", "csv")


@dataclass(frozen=True, slots=True, kw_only=True)
class CapturedMotionConfig:
    """Motion replayed from a file (``kind = "file"`` in scenario files)."""

    kind: Literal["file"] = "file"
    """Tells trajectory configs apart in scenario files."""
    path: Path
    """The file (relative paths are resolved against the scenario file's folder)."""
    format: TrajectoryFileFormat
    """``tum``, ``bvh``, ``fast-ycb`` (gt/poses.txt or its sequence folder), ``bop``
    (scene_gt.json or its scene folder) or ``csv`` (the trajectory CSV)."""
    joint: str | None = None
    """BVH only, required: the joint to follow, e.g. ``CC_Base_L_Hand``."""
    relative_to: str | None = None
    """BVH only: follow ``joint`` relative to this joint (e.g. ``CC_Base_Pelvis``), which
    removes walking and turning of the whole body."""
    bvh_unit: BvhUnit = "auto"
    """BVH only: length unit of the file (``auto`` detects it from the skeleton's size)."""
    object_id: int | None = None
    """BOP only: the ``obj_id`` to follow (optional when the scene shows one object)."""
    sample_rate_hz: float | None = None
    """Fast-YCB and BOP only (no time stamps in the file): frame rate [Hz], default 30."""
    lowpass_hz: float | None = None
    """Zero-phase low-pass cut-off [Hz] for position and rotation (about 10 Hz suits hand
    motion capture); None = no filtering."""
    window_s: tuple[float, float] | None = None
    """Keep only ``[start, end]`` [s] of the file (times relative to its first sample, before
    speed scaling); the trajectory then starts at 0."""
    speed_scale: float = 1.0
    """Play faster (> 1) or slower (< 1); velocities scale by it, accelerations by its square."""
    remove_drift_window_s: float | None = None
    """Subtract a centred moving average of the position over this window [s] (about 2 s for
    an operator walking with the object, as in TUM VI); None = keep."""
    grasp: GraspOffset = field(default_factory=GraspOffset)
    """Pose of the object in the tracked body (hand) frame."""
    placement: PlacementConfig = field(default_factory=PlacementConfig)
    """Where the motion goes in front of the camera."""

    def __post_init__(self) -> None:
        fmt = self.format
        if fmt not in TRAJECTORY_FILE_FORMATS:
            raise ConfigError(f"format {fmt!r} is not one of {', '.join(TRAJECTORY_FILE_FORMATS)}")
        if fmt == "bvh" and not self.joint:
            raise ConfigError(
                "format 'bvh' needs joint = the joint to follow, e.g. 'CC_Base_L_Hand'"
            )
        if fmt != "bvh" and (self.joint or self.relative_to or self.bvh_unit != "auto"):
            raise ConfigError(
                f"joint, relative_to and bvh_unit apply to format 'bvh' only, not {fmt!r}; "
                "remove them"
            )
        if fmt != "bop" and self.object_id is not None:
            raise ConfigError(f"object_id applies to format 'bop' only, not {fmt!r}")
        if self.sample_rate_hz is not None:
            if fmt not in ("fast-ycb", "bop"):
                raise ConfigError(
                    f"sample_rate_hz applies to formats without time stamps (fast-ycb, bop), "
                    f"not {fmt!r}"
                )
            if not (np.isfinite(self.sample_rate_hz) and self.sample_rate_hz > 0):
                raise ConfigError(f"sample_rate_hz must be positive, got {self.sample_rate_hz}")
        if self.lowpass_hz is not None and not (
            np.isfinite(self.lowpass_hz) and self.lowpass_hz > 0
        ):
            raise ConfigError(f"lowpass_hz must be positive, got {self.lowpass_hz}")
        if not (np.isfinite(self.speed_scale) and self.speed_scale > 0):
            raise ConfigError(f"speed_scale must be positive, got {self.speed_scale}")
        if self.remove_drift_window_s is not None and not (
            np.isfinite(self.remove_drift_window_s) and self.remove_drift_window_s > 0
        ):
            raise ConfigError(
                f"remove_drift_window_s must be positive, got {self.remove_drift_window_s}"
            )
        if self.window_s is not None:
            start, end = self.window_s
            if not (np.isfinite([start, end]).all() and 0 <= start < end):
                raise ConfigError(
                    f"window_s must be [start, end] with 0 <= start < end [s], got "
                    f"{self.window_s!r}"
                )

    def resolved_path(self, base_dir: Path | None) -> Path:
        """``path``, joined to ``base_dir`` when relative."""
        if base_dir is None or self.path.is_absolute():
            return self.path
        return Path(base_dir) / self.path


def read_pose_samples(
    path: str | Path,
    format: TrajectoryFileFormat,
    *,
    joint: str | None = None,
    relative_to: str | None = None,
    bvh_unit: BvhUnit = "auto",
    object_id: int | None = None,
    sample_rate_hz: float | None = None,
) -> PoseSamples:
    """Reads sampled poses from a file in any supported format (see the format modules).

    Raises:
        DatasetFormatError: the file does not follow its format (message names file and line).
        ConfigError: an unknown format, or a missing or unknown joint / object id.
    """
    if format == "tum":
        return read_tum(path)
    if format == "bvh":
        if joint is None:
            raise ConfigError("format 'bvh' needs a joint, e.g. 'CC_Base_L_Hand'")
        return bvh_pose_samples(read_bvh(path, unit=bvh_unit), joint, relative_to=relative_to)
    rate = FAST_YCB_RATE_HZ if sample_rate_hz is None else sample_rate_hz
    if format == "fast-ycb":
        return read_fast_ycb_poses(path, rate_hz=rate)
    if format == "bop":
        return read_bop_scene_gt(path, object_id=object_id, rate_hz=rate)
    if format == "csv":
        return csv_pose_samples(path)
    raise ConfigError(f"format {format!r} is not one of {', '.join(TRAJECTORY_FILE_FORMATS)}")


class CapturedTrajectory:
    """A placed captured motion, ``T_cam_obj(t)``; satisfies ``Trajectory``.

    Besides sampling it tells where the spline bridged tracking gaps, how much of the motion
    stays in view, and the rigid transforms used.
    """

    __slots__ = (
        "_mapped",
        "source",
        "knot_times_s",
        "bridged_intervals_s",
        "in_view_fraction",
    )

    def __init__(
        self,
        mapped: RigidlyMappedTrajectory,
        *,
        source: str,
        knot_times_s: F64,
        bridged_intervals_s: tuple[tuple[float, float], ...],
        in_view_fraction: float,
    ) -> None:
        self._mapped = mapped
        self.source = source
        """Where the motion comes from (file, joint, object)."""
        self.knot_times_s = knot_times_s
        """(N,) times of the samples the spline passes through [s] (trajectory time)."""
        self.bridged_intervals_s = bridged_intervals_s
        """Intervals ``(start_s, end_s)`` (trajectory time) around gaps in the file's time
        stamps, widened by the low-pass filter's settling time (1 / lowpass_hz): the motion
        there is interpolated, not measured."""
        self.in_view_fraction = in_view_fraction
        """Fraction of the samples whose object centre lies in the view region."""

    @property
    def T_cam_world(self) -> F64:
        """(4, 4) placement of the capture frame in the camera frame."""
        return self._mapped.T_left

    @property
    def T_hand_obj(self) -> F64:
        """(4, 4) grasp offset."""
        return self._mapped.T_right

    @property
    def start_s(self) -> float:
        return self._mapped.start_s

    @property
    def end_s(self) -> float:
        return self._mapped.end_s

    def sample(self, t_s: ArrayLike) -> TrajectorySample:
        """See ``Trajectory.sample``."""
        return self._mapped.sample(t_s)

    def sample_knots(self) -> TrajectorySample:
        """The trajectory at its spline knots (the file's samples after clean-up)."""
        return self._mapped.sample(self.knot_times_s)


def _bridged_intervals(
    gaps: list[tuple[float, float]],
    margin_s: float,
    shift_s: float,
    speed_scale: float,
    end_s: float,
) -> tuple[tuple[float, float], ...]:
    out = []
    for start, length in gaps:
        lo = (start - margin_s - shift_s) / speed_scale
        hi = (start + length + margin_s - shift_s) / speed_scale
        if hi >= 0.0 and lo <= end_s:
            out.append((max(lo, 0.0), min(hi, end_s)))
    return tuple(out)


def _camera_placement(
    config: CapturedMotionConfig,
    samples: PoseSamples,
    intrinsics: CameraIntrinsics,
    object_radius_m: float,
) -> tuple[str, NDArray[np.float64], float]:
    """The placement mode used (``fit`` or ``none``), ``T_cam_world`` (4, 4) and the fraction of
    object centres in view."""
    placement = config.placement
    region = ViewRegion.from_config(
        intrinsics, placement.working_distance_m, placement.in_view_margin, object_radius_m
    )
    p_obj = (samples.T_ref_obj @ config.grasp.T_hand_obj)[:, :3, 3]
    mode = placement.mode
    if mode == "auto":
        mode = "none" if samples.camera_frame else "fit"
    if mode == "fit":
        up = samples.up_ref if placement.up_axis == "auto" else up_vector(placement.up_axis)
        R = (
            np.eye(3)
            if up is None
            else camera_rotation_from_up(p_obj, up, np.radians(placement.camera_yaw_deg))
        )
        T_cam_world, fraction = fit_camera_anchor(p_obj, region, R_cam_world=R)
        return mode, T_cam_world, fraction
    return mode, np.eye(4), float(region.contains(p_obj).mean())


def build_captured_trajectory(
    config: CapturedMotionConfig,
    intrinsics: CameraIntrinsics,
    *,
    base_dir: Path | None = None,
    object_radius_m: float = 0.1,
) -> CapturedTrajectory:
    """Reads, cleans, replays and places a captured motion (see the module docstring).

    Args:
        config: the file and what to do with it.
        intrinsics: the static camera (at the world origin, OpenCV frame).
        base_dir: folder against which a relative ``config.path`` is resolved.
        object_radius_m: radius of the object's bounding sphere [m], for the in-view margin.

    Raises:
        DatasetFormatError: the file is malformed.
        ConfigError: bad settings, or fewer samples in view than
            ``placement.min_in_view_fraction``.
    """
    path = config.resolved_path(base_dir)
    samples = read_pose_samples(
        path,
        config.format,
        joint=config.joint,
        relative_to=config.relative_to,
        bvh_unit=config.bvh_unit,
        object_id=config.object_id,
        sample_rate_hz=config.sample_rate_hz,
    )
    gaps = find_gaps(samples.t_s)
    samples, shift = clean_samples(
        samples,
        lowpass_hz=config.lowpass_hz,
        remove_drift_window_s=config.remove_drift_window_s,
        window_s=config.window_s,
        speed_scale=config.speed_scale,
    )
    spline = SplinePoseTrajectory(samples.t_s, samples.T_ref_obj)
    step = float(np.median(np.diff(samples.t_s))) * config.speed_scale
    margin = max(1.0 / config.lowpass_hz if config.lowpass_hz else 0.0, step)
    bridged = _bridged_intervals(gaps, margin, shift, config.speed_scale, spline.end_s)

    placement = config.placement
    T_hand_obj = config.grasp.T_hand_obj
    mode, T_cam_world, fraction = _camera_placement(config, samples, intrinsics, object_radius_m)
    _log.info(
        "%s: %d samples over %.2f s placed with %.0f %% of the object centres in view",
        samples.source,
        len(samples),
        spline.end_s,
        100.0 * fraction,
    )
    if mode == "fit" and fraction < placement.min_in_view_fraction:
        raise ConfigError(
            f"{samples.source}: only {100 * fraction:.0f} % of the motion stays in view at "
            f"{placement.working_distance_m} m (need {100 * placement.min_in_view_fraction:.0f} "
            "%); remove walking (remove_drift_window_s, or relative_to for BVH), pick a "
            "window_s, widen working_distance_m, or lower placement.min_in_view_fraction"
        )
    mapped = RigidlyMappedTrajectory(spline, T_left=T_cam_world, T_right=T_hand_obj)
    return CapturedTrajectory(
        mapped,
        source=samples.source,
        knot_times_s=spline.knot_times_s,
        bridged_intervals_s=bridged,
        in_view_fraction=fraction,
    )
