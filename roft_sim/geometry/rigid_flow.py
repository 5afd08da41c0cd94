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


def _moved_points(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    z: NDArray[np.float64],
    body: NDArray[np.integer],
    motions: NDArray[np.float64],
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Points (P,) x, y, z in the earlier camera [m], each moved by its body's map
    ``motions[body]`` (B, 4, 4) into the later camera. One rigid map per body (few bodies): no
    per-pixel 4x4 matrices."""
    x_to, y_to, z_to = np.empty_like(z), np.empty_like(z), np.empty_like(z)
    for i in range(motions.shape[0]):
        sel = body == i
        if not sel.any():
            continue
        R, t = motions[i, :3, :3], motions[i, :3, 3]
        xs, ys, zs = x[sel], y[sel], z[sel]
        x_to[sel] = R[0, 0] * xs + R[0, 1] * ys + R[0, 2] * zs + t[0]
        y_to[sel] = R[1, 0] * xs + R[1, 1] * ys + R[1, 2] * zs + t[1]
        z_to[sel] = R[2, 0] * xs + R[2, 1] * ys + R[2, 2] * zs + t[2]
    return x_to, y_to, z_to


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
    depth = np.asarray(depth_from_m, dtype=np.float64)
    body = np.asarray(body_index)
    M = np.asarray(motions, dtype=np.float64)
    if depth.shape != intrinsics.shape or body.shape != intrinsics.shape:
        raise ValueError(
            f"depth {depth.shape} and body_index {body.shape} must match the camera "
            f"{intrinsics.shape}"
        )
    depth_to = None if depth_to_m is None else np.asarray(depth_to_m, dtype=np.float64)
    if depth_to is not None and depth_to.shape != intrinsics.shape:
        raise ValueError(f"depth_to_m {depth_to.shape} must match the camera {intrinsics.shape}")
    if M.ndim != 3 or M.shape[1:] != (4, 4):
        raise ValueError(f"motions must have shape (B, 4, 4), got {M.shape}")
    if body.max(initial=-1) >= M.shape[0]:
        raise ValueError(
            f"body_index refers to body {body.max()} but only {M.shape[0]} motions given"
        )

    ok = (depth > 0) & (body >= 0)
    rows, cols = np.nonzero(ok)
    z = depth[rows, cols]
    x = (cols - intrinsics.cx_px) * (z / intrinsics.fx_px)
    y = (rows - intrinsics.cy_px) * (z / intrinsics.fy_px)
    x_to, y_to, z_to = _moved_points(x, y, z, body[rows, cols], M)
    in_front = z_to > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        u_to = intrinsics.fx_px * x_to / z_to + intrinsics.cx_px
        v_to = intrinsics.fy_px * y_to / z_to + intrinsics.cy_px
    inside = (
        in_front
        & (u_to >= -0.5)
        & (u_to < intrinsics.width_px - 0.5)
        & (v_to >= -0.5)
        & (v_to < intrinsics.height_px - 0.5)
    )
    if depth_to is not None:
        tu = np.where(inside, np.rint(np.where(inside, u_to, 0.0)), 0).astype(np.int64)
        tv = np.where(inside, np.rint(np.where(inside, v_to, 0.0)), 0).astype(np.int64)
        d_seen = depth_to[tv, tu]
        tol = occlusion_tolerance[0] + occlusion_tolerance[1] * z_to
        occluded = (d_seen > 0) & (d_seen < z_to - tol)
        inside &= ~occluded
    flow = np.zeros(intrinsics.shape + (2,), dtype=np.float32)
    valid = np.zeros(intrinsics.shape, dtype=bool)
    r, c = rows[inside], cols[inside]
    flow[r, c, 0] = u_to[inside] - c
    flow[r, c, 1] = v_to[inside] - r
    valid[r, c] = True
    return flow, valid
