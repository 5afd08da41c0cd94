"""PNG encoders: pixels round-trip through libpng (OpenCV's decoder, an independent reader) at
every level, and the row filters chosen for speed are the ones written (docs/formats.md, "PNG
compression")."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from roft_sim.datasets.image_files import (
    FAST_PNG_LEVELS,
    decode_png_mask,
    decode_png_rgb,
    decode_png_u16,
    encode_png_mask,
    encode_png_rgb,
    encode_png_u16,
)
from roft_sim.errors import ConfigError


def _row_filters(png: bytes) -> set[int]:
    """The filter type byte of every scanline of a non-interlaced PNG (walked by hand)."""
    pos, idat, width, bytes_per_pixel = 8, b"", 0, 0
    while pos < len(png):
        (length,) = struct.unpack(">I", png[pos : pos + 4])
        kind, body = png[pos + 4 : pos + 8], png[pos + 8 : pos + 8 + length]
        assert (
            zlib.crc32(kind + body)
            == struct.unpack(">I", png[pos + 8 + length : pos + 12 + length])[0]
        )
        if kind == b"IHDR":
            width = struct.unpack(">I", body[:4])[0]
            assert body[12] == 0  # not interlaced
            bytes_per_pixel = {0: 1, 2: 3}[body[9]] * body[8] // 8
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    raw = zlib.decompress(idat)
    stride = 1 + width * bytes_per_pixel
    assert len(raw) % stride == 0
    return set(raw[::stride])


def _textured_rgb(rng: np.random.Generator) -> np.ndarray:
    """Smooth gradients plus noise: rows where libpng's full filter set picks several filters."""
    v, u = np.mgrid[0:96, 0:128].astype(np.float64)
    base = np.stack([u * 2, v * 2 + u, 128 + 60 * np.sin(u / 7) * np.cos(v / 5)], axis=2)
    return np.clip(base + rng.normal(0, 6, base.shape), 0, 255).astype(np.uint8)


def _libpng(data: bytes) -> np.ndarray:
    """Pixels as libpng (OpenCV) decodes them, BGR for colour."""
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert image is not None
    return image


def test_rgb_png_round_trips_with_the_up_filter_at_the_fast_levels():
    rgb = _textured_rgb(np.random.default_rng(0))
    for level in FAST_PNG_LEVELS:
        data = encode_png_rgb(rgb, level=level)
        assert (decode_png_rgb(data, "x.png") == rgb).all()
        assert (_libpng(data)[..., ::-1] == rgb).all()
        assert _row_filters(data) == {2}  # Up on every row (libpng's default mixes all five)
        assert len(data) < 0.8 * rgb.nbytes  # compressed, not stored
    # levels 4-9 go through libpng: its adaptive filters, smaller files on rendered frames
    # (tests/generation); level 0 stores
    level6 = encode_png_rgb(rgb, level=6)
    assert (decode_png_rgb(level6, "x.png") == rgb).all()
    assert len(_row_filters(level6)) > 1
    assert len(encode_png_rgb(rgb, level=0)) > rgb.nbytes


def test_mask_png_round_trips_unfiltered():
    rng = np.random.default_rng(1)
    mask = np.zeros((120, 160), bool)
    mask[30:90, 40:120] = True
    mask[rng.random(mask.shape) < 0.01] ^= True
    for level in (*FAST_PNG_LEVELS, 6):
        data = encode_png_mask(mask, level=level)
        assert (decode_png_mask(data, "m.png") == mask).all()
        assert (_libpng(data) == mask * 255).all()
        assert _row_filters(data) == {0}
        # deflate on 0/255 rows: far below the image's 19 200 raw bytes
        assert len(data) < 0.15 * mask.size


def test_u16_png_round_trips_big_endian_with_the_sub_filter():
    v, u = np.mgrid[0:60, 0:90]
    depth = (4000 + 30 * u + 7 * v + (u * v) % 3).astype(np.uint16)
    depth[10:20, 10:30] = 0  # no depth
    depth[0, 0] = 65535
    for level in FAST_PNG_LEVELS:
        data = encode_png_u16(depth, level=level)
        assert data[24] == 16  # IHDR bit depth
        assert (decode_png_u16(data, "d.png") == depth).all()
        assert (_libpng(data) == depth).all()
        assert _row_filters(data) == {1}
        assert len(data) < 0.5 * depth.nbytes


def test_png_bytes_depend_on_the_image_and_level_only():
    rgb = _textured_rgb(np.random.default_rng(2))
    assert encode_png_rgb(rgb) == encode_png_rgb(rgb.copy())
    assert encode_png_rgb(rgb, level=1) != encode_png_rgb(rgb, level=3)
    # a non-contiguous view encodes as its contiguous copy
    wide = np.concatenate([rgb, rgb], axis=1)
    assert encode_png_rgb(wide[:, ::2]) == encode_png_rgb(np.ascontiguousarray(wide[:, ::2]))


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    h=st.integers(1, 9),
    w=st.integers(1, 9),
    level=st.integers(0, 9),
    seed=st.integers(0, 2**16),
)
def test_every_kind_round_trips_through_libpng_at_every_level_and_size(h, w, level, seed):
    rng = np.random.default_rng(seed)
    rgb = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    mask = rng.random((h, w)) < 0.5
    u16 = rng.integers(0, 65536, (h, w), dtype=np.uint16)
    assert (_libpng(encode_png_rgb(rgb, level=level))[..., ::-1] == rgb).all()
    assert (_libpng(encode_png_mask(mask, level=level)) == mask * 255).all()
    assert (_libpng(encode_png_u16(u16, level=level)) == u16).all()


def test_a_bad_level_or_image_is_refused_before_encoding():
    with pytest.raises(ConfigError, match="integer 0-9"):
        encode_png_rgb(np.zeros((2, 2, 3), np.uint8), level=10)
    with pytest.raises(ValueError, match=r"\(H, W, 3\) uint8"):
        encode_png_rgb(np.zeros((2, 2, 3), np.float32))
    with pytest.raises(ValueError, match=r"\(H, W, 3\) uint8"):
        encode_png_rgb(np.zeros((2, 2, 4), np.uint8))
