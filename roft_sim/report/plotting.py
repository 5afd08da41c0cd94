"""Figures drawn with matplotlib (the Agg raster backend; no display, no ``pyplot`` global state):
per-frame error traces with pose arrivals marked, metric-versus-parameter curves (with confidence
bands), accuracy curves and grouped bar charts of tables (the paper's tables beside the simulation).

Every figure is built from :class:`Panel` s, one set of axes each, whose titles and axis labels
carry the units (``"position error [cm]"``), with a legend whenever a panel holds a labelled
series. Builders return a :class:`matplotlib.figure.Figure`, so tests can read back what was
drawn; :func:`save_figure` writes it as a PNG atomically (temp file, then rename) at 100 dpi, so
a figure is as readable in a browser at 100 % as on paper.

    panel = Panel(title="position error", y_label="error [cm]",
                  series=(Series(x=frames, y=err_cm, label="roft"),))
    save_figure(line_figure([panel], x_label="frame", events_x=arrivals_k,
                            events_label="pose arrives"), "trace.png")

NaN values break a line (matplotlib's convention), so missing frames leave a gap.
Video frames and stills stay with OpenCV (:mod:`roft_sim.report.overlay`).
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator
from numpy.typing import ArrayLike, NDArray

from roft_sim.datasets.atomic_files import atomic_write_bytes

F64 = NDArray[np.float64]

__all__ = [
    "DPI",
    "MARKERS",
    "EVENT_COLOR",
    "Series",
    "Panel",
    "line_figure",
    "bar_figure",
    "save_figure",
]

DPI = 100
"""Pixels per inch of saved figures: a 5.6 x 3.2 in panel is 560 x 320 px, read at 100 %."""
MARKERS = ("o", "s", "^", "D", "v", "x")
"""Marker shapes cycled through the series of a panel when markers are asked for."""
EVENT_COLOR = "0.6"
"""Grey of the vertical event lines (pose arrivals)."""
PANEL_SIZE_IN = (5.6, 3.2)
"""Default size of one panel [in]."""
_FONT_SIZE_PT = 9.0


@dataclass(frozen=True, slots=True, kw_only=True)
class Series:
    """One line of a panel."""

    x: ArrayLike
    """(N,) abscissae, in the panel's x unit."""
    y: ArrayLike
    """(N,) ordinates, in the panel's y unit; NaN leaves a gap."""
    label: str | None = None
    """Legend entry; None = not in the legend."""
    band_low: ArrayLike | None = None
    """(N,) lower edge of a shaded band around the line (a confidence interval), in the y
    unit; NaN leaves a gap. None = no band."""
    band_high: ArrayLike | None = None
    """(N,) upper edge of the band; given together with ``band_low``."""

    def __post_init__(self) -> None:
        x, y = np.shape(self.x), np.shape(self.y)
        if len(x) != 1 or x != y:
            raise ValueError(f"a series needs x and y of the same length (N,), got {x} and {y}")
        if (self.band_low is None) != (self.band_high is None):
            raise ValueError("a band needs both band_low and band_high")
        for edge in (self.band_low, self.band_high):
            if edge is not None and np.shape(edge) != x:
                raise ValueError(f"band edges need the shape of x {x}, got {np.shape(edge)}")


@dataclass(frozen=True, slots=True, kw_only=True)
class Panel:
    """One set of axes: a title, a y-axis label with its unit, and its series."""

    title: str
    """Title above the axes."""
    y_label: str
    """y-axis label with the unit in brackets, e.g. ``"position error [cm]"``."""
    series: tuple[Series, ...] = field(default_factory=tuple)
    """The lines drawn, in legend order."""
    y_range: tuple[float, float] | None = None
    """y-axis limits; None = matplotlib's automatic limits (from 0 for non-negative data)."""

    def __post_init__(self) -> None:
        r = self.y_range
        if r is not None and not (math.isfinite(r[0]) and math.isfinite(r[1]) and r[0] < r[1]):
            raise ValueError(f"y_range must be two finite values lo < hi, got {r}")


def _new_figure(
    n_panels: int, columns: int, panel_in: tuple[float, float]
) -> tuple[Figure, list[Axes]]:
    if n_panels < 1 or columns < 1:
        raise ValueError(f"need at least one panel and one column, got {n_panels}, {columns}")
    columns = min(columns, n_panels)
    rows = math.ceil(n_panels / columns)
    fig = Figure(figsize=(panel_in[0] * columns, panel_in[1] * rows), dpi=DPI, layout="constrained")
    axes = fig.subplots(rows, columns, squeeze=False).ravel().tolist()
    for ax in axes[n_panels:]:
        ax.set_visible(False)
    return fig, axes[:n_panels]


def _style(ax: Axes, panel: Panel, x_label: str, *, legend: bool = True) -> None:
    ax.set_title(panel.title, fontsize=_FONT_SIZE_PT + 1)
    ax.set_xlabel(x_label, fontsize=_FONT_SIZE_PT)
    ax.set_ylabel(panel.y_label, fontsize=_FONT_SIZE_PT)
    ax.tick_params(labelsize=_FONT_SIZE_PT - 0.5)
    ax.grid(True, color="0.9", linewidth=0.8)
    ax.set_axisbelow(True)
    if panel.y_range is not None:
        ax.set_ylim(*panel.y_range)
    if legend and ax.get_legend_handles_labels()[1]:
        ax.legend(fontsize=_FONT_SIZE_PT - 0.5, framealpha=0.9, loc="best")


def line_figure(
    panels: Sequence[Panel],
    *,
    x_label: str,
    title: str | None = None,
    columns: int = 2,
    markers: bool = False,
    integer_x: bool = False,
    events_x: ArrayLike | None = None,
    events_label: str = "pose arrives",
    panel_in: tuple[float, float] = PANEL_SIZE_IN,
) -> Figure:
    """Line plots, one panel per :class:`Panel`, laid out ``columns`` wide.

    Args:
        panels: what each set of axes shows.
        x_label: x-axis label with its unit, shared by every panel (``"frame"``, ``"delay
            [frames]"``).
        title: figure title above all panels; None = none.
        columns: panels per row.
        markers: draw a marker at every point (curves over a few swept values).
        integer_x: x ticks at whole numbers only (frames, delays).
        events_x: (M,) x positions of events (pose arrivals) drawn as thin grey vertical lines
            in every panel, with one legend entry ``events_label``.
        events_label: legend text of the events.
        panel_in: size of one panel [in] (x 100 dpi = pixels).

    Returns:
        The figure; write it with :func:`save_figure`.
    """
    fig, axes = _new_figure(len(panels), columns, panel_in)
    events = None if events_x is None else np.asarray(events_x, dtype=np.float64).ravel()
    for ax, panel in zip(axes, panels, strict=True):
        if events is not None and events.size:
            for i, x in enumerate(events[np.isfinite(events)]):
                ax.axvline(
                    x,
                    color=EVENT_COLOR,
                    linewidth=0.7,
                    linestyle="--",
                    zorder=1,
                    label=events_label if i == 0 else None,
                )
        for i, s in enumerate(panel.series):
            (line,) = ax.plot(
                np.asarray(s.x, dtype=np.float64),
                np.asarray(s.y, dtype=np.float64),
                label=s.label,
                linewidth=1.6 if markers else 1.1,
                marker=MARKERS[i % len(MARKERS)] if markers else None,
                markersize=5,
                zorder=2,
            )
            if s.band_low is not None and s.band_high is not None:
                ax.fill_between(
                    np.asarray(s.x, dtype=np.float64),
                    np.asarray(s.band_low, dtype=np.float64),
                    np.asarray(s.band_high, dtype=np.float64),
                    color=line.get_color(),
                    alpha=0.18,
                    linewidth=0,
                    zorder=1.5,
                )
        if integer_x:
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        _style(ax, panel, x_label)
    if title:
        fig.suptitle(title, fontsize=_FONT_SIZE_PT + 2)
    return fig


def bar_figure(
    categories: Sequence[str],
    panels: Sequence[tuple[str, str, Mapping[str, Sequence[float | None]]]],
    *,
    title: str | None = None,
    columns: int = 1,
    hatched: Sequence[str] = (),
    panel_in: tuple[float, float] = (9.0, 3.4),
) -> Figure:
    """Grouped bar charts of a table: ``categories`` on the x axis (objects, variants), one bar
    per group (method) in each category, one panel per metric.

    Args:
        categories: (C,) names along the x axis.
        panels: per panel ``(title, y_label, {group: (C,) values})``; None = no value (no bar).
        title: figure title; None = none.
        columns: panels per row.
        hatched: groups drawn hatched (e.g. the paper's published numbers beside the simulation).
        panel_in: size of one panel [in].
    """
    fig, axes = _new_figure(len(panels), columns, panel_in)
    x = np.arange(len(categories), dtype=np.float64)
    for ax, (panel_title, y_label, groups) in zip(axes, panels, strict=True):
        width = 0.8 / max(1, len(groups))
        for i, (name, values) in enumerate(groups.items()):
            if len(values) != len(categories):
                raise ValueError(
                    f"group {name!r} has {len(values)} values for {len(categories)} categories"
                )
            y = np.array([np.nan if v is None else float(v) for v in values])
            ax.bar(
                x + (i - (len(groups) - 1) / 2) * width,
                y,
                width,
                label=name,
                hatch="//" if name in hatched else None,
                edgecolor="white" if name not in hatched else "0.25",
                linewidth=0.5,
            )
        ax.set_xticks(x, [str(c) for c in categories], rotation=20, ha="right")
        _style(ax, Panel(title=panel_title, y_label=y_label), "", legend=False)
    handles, labels = axes[0].get_legend_handles_labels()
    if labels:  # one legend for every panel, beside them, so that no bar is hidden
        fig.legend(handles, labels, loc="outside right upper", fontsize=_FONT_SIZE_PT - 0.5)
    if title:
        fig.suptitle(title, fontsize=_FONT_SIZE_PT + 2)
    return fig


def save_figure(figure: Figure, path: str | Path) -> Path:
    """Writes ``figure`` as a PNG at :data:`DPI` atomically (parents created); returns the path."""
    path = Path(path)
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=DPI, metadata={"Software": None})
    atomic_write_bytes(path, buffer.getvalue())
    return path
