"""Pose sets a run makes from a sequence rather than reads: its ground truth as a detector
(:class:`WithGroundTruthPoses`, ``--poses gt``) and fresh draws of the DOPE-like pose detector
(:class:`WithRedrawnPoses`, ``redraw:<k>``: detector seeds as replicates).

A dataset stores one draw of the simulated pose estimator (its ``dope`` set). Under a fault
configuration without randomness (the ``paper`` preset: fixed rate and delay) and stored flow,
every run seed then sees the same detections, so seeds are no replicates. The pose set
``redraw:<k>`` (``RunOptions.poses``) is the same estimator drawn again on the sequence's ground
truth with draw seed ``k``: the error statistics the sequence was generated with (its metadata's
``scenario.networks.pose``; else the defaults, which calibrate each Fast-YCB object to the
paper's DOPE column), and the object's visible fraction per frame from the stored ground-truth
masks (all ones when the metadata says the object was never occluded). The masks stay the
dataset's draw. docs/statistics.md.
"""

from __future__ import annotations

import zlib
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.config_files import dataclass_from_mapping
from roft_sim.datasets.base import GT_MASK_SET, DetectorPoses, Sequence
from roft_sim.datasets.frames import GT_FULL_MASK_SET
from roft_sim.errors import ConfigError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.harness.options import GT_SET
from roft_sim.records import FlowField, ObjectModel, PoseTrack

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

__all__ = [
    "REDRAW_PREFIX",
    "WithGroundTruthPoses",
    "WithRedrawnPoses",
    "redraw_seed",
    "redraw_set",
]

REDRAW_PREFIX = "redraw:"
"""Pose-set spec prefix of a fresh detector draw: ``redraw:<k>``."""
_DETECTOR_STREAM = 0x444F5045  # "DOPE": the spawn key of the detector draws


class WithGroundTruthPoses:
    """A :class:`~roft_sim.datasets.base.Sequence` that also offers its ground truth as the
    detector pose set ``gt`` (every frame valid). Everything else is delegated unchanged.

    Used for the "GT pose" ablation on datasets that store no ``gt`` pose set; the poses still go
    through the fault stream (rate, delay, losses) like a detector's.
    """

    def __init__(self, sequence: Sequence) -> None:
        gt = sequence.ground_truth()
        if gt is None:
            raise ConfigError(
                f"sequence {sequence.name!r} has no ground truth, so it cannot feed ground-truth "
                "poses (--poses gt); pick one of its pose sets: "
                f"{list(sequence.pose_sets()) or 'none'}"
            )
        self._sequence = sequence
        self._gt_poses = DetectorPoses(
            T_cam_obj=np.array(gt.T_cam_obj, dtype=np.float64),
            valid=np.ones(len(gt), dtype=bool),
        )

    @property
    def inner(self) -> Sequence:
        """The wrapped sequence."""
        return self._sequence

    @property
    def name(self) -> str:
        return self._sequence.name

    @property
    def object_name(self) -> str:
        return self._sequence.object_name

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._sequence.intrinsics

    @property
    def fps(self) -> int:
        return self._sequence.fps

    def __len__(self) -> int:
        return len(self._sequence)

    def time_s(self, k: int) -> float:
        return self._sequence.time_s(k)

    def rgb(self, k: int) -> NDArray[np.uint8]:
        return self._sequence.rgb(k)

    def depth(self, k: int) -> F32:
        return self._sequence.depth(k)

    def flow_sets(self) -> tuple[str, ...]:
        return self._sequence.flow_sets()

    def flow(self, k: int, flow_set: str) -> FlowField | None:
        return self._sequence.flow(k, flow_set)

    def mask_sets(self) -> tuple[str, ...]:
        return self._sequence.mask_sets()

    def mask(self, k: int, mask_set: str) -> NDArray[np.bool_] | None:
        return self._sequence.mask(k, mask_set)

    def pose_sets(self) -> tuple[str, ...]:
        inner = tuple(s for s in self._sequence.pose_sets() if s != GT_SET)
        return (GT_SET, *inner)

    def detector_poses(self, pose_set: str) -> DetectorPoses:
        if pose_set == GT_SET:
            return self._gt_poses
        return self._sequence.detector_poses(pose_set)

    def ground_truth(self) -> PoseTrack | None:
        return self._sequence.ground_truth()

    def camera_poses(self) -> F64:
        return self._sequence.camera_poses()

    def object_model(self) -> ObjectModel | None:
        return self._sequence.object_model()

    def metadata(self) -> Mapping[str, Any]:
        return self._sequence.metadata()


def redraw_set(seed: int) -> str:
    """The pose-set spec of draw ``seed``."""
    return f"{REDRAW_PREFIX}{seed}"


def redraw_seed(spec: str) -> int | None:
    """The draw seed of a ``redraw:<k>`` spec; None for other specs.

    Raises:
        ConfigError: ``redraw:`` followed by anything but an integer >= 0.
    """
    if not spec.startswith(REDRAW_PREFIX):
        return None
    text = spec[len(REDRAW_PREFIX) :]
    if not text.isdigit():
        raise ConfigError(f"pose set {spec!r}: expected redraw:<seed>, a whole number >= 0")
    return int(text)


def _estimator_config(sequence: Sequence) -> Any:
    """The pose estimator's error statistics for the sequence's object."""
    from roft_sim.sensors.networks import PoseSetConfig

    metadata: Mapping[str, Any] = sequence.metadata() or {}
    stored = metadata.get("scenario", {})
    pose = stored.get("networks", {}).get("pose") if isinstance(stored, Mapping) else None
    config = PoseSetConfig()
    if isinstance(pose, Mapping):
        try:
            config = dataclass_from_mapping(PoseSetConfig, pose, where="metadata networks.pose")
        except ConfigError:
            config = PoseSetConfig()  # another version's keys: the calibrated defaults
    return config.estimator_for(sequence.object_name)


def _visible_fraction(sequence: Sequence) -> Any:
    """(N,) visible fraction per frame from the stored masks, or None (fully visible)."""
    visibility = (sequence.metadata() or {}).get("ground_truth_visibility")
    if isinstance(visibility, Mapping) and visibility.get("min") == 1.0:
        return None
    if not {GT_MASK_SET, GT_FULL_MASK_SET} <= set(sequence.mask_sets()):
        return None
    out = np.ones(len(sequence))
    for k in range(len(sequence)):
        visible = sequence.mask(k, GT_MASK_SET)
        full = sequence.mask(k, GT_FULL_MASK_SET)
        if visible is not None and full is not None and full.any():
            out[k] = min(1.0, float(visible.sum()) / float(full.sum()))
    return out


class WithRedrawnPoses(WithGroundTruthPoses):
    """A sequence that also offers the pose set ``redraw:<seed>`` (module docstring); every
    other set, the ground truth and the images are delegated unchanged."""

    def __init__(self, sequence: Sequence, seed: int) -> None:
        super().__init__(sequence)
        self._seed = seed
        self._set = redraw_set(seed)
        self._poses: DetectorPoses | None = None

    def pose_sets(self) -> tuple[str, ...]:
        return (*super().pose_sets(), self._set)

    def detector_poses(self, pose_set: str) -> DetectorPoses:
        if pose_set != self._set:
            return super().detector_poses(pose_set)
        if self._poses is None:
            from roft_sim.sensors.pose_estimator import simulate_pose_detections

            gt = self.inner.ground_truth()
            assert gt is not None  # checked by WithGroundTruthPoses
            key = (zlib.crc32(self.name.encode("utf-8")), _DETECTOR_STREAM)
            rng = np.random.default_rng(np.random.SeedSequence(self._seed, spawn_key=key))
            self._poses = simulate_pose_detections(
                gt,
                _estimator_config(self.inner),
                rng,
                visible_fraction=_visible_fraction(self.inner),
            )
        return self._poses
