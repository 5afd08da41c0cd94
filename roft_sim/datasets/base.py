"""The ``Sequence`` reader protocol shared by every dataset format, and an in-memory sequence.

A sequence is one camera stream of one object. Readers are lazy: images are read frame by
frame, never the whole sequence at once. Per-frame detector outputs (poses and masks computed on
EVERY frame, as in Fast-YCB) are part of the dataset; rates and delays are applied later by the
fault stream, never stored.
"""

from __future__ import annotations

from collections.abc import Mapping
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import FlowField, ObjectModel, PoseTrack

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]

__all__ = ["Sequence", "DetectorPoses", "InMemorySequence", "GT_MASK_SET", "GT_FLOW_SET"]

GT_MASK_SET = "gt"
"""Name of the ground-truth visible-mask set in every format."""

GT_FLOW_SET = "gt"
"""Name of the exact-flow set a generated dataset holds (``[[networks.flow_sets]]`` default)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectorPoses:
    """A pose network's output on every frame of a sequence (before rate, delay and faults)."""

    T_cam_obj: F64
    """(N, 4, 4) detected object pose per frame [m]; identity where ``valid`` is False."""
    valid: Bool
    """(N,) bool: False where the network found nothing (a row of seven zeros in Fast-YCB)."""

    def __post_init__(self) -> None:
        n = self.valid.shape[0]
        if self.valid.shape != (n,) or self.T_cam_obj.shape != (n, 4, 4):
            raise ValueError(
                f"DetectorPoses needs T_cam_obj (N, 4, 4) and valid (N,), got "
                f"{self.T_cam_obj.shape} and {self.valid.shape}"
            )

    def __len__(self) -> int:
        return int(self.valid.shape[0])


@runtime_checkable
class Sequence(Protocol):
    """One RGB-D sequence of one object, read lazily, frame by frame."""

    @property
    def name(self) -> str:
        """Sequence name (e.g. the folder name ``003_cracker_box``)."""
        ...

    @property
    def object_name(self) -> str:
        """Registry name of the tracked object."""
        ...

    @property
    def intrinsics(self) -> CameraIntrinsics:
        """Camera intrinsics (rgb and depth are registered and share them)."""
        ...

    @property
    def fps(self) -> int:
        """Nominal camera rate [Hz]."""
        ...

    def __len__(self) -> int:
        """Number of camera frames."""
        ...

    def time_s(self, k: int) -> float:
        """Time stamp [s] of frame k."""
        ...

    def rgb(self, k: int) -> U8:
        """(H, W, 3) uint8 RGB image of frame k."""
        ...

    def depth(self, k: int) -> F32:
        """(H, W) float32 z-depth [m] of frame k; 0 = no measurement."""
        ...

    def flow_sets(self) -> tuple[str, ...]:
        """Names of the stored optical-flow sets (may be empty)."""
        ...

    def flow(self, k: int, flow_set: str) -> FlowField | None:
        """Stored flow from frame k-1 to frame k of ``flow_set``; None for k = 0."""
        ...

    def mask_sets(self) -> tuple[str, ...]:
        """Names of the stored mask sets; ``gt`` (visible mask) when ground truth exists."""
        ...

    def mask(self, k: int, mask_set: str) -> Bool | None:
        """(H, W) bool mask of frame k from ``mask_set``; None when the set has no mask for k
        (a detector miss)."""
        ...

    def pose_sets(self) -> tuple[str, ...]:
        """Names of the stored detector pose sets (e.g. ``dope``)."""
        ...

    def detector_poses(self, pose_set: str) -> DetectorPoses:
        """The detector's pose on every frame."""
        ...

    def ground_truth(self) -> PoseTrack | None:
        """Ground-truth object poses and velocities for every frame; None for real data.

        Frames a dataset leaves unannotated (possible in a BOP scene made elsewhere) have NaN
        rows; velocities are NaN where the dataset stores none.
        """
        ...

    def camera_poses(self) -> F64:
        """(N, 4, 4) ``T_world_cam`` per frame [m] (identity for a static camera)."""
        ...

    def object_model(self) -> ObjectModel | None:
        """The object's mesh and model points if the dataset carries them, else None."""
        ...

    def metadata(self) -> Mapping[str, Any]:
        """Free-form metadata (scenario, seed, versions, conventions)."""
        ...


@dataclass(frozen=True, slots=True, kw_only=True)
class InMemorySequence:
    """A :class:`Sequence` held in memory: for tests, synthetic streams and small examples."""

    name: str
    object_name: str
    intrinsics: CameraIntrinsics
    fps: int
    rgb_frames: SequenceABC[U8]
    """N images (H, W, 3) uint8."""
    depth_frames: SequenceABC[F32]
    """N depth images (H, W) float32 [m]."""
    gt: PoseTrack | None = None
    gt_masks: SequenceABC[Bool] | None = None
    """N visible masks (H, W) bool, or None."""
    flows: Mapping[str, SequenceABC[FlowField | None]] = field(default_factory=dict)
    """Flow sets: name -> N entries (entry 0 is None)."""
    detector_masks: Mapping[str, SequenceABC[Bool | None]] = field(default_factory=dict)
    """Mask sets from detectors: name -> N entries (None = miss)."""
    detector_pose_sets: Mapping[str, DetectorPoses] = field(default_factory=dict)
    T_world_cam: F64 | None = None
    """(N, 4, 4) camera poses, or None for a static camera at the world origin."""
    model: ObjectModel | None = None
    extra_metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = len(self.rgb_frames)
        if len(self.depth_frames) != n:
            raise ValueError(f"{n} rgb frames but {len(self.depth_frames)} depth frames")
        for set_name, frames in {**self.flows, **self.detector_masks}.items():
            if len(frames) != n:
                raise ValueError(f"set {set_name!r} has {len(frames)} entries for {n} frames")
        if self.gt is not None and len(self.gt) != n:
            raise ValueError(f"ground truth has {len(self.gt)} rows for {n} frames")

    def __len__(self) -> int:
        return len(self.rgb_frames)

    def time_s(self, k: int) -> float:
        return k / self.fps

    def rgb(self, k: int) -> U8:
        return self.rgb_frames[k]

    def depth(self, k: int) -> F32:
        return self.depth_frames[k]

    def flow_sets(self) -> tuple[str, ...]:
        return tuple(self.flows)

    def flow(self, k: int, flow_set: str) -> FlowField | None:
        return self.flows[flow_set][k]

    def mask_sets(self) -> tuple[str, ...]:
        gt = (GT_MASK_SET,) if self.gt_masks is not None else ()
        return gt + tuple(self.detector_masks)

    def mask(self, k: int, mask_set: str) -> Bool | None:
        if mask_set == GT_MASK_SET and self.gt_masks is not None:
            return self.gt_masks[k]
        return self.detector_masks[mask_set][k]

    def pose_sets(self) -> tuple[str, ...]:
        return tuple(self.detector_pose_sets)

    def detector_poses(self, pose_set: str) -> DetectorPoses:
        return self.detector_pose_sets[pose_set]

    def ground_truth(self) -> PoseTrack | None:
        return self.gt

    def camera_poses(self) -> F64:
        if self.T_world_cam is None:
            return np.broadcast_to(np.eye(4), (len(self), 4, 4)).copy()
        return self.T_world_cam

    def object_model(self) -> ObjectModel | None:
        return self.model

    def metadata(self) -> Mapping[str, Any]:
        return self.extra_metadata
