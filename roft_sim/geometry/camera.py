"""Pinhole camera model in the OpenCV optical frame.

Frame: x right, y down, z forward (into the scene). Pixel coordinates ``(u, v)``: u along image
columns, v along rows, and the CENTRE of pixel (column i, row j) is at ``(u, v) = (i, j)``
(OpenCV's convention, also used by ROFT's flow model). So ``u = fx X/Z + cx``, ``v = fy Y/Z + cy``,
and the image spans ``u`` in ``[-0.5, width - 0.5]``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.errors import ConfigError

F64 = NDArray[np.float64]

__all__ = [
    "CameraIntrinsics",
    "project_points",
    "backproject_pixels",
    "backproject_depth",
    "pixel_grid",
]


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraIntrinsics:
    """Pinhole intrinsics without distortion."""

    fx_px: float
    """Focal length along u [px]."""
    fy_px: float
    """Focal length along v [px]."""
    cx_px: float
    """Principal point, column coordinate [px] (pixel centres at integers)."""
    cy_px: float
    """Principal point, row coordinate [px]."""
    width_px: int
    """Image width [px]."""
    height_px: int
    """Image height [px]."""

    def __post_init__(self) -> None:
        for name in ("fx_px", "fy_px", "cx_px", "cy_px"):
            value = getattr(self, name)
            if not np.isfinite(value):
                raise ConfigError(f"camera {name} must be finite, got {value}")
        if self.fx_px <= 0 or self.fy_px <= 0:
            raise ConfigError(
                f"camera focal lengths must be positive, got fx={self.fx_px}, fy={self.fy_px}"
            )
        if self.width_px <= 0 or self.height_px <= 0:
            raise ConfigError(
                f"camera resolution must be positive, got {self.width_px}x{self.height_px}"
            )

    @classmethod
    def from_matrix(cls, K: ArrayLike, width_px: int, height_px: int) -> CameraIntrinsics:
        """From a 3x3 matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (skew must be 0)."""
        K = np.asarray(K, dtype=np.float64)
        if K.shape != (3, 3) or abs(K[0, 1]) > 1e-12 or not np.allclose(K[2], [0, 0, 1]):
            raise ConfigError(
                f"expected a pinhole K [[fx,0,cx],[0,fy,cy],[0,0,1]], got {K.tolist()}"
            )
        return cls(
            fx_px=float(K[0, 0]),
            fy_px=float(K[1, 1]),
            cx_px=float(K[0, 2]),
            cy_px=float(K[1, 2]),
            width_px=int(width_px),
            height_px=int(height_px),
        )

    @property
    def K(self) -> F64:
        """Camera matrix ``(3, 3)``."""
        return np.array(
            [[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]]
        )

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(height, width)`` as numpy arrays use it."""
        return (self.height_px, self.width_px)

    @property
    def fovy_rad(self) -> float:
        """Vertical field of view [rad] (of the symmetric frustum through the image edges)."""
        return 2.0 * float(np.arctan(0.5 * self.height_px / self.fy_px))

    def resized(self, width_px: int, height_px: int) -> CameraIntrinsics:
        """Intrinsics of the same camera for an image resized to ``width_px x height_px``.

        Exact for pixel-centre coordinates: ``u' + 0.5 = (u + 0.5) * width_px / width``.
        """
        sx = width_px / self.width_px
        sy = height_px / self.height_px
        return dataclasses.replace(
            self,
            fx_px=self.fx_px * sx,
            fy_px=self.fy_px * sy,
            cx_px=(self.cx_px + 0.5) * sx - 0.5,
            cy_px=(self.cy_px + 0.5) * sy - 0.5,
            width_px=int(width_px),
            height_px=int(height_px),
        )


def project_points(intrinsics: CameraIntrinsics, p_cam: ArrayLike) -> F64:
    """Projects points ``p_cam`` ``(..., 3)`` [m] (camera frame) to pixels ``(..., 2)`` [px].

    Points at or behind the camera plane (z <= 0) project to NaN.
    """
    p = np.asarray(p_cam, dtype=np.float64)
    zs = np.where(p[..., 2] > 0, p[..., 2], np.nan)  # NaN / NaN raises no warning
    out = np.empty(p.shape[:-1] + (2,))
    out[..., 0] = intrinsics.fx_px * p[..., 0] / zs + intrinsics.cx_px
    out[..., 1] = intrinsics.fy_px * p[..., 1] / zs + intrinsics.cy_px
    return out


def backproject_pixels(intrinsics: CameraIntrinsics, uv_px: ArrayLike, z_m: ArrayLike) -> F64:
    """Camera-frame points ``(..., 3)`` [m] from pixels ``(..., 2)`` and z-depths ``(...)`` [m]."""
    uv = np.asarray(uv_px, dtype=np.float64)
    z = np.asarray(z_m, dtype=np.float64)
    x = (uv[..., 0] - intrinsics.cx_px) / intrinsics.fx_px * z
    y = (uv[..., 1] - intrinsics.cy_px) / intrinsics.fy_px * z
    return np.stack([x, y, z], axis=-1)


def pixel_grid(intrinsics: CameraIntrinsics) -> F64:
    """Pixel-centre coordinates ``(H, W, 2)`` as ``(u, v)`` [px]."""
    v, u = np.mgrid[0 : intrinsics.height_px, 0 : intrinsics.width_px].astype(np.float64)
    return np.stack([u, v], axis=-1)


def backproject_depth(intrinsics: CameraIntrinsics, depth_m: ArrayLike) -> F64:
    """Camera-frame points ``(H, W, 3)`` [m] of every pixel of a z-depth image ``(H, W)`` [m].

    Pixels without a measurement (depth 0) give the point (0, 0, 0).
    """
    depth = np.asarray(depth_m, dtype=np.float64)
    if depth.shape != intrinsics.shape:
        raise ValueError(f"depth shape {depth.shape} does not match the camera {intrinsics.shape}")
    return backproject_pixels(intrinsics, pixel_grid(intrinsics), depth)
