"""Procedural, seamlessly tiling textures for the table and the background.

Optical flow (ground truth checks, DIS, ROFT's flow) needs texture everywhere and at every scale,
so each style mixes band-limited noise at several scales, structure (planks, stones, threads,
shapes) and a fine grain. Noise is made periodic by filtering white noise in the Fourier domain
and shapes are drawn at their wrapped positions too, so a texture repeats without seams (one known
exception, kept so that rendered scenes stay as measured: ``posters`` draws its filled polygons
afresh at each wrapped copy, so a few rows show a seam; see docs/scenarios.md).
Everything is a pure function of ``rng``.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]

__all__ = ["periodic_noise", "procedural_texture"]


def periodic_noise(
    size_px: int, rng: np.random.Generator, *, sigma_px: tuple[float, float] | float
) -> F64:
    """Seamlessly tiling Gaussian-filtered white noise ``(S, S)``, zero mean, unit std.

    Args:
        size_px: side S [px].
        rng: noise source.
        sigma_px: blur standard deviation [px], one value or (along x, along y) for anisotropic
            (streaky) noise.
    """
    sx, sy = (sigma_px, sigma_px) if np.isscalar(sigma_px) else sigma_px  # type: ignore[misc]
    k = np.fft.fftfreq(size_px)
    ky, kx = np.meshgrid(k, k, indexing="ij")
    gain = np.exp(-2.0 * np.pi**2 * ((kx * sx) ** 2 + (ky * sy) ** 2))
    field = np.fft.ifft2(np.fft.fft2(rng.standard_normal((size_px, size_px))) * gain).real
    field -= field.mean()
    std = field.std()
    return field / std if std > 0 else field


def _fractal(size_px: int, rng: np.random.Generator, scales_px: tuple[float, ...]) -> F64:
    total = np.zeros((size_px, size_px))
    for i, s in enumerate(scales_px):
        total += 0.6**i * periodic_noise(size_px, rng, sigma_px=s)
    return total / float(total.std())


def _palette(values: F64, colours: F64) -> F64:
    """Maps values to RGB by piecewise-linear interpolation through ``colours`` (N, 3) in [0, 1]."""
    lo, hi = np.percentile(values, [1, 99])
    t = np.clip((values - lo) / max(hi - lo, 1e-12), 0, 1) * (len(colours) - 1)
    i = np.minimum(t.astype(int), len(colours) - 2)
    f = (t - i)[..., None]
    rgb: F64 = colours[i] * (1 - f) + colours[i + 1] * f
    return rgb


def _wrapped_offsets(size_px: int) -> list[tuple[int, int]]:
    return [(dx, dy) for dx in (-size_px, 0, size_px) for dy in (-size_px, 0, size_px)]


def _wood(size: int, rng: np.random.Generator) -> F64:
    planks = int(rng.integers(3, 6))
    grain = periodic_noise(size, rng, sigma_px=(size / 6, 1.5))
    warp = periodic_noise(size, rng, sigma_px=size / 10)
    y = np.arange(size)[:, None] / size
    rings = np.sin(2 * np.pi * (planks * 7 * y + 0.6 * warp) + 2.0 * grain)
    base = np.array([0.55, 0.36, 0.2]) + rng.uniform(-0.05, 0.05, 3)
    img = base * (0.82 + 0.12 * rings[..., None] + 0.06 * grain[..., None])
    x = np.arange(size)[None, :]
    plank = (x * planks) // size
    tints = 1 + rng.uniform(-0.15, 0.15, (planks, 3))
    img = img * tints[np.broadcast_to(plank, (size, size))]
    seams = (x * planks) % size < max(2, size // 300)
    img[np.broadcast_to(seams, (size, size))] *= 0.45
    knots = _fractal(size, rng, (size / 40, size / 120))
    return img * (1 + 0.08 * knots[..., None])


def _stone(size: int, rng: np.random.Generator) -> F64:
    field = _fractal(size, rng, (size / 12, size / 36, size / 100, 2.0))
    colours = rng.uniform(0.15, 0.85, (4, 3))
    img = _palette(field, colours)
    speckle = periodic_noise(size, rng, sigma_px=0.8)
    img *= 1 + 0.12 * speckle[..., None]
    return img


def _fabric(size: int, rng: np.random.Generator) -> F64:
    threads = int(rng.choice([32, 48, 64]))
    x = np.arange(size)[None, :] / size
    y = np.arange(size)[:, None] / size
    weave = np.sin(2 * np.pi * threads * x) * np.sin(2 * np.pi * threads * y)
    stripes_x = np.floor(x * 2 * int(rng.integers(2, 5))) % 2
    stripes_y = np.floor(y * 2 * int(rng.integers(2, 5))) % 2
    a, b, c = rng.uniform(0.2, 0.9, (3, 3))
    img = (
        a * (0.5 + 0.5 * stripes_x[..., None]) + b * (0.5 + 0.5 * stripes_y[..., None]) + c * 0.5
    ) / 2.0
    img *= 1 + 0.18 * weave[..., None]
    shaded: F64 = img * (1 + 0.1 * _fractal(size, rng, (size / 20, 3.0))[..., None])
    return shaded


def _posters(size: int, rng: np.random.Generator) -> F64:
    base = _palette(_fractal(size, rng, (size / 8, size / 30)), rng.uniform(0.3, 0.8, (3, 3)))
    canvas = np.ascontiguousarray((base * 255).astype(np.uint8))
    for _ in range(int(rng.integers(60, 90))):
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        kind = int(rng.integers(0, 4))
        cx, cy = (int(v) for v in rng.integers(0, size, 2))
        r1, r2 = (int(v) for v in rng.integers(size // 60, size // 10, 2))
        angle = float(rng.uniform(0, 180))
        thickness = int(rng.choice([-1, -1, max(1, size // 200), max(2, size // 100)]))
        for dx, dy in _wrapped_offsets(size):
            c = (cx + dx, cy + dy)
            if kind == 0:
                cv2.ellipse(canvas, c, (r1, r2), angle, 0, 360, colour, thickness, cv2.LINE_AA)
            elif kind == 1:
                cv2.rectangle(canvas, c, (c[0] + r1, c[1] + r2), colour, thickness, cv2.LINE_AA)
            elif kind == 2:
                end = (c[0] + 2 * r1 - r2, c[1] + 2 * r2 - r1)
                cv2.line(canvas, c, end, colour, max(1, size // 250), cv2.LINE_AA)
            else:
                pts = c + rng.integers(-r1, r1 + 1, (5, 2))
                cv2.fillPoly(canvas, [pts.astype(np.int32)], colour, cv2.LINE_AA)
    return canvas.astype(np.float64) / 255.0


_STYLES = {"wood": _wood, "stone": _stone, "fabric": _fabric, "posters": _posters}


def procedural_texture(style: str, size_px: int, rng: np.random.Generator) -> U8:
    """A seamlessly tiling RGB texture.

    Args:
        style: ``wood``, ``stone``, ``fabric`` or ``posters``.
        size_px: side of the square texture [px] (>= 16).
        rng: randomness; the same generator state gives the same texture.

    Returns:
        (S, S, 3) uint8 RGB.
    """
    if style not in _STYLES:
        raise ConfigError(f"unknown texture style {style!r}; expected one of {sorted(_STYLES)}")
    if size_px < 16:
        raise ConfigError(f"texture size must be >= 16 px, got {size_px}")
    img = _STYLES[style](size_px, rng)
    grain = periodic_noise(size_px, rng, sigma_px=0.6)
    img = img * (1 + 0.06 * grain[..., None])
    texture: U8 = np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)
    return texture
