"""Fast-YCB file encodings: depth and flow ``.float``, pose rows, ``cam_K.json``, ``data.txt``.

Binary layouts (native little-endian, no padding), as ROFT's readers expect:

- depth ``.float``: ``uint64 width, uint64 height``, then ``height*width`` float32 [m], row-major.
- flow ``.float``: ``int32 cv_type, uint64 cols, uint64 rows``, then ``rows*cols`` interleaved
  ``(du, dv)``: float32 px for ``CV_32FC2`` (13), int16 S10.5 (divide by 32) for ``CV_16SC2`` (11).

Numbers in text files are written in the shortest form that reads back to the same float64
(``repr``), so poses round-trip exactly through the text; integral values drop the ``.0``.
Every decoder checks sizes against the header before reading, so a corrupt header can neither
allocate huge arrays nor hang, and raises :class:`DatasetFormatError` naming the file.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Iterable
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.datasets.frames import flow_grid_shape
from roft_sim.errors import DatasetFormatError, located
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import axis_angle_from_matrix, matrix_from_axis_angle

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

__all__ = [
    "CV_16SC2",
    "CV_32FC2",
    "S10_5_SCALE",
    "MAX_IMAGE_SIDE_PX",
    "encode_depth_float",
    "decode_depth_float",
    "encode_flow_float",
    "decode_flow_float",
    "flow_grid_px",
    "format_number",
    "format_row",
    "format_rows",
    "parse_rows",
    "pose_row_from_transform",
    "transforms_from_pose_rows",
    "encode_cam_k_json",
    "decode_cam_k_json",
    "encode_data_txt_row",
    "AXIS_NORM_TOLERANCE",
]

CV_16SC2 = 11
"""OpenCV type code of two-channel int16 (NVOF S10.5 fixed-point flow)."""
CV_32FC2 = 13
"""OpenCV type code of two-channel float32 flow."""
S10_5_SCALE = 32.0
"""S10.5 fixed point: 5 fractional bits, so stored value = flow [px] * 32."""
MAX_IMAGE_SIDE_PX = 1 << 16
"""Largest image side a header may announce (anything larger is treated as corrupt)."""
AXIS_NORM_TOLERANCE = 1e-3
"""Largest | |axis| - 1 | the readers accept in axis-angle rows (the axis is then normalised)."""

_DEPTH_HEADER = struct.Struct("<QQ")
_FLOW_HEADER = struct.Struct("<iQQ")


def _check_side(value: int, what: str, path: str | Path) -> None:
    if not 0 < value <= MAX_IMAGE_SIDE_PX:
        raise DatasetFormatError(
            f"{located(path)}: header {what} = {value} is not a plausible image size "
            f"(1..{MAX_IMAGE_SIDE_PX}); the file is corrupt or not in this format"
        )


def encode_depth_float(depth_m: F32) -> bytes:
    """Fast-YCB depth file bytes of an ``(H, W)`` float32 z-depth image [m]."""
    h, w = depth_m.shape
    return _DEPTH_HEADER.pack(w, h) + np.ascontiguousarray(depth_m, dtype="<f4").tobytes()


def decode_depth_float(
    data: bytes, path: str | Path, *, shape: tuple[int, int] | None = None
) -> F32:
    """``(H, W)`` float32 z-depth [m] from Fast-YCB depth bytes; values <= 0 become 0.

    Args:
        data: the file's bytes.
        path: the file, for messages.
        shape: expected ``(H, W)`` (the camera's), or None.

    Raises:
        DatasetFormatError: short header, implausible or mismatched size, wrong byte count, or
            NaN/inf values.
    """
    if len(data) < _DEPTH_HEADER.size:
        raise DatasetFormatError(
            f"depth file {located(path)} has {len(data)} bytes, fewer than its 16-byte header "
            "(uint64 width, uint64 height)"
        )
    w, h = _DEPTH_HEADER.unpack_from(data)
    _check_side(w, "width", path)
    _check_side(h, "height", path)
    want = _DEPTH_HEADER.size + 4 * w * h
    if len(data) != want:
        raise DatasetFormatError(
            f"depth file {located(path)} has {len(data)} bytes; its header says {w}x{h} "
            f"float32, i.e. {want} bytes (the file is truncated or the header is wrong)"
        )
    if shape is not None and (h, w) != tuple(shape):
        raise DatasetFormatError(
            f"depth file {located(path)} is {w}x{h}; the camera is {shape[1]}x{shape[0]}"
        )
    depth: F32 = np.frombuffer(data, dtype="<f4", offset=_DEPTH_HEADER.size).reshape(h, w)
    if not np.isfinite(depth).all():
        bad = np.argwhere(~np.isfinite(depth))[0]
        raise DatasetFormatError(
            f"depth file {located(path)} has NaN/inf values (first at row {bad[0]}, column "
            f"{bad[1]}); depth must be finite metres, 0 = no measurement"
        )
    return np.maximum(depth, np.float32(0.0)).astype(np.float32, copy=False)


def encode_flow_float(flow_px: F32, encoding: str) -> bytes:
    """Fast-YCB flow file bytes of an ``(rows, cols, 2)`` float32 flow [px].

    Args:
        flow_px: the flow field on its grid.
        encoding: ``float32`` (CV_32FC2, exact) or ``s10.5`` (CV_16SC2: rounded to 1/32 px).

    Raises:
        ValueError: unknown encoding, or a vector outside the S10.5 range (|flow| >= 1024 px).
    """
    rows, cols, _ = flow_px.shape
    if encoding == "float32":
        body = np.ascontiguousarray(flow_px, dtype="<f4").tobytes()
        cv_type = CV_32FC2
    elif encoding == "s10.5":
        q = np.rint(flow_px.astype(np.float64) * S10_5_SCALE)
        if q.size and (q.min() < -32768 or q.max() > 32767):
            raise ValueError(
                f"flow of {np.abs(flow_px).max():.1f} px does not fit S10.5 (|flow| < 1024 px); "
                "store this set as float32"
            )
        body = q.astype("<i2").tobytes()
        cv_type = CV_16SC2
    else:
        raise ValueError(f"unknown flow encoding {encoding!r}; expected 'float32' or 's10.5'")
    return _FLOW_HEADER.pack(cv_type, cols, rows) + body


def flow_grid_px(rows: int, cols: int, image_shape: tuple[int, int], path: str | Path) -> int:
    """Grid cell size [px] of a ``rows x cols`` flow over an ``(H, W)`` image.

    ``grid = ceil(W / cols)``, as NVOF sizes its output; it must also give ``rows``.
    """
    h, w = image_shape
    grid = -(-w // cols)
    if grid < 1 or flow_grid_shape(h, w, grid) != (rows, cols):
        raise DatasetFormatError(
            f"flow file {located(path)} is {cols}x{rows}, which is no whole-pixel grid over the "
            f"{w}x{h} image (expected e.g. {w}x{h} or {flow_grid_shape(h, w, 4)[1]}x"
            f"{flow_grid_shape(h, w, 4)[0]} for a 4-px grid)"
        )
    return grid


def decode_flow_float(data: bytes, path: str | Path) -> tuple[F32, int]:
    """Flow ``(rows, cols, 2)`` float32 [px] and its OpenCV type from Fast-YCB flow bytes.

    S10.5 values are divided by 32 (exact in float32).

    Raises:
        DatasetFormatError: short header, unknown type, implausible size, wrong byte count, or
            NaN/inf values.
    """
    if len(data) < _FLOW_HEADER.size:
        raise DatasetFormatError(
            f"flow file {located(path)} has {len(data)} bytes, fewer than its 20-byte header "
            "(int32 cv_type, uint64 cols, uint64 rows)"
        )
    cv_type, cols, rows = _FLOW_HEADER.unpack_from(data)
    if cv_type not in (CV_16SC2, CV_32FC2):
        raise DatasetFormatError(
            f"flow file {located(path)} has OpenCV type {cv_type}; expected {CV_32FC2} "
            f"(CV_32FC2, float px) or {CV_16SC2} (CV_16SC2, S10.5 fixed point)"
        )
    _check_side(cols, "cols", path)
    _check_side(rows, "rows", path)
    item = 4 if cv_type == CV_32FC2 else 2
    want = _FLOW_HEADER.size + 2 * item * rows * cols
    if len(data) != want:
        raise DatasetFormatError(
            f"flow file {located(path)} has {len(data)} bytes; its header says {cols}x{rows} "
            f"of type {cv_type}, i.e. {want} bytes (truncated file or wrong header)"
        )
    if cv_type == CV_32FC2:
        flow = np.frombuffer(data, dtype="<f4", offset=_FLOW_HEADER.size).reshape(rows, cols, 2)
        if not np.isfinite(flow).all():
            raise DatasetFormatError(f"flow file {located(path)} has NaN/inf vectors")
        flow = flow.astype(np.float32)  # native-endian, writeable copy
    else:
        raw = np.frombuffer(data, dtype="<i2", offset=_FLOW_HEADER.size).reshape(rows, cols, 2)
        flow = raw.astype(np.float32) / np.float32(S10_5_SCALE)
    return flow, int(cv_type)


def _number_text(shortest: str) -> str:
    """A finite float's text from its ``repr`` (the shortest text that reads back to the same
    float64): ``1.0`` -> ``1``, ``-0.0`` -> ``0``."""
    if shortest in ("0.0", "-0.0"):
        return "0"
    return shortest[:-2] if shortest.endswith(".0") else shortest


def format_number(x: float) -> str:
    """Shortest text that reads back to the same float64; ``1.0`` -> ``1``, ``-0.0`` -> ``0``."""
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"cannot write the non-finite number {x} to a dataset text file")
    return _number_text(repr(x))


def format_row(values: Iterable[float]) -> str:
    """One text row: numbers separated by single spaces (no newline)."""
    return " ".join(format_number(v) for v in values)


def format_rows(rows: ArrayLike) -> str:
    """Whole rows of numbers as text: one line per row, each as :func:`format_row` writes it and
    ended by a newline; the same text as joining :func:`format_row` row by row, formatted in one
    pass (a 2620-point ``points.xyz`` in 15 ms instead of 23:
    the shortest-repr formatting itself is most of what is left).

    Args:
        rows: (N, M) numbers (anything ``numpy.asarray`` reads as float64).

    Raises:
        ValueError: ``rows`` is not 2-D, or holds NaN or inf (the message gives the first).
    """
    a = np.asarray(rows, dtype=np.float64)
    if a.ndim != 2:
        raise ValueError(f"need (N, M) rows of numbers, got an array of shape {a.shape}")
    finite = np.isfinite(a)
    if not finite.all():
        i, j = np.argwhere(~finite)[0]
        raise ValueError(
            f"cannot write the non-finite number {a[i, j]} (row {i}, column {j}) to a dataset "
            "text file"
        )
    texts = list(map(_number_text, map(repr, a.ravel().tolist())))
    n, m = int(a.shape[0]), int(a.shape[1])
    if m == 0:
        return "\n" * n
    return "".join(" ".join(texts[k : k + m]) + "\n" for k in range(0, n * m, m))


def parse_rows(text: str, path: Path, n_cols: int, *, n_rows: int | None = None) -> F64:
    """``(N, n_cols)`` float64 from whitespace-separated rows (empty lines only at the end).

    Raises:
        DatasetFormatError: a row with the wrong number of values, a non-number, NaN/inf, or
            (when ``n_rows`` is given) a different number of rows; the message names the line.
    """
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    out = np.empty((len(lines), n_cols))
    for i, line in enumerate(lines):
        fields = line.split()
        if len(fields) != n_cols:
            raise DatasetFormatError(
                f"{located(path, i + 1)}: expected {n_cols} numbers, got {len(fields)} "
                f"({line.strip()[:80]!r})"
            )
        try:
            out[i] = [float(f) for f in fields]
        except ValueError:
            raise DatasetFormatError(
                f"{located(path, i + 1)}: not a number in {line.strip()[:80]!r}"
            ) from None
        if not np.isfinite(out[i]).all():
            raise DatasetFormatError(f"{located(path, i + 1)}: NaN or inf in {line.strip()!r}")
    if n_rows is not None and len(lines) != n_rows:
        raise DatasetFormatError(
            f"{located(path)} has {len(lines)} rows; the sequence has {n_rows} frames"
        )
    return out


def pose_row_from_transform(T: F64) -> list[float]:
    """Seven numbers ``x y z ax ay az angle`` (metres, unit axis, angle [rad] in [0, pi])."""
    return [*np.asarray(T)[:3, 3], *axis_angle_from_matrix(np.asarray(T)[:3, :3])]


def transforms_from_pose_rows(
    rows: F64, path: Path, *, allow_zero_rows: bool, first_line: int = 1, t_col: int = 0
) -> tuple[F64, NDArray[np.bool_]]:
    """Transforms ``(N, 4, 4)`` and validity ``(N,)`` from rows holding ``x y z ax ay az angle``
    in columns ``t_col .. t_col + 6``.

    A row that is all zeros is a miss when ``allow_zero_rows`` (identity transform, valid False).
    An all-zero axis with a zero angle is the identity rotation (ROFT's capture tool writes
    camera poses that way). Other axes must be unit within :data:`AXIS_NORM_TOLERANCE`.

    Raises:
        DatasetFormatError: a non-unit axis, naming the line.
    """
    p = rows[:, t_col : t_col + 3]
    aa = rows[:, t_col + 3 : t_col + 7]
    miss = np.all(rows[:, t_col : t_col + 7] == 0.0, axis=1)
    if not allow_zero_rows and miss.any():
        line = int(np.argmax(miss)) + first_line
        raise DatasetFormatError(
            f"{located(path, line)}: a pose row of seven zeros (a detector miss) is not allowed "
            "in this file"
        )
    norm = np.linalg.norm(aa[:, :3], axis=1)
    identity = (norm == 0.0) & (aa[:, 3] == 0.0)
    bad = ~identity & ~miss & (np.abs(norm - 1.0) > AXIS_NORM_TOLERANCE)
    if bad.any():
        i = int(np.argmax(bad))
        raise DatasetFormatError(
            f"{located(path, i + first_line)}: rotation axis ({', '.join(map(str, aa[i, :3]))}) "
            f"has norm {norm[i]:.6g}; axis-angle rows need a unit axis, angle last"
        )
    aa = aa.copy()
    aa[identity | miss] = [1.0, 0.0, 0.0, 0.0]
    T = transform_from_rt(matrix_from_axis_angle(aa), p)
    T[miss] = np.eye(4)
    return T, ~miss


def encode_cam_k_json(intrinsics: CameraIntrinsics, *, name: str = "roft_sim") -> str:
    """``cam_K.json`` text, one key per line in the reference order (ROFT's scripts read fx, fy,
    cx, cy from lines 5 to 8)."""
    data = {
        "name": name,
        "width": intrinsics.width_px,
        "height": intrinsics.height_px,
        "fx": intrinsics.fx_px,
        "fy": intrinsics.fy_px,
        "cx": intrinsics.cx_px,
        "cy": intrinsics.cy_px,
    }
    return json.dumps(data, indent=4) + "\n"


def decode_cam_k_json(text: str, path: Path) -> CameraIntrinsics:
    """Intrinsics from ``cam_K.json`` text; values may be numbers or strings (real Fast-YCB).

    Raises:
        DatasetFormatError: invalid JSON, a missing key, or a value that is not a number.
    """
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise DatasetFormatError(f"{located(path, e.lineno)} is not valid JSON: {e.msg}") from None
    if not isinstance(data, dict):
        raise DatasetFormatError(f"{located(path)} must hold a JSON object, got {type(data)}")
    values = {}
    for key in ("fx", "fy", "cx", "cy", "width", "height"):
        if key not in data:
            raise DatasetFormatError(
                f"{located(path)} has no {key!r}; expected keys name, width, height, fx, fy, cx, "
                f"cy (found {sorted(data)})"
            )
        try:
            if isinstance(data[key], bool):  # float(True) == 1.0: not a number here
                raise TypeError
            values[key] = float(data[key])
        except (TypeError, ValueError):
            raise DatasetFormatError(
                f"{located(path)}: {key} = {data[key]!r} is not a number"
            ) from None
    for key in ("width", "height"):
        if not values[key].is_integer() or values[key] <= 0:
            raise DatasetFormatError(
                f"{located(path)}: {key} = {data[key]!r} must be a positive whole number of px"
            )
    try:
        return CameraIntrinsics(
            fx_px=values["fx"],
            fy_px=values["fy"],
            cx_px=values["cx"],
            cy_px=values["cy"],
            width_px=int(values["width"]),
            height_px=int(values["height"]),
        )
    except ValueError as e:
        raise DatasetFormatError(f"{located(path)}: invalid intrinsics: {e}") from None


def encode_data_txt_row(t_s: float, T_world_cam: F64) -> str:
    """One ``data.txt`` row: ``t_rgb t_depth x y z ax ay az angle`` (camera pose in the world)."""
    return format_row([t_s, t_s, *pose_row_from_transform(T_world_cam)])
