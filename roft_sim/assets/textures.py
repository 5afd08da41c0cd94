"""Procedural, richly detailed textures for the stand-in objects (optical flow needs texture).

The design is drawn in physical units (millimetres on the object's surface), then rasterised
at the requested resolution, so a smaller texture shows the same design with less detail. It
layers, in the object's colours:

1. printed-area regions: multi-scale value noise cut into the palette colours, each colour
   covering about the fraction of the surface given by its weight;
2. multi-scale shading noise (wavelengths 0.5-12 mm) over everything;
3. bands of fine stripes at random angles;
4. label blocks with a border, filled with text-like lines;
5. text-like marks (random letters and digits drawn with OpenCV's Hershey fonts) everywhere;
6. small dots, and a per-texel grain so that no area is flat.

Everything is drawn from one ``np.random.Generator``; the same arguments give the same image.
Bump :data:`TEXTURE_GENERATOR_VERSION` whenever the output changes, so caches are rebuilt.
"""

from __future__ import annotations

import string
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]

__all__ = ["TEXTURE_GENERATOR_VERSION", "procedural_texture"]

TEXTURE_GENERATOR_VERSION = 1
"""Version of the texture design; part of every cache key."""

_GLYPHS = string.ascii_uppercase + string.digits + "  -.&%"
_FONTS = (cv2.FONT_HERSHEY_SIMPLEX, cv2.FONT_HERSHEY_DUPLEX, cv2.FONT_HERSHEY_COMPLEX)


def _value_noise(
    rng: np.random.Generator, shape_px: tuple[int, int], px_per_mm: float, wavelength_mm: float
) -> F32:
    """Smooth noise in [0, 1], one random value per ``wavelength_mm`` cell, bicubic in between.

    The lattice is sized in millimetres, so the same ``rng`` state gives the same pattern at
    any resolution.
    """
    h, w = shape_px
    gh = int(np.ceil(h / (px_per_mm * wavelength_mm))) + 3
    gw = int(np.ceil(w / (px_per_mm * wavelength_mm))) + 3
    lattice = rng.random((gh, gw), dtype=np.float32)
    cell = px_per_mm * wavelength_mm
    big = cv2.resize(
        lattice, (max(1, round(gw * cell)), max(1, round(gh * cell))), interpolation=cv2.INTER_CUBIC
    )
    off = round(cell)
    out = big[off : off + h, off : off + w]
    if out.shape != (h, w):  # lattice too small after rounding: pad by reflection
        out = cv2.copyMakeBorder(
            out, 0, h - out.shape[0], 0, w - out.shape[1], cv2.BORDER_REFLECT_101
        )
    return np.clip(out, 0.0, 1.0)


def _fbm(
    rng: np.random.Generator,
    shape_px: tuple[int, int],
    px_per_mm: float,
    wavelengths_mm: tuple[float, ...],
    gain: float = 0.6,
) -> F32:
    """Fractal sum of value-noise octaves, normalised to zero mean and unit peak amplitude."""
    total = np.zeros(shape_px, dtype=np.float32)
    amplitude, norm = 1.0, 0.0
    for wavelength in wavelengths_mm:
        total += amplitude * (_value_noise(rng, shape_px, px_per_mm, wavelength) - 0.5)
        norm += 0.5 * amplitude
        amplitude *= gain
    return total / np.float32(norm)


def _luminance(rgb: NDArray[np.floating]) -> NDArray[np.floating]:
    lum: NDArray[np.floating] = 0.299 * rgb[..., 0] + 0.587 * rgb[..., 1] + 0.114 * rgb[..., 2]
    return lum


def _random_text(rng: np.random.Generator, n_chars: int) -> str:
    idx = rng.integers(0, len(_GLYPHS), size=n_chars)
    return "".join(_GLYPHS[i] for i in idx).strip() or "X"


def _draw_text_line(
    image: U8,
    rng: np.random.Generator,
    origin_px: tuple[float, float],
    cap_height_px: float,
    length_px: float,
    color: tuple[float, ...],
) -> None:
    """Draws words of random glyphs along a horizontal line, clipped to ``length_px``."""
    font = _FONTS[int(rng.integers(0, len(_FONTS)))]
    scale = max(cap_height_px / 22.0, 0.05)  # Hershey cap height is about 22 px at scale 1
    thickness = max(1, round(cap_height_px / 9.0))
    x0, y0 = origin_px
    x = x0
    while x < x0 + length_px:
        word = _random_text(rng, int(rng.integers(2, 9)))
        (tw, _), _ = cv2.getTextSize(word, font, scale, thickness)
        if x + tw > x0 + length_px and x > x0:
            break
        cv2.putText(
            image,
            word,
            (round(x), round(y0)),
            font,
            scale,
            color,
            thickness,
            lineType=cv2.LINE_AA,
        )
        x += tw + cap_height_px * float(rng.uniform(0.6, 1.2))


Color = tuple[float, ...]


@dataclass(frozen=True, slots=True, kw_only=True)
class _Inks:
    """The colours and scale every drawing step of :func:`procedural_texture` shares."""

    palette: NDArray[np.float32]
    """(C, 3) colours in [0, 1]."""
    weights: NDArray[np.float64]
    """(C,) colour fractions, summing to 1."""
    px_per_mm: float
    """Texels per millimetre of surface."""
    dark: Color
    """The darkest palette colour, 0-1."""
    light: Color
    """The lightest palette colour, 0-1."""

    def on_canvas(self) -> tuple[Color, Color]:
        """``(dark, light)`` as 0-255 colours, for drawing on the uint8 canvas."""
        return tuple(255.0 * c for c in self.dark), tuple(255.0 * c for c in self.light)


def _stripe_bands(
    image: NDArray[np.float32],
    rng: np.random.Generator,
    ink: _Inks,
) -> None:
    """Step 3: 4-7 bands of fine stripes over ``image`` (H, W, 3) [0-1], in place."""
    palette, weights, k, dark, light = ink.palette, ink.weights, ink.px_per_mm, ink.dark, ink.light
    h, w = image.shape[:2]
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float32)
    for _ in range(int(rng.integers(4, 8))):
        angle = float(rng.choice([0.0, 0.0, np.pi / 2, rng.uniform(0, np.pi)]))
        nx, ny = np.cos(angle), np.sin(angle)
        along = (cols * nx + rows * ny) / k  # mm across the band
        centre = float(rng.uniform(along.min(), along.max()))
        half_width = float(rng.uniform(4.0, 14.0))
        period = float(rng.uniform(1.2, 5.0))
        duty = float(rng.uniform(0.3, 0.6))
        inside = np.abs(along - centre) < half_width
        stripe = ((along - centre) / period) % 1.0 < duty
        color = palette[int(rng.choice(len(palette), p=weights))]
        if np.allclose(color, image[inside].mean(axis=0) if inside.any() else color, atol=0.15):
            color = np.asarray(dark if _luminance(color) > 0.5 else light, dtype=np.float32)
        mask = inside & stripe
        image[mask] = 0.35 * image[mask] + 0.65 * color


def _label_blocks(
    canvas: U8,
    rng: np.random.Generator,
    ink: _Inks,
) -> None:
    """Step 4: label blocks with a border and text lines, drawn into ``canvas`` (0-255)."""
    palette, weights, k = ink.palette, ink.weights, ink.px_per_mm
    dark, light = ink.on_canvas()
    h, w = canvas.shape[:2]
    area_mm2 = (h / k) * (w / k)
    for _ in range(max(2, int(area_mm2 / 2500.0))):
        bw, bh = rng.uniform(12.0, 55.0), rng.uniform(8.0, 35.0)
        x0, y0 = rng.uniform(-bw / 2, w / k), rng.uniform(-bh / 2, h / k)
        fill = palette[int(rng.choice(len(palette), p=weights))]
        text_ink = dark if _luminance(fill) > 0.45 else light
        fill_255 = tuple(255.0 * float(c) for c in fill)
        p0 = (round(x0 * k), round(y0 * k))
        p1 = (round((x0 + bw) * k), round((y0 + bh) * k))
        cv2.rectangle(canvas, p0, p1, fill_255, thickness=-1)
        cv2.rectangle(canvas, p0, p1, text_ink, thickness=max(1, round(0.6 * k)))
        cap = float(rng.uniform(1.5, 4.0))
        y = y0 + 2.0 * cap
        while y < y0 + bh - 0.5 * cap:
            _draw_text_line(canvas, rng, ((x0 + 1.5) * k, y * k), cap * k, (bw - 3.0) * k, text_ink)
            y += cap * float(rng.uniform(1.6, 2.2))


def _marks_and_dots(
    canvas: U8,
    rng: np.random.Generator,
    ink: _Inks,
) -> None:
    """Steps 5 and 6a: text-like marks everywhere, then dots, drawn into ``canvas``."""
    palette, weights, k = ink.palette, ink.weights, ink.px_per_mm
    dark, light = ink.on_canvas()
    h, w = canvas.shape[:2]
    area_mm2 = (h / k) * (w / k)
    for _ in range(int(area_mm2 / 350.0)):
        cap = float(rng.uniform(1.2, 7.0))
        x0, y0 = rng.uniform(-20.0, w / k), rng.uniform(0.0, h / k + cap)
        under = canvas[min(h - 1, max(0, round(y0 * k))), min(w - 1, max(0, round(x0 * k)))]
        mark_ink = dark if _luminance(under / 255.0) > 0.45 else light
        _draw_text_line(
            canvas, rng, (x0 * k, y0 * k), cap * k, rng.uniform(10.0, 60.0) * k, mark_ink
        )
    n_dots = int(area_mm2 / 15.0)
    centres = np.stack([rng.uniform(0, w, n_dots), rng.uniform(0, h, n_dots)], axis=1)
    radii = rng.uniform(0.15, 0.9, n_dots) * k
    colors = 255.0 * palette[rng.choice(len(palette), size=n_dots, p=weights)]
    for (cx, cy), r, c in zip(centres, radii, colors, strict=True):
        cv2.circle(canvas, (round(cx), round(cy)), max(1, round(r)), tuple(float(v) for v in c), -1)


def _shaded(canvas: U8, rng: np.random.Generator, k: float) -> U8:
    """Steps 2 and 6b: multi-scale shading over everything and per-texel grain."""
    h, w = canvas.shape[:2]
    shade = _fbm(rng, (h, w), k, (12.0, 6.0, 3.0, 1.5, 0.75), gain=0.85)
    image = canvas.astype(np.float32) / 255.0
    fine = _fbm(rng, (h, w), k, (1.0, 0.5), gain=0.8)
    image = 0.08 + 0.84 * image  # head-room, so that shading is never clipped flat
    image *= (1.0 + 0.25 * shade)[..., None]
    image += (0.12 * fine)[..., None]
    image += rng.uniform(-0.03, 0.03, size=(h, w, 1)).astype(np.float32)
    shaded: U8 = np.clip(np.rint(image * 255.0), 0, 255).astype(np.uint8)
    return shaded


def procedural_texture(
    palette_rgb: NDArray[np.uint8],
    weights: NDArray[np.float64],
    *,
    shape_px: tuple[int, int],
    px_per_mm: float,
    rng: np.random.Generator,
) -> U8:
    """A detailed, printed-packaging-like texture in the given colours.

    Args:
        palette_rgb: (C, 3) uint8 colours, C >= 2, most frequent first.
        weights: (C,) surface fractions of the colours (any positive scale).
        shape_px: (height, width) of the image [px].
        px_per_mm: texels per millimetre of object surface (sets the size of the features).
        rng: source of every random choice (seed it from the object name for a fixed design).

    Returns:
        (H, W, 3) uint8 RGB image.
    """
    palette = np.asarray(palette_rgb, dtype=np.float32) / 255.0
    weights = np.asarray(weights, dtype=np.float64)
    weights = weights / weights.sum()
    h, w = shape_px
    k = float(px_per_mm)
    lum = _luminance(palette)
    dark = tuple(float(c) for c in palette[int(np.argmin(lum))])
    light = tuple(float(c) for c in palette[int(np.argmax(lum))])

    # 1. printed-area regions, colour fractions from the weights (quantiles of a noise field)
    field = _fbm(rng, shape_px, k, (60.0, 25.0, 10.0), gain=0.55)
    cuts = np.quantile(field[:: max(1, h // 256), :: max(1, w // 256)], np.cumsum(weights)[:-1])
    region = np.searchsorted(cuts, field).astype(np.intp)
    image = palette[region]
    inks = _Inks(palette=palette, weights=weights, px_per_mm=k, dark=dark, light=light)
    _stripe_bands(image, rng, inks)  # 3.
    # drawing (OpenCV's text needs 8-bit images): colours as 0-255 tuples from here on
    canvas = np.clip(np.rint(image * 255.0), 0, 255).astype(np.uint8)
    _label_blocks(canvas, rng, inks)  # 4.
    _marks_and_dots(canvas, rng, inks)  # 5., 6a.
    return _shaded(canvas, rng, k)  # 2., 6b.
