"""Per-frame rendered images with their exact ground truth, and ground-truth optical flow.

Ground-truth flow is a MOTION FIELD computed from geometry, not from images: every pixel of the
earlier frame is back-projected with its exact z-depth, moved with the rigid motion of the body
it shows (static world, object, hand), and projected into the later frame
(:func:`roft_sim.geometry.rigid_flow.rigid_flow`). Shading changes (moving highlights, shadows)
have no flow. A vector is valid when the pixel shows a body, its target lies in front of the
camera and inside the later image, and the later depth there is not nearer than the moved point
(occlusion test). Any pair of frames works: any stride, forward or backward.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry import CameraIntrinsics, invert_transform
from roft_sim.geometry.rigid_flow import DEFAULT_OCCLUSION_TOLERANCE, rigid_flow
from roft_sim.records import FlowField

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

__all__ = [
    "RenderedFrame",
    "ground_truth_flow",
    "body_motions",
    "SEGMENT_BACKGROUND",
    "SEGMENT_OBJECT",
    "SEGMENT_HAND",
    "SEGMENT_DISTRACTOR",
    "segment_of_body",
]

SEGMENT_BACKGROUND, SEGMENT_OBJECT, SEGMENT_HAND, SEGMENT_DISTRACTOR = 0, 1, 2, 3
"""Ground-truth segment ids (:meth:`RenderedFrame.segment_ids`): background (static world, or
nothing drawn), the tracked object, the hand (every link), any distractor object."""


def segment_of_body(body_name: str) -> int:
    """Segment id of a rigid body by its name (``static``, ``object``, ``hand...``,
    ``distractor...``)."""
    if body_name == "object":
        return SEGMENT_OBJECT
    if body_name.startswith("hand"):
        return SEGMENT_HAND
    if body_name.startswith("distractor"):
        return SEGMENT_DISTRACTOR
    return SEGMENT_BACKGROUND


@dataclass(frozen=True, slots=True, kw_only=True)
class RenderedFrame:
    """One rendered camera frame and its exact ground truth. Velocities are in the camera frame
    (docs/conventions.md); ``t_s`` is the middle of the exposure."""

    k: int
    """Camera frame index."""
    t_s: float
    """Frame time ``k / fps`` [s] (the exposure's mid-time)."""
    rgb: NDArray[np.uint8]
    """(H, W, 3) uint8 RGB image (averaged over sub-frames when motion blur is on)."""
    depth_m: F32
    """(H, W) float32 exact z-depth [m] (distance to the camera plane), 0 = nothing."""
    sensor_depth_m: F32
    """(H, W) float32 z-depth [m] as the configured depth sensor reports it (the noise model
    applied to ``depth_m``; equal to it with ``kind = "none"``), 0 = no measurement."""
    object_mask: NDArray[np.bool_] | None
    """(H, W) bool, True on the object's visible pixels (None when segmentation is off)."""
    segmentation: NDArray[np.int32] | None
    """(H, W) int32 MuJoCo geom id per pixel, -1 = background (None when segmentation is off)."""
    body_index: NDArray[np.int8] | None
    """(H, W) int8 rigid body per pixel, an index into ``body_names`` and ``T_cam_bodies``;
    -1 = nothing (None when segmentation is off)."""
    T_cam_obj: F64
    """(4, 4) object pose in the camera frame [m]."""
    v_obj_mps: F64
    """(3,) velocity of the object origin relative to the camera, camera frame [m/s]."""
    w_radps: F64
    """(3,) angular velocity of the object relative to the camera, camera frame [rad/s]."""
    v_o_mps: F64
    """(3,) ROFT's spatial linear velocity ``v_obj - w x t_cam_obj`` [m/s]."""
    T_world_cam: F64
    """(4, 4) camera pose (OpenCV optical frame) in the world [m]; identity for a static camera."""
    T_cam_bodies: F64
    """(B, 4, 4) pose of each rigid body's frame in the camera frame [m], in ``body_names``
    order: the static world (``inv(T_world_cam)``), the object, the hand's links (if any), the
    distractors (if any)."""
    body_names: tuple[str, ...]
    """Names of the bodies, e.g. ``("static", "object", "hand")``."""
    camera_v_world_mps: F64 = field(default_factory=lambda: np.zeros(3))
    """(3,) the camera's own velocity (its origin), world frame [m/s]; the object's velocities
    above are relative to the moving camera."""
    camera_w_world_radps: F64 = field(default_factory=lambda: np.zeros(3))
    """(3,) the camera's own angular velocity, world frame [rad/s]."""
    distractor_names: tuple[str, ...] = ()
    """Object name of each distractor ``distractor<i>`` (registry name or mesh path)."""

    @property
    def T_cam_distractors(self) -> F64:
        """(D, 4, 4) pose of each distractor in the camera frame [m] (``distractor<i>``
        order); its visible mask is ``body_index == body_names.index(f"distractor{i}")``."""
        rows = [i for i, n in enumerate(self.body_names) if n.startswith("distractor")]
        return self.T_cam_bodies[rows].reshape(len(rows), 4, 4)

    def segment_ids(self) -> NDArray[np.uint8]:
        """(H, W) uint8 ground-truth segment id per pixel: :data:`SEGMENT_BACKGROUND`,
        :data:`SEGMENT_OBJECT`, :data:`SEGMENT_HAND` or :data:`SEGMENT_DISTRACTOR` (exact
        occlusion: each pixel shows the nearest surface)."""
        if self.body_index is None:
            raise ValueError("segment ids need the segmentation; render with segmentation=True")
        lut = np.array(
            [segment_of_body(n) for n in self.body_names] + [SEGMENT_BACKGROUND], dtype=np.uint8
        )
        return lut[self.body_index]  # index -1 (nothing) -> the last entry, background

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape (H, W)."""
        return self.depth_m.shape


def body_motions(earlier: RenderedFrame, later: RenderedFrame) -> F64:
    """Per-body maps ``(B, 4, 4)`` from earlier-camera to later-camera coordinates:
    ``M_b = T_cam_b(later) @ inv(T_cam_b(earlier))``."""
    if earlier.body_names != later.body_names:
        raise ValueError(
            f"frames of different scenes: bodies {earlier.body_names} vs {later.body_names}"
        )
    return later.T_cam_bodies @ invert_transform(earlier.T_cam_bodies)


def ground_truth_flow(
    earlier: RenderedFrame,
    later: RenderedFrame,
    intrinsics: CameraIntrinsics,
    *,
    occlusion_tolerance: tuple[float, float] = DEFAULT_OCCLUSION_TOLERANCE,
) -> FlowField:
    """Exact flow from frame ``earlier`` to frame ``later`` (see the module doc).

    Pass the later frame first for backward flow; the FlowField's ``from_k``/``to_k`` follow
    the argument order.

    Args:
        earlier: the frame whose pixels the flow starts from (needs depth and segmentation).
        later: the frame they move to (its depth is the occlusion test).
        intrinsics: the camera of both frames.
        occlusion_tolerance: (absolute [m], relative) slack of the occlusion depth test.

    Returns:
        FlowField ``(H, W, 2)`` float32 [px], ``grid_px = 1``, with ``valid``.
    """
    if earlier.body_index is None:
        raise ValueError(
            "ground-truth flow needs the segmentation of the earlier frame; render with "
            "segmentation=True"
        )
    flow, valid = rigid_flow(
        intrinsics,
        earlier.depth_m,
        earlier.body_index,
        body_motions(earlier, later),
        depth_to_m=later.depth_m,
        occlusion_tolerance=occlusion_tolerance,
    )
    return FlowField(flow_px=flow, from_k=earlier.k, to_k=later.k, grid_px=1, valid=valid)
