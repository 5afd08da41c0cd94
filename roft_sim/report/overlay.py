"""Overlay frames: the object's silhouette at the estimate and at the ground truth over the rgb, the
delayed masks a tracker received, and markers when a pose arrives. Drawn with OpenCV, no renderer.

The silhouette is the object's mesh projected with the pinhole model (every triangle whose three
vertices lie in front of the camera, filled with ``cv2.fillConvexPoly`` at 1/16 px precision; pixel
centres at integer ``(u, v)`` as in docs/conventions.md). A model without faces (points only) is
drawn as its projected points.

Colours (RGB): ground truth green, estimate magenta (filled, translucent), delayed mask yellow,
arrived pose cyan, arrival banner red.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import ObjectModel

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]
Bool = NDArray[np.bool_]

__all__ = [
    "GT_COLOR",
    "ESTIMATE_COLOR",
    "MASK_COLOR",
    "ARRIVAL_COLOR",
    "BANNER_COLOR",
    "silhouette_mask",
    "OverlayFrame",
    "draw_overlay",
]

GT_COLOR = (40, 220, 40)
ESTIMATE_COLOR = (230, 40, 230)
MASK_COLOR = (255, 220, 0)
ARRIVAL_COLOR = (0, 220, 255)
BANNER_COLOR = (220, 30, 30)
_SHIFT = 4
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def silhouette_mask(
    model: ObjectModel, T_cam_obj: F64, intrinsics: CameraIntrinsics, *, near_m: float = 1e-3
) -> Bool:
    """The pixels covered by the object at pose ``T_cam_obj``.

    Args:
        model: the object (mesh in the object frame; points only if it has no faces).
        T_cam_obj: (4, 4) object pose in the camera frame [m].
        intrinsics: the camera (image size and pinhole parameters).
        near_m: vertices closer than this to the camera plane drop their triangles [m].

    Returns:
        (H, W) bool, True on covered pixels: every pixel whose centre is inside a projected
        triangle, and the pixels its outline touches (OpenCV's rasterisation), so at most one
        pixel wider than the exact silhouette. All False for a non-finite pose.
    """
    h, w = intrinsics.height_px, intrinsics.width_px
    out = np.zeros((h, w), dtype=np.uint8)
    T = np.asarray(T_cam_obj, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        return out.astype(bool)
    faces = np.asarray(model.faces, dtype=np.int64)
    points = model.vertices_m if faces.size else model.model_points_m
    p = np.asarray(points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
    z = p[:, 2]
    front = z > near_m
    uv = np.full((p.shape[0], 2), np.nan)
    uv[front, 0] = intrinsics.fx_px * p[front, 0] / z[front] + intrinsics.cx_px
    uv[front, 1] = intrinsics.fy_px * p[front, 1] / z[front] + intrinsics.cy_px
    if faces.size:
        keep = front[faces].all(axis=1)
        tri = uv[faces[keep]]  # (F, 3, 2)
        # keep triangles whose box touches the image (also bounds the fixed-point values)
        lo, hi = tri.min(axis=1), tri.max(axis=1)
        visible = (hi[:, 0] >= -1) & (lo[:, 0] <= w) & (hi[:, 1] >= -1) & (lo[:, 1] <= h)
        tri = np.clip(tri[visible], -4 * max(w, h), 5 * max(w, h))
        # one call per triangle: fillPoly on many polygons fills their overlaps even-odd
        for triangle in np.round(tri * (1 << _SHIFT)).astype(np.int32):
            cv2.fillConvexPoly(out, triangle, 1, cv2.LINE_8, _SHIFT)
    else:
        ok = front & (uv[:, 0] >= -0.5) & (uv[:, 0] < w - 0.5)
        ok &= (uv[:, 1] >= -0.5) & (uv[:, 1] < h - 0.5)
        cols = np.round(uv[ok, 0]).astype(int)
        rows = np.round(uv[ok, 1]).astype(int)
        out[rows, cols] = 1
    return out.astype(bool)


def _contours(mask: Bool) -> Sequence[NDArray[np.int32]]:
    contours, _ = cv2.findContours(
        mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE
    )
    return cast(Sequence[NDArray[np.int32]], contours)  # cv2 types them as any int/float array


@dataclass(frozen=True, slots=True, kw_only=True)
class OverlayFrame:
    """What one overlay frame shows (any field may be None)."""

    rgb: U8
    """(H, W, 3) uint8 camera image."""
    gt_mask: Bool | None = None
    """Silhouette at the ground-truth pose."""
    estimate_mask: Bool | None = None
    """Silhouette at the estimate (None when the tracker has no pose)."""
    delayed_mask: Bool | None = None
    """The newest mask the tracker has received (as received: delayed, maybe corrupted)."""
    arrived_pose_mask: Bool | None = None
    """Silhouette at a pose detection arriving at this frame."""
    banner: str | None = None
    """Red banner text (e.g. ``pose of frame 54 arrives (+6)``)."""
    lines: tuple[str, ...] = ()
    """Text lines in the top-left corner (frame, errors)."""


def _legend(img: U8, scale: float) -> None:
    entries = (
        ("ground truth", GT_COLOR),
        ("estimate", ESTIMATE_COLOR),
        ("received mask", MASK_COLOR),
        ("arriving pose", ARRIVAL_COLOR),
    )
    h = img.shape[0]
    row = int(round(16 * scale / 0.4))
    y = h - 8 - row * (len(entries) - 1)
    for text, color in entries:
        cv2.rectangle(img, (8, y - row // 2), (8 + row // 2, y), color, -1)
        cv2.putText(img, text, (14 + row // 2, y), _FONT, scale, (255, 255, 255), 2, cv2.LINE_AA)
        cv2.putText(img, text, (14 + row // 2, y), _FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)
        y += row


def draw_overlay(frame: OverlayFrame, *, legend: bool = True) -> U8:
    """Draws one overlay frame; returns a new (H, W, 3) uint8 RGB image."""
    img = np.array(frame.rgb, dtype=np.uint8, copy=True)
    h, w = img.shape[:2]
    scale = float(np.clip(w / 1600.0, 0.3, 0.8))
    thick = max(1, round(2 * w / 1280.0 + 0.5))
    if frame.estimate_mask is not None and frame.estimate_mask.any():
        tint = img.astype(np.float32)
        sel = frame.estimate_mask
        tint[sel] = 0.65 * tint[sel] + 0.35 * np.array(ESTIMATE_COLOR, np.float32)
        img = tint.astype(np.uint8)
        cv2.drawContours(img, _contours(sel), -1, ESTIMATE_COLOR, thick, cv2.LINE_AA)
    if frame.delayed_mask is not None and frame.delayed_mask.any():
        cv2.drawContours(img, _contours(frame.delayed_mask), -1, MASK_COLOR, 1, cv2.LINE_AA)
    if frame.gt_mask is not None and frame.gt_mask.any():
        cv2.drawContours(img, _contours(frame.gt_mask), -1, GT_COLOR, thick, cv2.LINE_AA)
    if frame.arrived_pose_mask is not None and frame.arrived_pose_mask.any():
        cv2.drawContours(img, _contours(frame.arrived_pose_mask), -1, ARRIVAL_COLOR, thick)
    y = int(round(14 * scale / 0.4))
    for text in frame.lines:
        cv2.putText(img, text, (8, y), _FONT, scale, (0, 0, 0), 2, cv2.LINE_AA)
        cv2.putText(img, text, (8, y), _FONT, scale, (255, 255, 255), 1, cv2.LINE_AA)
        y += int(round(14 * scale / 0.4))
    if frame.banner:
        (tw, th), base = cv2.getTextSize(frame.banner, _FONT, scale, 1)
        x0 = w - tw - 16
        cv2.rectangle(img, (x0 - 6, 6), (w - 6, 14 + th + base), BANNER_COLOR, -1)
        cv2.putText(img, frame.banner, (x0, 10 + th), _FONT, scale, (255, 255, 255), 1, cv2.LINE_AA)
    if legend:
        _legend(img, scale)
    return img
