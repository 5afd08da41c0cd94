"""Records exchanged between the stages of roft_sim, and the protocols injected across them.

These are frozen, slotted dataclasses of numpy arrays. They are never mutated: build a new one
with ``dataclasses.replace``. Every array documents its shape, dtype, units and frame.

- :class:`FlowField`: optical flow between two camera frames.
- :class:`PoseDetection`, :class:`MaskDetection`: network outputs, tagged with the frame they were
  computed on and the frame at which they reach the tracker.
- :class:`Observation`: everything a tracker receives at one camera frame (never ground truth).
- :class:`Estimate`: what a tracker returns at one camera frame.
- :class:`PoseTrack`: poses and velocities over time (ground truth, detector output, estimates).
- :class:`ObjectModel`: the object's mesh and model points, in the object frame of the poses.
- :class:`DepthRenderer`: renders the object's depth at given poses; injected into trackers.

This module imports only numpy and :mod:`roft_sim.geometry`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import v_o_from_v_obj

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]

__all__ = [
    "FlowField",
    "PoseDetection",
    "MaskDetection",
    "Observation",
    "Estimate",
    "PoseTrack",
    "ObjectModel",
    "DepthRenderer",
    "ESTIMATE_COVARIANCE_ORDER",
]


def _check_shape(name: str, array: np.ndarray, shape: tuple[int | None, ...]) -> None:
    ok = array.ndim == len(shape) and all(
        s is None or s == a for s, a in zip(shape, array.shape, strict=True)
    )
    if not ok:
        wanted = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise ValueError(f"{name} must have shape {wanted}, got {array.shape}")


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowField:
    """Optical flow from camera frame ``from_k`` to frame ``to_k`` (usually ``to_k - 1``).

    The flow may be stored on a coarser grid than the image (NVIDIA's NVOF 1.0 gives one vector
    per 4x4 block): the vector of image pixel ``(u, v)`` is ``flow_px[v // grid_px, u // grid_px]``
    (block-nearest, no interpolation), as in ROFT.
    """

    flow_px: F32
    """(Hg, Wg, 2) float32 displacement ``(du, dv)`` [full-resolution px] that maps a pixel of
    frame ``from_k`` to its position in frame ``to_k``."""
    from_k: int
    """Index of the earlier camera frame."""
    to_k: int
    """Index of the later camera frame (the flow is delivered with this frame)."""
    grid_px: int = 1
    """Image pixels per flow cell along each axis."""
    valid: Bool | None = None
    """(Hg, Wg) bool: True where the vector is meaningful (None = all valid)."""

    def __post_init__(self) -> None:
        if self.flow_px.ndim != 3 or self.flow_px.shape[2] != 2:
            raise ValueError(f"flow_px must have shape (H, W, 2), got {self.flow_px.shape}")
        if self.grid_px < 1:
            raise ValueError(f"grid_px must be >= 1, got {self.grid_px}")
        if self.valid is not None:
            _check_shape("valid", self.valid, self.flow_px.shape[:2])

    @property
    def stride(self) -> int:
        """Number of camera frames spanned, ``to_k - from_k``."""
        return self.to_k - self.from_k

    def sample(self, u_px: NDArray[np.integer], v_px: NDArray[np.integer]) -> F64:
        """Flow ``(N, 2)`` [px] at integer image pixels ``u_px``, ``v_px`` ``(N,)`` (block-nearest).

        Pixels whose cell is marked invalid get NaN.
        """
        rows = np.asarray(v_px) // self.grid_px
        cols = np.asarray(u_px) // self.grid_px
        out: F64 = self.flow_px[rows, cols].astype(np.float64)
        if self.valid is not None:
            out[~self.valid[rows, cols]] = np.nan
        return out

    def dense(self, height_px: int, width_px: int) -> F32:
        """Flow ``(H, W, 2)`` [px] at full image resolution (each cell repeated, then cropped).

        Invalid cells become NaN.
        """
        f = self.flow_px
        if self.valid is not None:
            f = np.where(self.valid[..., None], f, np.float32(np.nan)).astype(np.float32)
        if self.grid_px > 1:
            f = np.repeat(np.repeat(f, self.grid_px, axis=0), self.grid_px, axis=1)
        if f.shape[0] < height_px or f.shape[1] < width_px:
            raise ValueError(
                f"flow grid {self.flow_px.shape[:2]} x {self.grid_px} px does not cover "
                f"{height_px}x{width_px}"
            )
        return np.ascontiguousarray(f[:height_px, :width_px])


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseDetection:
    """One pose from a (simulated or real) pose network, as delivered to a tracker."""

    capture_k: int
    """Camera frame the network says it computed this pose on (faults may make this wrong)."""
    arrival_k: int
    """Camera frame at which the pose reaches the tracker (``>= capture_k`` unless a fault skews
    the time stamps)."""
    T_cam_obj: F64
    """(4, 4) object pose in the camera frame [m] at ``capture_k``."""
    detection_id: int
    """Identifier unique within a stream; a duplicated delivery keeps its id. Lets the harness
    tell which injected faults a tracker caught; carries no ground truth."""

    def __post_init__(self) -> None:
        _check_shape("T_cam_obj", self.T_cam_obj, (4, 4))


@dataclass(frozen=True, slots=True, kw_only=True)
class MaskDetection:
    """One instance mask from a (simulated or real) segmentation network, as delivered."""

    capture_k: int
    """Camera frame the mask was computed on (as the network reports it)."""
    arrival_k: int
    """Camera frame at which the mask reaches the tracker."""
    mask: Bool
    """(H, W) bool, True on the object's visible pixels, full image resolution."""
    detection_id: int
    """Identifier unique within the mask stream; kept by duplicates."""

    def __post_init__(self) -> None:
        if self.mask.ndim != 2 or self.mask.dtype != np.bool_:
            raise ValueError(
                f"mask must be a 2-D bool array, got {self.mask.dtype} {self.mask.shape}"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class Observation:
    """What a tracker receives at camera frame ``k``. Never contains ground truth."""

    k: int
    """Camera frame index."""
    t_s: float
    """Camera time stamp [s] (``k / fps`` for a clean camera)."""
    rgb: U8 | None
    """(H, W, 3) uint8 RGB image, or None if the camera frame was dropped."""
    depth_m: F32 | None
    """(H, W) float32 z-depth [m], 0 = no measurement; None if the frame was dropped."""
    flow: FlowField | None
    """Flow from the previous delivered camera frame to this one (``flow.to_k == k``); None at
    the first frame, when this frame was dropped, or when no flow source is configured."""
    poses: tuple[PoseDetection, ...] = ()
    """Pose detections that ARRIVE at this frame (any capture frame), in delivery order."""
    masks: tuple[MaskDetection, ...] = ()
    """Mask detections that ARRIVE at this frame, in delivery order."""

    @property
    def camera_dropped(self) -> bool:
        """True when this camera frame carries no image (a fault dropped it)."""
        return self.depth_m is None


ESTIMATE_COVARIANCE_ORDER = (
    "t_x",
    "t_y",
    "t_z",
    "r_x",
    "r_y",
    "r_z",
    "v_x",
    "v_y",
    "v_z",
    "w_x",
    "w_y",
    "w_z",
)
"""Order of :attr:`Estimate.covariance`: position [m], rotation error as a rotation vector [rad]
with the GLOBAL (left) perturbation ``R_true = exp([r]x) R_est``, object-origin velocity [m/s],
angular velocity [rad/s], all in the camera frame."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Estimate:
    """A tracker's output at camera frame ``k``."""

    k: int
    """Camera frame index."""
    T_cam_obj: F64
    """(4, 4) estimated object pose in the camera frame [m]."""
    v_obj_mps: F64
    """(3,) estimated velocity of the object origin, camera frame [m/s]."""
    w_radps: F64
    """(3,) estimated angular velocity, camera frame [rad/s]."""
    covariance: F64 | None = None
    """(12, 12) covariance in :data:`ESTIMATE_COVARIANCE_ORDER`, or None."""
    valid: bool = True
    """False until the tracker has a pose (e.g. before the first detection arrived)."""
    spatial_twist: F64 | None = None
    """(6,) ``(v_o [m/s], w [rad/s])`` from a separate velocity estimator (ROFT's flow KF),
    camera frame; the reference evaluation scores velocity from this when present."""
    accepted_pose_ids: tuple[int, ...] = ()
    """``detection_id`` of every pose fused at this step."""
    rejected_pose_ids: tuple[int, ...] = ()
    """``detection_id`` of every pose rejected as an outlier at this step."""
    dropped_pose_ids: tuple[int, ...] = ()
    """``detection_id`` of every pose ignored at this step (too old for the buffer, or
    otherwise unusable), with the reason in ``diagnostics``."""
    diagnostics: Mapping[str, float | int | str] = field(default_factory=dict)
    """Free-form per-step numbers for reports (e.g. pixels used by the flow update)."""

    def __post_init__(self) -> None:
        _check_shape("T_cam_obj", self.T_cam_obj, (4, 4))
        _check_shape("v_obj_mps", self.v_obj_mps, (3,))
        _check_shape("w_radps", self.w_radps, (3,))
        if self.covariance is not None:
            _check_shape("covariance", self.covariance, (12, 12))
        if self.spatial_twist is not None:
            _check_shape("spatial_twist", self.spatial_twist, (6,))

    @classmethod
    def invalid(cls, k: int, **kwargs: object) -> Estimate:
        """An estimate that says "no pose yet": identity pose, zero velocity, ``valid=False``."""
        return cls(
            k=k,
            T_cam_obj=np.eye(4),
            v_obj_mps=np.zeros(3),
            w_radps=np.zeros(3),
            valid=False,
            **kwargs,  # type: ignore[arg-type]  # the caller's keywords are Estimate fields
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseTrack:
    """Poses and velocities of the object in the camera frame at N time stamps."""

    t_s: F64
    """(N,) time stamps [s]."""
    T_cam_obj: F64
    """(N, 4, 4) object poses in the camera frame [m]."""
    v_obj_mps: F64
    """(N, 3) velocity of the object origin (d/dt of the translation), camera frame [m/s]."""
    w_radps: F64
    """(N, 3) angular velocity, camera frame [rad/s]: ``dR/dt = [w]x R``."""

    def __post_init__(self) -> None:
        n = self.t_s.shape[0] if self.t_s.ndim == 1 else -1
        if n < 0:
            raise ValueError(f"t_s must have shape (N,), got {self.t_s.shape}")
        _check_shape("T_cam_obj", self.T_cam_obj, (n, 4, 4))
        _check_shape("v_obj_mps", self.v_obj_mps, (n, 3))
        _check_shape("w_radps", self.w_radps, (n, 3))

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def v_o_mps(self) -> F64:
        """(N, 3) ROFT's spatial linear velocity ``v_obj - w x t`` [m/s], camera frame."""
        return v_o_from_v_obj(self.v_obj_mps, self.w_radps, self.T_cam_obj[:, :3, 3])

    def select(self, index: slice | NDArray[np.integer]) -> PoseTrack:
        """The sub-track at ``index`` (a slice or an index array)."""
        return PoseTrack(
            t_s=self.t_s[index],
            T_cam_obj=self.T_cam_obj[index],
            v_obj_mps=self.v_obj_mps[index],
            w_radps=self.w_radps[index],
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectModel:
    """An object's geometry in the object frame that its poses refer to.

    For YCB objects this is the NVDU/DOPE-aligned frame used by Fast-YCB (the mesh's bounding-box
    centre at the origin); see docs/conventions.md.
    """

    name: str
    """Registry name, e.g. ``003_cracker_box``."""
    vertices_m: F64
    """(V, 3) mesh vertices, object frame [m]."""
    faces: NDArray[np.int64]
    """(F, 3) triangle vertex indices."""
    model_points_m: F64
    """(M, 3) fixed surface sample used by ADD metrics, object frame [m]."""
    mesh_path: Path | None = None
    """Textured mesh file in the SAME object frame, if one exists on disk."""

    def __post_init__(self) -> None:
        _check_shape("vertices_m", self.vertices_m, (None, 3))
        _check_shape("faces", self.faces, (None, 3))
        _check_shape("model_points_m", self.model_points_m, (None, 3))

    @property
    def diameter_m(self) -> float:
        """Largest distance between two model points [m] (exact over the model points)."""
        from scipy.spatial import ConvexHull, QhullError, distance

        pts = self.model_points_m
        try:  # the farthest pair lies on the convex hull; far fewer pairs to compare
            candidates = pts[ConvexHull(pts).vertices] if len(pts) > 4 else pts
        except QhullError:  # flat or collinear point sets have no 3-D hull
            candidates = pts
        return float(distance.pdist(candidates).max(initial=0.0))


@runtime_checkable
class DepthRenderer(Protocol):
    """Renders the depth of ONE object (fixed at construction) at given poses.

    Injected into trackers that need it (ROFT's outlier rejection); implemented by
    :mod:`roft_sim.render` with MuJoCo, so trackers never import MuJoCo.
    """

    def render_depth(self, T_cam_obj: F64, intrinsics: CameraIntrinsics) -> F32:
        """Depth images of the object alone.

        Args:
            T_cam_obj: (N, 4, 4) object poses in the camera frame [m].
            intrinsics: camera to render with (any resolution).

        Returns:
            (N, H, W) float32 z-depth [m], 0 where the object is not seen.
        """
        ...
