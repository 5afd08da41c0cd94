"""The one place that converts between the OpenCV pinhole camera and MuJoCo's camera.

OpenCV optical frame: x right, y down, z forward; pixel centres at integer ``(u, v)``, so the image
spans ``u`` in ``[-0.5, W - 0.5]`` (docs/conventions.md). MuJoCo cameras look along their -z axis
with y up and x right, so ``R_cv_mj = diag(1, -1, -1)`` (a half turn about x).

MuJoCo 3.2+ (and 4.0) cameras take pinhole intrinsics as ``resolution``, ``sensor_size`` [m],
``focal_pixel`` and ``principal_pixel``. Measured on MuJoCo 4.0
(``tests/render/test_mujoco_camera.py`` checks it against the compiled frustum), the frustum at
the near plane ``n`` is

    x in n / fx * [p_x - W/2, p_x + W/2],   y in n / fy * [-H/2 - p_y, H/2 - p_y]   (MuJoCo frame)

with edges at the image borders (OpenGL pixel centres at half-integers). Matching these edges
to ours (``u = -0.5`` at the left border, ``v = -0.5`` at the top) gives

    principal_pixel = (W/2 - 0.5 - cx,  H/2 - 0.5 - cy),

i.e. MuJoCo's principal "offset" is the image centre minus the OpenCV principal point, in both
axes (x because MuJoCo shifts the frustum, not the image; y because its y axis points up).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry.camera import CameraIntrinsics

F64 = NDArray[np.float64]

__all__ = [
    "R_CV_MJ",
    "QUAT_CV_MJ",
    "SENSOR_PIXEL_PITCH_M",
    "MujocoCameraParams",
    "mujoco_camera_params",
    "intrinsics_from_mujoco_camera",
    "mujoco_camera_pose_from_opencv",
    "opencv_pose_from_mujoco_camera",
]

R_CV_MJ = np.diag([1.0, -1.0, -1.0])
"""Rotation of the MuJoCo camera frame in the OpenCV optical frame (and its own inverse)."""

QUAT_CV_MJ = (0.0, 1.0, 0.0, 0.0)
"""``R_CV_MJ`` as a (w, x, y, z) quaternion: a half turn about x. Use it as the ``quat`` of a
MuJoCo camera attached to a body whose frame is the OpenCV optical frame."""

SENSOR_PIXEL_PITCH_M = 1e-5
"""Nominal pixel pitch used to express the intrinsics as a MuJoCo sensor size [m/px]. Any
positive value gives the same projection: MuJoCo uses only the ratios."""


@dataclass(frozen=True, slots=True)
class MujocoCameraParams:
    """MuJoCo camera attributes equivalent to an OpenCV pinhole camera."""

    resolution: tuple[int, int]
    """(width, height) [px]."""
    sensor_size_m: tuple[float, float]
    """(width, height) of the sensor [m] (resolution times :data:`SENSOR_PIXEL_PITCH_M`)."""
    focal_pixel: tuple[float, float]
    """(fx, fy) [px]."""
    principal_pixel: tuple[float, float]
    """MuJoCo's principal offset [px]: ``(W/2 - 0.5 - cx, H/2 - 0.5 - cy)`` (module doc)."""


def mujoco_camera_params(intrinsics: CameraIntrinsics) -> MujocoCameraParams:
    """MuJoCo camera attributes that render exactly the pinhole camera ``intrinsics``."""
    w, h = intrinsics.width_px, intrinsics.height_px
    return MujocoCameraParams(
        resolution=(w, h),
        sensor_size_m=(w * SENSOR_PIXEL_PITCH_M, h * SENSOR_PIXEL_PITCH_M),
        focal_pixel=(intrinsics.fx_px, intrinsics.fy_px),
        principal_pixel=(w / 2 - 0.5 - intrinsics.cx_px, h / 2 - 0.5 - intrinsics.cy_px),
    )


def intrinsics_from_mujoco_camera(
    resolution: ArrayLike, sensor_size_m: ArrayLike, intrinsic_m: ArrayLike
) -> CameraIntrinsics:
    """Pinhole intrinsics of a compiled MuJoCo camera (the inverse of :func:`mujoco_camera_params`).

    Args:
        resolution: (2,) ``model.cam_resolution[i]`` (width, height) [px].
        sensor_size_m: (2,) ``model.cam_sensorsize[i]`` [m].
        intrinsic_m: (4,) ``model.cam_intrinsic[i]``: focal lengths and principal offset [m].
    """
    w, h = (int(x) for x in np.asarray(resolution))
    sw, sh = (float(x) for x in np.asarray(sensor_size_m))
    f_x, f_y, p_x, p_y = (float(x) for x in np.asarray(intrinsic_m))
    return CameraIntrinsics(
        fx_px=f_x / sw * w,
        fy_px=f_y / sh * h,
        cx_px=w / 2 - 0.5 - p_x / sw * w,
        cy_px=h / 2 - 0.5 - p_y / sh * h,
        width_px=w,
        height_px=h,
    )


def mujoco_camera_pose_from_opencv(T_world_cam: ArrayLike) -> F64:
    """World pose ``(..., 4, 4)`` of the MuJoCo camera frame from the OpenCV camera pose."""
    T = np.array(T_world_cam, dtype=np.float64)
    T[..., :3, :3] = T[..., :3, :3] @ R_CV_MJ
    return T


def opencv_pose_from_mujoco_camera(cam_xpos: ArrayLike, cam_xmat: ArrayLike) -> F64:
    """OpenCV camera pose ``T_world_cam`` (4, 4) from MuJoCo's ``data.cam_xpos[i]`` (3,) [m] and
    ``data.cam_xmat[i]`` (9,) or (3, 3)."""
    T = np.eye(4)
    T[:3, :3] = np.asarray(cam_xmat, dtype=np.float64).reshape(3, 3) @ R_CV_MJ
    T[:3, 3] = np.asarray(cam_xpos, dtype=np.float64)
    return T
