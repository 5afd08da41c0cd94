"""Flow-aided mask synchronisation (paper eqs. 1-3; reference report section 2).

A mask is held as the sorted row-major linear indices of its pixels (:class:`PixelSet`): the
velocity filter takes every 35th of them in row-major order and the outlier test every 2nd, and
warping moves points, not images, so this is the natural form and avoids full-image passes.

Warping is forward splatting by chained point tracking, as in the reference: every mask pixel
starts at its integer position, is moved by each flow in turn, the flow being looked up
(block-nearest on the flow grid) at the pixel the moving point currently lies in, and lands in
the pixel of its final position. Points that leave the image or meet an invalid flow vector are
dropped. Differences from the reference (see docs/roft.md):

- pixels not hit are background: the reference's ``cv::remap`` copy of pixel (0, 0) into every
  unhit pixel (which turns the whole image into foreground when a detector mask has (0, 0) set)
  does not exist here;
- the pixel of a sub-pixel position is the nearest one by default (pixel centres are at integer
  coordinates); ``rounding = "truncate"`` gives the reference's C truncation;
- by default the tracked points keep their sub-pixel positions from frame to frame
  (:class:`TrackedPoints`, ``subpixel = true``) and the mask is closed on 3x3 neighbourhoods
  after every step (``cleanup = "close"``), which fills the holes splatting leaves where the
  object grows and never removes a pixel (a binary median would remove points scattered by
  flow noise until the mask collapsed); the reference re-warps the mask
  image from integer pixels every frame with no clean-up (``subpixel = false``,
  ``cleanup = "none"``);
- a delayed mask is warped through the buffered flows from ITS capture frame to now (any delay,
  not the reference's fixed last six), and a mask older than the one in use is ignored.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.records import FlowField, MaskDetection
from roft_sim.trackers.roft.config import MaskSyncConfig
from roft_sim.trackers.roft.medians import median

__all__ = [
    "PixelSet",
    "TrackedPoints",
    "track_points",
    "warp_pixels",
    "erode_pixels",
    "metric_erosion_px",
    "lookup_flow",
    "MaskSynchroniser",
    "MaskStep",
]

I64 = NDArray[np.int64]

_FLOW_INVALID_ABOVE_PX = 1e9
"""Flow components at or above this magnitude are invalid (the reference's bound)."""


@dataclass(frozen=True, slots=True)
class MaskWindow:
    """A mask as a 0/1 bitmap of a window of the image: ``bits[r, c]`` is pixel
    ``(r0 + r, c0 + c)``. The window may reach beyond the image; no pixel outside it is set.
    Never changed once made."""

    bits: NDArray[np.uint8]
    """(rows, cols) 0 or 1."""
    r0: int
    """Image row of the window's first row."""
    c0: int
    """Image column of the window's first column."""


class PixelSet:
    """The pixels of a mask in row-major order: linear indices ``v * W + u`` (sorted, unique)
    with their columns and rows.

    Made from those arrays, or from a window bitmap (:meth:`from_window`), whose arrays are then
    computed when first asked for: a mask a step only subsamples (the velocity filter reads
    every 35th pixel, the outlier test every 2nd) never materialises its full index arrays.
    """

    __slots__ = ("shape", "window", "_index", "_u", "_v", "_size")

    def __init__(
        self,
        index: I64,
        u: I64,
        v: I64,
        shape: tuple[int, int],
        window: MaskWindow | None = None,
    ):
        """Args:
        index: (N,) int64 linear pixel indices, ascending.
        u: (N,) int64 columns.
        v: (N,) int64 rows.
        shape: (H, W) of the image.
        window: the same mask as a window bitmap, when there is one.
        """
        self.shape = shape
        """(H, W) of the image."""
        self.window = window
        """The same mask as a window bitmap when it was made from one (morphology then needs no
        new bitmap)."""
        self._index: I64 | None = index
        self._u: I64 | None = u
        self._v: I64 | None = v
        self._size = int(index.shape[0])

    @classmethod
    def from_window(cls, window: MaskWindow, shape: tuple[int, int]) -> PixelSet:
        """The set pixels of a window bitmap, all inside the image of ``shape`` (H, W)."""
        out = cls.__new__(cls)
        out.shape, out.window = shape, window
        out._index = out._u = out._v = None
        out._size = int(np.count_nonzero(window.bits))
        return out

    @classmethod
    def from_mask(cls, mask: NDArray[np.bool_]) -> PixelSet:
        """From an (H, W) bool mask."""
        index = np.flatnonzero(mask)  # much faster than the 2-D np.nonzero
        v = index // mask.shape[1]
        return cls(index, index - v * mask.shape[1], v, (mask.shape[0], mask.shape[1]))

    @classmethod
    def from_index(cls, index: NDArray[np.integer], shape: tuple[int, int]) -> PixelSet:
        """From row-major linear indices (sorted and made unique here)."""
        unique: I64 = np.unique(np.asarray(index, dtype=np.int64))
        v = unique // shape[1]
        return cls(unique, unique - v * shape[1], v, shape)

    @classmethod
    def empty(cls, shape: tuple[int, int]) -> PixelSet:
        z = np.zeros(0, dtype=np.int64)
        return cls(z, z, z, shape)

    def __len__(self) -> int:
        return self._size

    @property
    def index(self) -> I64:
        """(N,) int64 linear pixel indices ``v * W + u``, ascending."""
        if self._index is None:
            self._index, self._u, self._v = self.strided(1)
        return self._index

    @property
    def u(self) -> I64:
        """(N,) int64 columns."""
        if self._u is None:
            self._index, self._u, self._v = self.strided(1)
        return self._u

    @property
    def v(self) -> I64:
        """(N,) int64 rows."""
        if self._v is None:
            self._index, self._u, self._v = self.strided(1)
        return self._v

    def strided(self, step: int) -> tuple[I64, I64, I64]:
        """``(index, u, v)`` of every ``step``-th pixel in row-major order."""
        if self._index is not None and self._u is not None and self._v is not None:
            return self._index[::step], self._u[::step], self._v[::step]
        assert self.window is not None  # a lazy set always has its bitmap
        bits = self.window.bits
        cols = bits.shape[1]
        flat = np.flatnonzero(bits.view(np.bool_))[::step]
        rr = flat // cols
        cc = flat - rr * cols + self.window.c0
        rr += self.window.r0
        return rr * self.shape[1] + cc, cc, rr

    def values_at(self, image: NDArray[np.floating]) -> NDArray[np.floating]:
        """(N,) the values of an (H, W) image at the pixels, in row-major order."""
        if self._index is not None or self.window is None:
            return np.take(image.reshape(-1), self.index)
        w = self.window
        r_lo, c_lo = max(0, -w.r0), max(0, -w.c0)
        bits = w.bits[r_lo:, c_lo:]
        rows, cols = bits.shape
        crop = image[w.r0 + r_lo : w.r0 + r_lo + rows, w.c0 + c_lo : w.c0 + c_lo + cols]
        out: NDArray[np.floating] = crop[bits[: crop.shape[0], : crop.shape[1]].view(np.bool_)]
        return out

    def uv(self, stride: int = 1) -> tuple[I64, I64]:
        """Columns u and rows v ``(M,)`` of every ``stride``-th pixel in row-major order."""
        _, u, v = self.strided(stride)
        return u, v

    def to_mask(self) -> NDArray[np.bool_]:
        """The (H, W) bool mask."""
        mask = np.zeros(self.shape[0] * self.shape[1], dtype=bool)
        mask[self.index] = True
        return mask.reshape(self.shape)


def _complex_flow(flow: FlowField) -> NDArray[np.complex64]:
    """The flow grid viewed as complex64 ``du + i dv``, shape (Hg * Wg,): one gather reads both
    components."""
    f = flow.flow_px
    if f.dtype != np.float32 or not f.flags.c_contiguous:
        f = np.ascontiguousarray(f, dtype=np.float32)
    return f.view(np.complex64).reshape(-1)


def lookup_flow(
    flow: FlowField,
    u: NDArray[np.integer],
    v: NDArray[np.integer],
    index: NDArray[np.integer] | None = None,
) -> tuple[NDArray[np.complex64], NDArray[np.bool_]]:
    """Flow ``du + i dv`` ``(N,)`` at integer pixels inside the image and its validity (block-
    nearest on the flow grid; non-finite vectors, magnitudes >= 1e9 and cells marked invalid or
    outside the grid are invalid).

    Args:
        flow: the flow field.
        u, v: (N,) columns and rows of the pixels [px].
        index: (N,) their row-major indices ``v * W + u`` in an image of the flow's size, when
            the caller has them (a dense flow is then read without computing them).
    """
    g = flow.grid_px
    hg, wg = flow.flow_px.shape[:2]
    inside = None
    if g == 1 and index is not None:
        lin = index
    else:
        r, c = (v, u) if g == 1 else (v // g, u // g)
        lin = r * wg + c
        if u.size and (hg * g < v.max() + 1 or wg * g < u.max() + 1):
            inside = (r < hg) & (c < wg)
            lin = np.where(inside, lin, 0)
    f = np.take(_complex_flow(flow), lin)
    ok = np.abs(f) < _FLOW_INVALID_ABOVE_PX  # False for NaN and inf
    if inside is not None:
        ok &= inside
    if flow.valid is not None:
        ok &= np.take(flow.valid.reshape(-1), lin)
    return f, ok


def _to_pixels(
    u: NDArray[np.float64], v: NDArray[np.float64], shape: tuple[int, int], rounding: str
) -> tuple[NDArray[np.bool_], I64, I64]:
    """Which sub-pixel positions lie in the image, and their pixels (for the inside ones)."""
    h, w = shape
    if rounding == "nearest":  # pixel i spans [i - 0.5, i + 0.5)
        inside = (u >= -0.5) & (u < w - 0.5) & (v >= -0.5) & (v < h - 0.5)
        off = 0.5
    else:  # C truncation: (-1, 0) -> 0, as the reference
        inside = (u > -1.0) & (u < w) & (v > -1.0) & (v < h)
        off = 0.0
    if not inside.all():
        u, v = u[inside], v[inside]
    # for inside positions u + off > -1 ... >= 0 (nearest), so truncation is the floor
    return inside, (u + off).astype(np.int64), (v + off).astype(np.int64)


_SQUARE_3 = np.ones((3, 3), dtype=np.uint8)
"""The 3x3 structuring element of the mask clean-up."""


def _window_bitmap(
    u: I64, v: I64, pad: int
) -> tuple[NDArray[np.uint8], NDArray[np.intp], int, int]:
    """A 0/1 bitmap of the pixels ``(u, v)`` (N,) on their bounding box grown by ``pad`` on each
    side (it may extend beyond the image), the pixels' flat indices in it, and the box's first
    row and column in the image."""
    r0, c0 = int(v.min()) - pad, int(u.min()) - pad
    rows = int(v.max()) - r0 + 1 + pad
    cols = int(u.max()) - c0 + 1 + pad
    flat = (v - r0) * cols + (u - c0)
    return np.zeros((rows, cols), dtype=np.uint8), flat, r0, c0


def mask_window(pixels: PixelSet) -> MaskWindow:
    """The mask as a window bitmap: its own, or one on its bounding box."""
    if pixels.window is not None:
        return pixels.window
    bits, flat, r0, c0 = _window_bitmap(pixels.u, pixels.v, 0)
    bits.reshape(-1)[flat] = 1
    return MaskWindow(bits, r0, c0)


def _clip_to_image(window: NDArray[np.uint8], r0: int, c0: int, shape: tuple[int, int]) -> None:
    """Clears, in place, the part of a bitmap whose top-left pixel is image pixel ``(r0, c0)``
    that lies outside an image of ``shape`` (H, W)."""
    h, w = shape
    rows, cols = window.shape
    if r0 < 0:
        window[:-r0] = 0
    if r0 + rows > h:
        window[max(h - r0, 0) :] = 0
    if c0 < 0:
        window[:, :-c0] = 0
    if c0 + cols > w:
        window[:, max(w - c0, 0) :] = 0


def _pixels_in_window(
    window: NDArray[np.uint8], r0: int, c0: int, shape: tuple[int, int]
) -> PixelSet:
    """The set pixels of a 0/1 bitmap whose top-left pixel is image pixel ``(r0, c0)``, all
    inside the image of ``shape`` (H, W), in row-major order (the bitmap is kept with them: do
    not change it afterwards)."""
    return PixelSet.from_window(MaskWindow(window, r0, c0), shape)


def erode_pixels(pixels: PixelSet, radius_px: int) -> PixelSet:
    """Erosion by the (2r+1)^2 square: the pixels whose whole neighbourhood is in the mask
    (pixels outside the image count as not in the mask).

    Args:
        pixels: the mask.
        radius_px: r >= 0 [px]; 0 returns ``pixels`` itself.
    """
    if radius_px <= 0 or len(pixels) == 0:
        return pixels
    window = mask_window(pixels)
    return _pixels_in_window(_eroded(window.bits, radius_px), window.r0, window.c0, pixels.shape)


def _eroded(window: NDArray[np.uint8], radius_px: int) -> NDArray[np.uint8]:
    """Erosion of a 0/1 bitmap by the (2r+1)^2 square, outside the bitmap counting as unset."""
    size = 2 * radius_px + 1
    kernel = np.ones((size, size), dtype=np.uint8)
    out = cv2.erode(window, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return np.asarray(out, dtype=np.uint8)  # the same array


def _closed(window: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Closing of a 0/1 bitmap by the 3x3 square (pad the bitmap by 2: its borders then never
    matter)."""
    return np.asarray(cv2.morphologyEx(window, cv2.MORPH_CLOSE, _SQUARE_3), dtype=np.uint8)


CLEANUPS = ("none", "close")
"""Mask clean-ups after each warp step (see ``MaskSyncConfig.cleanup``)."""


def _splat(u: I64, v: I64, shape: tuple[int, int], cleanup: str) -> PixelSet:
    """Unique sorted pixel set of integer positions already inside the image, optionally
    closed on the 3x3 neighbourhood (``close``)."""
    if u.size == 0:
        return PixelSet.empty(shape)
    window, flat, r0, c0 = _window_bitmap(u, v, 2 if cleanup != "none" else 0)
    window.reshape(-1)[flat] = 1
    if cleanup == "close":
        window = _closed(window)
        _clip_to_image(window, r0, c0, shape)
    return _pixels_in_window(window, r0, c0, shape)


def warp_pixels(
    pixels: PixelSet,
    flows: Sequence[FlowField],
    *,
    rounding: str = "nearest",
    cleanup: str = "none",
) -> PixelSet:
    """Moves a mask through consecutive flows by point tracking (forward splatting).

    Args:
        pixels: the mask in the frame the first flow starts from.
        flows: flows in chronological order (each F maps its ``from_k`` to its ``to_k``).
        rounding: ``nearest`` or ``truncate``: how a sub-pixel position picks its pixel, both
            for the flow lookup and for the landing pixel.
        cleanup: ``none``: chained tracking, each point keeps its sub-pixel position through all
            flows and is rasterised once at the end (the reference); ``close``: the mask is
            rasterised and closed on its 3x3 neighbourhoods after EACH flow (the closing fills
            the holes splatting leaves).

    Returns:
        The mask in the frame the last flow ends at. Points that leave the image or hit an
        invalid flow vector are dropped.
    """
    if cleanup not in CLEANUPS:
        raise ValueError(f"cleanup must be one of {CLEANUPS}, got {cleanup!r}")
    if cleanup != "none" and len(flows) > 1:
        for flow in flows:
            pixels = warp_pixels(pixels, [flow], rounding=rounding, cleanup=cleanup)
        return pixels
    if not flows:
        return pixels
    shape = pixels.shape
    u_i, v_i = pixels.u, pixels.v
    if len(flows) == 1 and rounding == "nearest":
        # integer positions moved once: round(u + du) = u + floor(du + 0.5)
        f, ok = lookup_flow(flows[0], u_i, v_i)
        if not ok.all():
            u_i, v_i, f = u_i[ok], v_i[ok], f[ok]
        u_i = u_i + np.floor(f.real + np.float64(0.5)).astype(np.int64)
        v_i = v_i + np.floor(f.imag + np.float64(0.5)).astype(np.int64)
        h, w = shape
        inside = (u_i >= 0) & (u_i < w) & (v_i >= 0) & (v_i < h)
        if not inside.all():
            u_i, v_i = u_i[inside], v_i[inside]
        return _splat(u_i, v_i, shape, cleanup)
    u: NDArray[np.float64] = u_i.astype(np.float64)
    v: NDArray[np.float64] = v_i.astype(np.float64)
    for flow in flows:
        f, ok = lookup_flow(flow, u_i, v_i)
        if not ok.all():
            u, v, f = u[ok], v[ok], f[ok]
        u = u + f.real
        v = v + f.imag
        inside, u_i, v_i = _to_pixels(u, v, shape, rounding)
        if u_i.shape != u.shape:
            u, v = u[inside], v[inside]
    return _splat(u_i, v_i, shape, cleanup)


@dataclass(frozen=True, slots=True)
class TrackedPoints:
    """A mask as sub-pixel points tracked through the flow, with its rasterised pixel set.

    Between flow steps the points keep their float positions (no re-rasterisation, so motion
    of a fraction of a pixel per frame accumulates instead of being rounded away); the pixel
    set is their nearest pixels, closed on 3x3 neighbourhoods when asked, and the pixels the
    closing fills inside the mask (3x3 neighbourhood wholly in the closed mask) become new
    points at their centres, so a mask that grows in the image keeps its density while its
    boundary stays where the points are (promoting every filled pixel made the mask grow by
    about a pixel ring per frame under flow noise)."""

    u_px: NDArray[np.float64]
    """(N,) columns of the points [px] (pixel centres at integer coordinates)."""
    v_px: NDArray[np.float64]
    """(N,) rows of the points [px]."""
    pixels: PixelSet
    """The rasterised (and closed) mask."""

    @classmethod
    def from_pixels(cls, pixels: PixelSet) -> TrackedPoints:
        """One point at the centre of every pixel."""
        return cls(pixels.u.astype(np.float64), pixels.v.astype(np.float64), pixels)


def track_points(points: TrackedPoints, flow: FlowField, *, cleanup: str) -> TrackedPoints:
    """Moves sub-pixel points by one flow (looked up at the pixel each point lies in) and
    rasterises them to the nearest pixels, with ``close`` or no clean-up.

    Points that leave the image or meet an invalid flow vector are dropped; several points in
    one pixel are reduced to the first. ``cleanup = "close"`` fills the one-pixel holes that
    splatting leaves where the object grows; unlike a binary median it never removes a pixel,
    so flow noise that scatters the points cannot shrink the mask to nothing.

    Args:
        points: the mask in the frame ``flow.from_k``.
        flow: one flow field.
        cleanup: ``none`` or ``close``.
    """
    if cleanup not in CLEANUPS:
        raise ValueError(f"track_points supports cleanup 'none' or 'close', got {cleanup!r}")
    shape = points.pixels.shape
    h, w = shape
    u, v = points.u_px, points.v_px
    # every point lies in the image (u >= -0.5): truncation of u + 0.5 is its nearest pixel
    ui = (u + 0.5).astype(np.int32)
    vi = (v + 0.5).astype(np.int32)
    dense = flow.grid_px == 1 and flow.flow_px.shape[:2] == shape
    f, ok = lookup_flow(flow, ui, vi, vi * w + ui if dense else None)
    u = u + f.real
    v = v + f.imag
    # kept: a valid flow vector that leaves the point in the image
    ok &= (u >= -0.5) & (u < w - 0.5) & (v >= -0.5) & (v < h - 0.5)
    if not ok.all():
        u, v = u[ok], v[ok]
    if u.size == 0:
        return TrackedPoints(u, v, PixelSet.empty(shape))
    ui = (u + 0.5).astype(np.int32)
    vi = (v + 0.5).astype(np.int32)
    pad = 2 if cleanup == "close" else 0
    r0, c0 = int(vi.min()) - pad, int(ui.min()) - pad
    rows = int(vi.max()) - r0 + 1 + pad
    cols = int(ui.max()) - c0 + 1 + pad
    # the first point in each pixel: the smallest point index landing there
    n = u.size
    owner = np.full(rows * cols, n, dtype=np.int32)
    np.minimum.at(owner, (vi - r0) * cols + (ui - c0), np.arange(n, dtype=np.int32))
    landed = owner < n
    first = owner[landed]  # in row-major pixel order
    hit = landed.view(np.uint8).reshape(rows, cols)
    filled: NDArray[np.uint8] | None = None
    if cleanup == "close":
        closed = _closed(hit)
        _clip_to_image(closed, r0, c0, shape)
        filled = closed & ~hit & _eroded(closed, 1)  # filled pixels inside the closed mask
        pixels = _pixels_in_window(closed, r0, c0, shape)
    else:
        pixels = _pixels_in_window(hit, r0, c0, shape)
    new = _pixels_in_window(filled, r0, c0, shape) if filled is not None else None
    # the kept points, then one at the centre of each filled pixel
    m = first.size
    extra = len(new) if new is not None else 0
    u_out, v_out = np.empty(m + extra), np.empty(m + extra)
    # mode="clip": the indices are valid, and "raise" with ``out`` buffers a copy (10x slower)
    np.take(u, first, out=u_out[:m], mode="clip")
    np.take(v, first, out=v_out[:m], mode="clip")
    if new is not None and extra:
        _, new_u, new_v = new.strided(1)
        u_out[m:] = new_u
        v_out[m:] = new_v
    return TrackedPoints(u_out, v_out, pixels)


def metric_erosion_px(
    pixels: PixelSet,
    depth_m: NDArray[np.floating],
    focal_px: float,
    erosion_m: float,
    max_removed_fraction: float,
) -> int:
    """Erosion radius [px] that removes a band ``erosion_m`` wide at the object's median depth,
    reduced until at most ``max_removed_fraction`` of the mask is removed.

    Args:
        pixels: the mask.
        depth_m: (H, W) z-depth [m]; the median over the mask's valid (> 0) pixels is used.
        focal_px: focal length [px].
        erosion_m: band width on the object [m].
        max_removed_fraction: in [0, 1).
    """
    return metric_erosion(pixels, depth_m, focal_px, erosion_m, max_removed_fraction)[0]


def metric_erosion(
    pixels: PixelSet,
    depth_m: NDArray[np.floating],
    focal_px: float,
    erosion_m: float,
    max_removed_fraction: float,
) -> tuple[int, PixelSet]:
    """:func:`metric_erosion_px`'s radius and the mask eroded by it (``pixels`` itself for 0)."""
    if len(pixels) == 0 or erosion_m <= 0:
        return 0, pixels
    z = pixels.values_at(depth_m)
    z = z[np.isfinite(z) & (z > 0)]
    if z.size == 0:
        return 0, pixels
    radius = int(round(erosion_m * focal_px / median(z)))
    window = mask_window(pixels) if radius > 0 else None
    while radius > 0 and window is not None:
        bits = _eroded(window.bits, radius)
        if cv2.countNonZero(bits) >= (1.0 - max_removed_fraction) * len(pixels):
            return radius, _pixels_in_window(bits, window.r0, window.c0, pixels.shape)
        radius -= 1
    return 0, pixels


@dataclass(frozen=True, slots=True)
class MaskStep:
    """What the synchroniser did at one frame."""

    pixels: PixelSet | None
    """The synchronised mask of the frame (None before any usable mask)."""
    capture_k: int | None
    """Capture frame of the detection the mask descends from."""
    counts: dict[str, int] = field(default_factory=dict)
    """Diagnostics: masks used, ignored (older than the one in use), dropped (too old for the
    flow buffer, empty, wrong size, captured in the future), flows used in the warp."""
    history: tuple[tuple[int, PixelSet], ...] = ()
    """When a delayed mask arrived and was warped point by point (``subpixel``): ``(frame,
    mask)`` of that mask at its capture frame and after each buffered flow, in frame order
    (the last is ``pixels``); empty otherwise."""


class MaskSynchroniser:
    """Keeps a mask synchronised with the camera stream (paper eqs. 2 and 3).

    Per frame k: a delayed mask that arrives (capture c <= k) is warped through the buffered
    flows F_{c+1} ... F_k; otherwise the current mask is propagated with F_k. A mask older than
    (or as old as) the one in use is ignored; one older than the horizon is dropped. With
    ``flow_aided = False`` masks are used as they arrive (the "w/o segm. sync." ablation).
    Missing flows (dropped camera frames, no flow source) are treated as no motion.
    """

    def __init__(self, config: MaskSyncConfig, shape: tuple[int, int], horizon_frames: int):
        self._config = config
        self._shape = shape
        self._horizon = horizon_frames
        self.reset()

    def reset(self) -> None:
        self._flows: dict[int, FlowField] = {}
        self._pixels: PixelSet | None = None
        self._points: TrackedPoints | None = None
        self._capture_k: int | None = None

    def step(self, k: int, flow: FlowField | None, masks: Sequence[MaskDetection]) -> MaskStep:
        """Advances to frame k with its flow F_k (or None) and the masks arriving at k."""
        cfg = self._config
        counts = {"masks_used": 0, "masks_ignored": 0, "masks_dropped": 0, "warp_flows": 0}
        if cfg.flow_aided and flow is not None and flow.to_k == k and flow.from_k < k:
            self._flows[k] = flow
        best: MaskDetection | None = None
        history: tuple[tuple[int, PixelSet], ...] = ()
        for det in masks:
            c = det.capture_k
            usable_shape = det.mask.shape == self._shape
            if not usable_shape or c > k or c < k - self._horizon or not det.mask.any():
                counts["masks_dropped"] += 1
            elif (self._capture_k is not None and c <= self._capture_k) or (
                best is not None and c < best.capture_k
            ):
                counts["masks_ignored"] += 1
            else:
                if best is not None:
                    counts["masks_ignored"] += 1
                best = det
        if best is not None:
            counts["masks_used"] = 1
            pixels = PixelSet.from_mask(best.mask)
            if cfg.flow_aided:
                chain = [
                    self._flows[j]
                    for j in sorted(self._flows)
                    if best.capture_k < j <= k and self._flows[j].from_k >= best.capture_k
                ]
                counts["warp_flows"] = len(chain)
                if cfg.subpixel:
                    points = TrackedPoints.from_pixels(pixels)
                    steps = [(best.capture_k, pixels)]
                    for flow_j in chain:
                        points = track_points(points, flow_j, cleanup=cfg.cleanup)
                        steps.append((flow_j.to_k, points.pixels))
                    self._points, pixels = points, points.pixels
                    history = tuple(steps)
                else:
                    pixels = warp_pixels(pixels, chain, rounding=cfg.rounding, cleanup=cfg.cleanup)
            self._pixels, self._capture_k = pixels, best.capture_k
        elif cfg.flow_aided and self._pixels is not None and k in self._flows:
            counts["warp_flows"] = 1
            if cfg.subpixel and self._points is not None:
                self._points = track_points(self._points, self._flows[k], cleanup=cfg.cleanup)
                self._pixels = self._points.pixels
            else:
                self._pixels = warp_pixels(
                    self._pixels,
                    [self._flows[k]],
                    rounding=cfg.rounding,
                    cleanup=cfg.cleanup,
                )
        for j in [j for j in self._flows if j <= k - self._horizon]:
            del self._flows[j]
        return MaskStep(self._pixels, self._capture_k, counts, history)
