"""PNG encoders: pixels round-trip, and the row filters / zlib strategy chosen for speed are the
ones written (docs/formats.md, "PNG compression")."""

from __future__ import annotations

import struct
import zlib

import numpy as np

from roft_sim.datasets.image_files import (
    decode_png_mask,
    decode_png_rgb,
    encode_png_mask,
    encode_png_rgb,
)


def _row_filters(png: bytes) -> set[int]:
    """The filter type byte of every scanline of an 8-bit, non-interlaced PNG."""
    pos, idat, width, channels = 8, b"", 0, 0
    while pos < len(png):
        (length,) = struct.unpack(">I", png[pos : pos + 4])
        kind, body = png[pos + 4 : pos + 8], png[pos + 8 : pos + 8 + length]
        if kind == b"IHDR":
            width = struct.unpack(">I", body[:4])[0]
            assert body[8] == 8 and body[12] == 0  # bit depth 8, not interlaced
            channels = {0: 1, 2: 3}[body[9]]
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    raw = zlib.decompress(idat)
    stride = 1 + width * channels
    assert len(raw) % stride == 0
    return set(raw[::stride])


def _textured_rgb(rng: np.random.Generator) -> np.ndarray:
    """Smooth gradients plus noise: rows where libpng's full filter set picks several filters."""
    v, u = np.mgrid[0:96, 0:128].astype(np.float64)
    base = np.stack([u * 2, v * 2 + u, 128 + 60 * np.sin(u / 7) * np.cos(v / 5)], axis=2)
    return np.clip(base + rng.normal(0, 6, base.shape), 0, 255).astype(np.uint8)


def test_rgb_png_round_trips_with_the_up_filter():
    rgb = _textured_rgb(np.random.default_rng(0))
    data = encode_png_rgb(rgb)
    assert (decode_png_rgb(data, "x.png") == rgb).all()
    assert _row_filters(data) == {2}  # Up on every row (libpng's default mixes all five)
    # zlib's run-length coder ignores the level: other levels keep libpng's adaptive filters
    # (on rendered frames a higher level then gives smaller files: tests/generation)
    level3 = encode_png_rgb(rgb, level=3)
    assert (decode_png_rgb(level3, "x.png") == rgb).all()
    assert len(_row_filters(level3)) > 1


def test_mask_png_round_trips_unfiltered_and_run_length_coded():
    rng = np.random.default_rng(1)
    mask = np.zeros((120, 160), bool)
    mask[30:90, 40:120] = True
    mask[rng.random(mask.shape) < 0.01] ^= True
    data = encode_png_mask(mask)
    assert (decode_png_mask(data, "m.png") == mask).all()
    assert _row_filters(data) == {0}
    # zlib's run-length strategy on 0/255 rows: far below the image's 19 200 raw bytes
    assert len(data) < 0.15 * mask.size
