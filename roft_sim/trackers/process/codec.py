"""The wire format of the tracker process protocol (docs/process.md): framing, arrays, messages.

A message is a MessagePack map whose ``type`` names it, sent as a 4-byte little-endian unsigned
length followed by that many bytes. Every numpy array travels as a map ``{"dtype", "shape",
"data"}``: ``data`` is the raw C-order little-endian buffer (MessagePack ``bin``). Poses travel
as a position ``t_m`` (3,) and a unit quaternion ``q_wxyz`` (4,), scalar first.

The functions come in pairs: ``<message>_message`` builds a map, ``<record>_from_<message>``
checks one and builds the record. Every check failure raises :class:`ProtocolError` naming the
field, what was received and what was expected. MessagePack (the ``process`` extra) is imported
only when a message is packed or unpacked.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import PluginError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import pq_from_transform, transform_from_pq
from roft_sim.records import (
    Estimate,
    FlowField,
    MaskDetection,
    ObjectModel,
    Observation,
    PoseDetection,
)
from roft_sim.trackers.process.shared import SharedReader, SharedWriter

__all__ = [
    "PROTOCOL_VERSION",
    "HEADER",
    "MAX_MESSAGE_BYTES",
    "QUAT_NORM_TOL",
    "TrackerProcessError",
    "ProtocolError",
    "pack",
    "unpack",
    "array_message",
    "array_from_message",
    "hello_message",
    "context_from_hello",
    "HelloContent",
    "reset_message",
    "initial_from_reset",
    "observation_message",
    "observation_from_message",
    "estimate_message",
    "estimate_from_message",
    "ready_message",
    "check_ready",
    "error_message",
    "bye_message",
    "check_type",
]

PROTOCOL_VERSION = 1
"""Version of the protocol; ``hello`` and ``ready`` carry it and both sides must agree."""
HEADER = struct.Struct("<I")
"""The frame header: the length of the MessagePack payload [bytes], little-endian uint32."""
MAX_MESSAGE_BYTES = 1 << 30
"""Largest payload either side accepts [bytes]."""
QUAT_NORM_TOL = 1e-6
"""Largest accepted ``| |q| - 1 |`` of a quaternion received."""

_DTYPES: dict[str, np.dtype[Any]] = {
    "uint8": np.dtype("u1"),
    "bool": np.dtype("?"),
    "int32": np.dtype("<i4"),
    "int64": np.dtype("<i8"),
    "float32": np.dtype("<f4"),
    "float64": np.dtype("<f8"),
}
_ARRAY_KEYS = frozenset({"dtype", "shape", "data"})
_SHARED_ARRAY_KEYS = frozenset({"dtype", "shape", "shm_offset"})


class TrackerProcessError(PluginError):
    """A tracker process failed: it crashed, hung, sent an error, or broke the protocol. A sweep
    records the failed cell and goes on with the others."""


class ProtocolError(TrackerProcessError):
    """A message broke the protocol (wrong type, missing or unknown field, wrong shape or dtype,
    a non-finite number, a non-unit quaternion, a reply for another frame)."""


def _msgpack() -> Any:
    try:
        import msgpack
    except ImportError as e:
        raise PluginError(
            "the tracker process protocol needs the msgpack package; install the extra: "
            "pip install 'roft_sim[process]'"
        ) from e
    return msgpack


def pack(message: Mapping[str, Any]) -> bytes:
    """The frame of ``message``: header and MessagePack payload."""
    payload: bytes = _msgpack().packb(message, use_bin_type=True)
    if len(payload) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message of {len(payload)} bytes exceeds {MAX_MESSAGE_BYTES}")
    return HEADER.pack(len(payload)) + payload


def unpack(payload: bytes | bytearray | memoryview) -> dict[str, Any]:
    """The map of one payload (the bytes after the header)."""
    msgpack = _msgpack()
    try:
        message = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except (ValueError, msgpack.UnpackException) as e:
        raise ProtocolError(f"payload of {len(payload)} bytes is not MessagePack: {e}") from e
    if not isinstance(message, dict) or not isinstance(message.get("type"), str):
        raise ProtocolError(
            f"message: received a {type(message).__name__}, expected a map with a 'type' string"
        )
    return message


# ----------------------------------------------------------------------------------- checks
def _get(message: Mapping[str, Any], where: str, key: str, *, optional: bool = False) -> Any:
    if key not in message:
        if optional:
            return None
        raise ProtocolError(f"{where}: missing field {key!r} (fields received: {sorted(message)})")
    return message[key]


def _check_keys(message: Mapping[str, Any], where: str, allowed: frozenset[str]) -> None:
    unknown = sorted(set(message) - allowed)
    if unknown:
        raise ProtocolError(
            f"{where}: unknown field {unknown[0]!r}; expected only {sorted(allowed)}"
        )


def check_type(message: Mapping[str, Any], expected: str) -> None:
    """Raises :class:`ProtocolError` unless ``message['type'] == expected``."""
    if message.get("type") != expected:
        raise ProtocolError(
            f"message: received type {message.get('type')!r}, expected {expected!r}"
        )


def _int(message: Mapping[str, Any], where: str, key: str) -> int:
    value = _get(message, where, key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise ProtocolError(f"{where}.{key}: received {value!r}, expected an integer")
    return value


def _float(message: Mapping[str, Any], where: str, key: str) -> float:
    value = _get(message, where, key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ProtocolError(f"{where}.{key}: received {value!r}, expected a finite number")
    return float(value)


def _ids(message: Mapping[str, Any], where: str, key: str) -> tuple[int, ...]:
    value = _get(message, where, key, optional=True)
    if value is None:
        return ()
    if not isinstance(value, list) or not all(
        isinstance(i, int) and not isinstance(i, bool) for i in value
    ):
        raise ProtocolError(f"{where}.{key}: received {value!r}, expected a list of integers")
    return tuple(value)


# ----------------------------------------------------------------------------------- arrays
def array_message(array: NDArray[Any], shared: SharedWriter | None = None) -> dict[str, Any]:
    """``{"dtype", "shape", "data"}`` of ``array`` (data: C-order little-endian bytes), or
    ``{"dtype", "shape", "shm_offset"}`` when ``shared`` takes it."""
    for name, dtype in _DTYPES.items():
        if array.dtype == dtype or array.dtype == dtype.newbyteorder("="):
            data = np.ascontiguousarray(array, dtype=dtype)
            offset = None if shared is None else shared.place(data)
            if offset is not None:
                return {"dtype": name, "shape": list(array.shape), "shm_offset": offset}
            return {"dtype": name, "shape": list(array.shape), "data": data.data}
    raise ProtocolError(f"array of dtype {array.dtype} cannot be sent; expected one of {_DTYPES}")


def array_from_message(
    value: Any,
    field: str,
    *,
    dtype: str,
    shape: Sequence[int | None],
    finite: bool = False,
    shared: SharedReader | None = None,
) -> NDArray[Any]:
    """The array in ``value`` (an array map), checked against ``dtype`` and ``shape``.

    Args:
        value: the received map.
        field: the field's path for error messages (``observation.depth_m``).
        dtype: the expected dtype name (``float32``, ``uint8``, ...).
        shape: the expected shape; None matches any length.
        finite: reject NaN and infinity.
        shared: the shared file, for arrays sent with ``shm_offset``.

    Returns:
        A read-only view of the received buffer (no copy), or a copy out of the shared file.
    """
    keys = frozenset(value) if isinstance(value, dict) else frozenset()
    if keys != _ARRAY_KEYS and (keys != _SHARED_ARRAY_KEYS or shared is None):
        got = sorted(value) if isinstance(value, dict) else type(value).__name__
        raise ProtocolError(f"{field}: received {got}, expected an array map {sorted(_ARRAY_KEYS)}")
    if value["dtype"] != dtype:
        raise ProtocolError(f"{field}: received dtype {value['dtype']!r}, expected {dtype!r}")
    got_shape = value["shape"]
    ok = (
        isinstance(got_shape, list)
        and len(got_shape) == len(shape)
        and all(isinstance(n, int) and n >= 0 for n in got_shape)
        and all(s is None or s == n for s, n in zip(shape, got_shape, strict=False))
    )
    if not ok:
        wanted = "[" + ", ".join("N" if s is None else str(s) for s in shape) + "]"
        raise ProtocolError(f"{field}: received shape {got_shape!r}, expected {wanted}")
    np_dtype = _DTYPES[dtype]
    if "shm_offset" in value:
        assert shared is not None  # checked with the keys
        try:
            array = shared.copy(value["shm_offset"], np_dtype, tuple(got_shape))
        except (TypeError, ValueError) as e:
            raise ProtocolError(
                f"{field}: shm_offset {value['shm_offset']!r} is outside the shared file ({e})"
            ) from None
        return _finite(array, field) if finite else array
    data = value["data"]
    n_bytes = math.prod(got_shape) * np_dtype.itemsize
    if not isinstance(data, bytes | bytearray | memoryview) or len(data) != n_bytes:
        size = len(data) if isinstance(data, bytes | bytearray | memoryview) else "no"
        raise ProtocolError(
            f"{field}: received {size} bytes of data, expected {n_bytes} for shape {got_shape} "
            f"{dtype}"
        )
    array = np.frombuffer(data, dtype=np_dtype).reshape(got_shape)
    return _finite(array, field) if finite else array


def _finite(array: NDArray[Any], field: str) -> NDArray[Any]:
    if not np.isfinite(array).all():
        bad = np.argwhere(~np.isfinite(array))[0].tolist()
        raise ProtocolError(
            f"{field}: received {array[tuple(bad)]} at index {bad}, expected finite numbers"
        )
    return array


# ------------------------------------------------------------------------------------ poses
def _pose_fields(T_cam_obj: NDArray[np.float64]) -> dict[str, Any]:
    t_m, q_wxyz = pq_from_transform(T_cam_obj)
    return {"t_m": array_message(t_m), "q_wxyz": array_message(q_wxyz)}


def _pose_from_fields(message: Mapping[str, Any], where: str) -> NDArray[np.float64]:
    t_m = array_from_message(
        _get(message, where, "t_m"), f"{where}.t_m", dtype="float64", shape=(3,), finite=True
    )
    q = array_from_message(
        _get(message, where, "q_wxyz"), f"{where}.q_wxyz", dtype="float64", shape=(4,), finite=True
    )
    norm = math.sqrt(float(q @ q))
    if abs(norm - 1.0) > QUAT_NORM_TOL:
        raise ProtocolError(
            f"{where}.q_wxyz: received {q.tolist()} of norm {norm:.9g}, expected a unit "
            f"quaternion (w, x, y, z) with | |q| - 1 | <= {QUAT_NORM_TOL:g}"
        )
    return transform_from_pq(t_m, q)


def _vector(message: Mapping[str, Any], where: str, key: str, n: int) -> NDArray[np.float64]:
    value = _get(message, where, key)
    return array_from_message(value, f"{where}.{key}", dtype="float64", shape=(n,), finite=True)


# --------------------------------------------------------------------------------- handshake
_INTRINSICS = ("fx_px", "fy_px", "cx_px", "cy_px", "width_px", "height_px")
_HELLO_KEYS = frozenset({"type", "protocol", "intrinsics", "fps", "object", "seed", "shm"})
_OBJECT_KEYS = frozenset({"name", "vertices_m", "faces", "model_points_m"})


def _check_version(message: Mapping[str, Any], where: str) -> None:
    version = _get(message, where, "protocol")
    if version != PROTOCOL_VERSION:
        raise ProtocolError(
            f"{where}.protocol: received version {version!r}, expected {PROTOCOL_VERSION}; "
            "update the tracker (or roft_sim) so both speak the same version"
        )


def hello_message(
    *,
    intrinsics: CameraIntrinsics,
    fps: int,
    object_model: ObjectModel,
    seed: int,
    shared: SharedWriter | None = None,
) -> dict[str, Any]:
    """The first message to the child: the protocol version, the tracker's context and the
    shared file offered for large arrays (if any)."""
    return {
        "type": "hello",
        "protocol": PROTOCOL_VERSION,
        "intrinsics": {name: getattr(intrinsics, name) for name in _INTRINSICS},
        "fps": int(fps),
        "object": {
            "name": object_model.name,
            "vertices_m": array_message(object_model.vertices_m),
            "faces": array_message(object_model.faces.astype(np.int64)),
            "model_points_m": array_message(object_model.model_points_m),
        },
        "seed": int(seed),
        "shm": None if shared is None else {"path": shared.path, "bytes": shared.size_bytes},
    }


@dataclass(frozen=True, slots=True, kw_only=True)
class HelloContent:
    """What a ``hello`` carries, checked."""

    intrinsics: CameraIntrinsics
    """Camera intrinsics of the observations."""
    fps: int
    """Camera frame rate [Hz]."""
    object_model: ObjectModel
    """The tracked object's mesh and model points (object frame, [m])."""
    seed: int
    """Seed of the tracker's random generator."""
    shm_path: str | None = None
    """The shared file offered for large arrays, or None."""
    shm_bytes: int = 0
    """Its size [bytes]."""


def context_from_hello(message: Mapping[str, Any]) -> HelloContent:
    """Checks a ``hello`` and returns its content."""
    check_type(message, "hello")
    _check_keys(message, "hello", _HELLO_KEYS)
    _check_version(message, "hello")
    raw = _get(message, "hello", "intrinsics")
    if not isinstance(raw, dict):
        raise ProtocolError(f"hello.intrinsics: received {raw!r}, expected a map")
    _check_keys(raw, "hello.intrinsics", frozenset(_INTRINSICS))
    values: dict[str, Any] = {n: _float(raw, "hello.intrinsics", n) for n in _INTRINSICS[:4]}
    values |= {n: _int(raw, "hello.intrinsics", n) for n in _INTRINSICS[4:]}
    obj = _get(message, "hello", "object")
    if not isinstance(obj, dict):
        raise ProtocolError(f"hello.object: received {obj!r}, expected a map")
    _check_keys(obj, "hello.object", _OBJECT_KEYS)
    name = _get(obj, "hello.object", "name")
    if not isinstance(name, str):
        raise ProtocolError(f"hello.object.name: received {name!r}, expected a string")
    model = ObjectModel(
        name=name,
        vertices_m=array_from_message(
            _get(obj, "hello.object", "vertices_m"),
            "hello.object.vertices_m",
            dtype="float64",
            shape=(None, 3),
            finite=True,
        ),
        faces=array_from_message(
            _get(obj, "hello.object", "faces"), "hello.object.faces", dtype="int64", shape=(None, 3)
        ),
        model_points_m=array_from_message(
            _get(obj, "hello.object", "model_points_m"),
            "hello.object.model_points_m",
            dtype="float64",
            shape=(None, 3),
            finite=True,
        ),
    )
    fps = _int(message, "hello", "fps")
    shm = _get(message, "hello", "shm", optional=True)
    if shm is not None and not (
        isinstance(shm, dict)
        and isinstance(shm.get("path"), str)
        and isinstance(shm.get("bytes"), int)
    ):
        raise ProtocolError(f"hello.shm: received {shm!r}, expected nil or {{path, bytes}}")
    return HelloContent(
        intrinsics=CameraIntrinsics(**values),
        fps=fps,
        object_model=model,
        seed=_int(message, "hello", "seed"),
        shm_path=None if shm is None else shm["path"],
        shm_bytes=0 if shm is None else shm["bytes"],
    )


def ready_message(name: str, *, shm: bool = False) -> dict[str, Any]:
    """The child's reply to ``hello`` (``shm``: it takes large arrays through the shared file)
    and ``reset``."""
    return {"type": "ready", "protocol": PROTOCOL_VERSION, "name": name, "shm": shm}


def check_ready(message: Mapping[str, Any], after: str) -> bool:
    """Checks a ``ready`` (the reply to ``after``); returns whether the child takes large
    arrays through the shared file."""
    check_type(message, "ready")
    where = f"ready (reply to {after})"
    _check_keys(message, where, frozenset({"type", "protocol", "name", "shm"}))
    _check_version(message, where)
    shm = _get(message, where, "shm", optional=True)
    if shm is not None and not isinstance(shm, bool):
        raise ProtocolError(f"{where}.shm: received {shm!r}, expected true or false")
    return bool(shm)


def error_message(text: str) -> dict[str, Any]:
    """The child's reply when it cannot go on (it exits after sending it)."""
    return {"type": "error", "message": text}


def bye_message() -> dict[str, Any]:
    """The last message: the child exits with status 0 without replying."""
    return {"type": "bye"}


# ------------------------------------------------------------------------------------ reset
_INITIAL_KEYS = frozenset({"k", "t_m", "q_wxyz", "v_obj_mps", "w_radps"})


def reset_message(initial: Estimate | None) -> dict[str, Any]:
    """Starts a sequence from ``initial`` (pose and velocity at frame ``initial.k``) or none."""
    if initial is None:
        return {"type": "reset", "initial": None}
    return {
        "type": "reset",
        "initial": {
            "k": int(initial.k),
            **_pose_fields(initial.T_cam_obj),
            "v_obj_mps": array_message(np.asarray(initial.v_obj_mps, dtype=np.float64)),
            "w_radps": array_message(np.asarray(initial.w_radps, dtype=np.float64)),
        },
    }


def initial_from_reset(message: Mapping[str, Any]) -> Estimate | None:
    """Checks a ``reset`` and returns its initial estimate (None: start from a detection)."""
    check_type(message, "reset")
    _check_keys(message, "reset", frozenset({"type", "initial"}))
    raw = _get(message, "reset", "initial")
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise ProtocolError(f"reset.initial: received {raw!r}, expected a map or nil")
    _check_keys(raw, "reset.initial", _INITIAL_KEYS)
    return Estimate(
        k=_int(raw, "reset.initial", "k"),
        T_cam_obj=_pose_from_fields(raw, "reset.initial"),
        v_obj_mps=_vector(raw, "reset.initial", "v_obj_mps", 3),
        w_radps=_vector(raw, "reset.initial", "w_radps", 3),
    )


# ------------------------------------------------------------------------------ observation
_OBSERVATION_KEYS = frozenset({"type", "k", "t_s", "rgb", "depth_m", "flow", "poses", "masks"})
_FLOW_KEYS = frozenset({"flow_px", "from_k", "to_k", "grid_px", "valid"})
_POSE_KEYS = frozenset({"capture_k", "arrival_k", "detection_id", "t_m", "q_wxyz"})
_MASK_KEYS = frozenset({"capture_k", "arrival_k", "detection_id", "mask"})


def _optional_array(
    array: NDArray[Any] | None, shared: SharedWriter | None = None
) -> dict[str, Any] | None:
    return None if array is None else array_message(array, shared)


def _flow_message(flow: FlowField | None, shared: SharedWriter | None) -> dict[str, Any] | None:
    if flow is None:
        return None
    return {
        "flow_px": array_message(flow.flow_px, shared),
        "from_k": int(flow.from_k),
        "to_k": int(flow.to_k),
        "grid_px": int(flow.grid_px),
        "valid": _optional_array(flow.valid, shared),
    }


def observation_message(
    observation: Observation, shared: SharedWriter | None = None
) -> dict[str, Any]:
    """Camera frame ``observation.k``: images, flow, and the detections that arrived at it
    (large arrays through ``shared`` when given: it is rewritten from its start)."""
    if shared is not None:
        shared.start()
    return {
        "type": "observation",
        "k": int(observation.k),
        "t_s": float(observation.t_s),
        "rgb": _optional_array(observation.rgb, shared),
        "depth_m": _optional_array(observation.depth_m, shared),
        "flow": _flow_message(observation.flow, shared),
        "poses": [
            {
                "capture_k": int(p.capture_k),
                "arrival_k": int(p.arrival_k),
                "detection_id": int(p.detection_id),
                **_pose_fields(p.T_cam_obj),
            }
            for p in observation.poses
        ],
        "masks": [
            {
                "capture_k": int(m.capture_k),
                "arrival_k": int(m.arrival_k),
                "detection_id": int(m.detection_id),
                "mask": array_message(m.mask, shared),
            }
            for m in observation.masks
        ],
    }


def _flow_from_message(raw: Any, where: str, shared: SharedReader | None) -> FlowField | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise ProtocolError(f"{where}: received {raw!r}, expected a map or nil")
    _check_keys(raw, where, _FLOW_KEYS)
    flow_px = array_from_message(
        _get(raw, where, "flow_px"),
        f"{where}.flow_px",
        dtype="float32",
        shape=(None, None, 2),
        shared=shared,
    )
    valid = _get(raw, where, "valid", optional=True)
    return FlowField(
        flow_px=flow_px,
        from_k=_int(raw, where, "from_k"),
        to_k=_int(raw, where, "to_k"),
        grid_px=_int(raw, where, "grid_px"),
        valid=None
        if valid is None
        else array_from_message(
            valid, f"{where}.valid", dtype="bool", shape=flow_px.shape[:2], shared=shared
        ),
    )


def _list(message: Mapping[str, Any], where: str, key: str) -> list[Any]:
    value = _get(message, where, key)
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise ProtocolError(f"{where}.{key}: received {value!r}, expected a list of maps")
    return value


def _detections(
    message: Mapping[str, Any], hw: tuple[int, int] | None, shared: SharedReader | None
) -> tuple[tuple[PoseDetection, ...], tuple[MaskDetection, ...]]:
    poses = []
    for i, raw in enumerate(_list(message, "observation", "poses")):
        where = f"observation.poses[{i}]"
        _check_keys(raw, where, _POSE_KEYS)
        poses.append(
            PoseDetection(
                capture_k=_int(raw, where, "capture_k"),
                arrival_k=_int(raw, where, "arrival_k"),
                detection_id=_int(raw, where, "detection_id"),
                T_cam_obj=_pose_from_fields(raw, where),
            )
        )
    masks = []
    for i, raw in enumerate(_list(message, "observation", "masks")):
        where = f"observation.masks[{i}]"
        _check_keys(raw, where, _MASK_KEYS)
        mask = array_from_message(
            _get(raw, where, "mask"),
            f"{where}.mask",
            dtype="bool",
            shape=hw or (None, None),
            shared=shared,
        )
        masks.append(
            MaskDetection(
                capture_k=_int(raw, where, "capture_k"),
                arrival_k=_int(raw, where, "arrival_k"),
                detection_id=_int(raw, where, "detection_id"),
                mask=mask,
            )
        )
    return tuple(poses), tuple(masks)


def observation_from_message(
    message: Mapping[str, Any],
    *,
    intrinsics: CameraIntrinsics | None = None,
    shared: SharedReader | None = None,
) -> Observation:
    """Checks an ``observation`` (images at the ``intrinsics`` resolution when given; arrays
    with ``shm_offset`` copied out of ``shared``)."""
    check_type(message, "observation")
    _check_keys(message, "observation", _OBSERVATION_KEYS)
    hw = None if intrinsics is None else (intrinsics.height_px, intrinsics.width_px)
    h, w = hw if hw is not None else (None, None)
    rgb = _get(message, "observation", "rgb")
    depth = _get(message, "observation", "depth_m")
    poses, masks = _detections(message, hw, shared)
    return Observation(
        k=_int(message, "observation", "k"),
        t_s=_float(message, "observation", "t_s"),
        rgb=None
        if rgb is None
        else array_from_message(
            rgb, "observation.rgb", dtype="uint8", shape=(h, w, 3), shared=shared
        ),
        depth_m=None
        if depth is None
        else array_from_message(
            depth, "observation.depth_m", dtype="float32", shape=(h, w), shared=shared
        ),
        flow=_flow_from_message(_get(message, "observation", "flow"), "observation.flow", shared),
        poses=poses,
        masks=masks,
    )


# --------------------------------------------------------------------------------- estimate
_ESTIMATE_KEYS = frozenset(
    {
        "type",
        "k",
        "valid",
        "t_m",
        "q_wxyz",
        "v_obj_mps",
        "w_radps",
        "covariance",
        "spatial_twist",
        "accepted_pose_ids",
        "rejected_pose_ids",
        "dropped_pose_ids",
        "diagnostics",
    }
)


def estimate_message(estimate: Estimate) -> dict[str, Any]:
    """The child's reply to an ``observation``: every :class:`Estimate` field."""
    return {
        "type": "estimate",
        "k": int(estimate.k),
        "valid": bool(estimate.valid),
        **_pose_fields(estimate.T_cam_obj),
        "v_obj_mps": array_message(np.asarray(estimate.v_obj_mps, dtype=np.float64)),
        "w_radps": array_message(np.asarray(estimate.w_radps, dtype=np.float64)),
        "covariance": _optional_array(estimate.covariance),
        "spatial_twist": _optional_array(estimate.spatial_twist),
        "accepted_pose_ids": [int(i) for i in estimate.accepted_pose_ids],
        "rejected_pose_ids": [int(i) for i in estimate.rejected_pose_ids],
        "dropped_pose_ids": [int(i) for i in estimate.dropped_pose_ids],
        "diagnostics": dict(estimate.diagnostics),
    }


def _diagnostics(message: Mapping[str, Any]) -> dict[str, float | int | str]:
    raw = _get(message, "estimate", "diagnostics", optional=True)
    if raw is None:
        return {}
    ok = isinstance(raw, dict) and all(
        isinstance(key, str) and isinstance(v, int | float | str) and not isinstance(v, bool)
        for key, v in raw.items()
    )
    if not ok:
        raise ProtocolError(
            f"estimate.diagnostics: received {raw!r}, expected a map of strings to numbers or "
            "strings"
        )
    return dict(raw)


def estimate_from_message(message: Mapping[str, Any], *, k: int) -> Estimate:
    """Checks the ``estimate`` replied to observation ``k`` and returns it."""
    check_type(message, "estimate")
    _check_keys(message, "estimate", _ESTIMATE_KEYS)
    got_k = _int(message, "estimate", "k")
    if got_k != k:
        raise ProtocolError(
            f"estimate.k: received frame {got_k}, expected {k} (the frame of the observation "
            "it replies to)"
        )
    valid = _get(message, "estimate", "valid")
    if not isinstance(valid, bool):
        raise ProtocolError(f"estimate.valid: received {valid!r}, expected true or false")
    covariance = _get(message, "estimate", "covariance", optional=True)
    twist = _get(message, "estimate", "spatial_twist", optional=True)
    return Estimate(
        k=got_k,
        T_cam_obj=_pose_from_fields(message, "estimate"),
        v_obj_mps=_vector(message, "estimate", "v_obj_mps", 3),
        w_radps=_vector(message, "estimate", "w_radps", 3),
        covariance=None
        if covariance is None
        else array_from_message(
            covariance, "estimate.covariance", dtype="float64", shape=(12, 12), finite=True
        ),
        valid=valid,
        spatial_twist=None if twist is None else _vector(message, "estimate", "spatial_twist", 6),
        accepted_pose_ids=_ids(message, "estimate", "accepted_pose_ids"),
        rejected_pose_ids=_ids(message, "estimate", "rejected_pose_ids"),
        dropped_pose_ids=_ids(message, "estimate", "dropped_pose_ids"),
        diagnostics=_diagnostics(message),
    )
