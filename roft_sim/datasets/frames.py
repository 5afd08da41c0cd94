"""What a dataset writer receives for one camera frame, and the writer protocol.

A generator (``roft-sim generate``) produces one :class:`DatasetFrame` per camera frame and hands
it to a :class:`SequenceWriter` (made by :func:`roft_sim.datasets.open_writer`). Writers stream:
each frame goes to disk at once, atomically, in any order, so several worker processes can share
one writer (it holds no open files and pickles), an interrupted run can be resumed
(:meth:`SequenceWriter.completed_frames`), and memory stays flat in the sequence length.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import as_transform
from roft_sim.records import FlowField

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]

__all__ = [
    "DatasetFrame",
    "DistractorTruth",
    "SequenceWriter",
    "FlowEncoding",
    "FLOW_ENCODINGS",
    "GT_FULL_MASK_SET",
    "check_set_name",
    "flow_grid_shape",
]

FlowEncoding = Literal["float32", "s10.5"]
"""How a flow set is stored: ``float32`` (OpenCV CV_32FC2, exact) or ``s10.5`` (CV_16SC2 in
NVIDIA's S10.5 fixed point, 1/32 px steps, |flow| < 1024 px; values are rounded to 1/32 px)."""

FLOW_ENCODINGS: tuple[str, ...] = ("float32", "s10.5")

GT_FULL_MASK_SET = "gt_full"
"""Name of the ground-truth FULL (amodal, occlusion-free) silhouette mask set, when stored."""

_SET_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")


def check_set_name(kind: str, name: str) -> None:
    """Raises ValueError unless ``name`` is a usable flow/mask/pose set name (a file-name part)."""
    if not isinstance(name, str) or not _SET_NAME.match(name):
        raise ValueError(
            f"{kind} set name {name!r} is not usable as a folder name; use letters, digits, "
            "'_', '.', '-' (starting with a letter or digit), e.g. 'nvof_1_slow'"
        )


def flow_grid_shape(height_px: int, width_px: int, grid_px: int) -> tuple[int, int]:
    """Shape ``(rows, cols)`` of a flow field on a ``grid_px`` grid covering an image."""
    return (-(-height_px // grid_px), -(-width_px // grid_px))


def _check_array(name: str, a: object, dtype: type, shape: tuple[int, ...]) -> None:
    if not isinstance(a, np.ndarray) or a.dtype != dtype or a.shape != shape:
        got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
        want = f"{np.dtype(dtype)} {shape}"
        raise ValueError(f"DatasetFrame.{name} must be a {want} array, got {got}")


def _check_pose(name: str, T: object) -> None:
    if not isinstance(T, np.ndarray) or T.shape != (4, 4):
        raise ValueError(f"DatasetFrame.{name} must be a (4, 4) array, got {T!r:.60}")
    try:
        as_transform(T)
    except ValueError as e:
        raise ValueError(f"DatasetFrame.{name} is not a rigid transform: {e}") from None


@dataclass(frozen=True, slots=True, kw_only=True)
class DistractorTruth:
    """Ground truth of one distractor object in a frame (clutter; see docs/scenarios.md)."""

    name: str
    """Its object name (registry name or mesh path)."""
    T_cam_obj: F64
    """(4, 4) its pose in the camera frame [m]."""
    mask: Bool
    """(H, W) bool its visible pixels."""
    mask_full: Bool | None = None
    """(H, W) bool its full silhouette ignoring occluders, or None."""


@dataclass(frozen=True, slots=True, kw_only=True)
class DatasetFrame:
    """Everything a generator produces for one camera frame ``k``.

    Images are full resolution ``(H, W)``. Ground truth is either given on every frame of a
    sequence or on none (a real recording); the same holds for each flow/mask/pose set name.
    """

    k: int
    """Camera frame index, 0-based."""
    t_s: float
    """Camera time stamp [s] (``k / fps`` for a clean camera)."""
    rgb: U8
    """(H, W, 3) uint8 RGB image."""
    depth_m: F32
    """(H, W) float32 z-depth [m], 0 = no measurement; finite and >= 0."""
    T_world_cam: F64
    """(4, 4) camera pose in the world [m] (identity for a static camera)."""
    gt_T_cam_obj: F64 | None = None
    """(4, 4) ground-truth object pose in the camera frame [m], or None (no ground truth)."""
    gt_v_obj_mps: F64 | None = None
    """(3,) velocity of the object origin, d/dt of ``t_cam_obj``, camera frame [m/s]."""
    gt_w_radps: F64 | None = None
    """(3,) angular velocity, camera frame [rad/s]: ``dR_cam_obj/dt = [w]x R_cam_obj``."""
    gt_mask: Bool | None = None
    """(H, W) bool visible mask of the object (after occlusion), or None."""
    gt_mask_full: Bool | None = None
    """(H, W) bool full silhouette of the object ignoring occluders (BOP ``mask/``), or None."""
    flows: Mapping[str, FlowField] = field(default_factory=dict)
    """Flow set name -> ``F_k`` from frame k-1 to k (``from_k = k-1``, ``to_k = k``), on any
    grid that covers the image; empty for k = 0."""
    detector_masks: Mapping[str, Bool | None] = field(default_factory=dict)
    """Mask set name -> (H, W) bool detector mask of this frame, None = detector miss."""
    detector_poses: Mapping[str, F64 | None] = field(default_factory=dict)
    """Pose set name -> (4, 4) detected ``T_cam_obj`` [m], None = miss."""
    gt_visible_fraction: float | None = None
    """Visible fraction of the object in [0, 1] (``|visible| / |visible or full|``), or None;
    summarised per sequence in the metadata (``ground_truth_visibility``)."""
    gt_distractors: tuple[DistractorTruth, ...] = ()
    """Ground truth of the distractor objects (BOP writes them; the other formats keep the
    tracked object only)."""

    def __post_init__(self) -> None:
        if isinstance(self.k, bool) or not isinstance(self.k, int | np.integer) or self.k < 0:
            raise ValueError(f"DatasetFrame.k must be an int >= 0, got {self.k!r}")
        if not np.isfinite(self.t_s):
            raise ValueError(f"DatasetFrame.t_s must be finite, got {self.t_s}")
        if not isinstance(self.rgb, np.ndarray) or self.rgb.ndim != 3:
            raise ValueError("DatasetFrame.rgb must be an (H, W, 3) uint8 array")
        h, w = self.rgb.shape[:2]
        _check_array("rgb", self.rgb, np.uint8, (h, w, 3))
        _check_array("depth_m", self.depth_m, np.float32, (h, w))
        if not np.isfinite(self.depth_m).all() or (self.depth_m < 0).any():
            raise ValueError(
                f"frame {self.k}: depth_m must be finite and >= 0 (0 = no measurement); "
                "replace NaN/inf/negative values by 0"
            )
        _check_pose("T_world_cam", self.T_world_cam)
        if self.gt_T_cam_obj is not None:
            _check_pose("gt_T_cam_obj", self.gt_T_cam_obj)
        for name in ("gt_v_obj_mps", "gt_w_radps"):
            v = getattr(self, name)
            if v is None:
                continue
            if self.gt_T_cam_obj is None:
                raise ValueError(f"DatasetFrame.{name} is given without gt_T_cam_obj")
            _check_array(name, v, np.float64, (3,))
            if not np.isfinite(v).all():
                raise ValueError(f"DatasetFrame.{name} must be finite, got {v}")
        if (self.gt_v_obj_mps is None) != (self.gt_w_radps is None):
            raise ValueError("give both gt_v_obj_mps and gt_w_radps, or neither")
        for name in ("gt_mask", "gt_mask_full"):
            m = getattr(self, name)
            if m is not None:
                _check_array(name, m, np.bool_, (h, w))
        if self.gt_visible_fraction is not None and not 0.0 <= self.gt_visible_fraction <= 1.0:
            raise ValueError(
                f"DatasetFrame.gt_visible_fraction must lie in [0, 1], got "
                f"{self.gt_visible_fraction}"
            )
        for i, d in enumerate(self.gt_distractors):
            _check_pose(f"gt_distractors[{i}].T_cam_obj", d.T_cam_obj)
            _check_array(f"gt_distractors[{i}].mask", d.mask, np.bool_, (h, w))
            if d.mask_full is not None:
                _check_array(f"gt_distractors[{i}].mask_full", d.mask_full, np.bool_, (h, w))
        if self.k == 0 and self.flows:
            raise ValueError(f"frame 0 has no previous frame, but flows {list(self.flows)} given")
        for set_name, flow in self.flows.items():
            check_set_name("flow", set_name)
            if not isinstance(flow, FlowField):
                raise ValueError(f"flow {set_name!r} must be a FlowField, got {type(flow)}")
            if (flow.from_k, flow.to_k) != (self.k - 1, self.k):
                raise ValueError(
                    f"flow {set_name!r} of frame {self.k} goes {flow.from_k} -> {flow.to_k}; "
                    f"datasets store F_k from frame {self.k - 1} to {self.k}"
                )
            want = flow_grid_shape(h, w, flow.grid_px)
            if flow.flow_px.dtype != np.float32 or flow.flow_px.shape[:2] != want:
                raise ValueError(
                    f"flow {set_name!r} of frame {self.k}: a {flow.grid_px}-px grid over "
                    f"{w}x{h} needs float32 {want + (2,)}, got {flow.flow_px.dtype} "
                    f"{flow.flow_px.shape}"
                )
            if not np.isfinite(flow.flow_px).all():
                raise ValueError(
                    f"flow {set_name!r} of frame {self.k} has NaN/inf; store finite vectors "
                    "and mark unusable cells in FlowField.valid"
                )
            if flow.valid is not None and flow.valid.dtype != np.bool_:
                raise ValueError(f"flow {set_name!r}: valid must be bool, got {flow.valid.dtype}")
        for set_name, m in self.detector_masks.items():
            check_set_name("mask", set_name)
            if set_name in ("gt", GT_FULL_MASK_SET):
                raise ValueError(f"mask set name {set_name!r} is reserved for ground truth")
            if m is not None:
                _check_array(f"detector_masks[{set_name!r}]", m, np.bool_, (h, w))
        for set_name, T in self.detector_poses.items():
            check_set_name("pose", set_name)
            if set_name == "gt":
                raise ValueError("pose set name 'gt' is reserved for ground truth")
            if T is not None:
                _check_pose(f"detector_poses[{set_name!r}]", T)

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(H, W)``."""
        return (int(self.rgb.shape[0]), int(self.rgb.shape[1]))

    def check_intrinsics(self, intrinsics: CameraIntrinsics) -> None:
        """Raises ValueError unless the images have the camera's resolution."""
        if self.shape != intrinsics.shape:
            raise ValueError(
                f"frame {self.k} is {self.shape[1]}x{self.shape[0]} but the sequence camera is "
                f"{intrinsics.width_px}x{intrinsics.height_px}"
            )


@runtime_checkable
class SequenceWriter(Protocol):
    """Streams the frames of one sequence to disk.

    Frames may come in any order and from several processes (the writer holds no open files and
    pickles); each :meth:`write_frame` is atomic: after a crash a frame is either complete or
    absent from :meth:`completed_frames`. Call :meth:`finalize` once, in one process, after all
    frames are written.
    """

    def write_frame(self, frame: DatasetFrame) -> None:
        """Writes one frame (temp files + rename); rewriting a frame replaces it."""
        ...

    def completed_frames(self) -> set[int]:
        """Indices of the frames fully written so far (for ``--resume``)."""
        ...

    def finalize(self) -> Path:
        """Assembles the per-sequence files, checks completeness, writes metadata.

        Returns:
            The sequence path (a folder, or the ``.h5`` file).

        Raises:
            DatasetFormatError: frames are missing (named) or inconsistent with each other.
        """
        ...
