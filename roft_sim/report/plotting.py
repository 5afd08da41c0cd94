"""Line plots drawn with OpenCV (the project has no matplotlib): axes with nice ticks, grid, labels,
legend, lines, markers, vertical event markers, PNG output.

    plot = LinePlot(title="position error", x_label="frame", y_label="cm")
    plot.add_line(frames, err_cm, label="roft")
    plot.add_events(arrival_frames, label="pose arrives")
    plot.save("trace.png")

Coordinates: :meth:`LinePlot.data_to_px` maps data ``(x, y)`` to image pixel coordinates
``(u, v)`` (column, row; pixel centres at integers, as everywhere in roft_sim): ``x`` grows to the
right, ``y`` upwards. The axis limits are the data range widened to nice tick values
(:func:`nice_ticks`) unless given. NaN and inf values break a line (and draw no marker).

Images are RGB ``(H, W, 3)`` uint8; :func:`save_png` converts to OpenCV's BGR at the file
boundary only.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

U8 = NDArray[np.uint8]
F64 = NDArray[np.float64]

__all__ = [
    "PALETTE",
    "MARKERS",
    "nice_ticks",
    "tick_labels",
    "LinePlot",
    "stack_images",
    "save_png",
]

PALETTE: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
)
"""Series colours (RGB), the 'tab10' palette, used in order."""
MARKERS = ("o", "s", "^", "x", "d")
"""Marker shapes: circle, square, triangle, cross, diamond."""

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_SHIFT = 4
"""Fractional bits of the sub-pixel coordinates handed to OpenCV's drawing functions."""
_WHITE = (255, 255, 255)
_BLACK = (0, 0, 0)
_GRID = (225, 225, 225)


def _nice_number(x: float, *, integer: bool = False) -> float:
    """The smallest 'nice' number (1, 2, 2.5, 5 times a power of ten; no 2.5 for integer axes)
    that is >= ``x > 0``."""
    exponent = math.floor(math.log10(x))
    fraction = x / 10**exponent
    choices = (1.0, 2.0, 5.0) if integer else (1.0, 2.0, 2.5, 5.0)
    nice = next((n for n in choices if fraction <= n * (1 + 1e-12)), 10.0)
    return float(nice * 10**exponent)


def nice_ticks(lo: float, hi: float, *, max_ticks: int = 6, integer: bool = False) -> F64:
    """Evenly spaced 'nice' tick values covering ``[lo, hi]`` (first <= lo, last >= hi).

    The step is 1, 2, 2.5 or 5 times a power of ten (``integer``: 1, 2 or 5 times, and at least
    1), chosen so that there are at most about ``max_ticks`` ticks. An empty range (lo == hi) is
    widened by one unit (or 10 %) each way.

    Raises:
        ValueError: non-finite limits, ``lo > hi`` or ``max_ticks < 2``.
    """
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi or max_ticks < 2:
        raise ValueError(f"need finite lo <= hi and max_ticks >= 2, got {lo}, {hi}, {max_ticks}")
    if lo == hi:
        pad = abs(lo) * 0.1 if lo != 0 else 1.0
        lo, hi = lo - pad, hi + pad
    step = _nice_number((hi - lo) / (max_ticks - 1), integer=integer)
    if integer:
        step = max(step, 1.0)
    first = math.floor(lo / step + 1e-9) * step
    last = math.ceil(hi / step - 1e-9) * step
    n = int(round((last - first) / step)) + 1
    ticks = first + step * np.arange(n)
    # snap values that should be exact (0.30000000000000004 -> 0.3)
    digits = max(0, -math.floor(math.log10(step)) + 2)
    return np.round(ticks, digits) + 0.0


def tick_labels(ticks: ArrayLike) -> list[str]:
    """Text of tick values with just enough decimals to tell neighbours apart."""
    t = np.asarray(ticks, dtype=np.float64)
    if t.size < 2:
        return [f"{v:g}" for v in t]
    step = float(np.min(np.diff(t)))
    decimals = 0
    while decimals < 6 and abs(round(step, decimals) - step) > 1e-9 * max(1.0, abs(step)):
        decimals += 1
    return [f"{v:.{decimals}f}" for v in t]


def _text_size(text: str, scale: float) -> tuple[int, int]:
    (w, h), baseline = cv2.getTextSize(text, _FONT, scale, 1)
    return w, h + baseline


def _put_text(
    img: U8, text: str, org: tuple[int, int], scale: float, color: tuple[int, int, int] = _BLACK
) -> None:
    cv2.putText(img, text, org, _FONT, scale, color, 1, cv2.LINE_AA)


def _fixed(u: float) -> int:
    return int(round(u * (1 << _SHIFT)))


@dataclass(frozen=True, slots=True)
class _Series:
    x: F64
    y: F64
    label: str | None
    color: tuple[int, int, int]
    marker: str | None
    line: bool
    width_px: int


@dataclass(frozen=True, slots=True)
class _Events:
    x: F64
    label: str | None
    color: tuple[int, int, int]


class LinePlot:
    """One set of axes with lines, markers and vertical event markers (see module docstring).

    Args:
        width_px, height_px: image size [px].
        title, x_label, y_label: texts.
        x_range, y_range: axis limits; None = the data range widened to nice ticks.
        max_ticks: about how many ticks per axis.
        x_integer: x ticks at whole numbers only (frames, delays).
    """

    margin_left_px = 72
    margin_right_px = 16
    margin_top_px = 34
    margin_bottom_px = 48
    font_scale = 0.45

    def __init__(
        self,
        *,
        width_px: int = 640,
        height_px: int = 360,
        title: str = "",
        x_label: str = "",
        y_label: str = "",
        x_range: tuple[float, float] | None = None,
        y_range: tuple[float, float] | None = None,
        max_ticks: int = 6,
        x_integer: bool = False,
    ) -> None:
        min_w = self.margin_left_px + self.margin_right_px + 40
        min_h = self.margin_top_px + self.margin_bottom_px + 40
        if width_px < min_w or height_px < min_h:
            raise ValueError(
                f"plot must be at least {min_w}x{min_h} px, got {width_px}x{height_px}"
            )
        for name, r in (("x_range", x_range), ("y_range", y_range)):
            if r is not None and not (math.isfinite(r[0]) and math.isfinite(r[1]) and r[0] < r[1]):
                raise ValueError(f"{name} must be two finite values lo < hi, got {r}")
        self.width_px, self.height_px = int(width_px), int(height_px)
        self.title, self.x_label, self.y_label = title, x_label, y_label
        self._x_range, self._y_range = x_range, y_range
        self.max_ticks = max_ticks
        self.x_integer = x_integer
        self._series: list[_Series] = []
        self._events: list[_Events] = []

    # ----------------------------------------------------------------------- content
    def _next_color(self) -> tuple[int, int, int]:
        return PALETTE[(len(self._series) + len(self._events)) % len(PALETTE)]

    def add_line(
        self,
        x: ArrayLike,
        y: ArrayLike,
        *,
        label: str | None = None,
        color: tuple[int, int, int] | None = None,
        marker: str | None = None,
        line: bool = True,
        width_px: int = 2,
    ) -> LinePlot:
        """Adds a series: ``x``, ``y`` of shape (N,); ``marker`` one of :data:`MARKERS`."""
        xa = np.asarray(x, dtype=np.float64).ravel()
        ya = np.asarray(y, dtype=np.float64).ravel()
        if xa.shape != ya.shape:
            raise ValueError(f"x and y must have the same length, got {xa.shape} and {ya.shape}")
        if marker is not None and marker not in MARKERS:
            raise ValueError(f"unknown marker {marker!r}; expected one of {MARKERS}")
        if not line and marker is None:
            raise ValueError("a series needs a line or a marker")
        self._series.append(
            _Series(xa, ya, label, color or self._next_color(), marker, line, int(width_px))
        )
        return self

    def add_events(
        self,
        x: ArrayLike,
        *,
        label: str | None = None,
        color: tuple[int, int, int] | None = None,
    ) -> LinePlot:
        """Adds vertical markers at ``x`` (N,) spanning the plot height (e.g. arrivals)."""
        xa = np.asarray(x, dtype=np.float64).ravel()
        self._events.append(_Events(xa[np.isfinite(xa)], label, color or (150, 150, 150)))
        return self

    # ----------------------------------------------------------------------- geometry
    def _data_limits(self, axis: int) -> tuple[float, float] | None:
        values = []
        for s in self._series:
            v = s.x if axis == 0 else s.y
            values.append(v[np.isfinite(s.x) & np.isfinite(s.y)])
        if axis == 0:
            values += [e.x for e in self._events]
        data = np.concatenate(values) if values else np.zeros(0)
        if data.size == 0:
            return None
        return float(data.min()), float(data.max())

    def _axis(self, axis: int) -> tuple[float, float, F64]:
        given = self._x_range if axis == 0 else self._y_range
        integer = self.x_integer and axis == 0
        if given is not None:
            lo, hi = given
            ticks = nice_ticks(lo, hi, max_ticks=self.max_ticks, integer=integer)
            return lo, hi, ticks[(ticks >= lo - 1e-12) & (ticks <= hi + 1e-12)]
        limits = self._data_limits(axis) or (0.0, 1.0)
        ticks = nice_ticks(*limits, max_ticks=self.max_ticks, integer=integer)
        return float(ticks[0]), float(ticks[-1]), ticks

    @property
    def x_limits(self) -> tuple[float, float]:
        """The x axis range (data units)."""
        lo, hi, _ = self._axis(0)
        return lo, hi

    @property
    def y_limits(self) -> tuple[float, float]:
        """The y axis range (data units)."""
        lo, hi, _ = self._axis(1)
        return lo, hi

    @property
    def plot_area_px(self) -> tuple[int, int, int, int]:
        """``(left, top, right, bottom)`` pixel columns/rows of the axes' frame (inclusive)."""
        return (
            self.margin_left_px,
            self.margin_top_px,
            self.width_px - 1 - self.margin_right_px,
            self.height_px - 1 - self.margin_bottom_px,
        )

    def data_to_px(self, x: ArrayLike, y: ArrayLike) -> tuple[F64, F64]:
        """Image coordinates ``(u, v)`` [px] of data points ``(x, y)`` (any matching shapes).

        ``x_limits`` maps to the frame's left and right columns, ``y_limits`` to its bottom and
        top rows.
        """
        (x0, x1), (y0, y1) = self.x_limits, self.y_limits
        left, top, right, bottom = self.plot_area_px
        xa = np.asarray(x, dtype=np.float64)
        ya = np.asarray(y, dtype=np.float64)
        u = left + (xa - x0) / (x1 - x0) * (right - left)
        v = bottom - (ya - y0) / (y1 - y0) * (bottom - top)
        return u, v

    # ----------------------------------------------------------------------- drawing
    @staticmethod
    def _draw_marker(
        img: U8, u: float, v: float, marker: str, color: tuple[int, int, int], size: int = 4
    ) -> None:
        c = (_fixed(u), _fixed(v))
        s = size << _SHIFT
        if marker == "o":
            cv2.circle(img, c, s, color, -1, cv2.LINE_AA, _SHIFT)
        elif marker == "s":
            cv2.rectangle(img, (c[0] - s, c[1] - s), (c[0] + s, c[1] + s), color, -1, 8, _SHIFT)
        elif marker in ("^", "d"):
            if marker == "^":
                pts = [(c[0], c[1] - s), (c[0] - s, c[1] + s), (c[0] + s, c[1] + s)]
            else:
                pts = [(c[0], c[1] - s), (c[0] - s, c[1]), (c[0], c[1] + s), (c[0] + s, c[1])]
            cv2.fillPoly(img, [np.array(pts, np.int32)], color, cv2.LINE_AA, _SHIFT)
        else:  # "x"
            for a, b in (((-1, -1), (1, 1)), ((-1, 1), (1, -1))):
                p = (c[0] + a[0] * s, c[1] + a[1] * s)
                q = (c[0] + b[0] * s, c[1] + b[1] * s)
                cv2.line(img, p, q, color, 2, cv2.LINE_AA, _SHIFT)
            # the centre pixel carries the colour exactly
            cv2.circle(img, c, 1 << _SHIFT, color, -1, 8, _SHIFT)

    def _draw_series(self, img: U8, s: _Series, origin: tuple[int, int]) -> None:
        """Draws ``s`` into ``img``, whose pixel (0, 0) is the plot image's ``origin``."""
        u, v = self.data_to_px(s.x, s.y)
        u, v = u - origin[0], v - origin[1]
        finite = np.isfinite(u) & np.isfinite(v)
        if s.line:
            # split into runs of finite points; NaN/inf break the line
            breaks = np.flatnonzero(~finite)
            start = 0
            for end in [*breaks.tolist(), len(u)]:
                if end - start >= 2:
                    pts = np.stack([u[start:end], v[start:end]], axis=1) * (1 << _SHIFT)
                    cv2.polylines(
                        img,
                        [np.round(pts).astype(np.int32)],
                        False,
                        s.color,
                        s.width_px,
                        cv2.LINE_AA,
                        _SHIFT,
                    )
                start = end + 1
        if s.marker is not None:
            for ui, vi in zip(u[finite], v[finite], strict=True):
                self._draw_marker(img, float(ui), float(vi), s.marker, s.color)

    def _draw_legend(self, img: U8) -> None:
        entries = [(s.label, s.color, s.marker, s.line) for s in self._series if s.label]
        entries += [(e.label, e.color, None, True) for e in self._events if e.label]
        if not entries:
            return
        scale = self.font_scale
        row_h = _text_size("Ag", scale)[1] + 6
        text_w = max(_text_size(label, scale)[0] for label, *_ in entries)
        w, h = 34 + text_w + 8, row_h * len(entries) + 6
        x0, y0 = self._legend_corner(w, h)
        img[y0 : y0 + h, x0 : x0 + w] = 255
        cv2.rectangle(img, (x0, y0), (x0 + w - 1, y0 + h - 1), (180, 180, 180), 1)
        for i, (label, color, marker, line) in enumerate(entries):
            yc = y0 + 3 + row_h * i + row_h // 2
            if line:
                cv2.line(img, (x0 + 6, yc), (x0 + 28, yc), color, 2, cv2.LINE_AA)
            if marker is not None:
                self._draw_marker(img, x0 + 17, yc, marker, color)
            _put_text(img, label, (x0 + 34, yc + row_h // 2 - 5), scale)

    def _legend_corner(self, w: int, h: int) -> tuple[int, int]:
        """Top-left pixel of a ``w`` x ``h`` legend: the corner of the plot area that covers the
        fewest data points (ties: top right, top left, bottom right, bottom left)."""
        left, top, right, bottom = self.plot_area_px
        corners = [
            (right - w - 6, top + 6),
            (left + 6, top + 6),
            (right - w - 6, bottom - h - 6),
            (left + 6, bottom - h - 6),
        ]
        us, vs = [], []
        for s in self._series:
            u, v = self.data_to_px(s.x, s.y)
            if s.line and u.size >= 2:  # sample along the segments, not only at the vertices
                t = np.linspace(0.0, 1.0, 16)[:, None]
                u = (u[:-1] * (1 - t) + u[1:] * t).ravel()
                v = (v[:-1] * (1 - t) + v[1:] * t).ravel()
            us.append(u)
            vs.append(v)
        u = np.concatenate(us) if us else np.zeros(0)
        v = np.concatenate(vs) if vs else np.zeros(0)

        def covered(corner: tuple[int, int]) -> int:
            x0, y0 = corner
            inside = (u >= x0 - 4) & (u <= x0 + w + 4) & (v >= y0 - 4) & (v <= y0 + h + 4)
            return int(np.count_nonzero(inside))

        return min(corners, key=covered)

    def render(self) -> U8:
        """The plot as an RGB image ``(height_px, width_px, 3)`` uint8."""
        img = np.full((self.height_px, self.width_px, 3), 255, dtype=np.uint8)
        left, top, right, bottom = self.plot_area_px
        x0, x1, xticks = self._axis(0)
        y0, y1, yticks = self._axis(1)
        scale = self.font_scale
        # grid and ticks
        for t, text in zip(xticks, tick_labels(xticks), strict=True):
            u = int(round(float(self.data_to_px(t, y0)[0])))
            cv2.line(img, (u, top), (u, bottom), _GRID, 1)
            cv2.line(img, (u, bottom), (u, bottom + 4), _BLACK, 1)
            tw, th = _text_size(text, scale)
            _put_text(img, text, (u - tw // 2, bottom + 6 + th), scale)
        for t, text in zip(yticks, tick_labels(yticks), strict=True):
            v = int(round(float(self.data_to_px(x0, t)[1])))
            cv2.line(img, (left, v), (right, v), _GRID, 1)
            cv2.line(img, (left - 4, v), (left, v), _BLACK, 1)
            tw, th = _text_size(text, scale)
            _put_text(img, text, (left - 7 - tw, v + th // 2 - 2), scale)
        # content, clipped to the plot area
        area = img[top : bottom + 1, left : right + 1].copy()
        for e in self._events:
            for x in e.x:
                u_area = float(self.data_to_px(x, y0)[0]) - left
                cv2.line(
                    area,
                    (_fixed(u_area), 0),
                    (_fixed(u_area), _fixed(bottom - top)),
                    e.color,
                    1,
                    cv2.LINE_AA,
                    _SHIFT,
                )
        for s in self._series:
            self._draw_series(area, s, (left, top))
        img[top : bottom + 1, left : right + 1] = area
        cv2.rectangle(img, (left, top), (right, bottom), _BLACK, 1)
        # texts
        if self.title:
            tw, th = _text_size(self.title, scale * 1.15)
            _put_text(img, self.title, ((left + right - tw) // 2, top - 10), scale * 1.15)
        if self.x_label:
            tw, th = _text_size(self.x_label, scale)
            _put_text(img, self.x_label, ((left + right - tw) // 2, self.height_px - 8), scale)
        if self.y_label:
            tw, th = _text_size(self.y_label, scale)
            label: NDArray[Any] = np.full((th + 4, tw + 4, 3), 255, dtype=np.uint8)
            _put_text(label, self.y_label, (2, th - 2), scale)
            label = cv2.rotate(label, cv2.ROTATE_90_COUNTERCLOCKWISE)
            lh, lw = label.shape[:2]
            r0 = max(0, (top + bottom - lh) // 2)
            img[r0 : r0 + lh, 4 : 4 + lw] = label[: self.height_px - r0]
        self._draw_legend(img)
        return img

    def save(self, path: str | Path) -> Path:
        """Renders and writes a PNG; returns the path."""
        return save_png(path, self.render())


def stack_images(images: Sequence[U8], *, direction: str = "vertical") -> U8:
    """Stacks RGB images vertically or horizontally, padding with white to a common size."""
    if not images:
        raise ValueError("need at least one image to stack")
    if direction not in ("vertical", "horizontal"):
        raise ValueError(f"direction must be 'vertical' or 'horizontal', got {direction!r}")
    axis = 0 if direction == "vertical" else 1
    other = 1 - axis
    size = max(im.shape[other] for im in images)
    padded = []
    for im in images:
        pad = [(0, 0), (0, 0), (0, 0)]
        pad[other] = (0, size - im.shape[other])
        padded.append(np.pad(im, pad, constant_values=255))
    return np.concatenate(padded, axis=axis)


def save_png(path: str | Path, rgb: U8) -> Path:
    """Writes an RGB image as PNG, atomically (temp file, then rename); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    ok, data = cv2.imencode(".png", np.ascontiguousarray(rgb[..., ::-1]))
    if not ok:
        raise ValueError(f"OpenCV could not encode a PNG of shape {rgb.shape}")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(data.tobytes())
    os.replace(tmp, path)
    return path
