"""Topics, frame ids, stamps and the ROS 2 messages of a bag, built from and read into arrays.

Messages are plain dicts in the layout of their ``.msg`` definitions (:mod:`roft_sim.bags.msgdefs`),
which ``mcap_ros2`` encodes as CDR; a decoded message (any object with the same attribute names)
reads back through the ``*_from_message`` functions.

Time: frame ``k`` of a sequence at ``fps`` Hz is stamped ``k / fps`` seconds, as integer
nanoseconds rounded to the nearest (:func:`stamp_ns_from_frame`); the same number is the log
time of what arrives at frame ``k``.

Quaternions: ``geometry_msgs`` stores ``(x, y, z, w)``; the package keeps ``(w, x, y, z)``. Only
:func:`quat_msg_from_matrix` and :func:`matrix_from_quat_msg` cross that boundary.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError, DatasetFormatError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.so3 import (
    canonical_quat,
    matrix_from_quat,
    quat_from_matrix,
    quat_wxyz_from_xyzw,
    quat_xyzw_from_wxyz,
)

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]

__all__ = [
    "COLOR_TOPIC",
    "COLOR_INFO_TOPIC",
    "DEPTH_TOPIC",
    "DEPTH_INFO_TOPIC",
    "DETECTOR_POSE_TOPIC",
    "MASK_TOPIC",
    "TF_TOPIC",
    "GT_TWIST_TOPIC",
    "TRACKER_POSE_TOPIC",
    "TRACKER_TWIST_TOPIC",
    "CAMERA_FRAME",
    "OBJECT_FRAME",
    "GT_OBJECT_FRAME",
    "IMAGE",
    "CAMERA_INFO",
    "POSE_STAMPED",
    "TWIST_STAMPED",
    "TF_MESSAGE",
    "DepthEncoding",
    "DEPTH_ENCODINGS",
    "TwistLinear",
    "TWIST_LINEARS",
    "NS_PER_S",
    "stamp_ns_from_frame",
    "frame_from_stamp_ns",
    "time_msg",
    "ns_from_time_msg",
    "header",
    "quat_msg_from_matrix",
    "matrix_from_quat_msg",
    "rgb_image_msg",
    "mask_image_msg",
    "depth_image_msg",
    "depth_m_from_image_msg",
    "array_from_image_msg",
    "camera_info_msg",
    "pose_stamped_msg",
    "transform_from_pose_msg",
    "tf_msg",
    "twist_stamped_msg",
    "twist_from_msg",
]

COLOR_TOPIC = "/camera/color/image_raw"
COLOR_INFO_TOPIC = "/camera/color/camera_info"
DEPTH_TOPIC = "/camera/depth/image_rect"
DEPTH_INFO_TOPIC = "/camera/depth/camera_info"
DETECTOR_POSE_TOPIC = "/detector/pose"
MASK_TOPIC = "/segmenter/mask"
TF_TOPIC = "/tf"
GT_TWIST_TOPIC = "/ground_truth/twist"
TRACKER_POSE_TOPIC = "/tracker/pose"
TRACKER_TWIST_TOPIC = "/tracker/twist"

CAMERA_FRAME = "camera_color_optical_frame"
"""The camera's optical frame (x right, y down, z forward); depth is registered to it."""
OBJECT_FRAME = "object"
"""The tracker's own estimated object frame: a twist stamped in it is the body twist (the
object's velocity and angular velocity expressed in its own frame), which carries the
estimate's ``v_obj`` and ``w`` whatever the bag's convention (a run's frame without a spatial
twist)."""
GT_OBJECT_FRAME = "object_ground_truth"
"""The child frame of the ground truth on ``/tf`` (a tracker's own ``object`` frame does not
collide with it)."""

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
TWIST_STAMPED = "geometry_msgs/msg/TwistStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

DepthEncoding = Literal["32FC1", "16UC1"]
"""REP 118 depth images: ``32FC1`` metres (NaN = no return) or ``16UC1`` millimetres (0 = no
return)."""
DEPTH_ENCODINGS: tuple[str, ...] = get_args(DepthEncoding)

TwistLinear = Literal["origin", "spatial"]
"""What ``twist.linear`` of a ``TwistStamped`` holds (``twist.angular`` is always ``w``):
``origin``, the velocity of the object's origin ``v_obj`` (d/dt of the ``/tf`` translation);
``spatial``, the velocity ``v_o = v_obj - w x t`` of the object point at the camera origin (the
spatial twist of ROFT's velocity filter, scored as the reference does with ``v = v_o + w x
t_gt``). Both in the camera optical frame."""
TWIST_LINEARS: tuple[str, ...] = get_args(TwistLinear)

NS_PER_S = 1_000_000_000
_MAX_MM = 65535


def stamp_ns_from_frame(k: int, fps: int) -> int:
    """The time of frame ``k`` at ``fps`` Hz, ``k / fps`` [s], in integer nanoseconds (nearest,
    halves up)."""
    return (2 * int(k) * NS_PER_S + int(fps)) // (2 * int(fps))


def frame_from_stamp_ns(stamp_ns: int, fps: int) -> int:
    """The frame whose time (:func:`stamp_ns_from_frame`) is nearest to ``stamp_ns``."""
    return (2 * int(stamp_ns) * int(fps) + NS_PER_S) // (2 * NS_PER_S)


def time_msg(stamp_ns: int) -> dict[str, int]:
    """A ``builtin_interfaces/Time`` of ``stamp_ns`` [ns]."""
    sec, nanosec = divmod(int(stamp_ns), NS_PER_S)
    return {"sec": sec, "nanosec": nanosec}


def ns_from_time_msg(stamp: Any) -> int:
    """Nanoseconds of a decoded ``builtin_interfaces/Time``."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def header(stamp_ns: int, frame_id: str = CAMERA_FRAME) -> dict[str, Any]:
    """A ``std_msgs/Header``."""
    return {"stamp": time_msg(stamp_ns), "frame_id": frame_id}


def quat_msg_from_matrix(R: F64) -> dict[str, float]:
    """The ``geometry_msgs/Quaternion`` ``(x, y, z, w)`` of the rotation ``R`` (3, 3), w >= 0."""
    x, y, z, w = quat_xyzw_from_wxyz(canonical_quat(quat_from_matrix(R))).tolist()
    return {"x": x, "y": y, "z": z, "w": w}


def matrix_from_quat_msg(q: Any) -> F64:
    """The rotation (3, 3) of a decoded ``geometry_msgs/Quaternion`` (normalised).

    Raises:
        ValueError: a zero or non-finite quaternion.
    """
    return matrix_from_quat(quat_wxyz_from_xyzw([q.x, q.y, q.z, q.w]))


def _image(stamp_ns: int, encoding: str, pixels: np.ndarray) -> dict[str, Any]:
    h, w = pixels.shape[:2]
    data = np.ascontiguousarray(pixels)
    return {
        "header": header(stamp_ns),
        "height": h,
        "width": w,
        "encoding": encoding,
        "is_bigendian": int(data.dtype.byteorder == ">"),
        "step": data.strides[0],
        "data": data.tobytes(),
    }


def rgb_image_msg(stamp_ns: int, rgb: U8) -> dict[str, Any]:
    """An ``rgb8`` ``sensor_msgs/Image`` of ``rgb`` (H, W, 3) uint8."""
    return _image(stamp_ns, "rgb8", np.asarray(rgb, dtype=np.uint8))


def mask_image_msg(stamp_ns: int, mask: NDArray[np.bool_]) -> dict[str, Any]:
    """A ``mono8`` ``sensor_msgs/Image`` of ``mask`` (H, W) bool: 255 on the object, 0 off it."""
    return _image(
        stamp_ns, "mono8", np.where(np.asarray(mask, dtype=bool), 255, 0).astype(np.uint8)
    )


def depth_image_msg(stamp_ns: int, depth_m: F32, encoding: DepthEncoding) -> dict[str, Any]:
    """A REP 118 depth ``sensor_msgs/Image`` of ``depth_m`` (H, W) [m], 0 = no return.

    ``32FC1``: metres, NaN where there is no return. ``16UC1``: millimetres rounded to the
    nearest, 0 where there is no return or the depth does not fit (above 65.535 m).
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    valid = np.isfinite(depth) & (depth > 0)
    if encoding == "32FC1":
        return _image(stamp_ns, encoding, np.where(valid, depth, np.float32(np.nan)))
    if encoding == "16UC1":
        mm = np.rint(np.where(valid, depth, 0).astype(np.float64) * 1e3)
        return _image(stamp_ns, encoding, np.where(mm <= _MAX_MM, mm, 0).astype("<u2"))
    raise ConfigError(f"unknown depth encoding {encoding!r}; expected one of {DEPTH_ENCODINGS}")


_PIXEL_TYPES: Mapping[str, tuple[str, int]] = {
    "rgb8": ("u1", 3),
    "mono8": ("u1", 1),
    "32FC1": ("f4", 1),
    "16UC1": ("u2", 1),
}


def array_from_image_msg(msg: Any) -> np.ndarray:
    """The pixels of a decoded ``sensor_msgs/Image`` of an encoding this module writes: (H, W)
    or (H, W, 3), native byte order.

    Raises:
        DatasetFormatError: another encoding, or a size that does not match.
    """
    if msg.encoding not in _PIXEL_TYPES:
        raise DatasetFormatError(
            f"image encoding {msg.encoding!r} is not one of {sorted(_PIXEL_TYPES)}"
        )
    kind, channels = _PIXEL_TYPES[msg.encoding]
    dtype = np.dtype((">" if msg.is_bigendian else "<") + kind)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if step < w * channels * dtype.itemsize or data.size != h * step:
        raise DatasetFormatError(
            f"{msg.encoding} image of {w}x{h} with step {step} has {data.size} bytes"
        )
    rows = data.reshape(h, step)[:, : w * channels * dtype.itemsize]
    pixels = np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="))
    return pixels.reshape((h, w, channels) if channels > 1 else (h, w))


def depth_m_from_image_msg(msg: Any) -> F32:
    """Depth (H, W) float32 [m], 0 = no return, from a decoded REP 118 depth image."""
    pixels = array_from_image_msg(msg)
    if msg.encoding == "16UC1":
        return (pixels.astype(np.float32) / np.float32(1e3)).astype(np.float32)
    if msg.encoding != "32FC1":
        raise DatasetFormatError(f"not a depth image: encoding {msg.encoding!r}")
    return np.where(np.isfinite(pixels), pixels, 0).astype(np.float32)


def camera_info_msg(stamp_ns: int, intrinsics: CameraIntrinsics) -> dict[str, Any]:
    """A ``sensor_msgs/CameraInfo`` of a pinhole camera without distortion (``plumb_bob``,
    zero coefficients; K and P in OpenCV's convention, pixel centres at integers, as ROS)."""
    fx, fy, cx, cy = intrinsics.fx_px, intrinsics.fy_px, intrinsics.cx_px, intrinsics.cy_px
    return {
        "header": header(stamp_ns),
        "height": intrinsics.height_px,
        "width": intrinsics.width_px,
        "distortion_model": "plumb_bob",
        "d": [0.0] * 5,
        "k": [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        "r": [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        "p": [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        "binning_x": 0,
        "binning_y": 0,
        "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
    }


def pose_stamped_msg(stamp_ns: int, T_cam_obj: F64) -> dict[str, Any]:
    """A ``geometry_msgs/PoseStamped`` of ``T_cam_obj`` (4, 4) [m] in the camera frame."""
    x, y, z = np.asarray(T_cam_obj, dtype=np.float64)[:3, 3].tolist()
    return {
        "header": header(stamp_ns),
        "pose": {
            "position": {"x": x, "y": y, "z": z},
            "orientation": quat_msg_from_matrix(np.asarray(T_cam_obj)[:3, :3]),
        },
    }


def transform_from_pose_msg(pose: Any) -> F64:
    """``T`` (4, 4) [m] of a decoded ``geometry_msgs/Pose``.

    Raises:
        ValueError: a zero or non-finite quaternion, or a non-finite position.
    """
    T = np.eye(4)
    T[:3, :3] = matrix_from_quat_msg(pose.orientation)
    T[:3, 3] = [pose.position.x, pose.position.y, pose.position.z]
    if not np.isfinite(T).all():
        raise ValueError(f"non-finite position {T[:3, 3].tolist()}")
    return T


def tf_msg(stamp_ns: int, T_cam_obj: F64, child_frame: str = GT_OBJECT_FRAME) -> dict[str, Any]:
    """A ``tf2_msgs/TFMessage`` with the one transform camera optical frame -> ``child_frame``."""
    x, y, z = np.asarray(T_cam_obj, dtype=np.float64)[:3, 3].tolist()
    transform = {
        "header": header(stamp_ns),
        "child_frame_id": child_frame,
        "transform": {
            "translation": {"x": x, "y": y, "z": z},
            "rotation": quat_msg_from_matrix(np.asarray(T_cam_obj)[:3, :3]),
        },
    }
    return {"transforms": [transform]}


def twist_stamped_msg(
    stamp_ns: int, linear: F64, angular_radps: F64, frame_id: str = CAMERA_FRAME
) -> dict[str, Any]:
    """A ``geometry_msgs/TwistStamped``: ``linear`` (3,) [m/s] (in the camera frame, see
    :data:`TwistLinear`; in :data:`OBJECT_FRAME`, the body twist) and ``angular_radps`` (3,)
    [rad/s], both expressed in ``frame_id``."""
    (vx, vy, vz), (wx, wy, wz) = np.asarray(linear).tolist(), np.asarray(angular_radps).tolist()
    return {
        "header": header(stamp_ns, frame_id),
        "twist": {"linear": {"x": vx, "y": vy, "z": vz}, "angular": {"x": wx, "y": wy, "z": wz}},
    }


def twist_from_msg(msg: Any) -> tuple[F64, F64]:
    """``(linear [m/s], angular [rad/s])``, each (3,), of a decoded ``TwistStamped``."""
    lin, ang = msg.twist.linear, msg.twist.angular
    return np.array([lin.x, lin.y, lin.z]), np.array([ang.x, ang.y, ang.z])
