"""Exact optical flow of a scene of rigid bodies, from depth, poses and intrinsics.

For a pixel ``p`` of the earlier frame with z-depth ``Z`` on body ``b``:
``X = Z K^-1 [p; 1]`` (earlier camera frame), ``X' = M_b X`` (later camera frame),
``p' = pi(K X')``,
and the flow is ``p' - p``. ``M_b`` maps earlier-camera coordinates of body b's points to
later-camera coordinates: ``M_obj = T_cam_obj(to) @ inv(T_cam_obj(from))`` for the object and
``M_static = inv(T_world_cam(to)) @ T_world_cam(from)`` for the static world.

This is a motion field (no shading effects), valid for any stride, forward or backward. A pixel
is valid when it has depth and a body, its target is in front of the camera and inside the image,
and (when the later depth is given) it is not occluded there: the later depth at the target pixel
is not nearer than the moved point by more than the tolerance.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry.camera import (
    CameraIntrinsics,
)

__all__ = ["rigid_flow", "object_and_static_motions", "DEFAULT_OCCLUSION_TOLERANCE"]

DEFAULT_OCCLUSION_TOLERANCE = (0.005, 0.01)
"""(absolute [m], relative to depth) tolerance of the occlusion depth test."""


def object_and_static_motions(
    T_cam_obj_from: ArrayLike,
    T_cam_obj_to: ArrayLike,
    T_world_cam_from: ArrayLike | None = None,
    T_world_cam_to: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Motions ``(2, 4, 4)``: index 0 the static world, index 1 the object (see module doc).

    Camera poses default to a static camera.
    """
    T_from = np.asarray(T_cam_obj_from, dtype=np.float64)
    T_to = np.asarray(T_cam_obj_to, dtype=np.float64)
    M_obj = T_to @ np.linalg.inv(T_from)
    if T_world_cam_from is None or T_world_cam_to is None:
        M_static = np.eye(4)
    else:
        M_static = np.linalg.inv(np.asarray(T_world_cam_to, dtype=np.float64)) @ np.asarray(
            T_world_cam_from, dtype=np.float64
        )
    return np.stack([M_static, M_obj])


def rigid_flow(
    intrinsics: CameraIntrinsics,
    depth_from_m: ArrayLike,
    body_index: ArrayLike,
    motions: ArrayLike,
    *,
    depth_to_m: ArrayLike | None = None,
    occlusion_tolerance: tuple[float, float] = DEFAULT_OCCLUSION_TOLERANCE,
) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Flow of every pixel of the earlier frame and its validity.

    Computed in float32, body by body, on each body's bounding box only (few pixels for the
    object and the hand); a body that does not move (an identity motion: the static world seen
    by a static camera) needs no projection at all: its flow is exactly 0 and only the occlusion
    test is run, pixel on pixel.

    Args:
        intrinsics: camera of both frames.
        depth_from_m: (H, W) z-depth of the earlier frame [m], 0 = none.
        body_index: (H, W) int, index into ``motions`` of the body seen at each pixel of the
            earlier frame; negative = no body (the pixel is invalid).
        motions: (B, 4, 4) per-body map from earlier-camera to later-camera coordinates.
        depth_to_m: (H, W) z-depth of the later frame [m] for the occlusion test, or None to skip.
        occlusion_tolerance: (absolute [m], relative) slack of the occlusion test.

    Returns:
        flow (H, W, 2) float32 ``(du, dv)`` [px] (0 where invalid), valid (H, W) bool.
    """
    depth = np.asarray(depth_from_m, dtype=np.float32)
    body = np.asarray(body_index)
    M = np.asarray(motions, dtype=np.float64)
    if depth.shape != intrinsics.shape or body.shape != intrinsics.shape:
        raise ValueError(
            f"depth {depth.shape} and body_index {body.shape} must match the camera "
            f"{intrinsics.shape}"
        )
    depth_to = None if depth_to_m is None else np.asarray(depth_to_m, dtype=np.float32)
    if depth_to is not None and depth_to.shape != intrinsics.shape:
        raise ValueError(f"depth_to_m {depth_to.shape} must match the camera {intrinsics.shape}")
    if M.ndim != 3 or M.shape[1:] != (4, 4):
        raise ValueError(f"motions must have shape (B, 4, 4), got {M.shape}")
    if body.max(initial=-1) >= M.shape[0]:
        raise ValueError(
            f"body_index refers to body {body.max()} but only {M.shape[0]} motions given"
        )
    flow = np.zeros(intrinsics.shape + (2,), dtype=np.float32)
    valid = np.zeros(intrinsics.shape, dtype=bool)
    has_depth = depth > 0
    for i in range(M.shape[0]):
        on_body = has_depth & (body == i)
        box = _bounding_box(on_body)
        if box is None:
            continue
        if np.array_equal(M[i], _IDENTITY):
            if depth_to is not None:
                on_body &= ~_occluded_in_place(depth, depth_to, occlusion_tolerance)
            valid |= on_body
        else:
            _moved_body_flow(
                intrinsics, depth, on_body, M[i], box, depth_to, occlusion_tolerance, flow, valid
            )
    return flow, valid


_IDENTITY = np.eye(4)


def _bounding_box(mask: NDArray[np.bool_]) -> tuple[slice, slice] | None:
    """(rows, cols) slices of the smallest box holding every True pixel; None when none is."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask[rows[0] : rows[-1] + 1].any(axis=0))
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def _occluded_in_place(
    depth: NDArray[np.float32], depth_to: NDArray[np.float32], tolerance: tuple[float, float]
) -> NDArray[np.bool_]:
    """Occlusion test of points that stay where they are (z_to = z, target = the same pixel)."""
    tol = np.float32(tolerance[0]) + np.float32(tolerance[1]) * depth
    return (depth_to > 0) & (depth_to < depth - tol)


def _moved_body_flow(
    intrinsics: CameraIntrinsics,
    depth: NDArray[np.float32],
    on_body: NDArray[np.bool_],
    motion: NDArray[np.float64],
    box: tuple[slice, slice],
    depth_to: NDArray[np.float32] | None,
    tolerance: tuple[float, float],
    flow: NDArray[np.float32],
    valid: NDArray[np.bool_],
) -> None:
    """Writes the flow and validity of one moving body's pixels (inside ``box``) in place."""
    rs, cs = box
    k = intrinsics
    sel = on_body[rs, cs]
    z = depth[rs, cs]
    cols = np.arange(cs.start, cs.stop, dtype=np.float32)
    rows = np.arange(rs.start, rs.stop, dtype=np.float32)[:, None]
    xn = (cols - np.float32(k.cx_px)) / np.float32(k.fx_px)  # x / z of each column
    yn = (rows - np.float32(k.cy_px)) / np.float32(k.fy_px)  # y / z of each row
    R = motion[:3, :3].astype(np.float32)
    t = motion[:3, 3].astype(np.float32)
    x_to = z * (R[0, 0] * xn + R[0, 1] * yn + R[0, 2]) + t[0]
    y_to = z * (R[1, 0] * xn + R[1, 1] * yn + R[1, 2]) + t[1]
    z_to = z * (R[2, 0] * xn + R[2, 1] * yn + R[2, 2]) + t[2]
    ok = sel & (z_to > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_z = np.where(ok, np.float32(1.0) / z_to, np.float32(0.0))
    u_to = np.float32(k.fx_px) * x_to * inv_z + np.float32(k.cx_px)
    v_to = np.float32(k.fy_px) * y_to * inv_z + np.float32(k.cy_px)
    ok &= (u_to >= -0.5) & (u_to < k.width_px - 0.5) & (v_to >= -0.5) & (v_to < k.height_px - 0.5)
    if depth_to is not None:
        tu = np.rint(np.where(ok, u_to, 0.0)).astype(np.intp)
        tv = np.rint(np.where(ok, v_to, 0.0)).astype(np.intp)
        d_seen = depth_to[tv, tu]
        tol = np.float32(tolerance[0]) + np.float32(tolerance[1]) * z_to
        ok &= ~((d_seen > 0) & (d_seen < z_to - tol))
    out = flow[rs, cs]  # a view: other bodies' pixels in the box are left as they are
    np.copyto(out[..., 0], u_to - cols, where=ok)
    np.copyto(out[..., 1], v_to - rows, where=ok)
    valid[rs, cs] |= ok
