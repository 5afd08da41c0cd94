"""PNG encoding of RGB images, masks and 16-bit depth, with errors that name the file.

RGB is ``(H, W, 3)`` uint8 in RGB order in memory; OpenCV's BGR order appears only here. Masks are
``(H, W)`` bool in memory and single-channel 8-bit 0/255 on disk; reading follows ROFT's
binarisation (any value > 1 is foreground), so detector masks with soft, resized edges read as
ROFT reads them. Encoding is deterministic (a given zlib level, no time stamps): the same image
and level give the same bytes on a given processor. The level trades time for size
(docs/formats.md, "PNG compression"): levels 1-3 (1, the default) write the PNG here with one
fixed row filter per kind of image (RGB: Up; masks: none; 16-bit: Sub) and compress it with
ISA-L's deflate (``isal``), about 4x faster than libpng with zlib at equal size; level 0
(stored) and levels 4-9 go through OpenCV's libpng and zlib (adaptive row filters for RGB and
16-bit images: slower, smaller).
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import cast

import cv2
import numpy as np
from isal import isal_zlib
from numpy.typing import NDArray

from roft_sim.errors import ConfigError, DatasetFormatError, located

__all__ = [
    "encode_png_rgb",
    "decode_png_rgb",
    "encode_png_mask",
    "decode_png_mask",
    "encode_png_u16",
    "decode_png_u16",
    "read_file_bytes",
    "PNG_COMPRESSION",
    "check_png_compression",
]

PNG_COMPRESSION = 1
"""Default compression level of the PNGs we write (0-9, zlib's scale); a writer's level is part of
its settings, so a resumed sequence keeps it and its files stay byte-identical."""

MAX_PNG_SIDE_PX = 1 << 15
"""Largest image side accepted in a PNG header (anything larger is treated as corrupt)."""


def check_png_compression(level: object) -> int:
    """``level`` as a zlib level 0-9, or ConfigError saying what was given."""
    if isinstance(level, bool) or not isinstance(level, int) or not 0 <= level <= 9:
        raise ConfigError(
            f"PNG compression level must be an integer 0-9 (0 = none, 1 = fastest, 9 = "
            f"smallest), got {level!r}"
        )
    return level


def read_file_bytes(path: str | Path, what: str) -> bytes:
    """Reads a whole file; a missing file raises DatasetFormatError naming it and ``what``."""
    try:
        with open(path, "rb") as f:
            return f.read()
    except FileNotFoundError:
        raise DatasetFormatError(f"{what} file {located(path)} is missing") from None
    except IsADirectoryError:
        raise DatasetFormatError(f"{what} path {located(path)} is a folder, not a file") from None


FAST_PNG_LEVELS = range(1, 4)
"""Levels written by :func:`_fast_png` (ISA-L's deflate levels 1-3); the others by libpng."""

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_FILTER_NONE, _FILTER_SUB, _FILTER_UP = 0, 1, 2  # PNG row filter types (PNG spec, 9.2)

_MASK_PNG_PARAMS = (
    cv2.IMWRITE_PNG_FILTER,
    cv2.IMWRITE_PNG_FILTER_NONE,
    cv2.IMWRITE_PNG_STRATEGY,
    cv2.IMWRITE_PNG_STRATEGY_RLE,
)
"""0/255 masks at levels 0 and 4-9 (libpng): no row filter and zlib's run-length strategy, which
suit long runs of two values (zlib's run-length coder ignores the level, so there the level
changes nothing but level 0, stored)."""


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    """One PNG chunk: length, type, body, CRC-32 of type and body (PNG spec, 5.3)."""
    crc = zlib.crc32(body, zlib.crc32(kind))
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)


def _filtered_scanlines(rows: NDArray[np.uint8], row_filter: int, bpp: int) -> NDArray[np.uint8]:
    """``(H, 1 + N)`` PNG scanlines of ``(H, N)`` row bytes: each row's filter type byte, then its
    bytes filtered (modulo 256) with None, Sub (minus the byte ``bpp`` to the left) or Up (minus
    the byte above; the first row's "above" is zeros, so it is stored as it is)."""
    h, n = rows.shape
    out = np.empty((h, n + 1), dtype=np.uint8)
    out[:, 0] = row_filter
    if row_filter == _FILTER_NONE:
        out[:, 1:] = rows
    elif row_filter == _FILTER_SUB:
        out[:, 1 : 1 + bpp] = rows[:, :bpp]
        np.subtract(rows[:, bpp:], rows[:, :-bpp], out=out[:, 1 + bpp :])
    else:
        out[0, 1:] = rows[0]
        np.subtract(rows[1:], rows[:-1], out=out[1:, 1:])
    return out


def _fast_png(image: NDArray[np.uint8] | NDArray[np.uint16], level: int, row_filter: int) -> bytes:
    """PNG bytes of a grey ``(H, W)`` uint8/uint16 or RGB ``(H, W, 3)`` uint8 image: one row
    filter for every row, one IDAT chunk compressed by ISA-L at ``level`` (1-3)."""
    h, w = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    depth_bits = 8 * image.dtype.itemsize
    # PNG samples are big-endian
    samples = image.astype(">u2", copy=False) if depth_bits == 16 else image
    rows = np.ascontiguousarray(samples).view(np.uint8).reshape(h, -1)
    colour_type = {1: 0, 3: 2}[channels]  # grey, truecolour
    header = struct.pack(">IIBBBBB", w, h, depth_bits, colour_type, 0, 0, 0)
    scanlines = _filtered_scanlines(rows, row_filter, channels * image.dtype.itemsize)
    return b"".join(
        (
            _PNG_SIGNATURE,
            _png_chunk(b"IHDR", header),
            _png_chunk(b"IDAT", isal_zlib.compress(scanlines, level)),
            _png_chunk(b"IEND", b""),
        )
    )


def _encode(
    image: NDArray[np.uint8] | NDArray[np.uint16],
    level: int,
    row_filter: int,
    libpng_extra: tuple[int, ...] = (),
) -> bytes:
    """PNG bytes of a grey ``(H, W)`` or RGB ``(H, W, 3)`` image at ``level``: levels 1-3 by
    :func:`_fast_png` with ``row_filter``, the others by libpng (OpenCV; RGB turned to its BGR
    order here) with ``libpng_extra`` imwrite parameters."""
    if check_png_compression(level) in FAST_PNG_LEVELS:
        return _fast_png(image, level, row_filter)
    opencv_order = (
        cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    )
    params = [cv2.IMWRITE_PNG_COMPRESSION, level, *libpng_extra]
    ok, buf = cv2.imencode(".png", opencv_order, params)
    if not ok:  # pragma: no cover - OpenCV fails only on unsupported dtypes, checked by callers
        raise ValueError(f"OpenCV could not encode a {image.dtype} {image.shape} image as PNG")
    return buf.tobytes()


def _decode(
    data: bytes, path: str | Path, what: str, shape: tuple[int, int] | None = None
) -> np.ndarray:
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise DatasetFormatError(
            f"{what} file {located(path)} is not a PNG (it starts with {data[:8]!r})"
        )
    # Check the size in the header BEFORE decoding: a corrupt header could announce a huge
    # image that takes seconds and gigabytes to decode.
    if len(data) < 24 or data[12:16] != b"IHDR":
        raise DatasetFormatError(f"{what} file {located(path)} has no PNG IHDR header")
    width, height = struct.unpack(">II", data[16:24])
    if not (0 < width <= MAX_PNG_SIDE_PX and 0 < height <= MAX_PNG_SIDE_PX):
        raise DatasetFormatError(
            f"{what} file {located(path)}: header size {width}x{height} is not plausible"
        )
    if shape is not None and (height, width) != tuple(shape):
        raise DatasetFormatError(
            f"{what} {located(path)} is {width}x{height} px; the camera is {shape[1]}x{shape[0]}"
        )
    data = _checked_png_chunks(data, path, what)
    try:
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    except cv2.error as e:
        raise DatasetFormatError(f"{what} file {located(path)} is a corrupt PNG: {e}") from None
    if image is None:
        raise DatasetFormatError(f"{what} file {located(path)} is a corrupt or truncated PNG")
    return image


def _checked_png_chunks(data: bytes, path: str | Path, what: str) -> bytes:
    """Walks the PNG chunks (length, type, CRC) up to IEND and returns the bytes up to it.

    OpenCV can spend seconds on some corrupt files (seen while fuzzing); a structural check with
    CRCs first rejects them in microseconds and names the damaged chunk.
    """
    pos = 8
    while True:
        if pos + 12 > len(data):
            raise DatasetFormatError(
                f"{what} file {located(path)} is truncated (PNG chunk at byte {pos} incomplete)"
            )
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind = data[pos + 4 : pos + 8]
        end = pos + 12 + length
        if end > len(data):
            raise DatasetFormatError(
                f"{what} file {located(path)} is truncated: chunk {kind!r} at byte {pos} needs "
                f"{length} bytes"
            )
        (crc,) = struct.unpack(">I", data[end - 4 : end])
        if zlib.crc32(data[pos + 4 : end - 4]) != crc:
            raise DatasetFormatError(
                f"{what} file {located(path)} is corrupt: CRC mismatch in chunk {kind!r} at byte "
                f"{pos}"
            )
        if kind == b"IEND":
            return data[:end]
        pos = end


def encode_png_rgb(rgb: NDArray[np.uint8], *, level: int = PNG_COMPRESSION) -> bytes:
    """PNG bytes of an ``(H, W, 3)`` uint8 RGB image (stored as 8-bit colour) at ``level``."""
    if rgb.dtype != np.uint8 or rgb.ndim != 3 or rgb.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) uint8 RGB image, got {rgb.dtype} {rgb.shape}")
    # libpng: its adaptive row filters, zlib's default strategy
    return _encode(rgb, level, _FILTER_UP)


def decode_png_rgb(
    data: bytes, path: str | Path, *, shape: tuple[int, int] | None = None
) -> NDArray[np.uint8]:
    """``(H, W, 3)`` uint8 RGB from PNG bytes (grey and RGBA are converted; 16-bit is refused).

    Args:
        data: the file's bytes.
        path: the file, for messages.
        shape: expected ``(H, W)``, or None.
    """
    image = _decode(data, path, "rgb image", shape)
    if image.dtype != np.uint8:
        raise DatasetFormatError(
            f"rgb image {located(path)} has {image.dtype} pixels; expected 8-bit colour"
        )
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    else:
        image = np.ascontiguousarray(image[..., ::-1])
    _check_shape(image.shape[:2], shape, path, "rgb image")
    return cast(NDArray[np.uint8], image)  # uint8 checked above; cv2 types results as any dtype


def encode_png_mask(mask: NDArray[np.bool_], *, level: int = PNG_COMPRESSION) -> bytes:
    """PNG bytes of an ``(H, W)`` bool mask as single-channel 8-bit 0/255 at ``level``."""
    grey = np.asarray(mask, dtype=bool).view(np.uint8) * np.uint8(255)
    return _encode(grey, level, _FILTER_NONE, _MASK_PNG_PARAMS)


def decode_png_mask(
    data: bytes, path: str | Path, *, shape: tuple[int, int] | None = None
) -> NDArray[np.bool_]:
    """``(H, W)`` bool mask from an 8-bit PNG: True where the value is > 1 (ROFT's threshold).

    Colour masks are converted to grey first, as ROFT does.
    """
    image = _decode(data, path, "mask", shape)
    if image.dtype != np.uint8:
        raise DatasetFormatError(
            f"mask {located(path)} has {image.dtype} pixels; expected 8-bit 0/255"
        )
    if image.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        image = cv2.cvtColor(image, code)
    _check_shape(image.shape[:2], shape, path, "mask")
    return image > 1


def encode_png_u16(image: NDArray[np.uint16], *, level: int = PNG_COMPRESSION) -> bytes:
    """PNG bytes of an ``(H, W)`` uint16 image (BOP depth) at ``level``."""
    if image.dtype != np.uint16 or image.ndim != 2:
        raise ValueError(f"expected an (H, W) uint16 image, got {image.dtype} {image.shape}")
    return _encode(image, level, _FILTER_SUB)  # libpng: its default filters


def decode_png_u16(
    data: bytes, path: str | Path, *, shape: tuple[int, int] | None = None
) -> NDArray[np.uint16]:
    """``(H, W)`` uint16 image from a 16-bit single-channel PNG."""
    image = _decode(data, path, "16-bit depth image", shape)
    if image.dtype != np.uint16 or image.ndim != 2:
        raise DatasetFormatError(
            f"depth image {located(path)} is {image.dtype} with shape {image.shape}; expected "
            "a single-channel 16-bit PNG"
        )
    _check_shape(image.shape, shape, path, "depth image")
    return image


def _check_shape(
    got: tuple[int, ...], want: tuple[int, int] | None, path: str | Path, what: str
) -> None:
    if want is not None and tuple(got) != tuple(want):
        raise DatasetFormatError(
            f"{what} {located(path)} is {got[1]}x{got[0]} px; the camera is {want[1]}x{want[0]}"
        )
