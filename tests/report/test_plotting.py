"""matplotlib figures: what each panel draws (read back from the artists), labels with units,
legends, event lines, bar groups, and the PNG written at 100 dpi."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from matplotlib.lines import Line2D

from roft_sim.report.plotting import (
    DPI,
    EVENT_COLOR,
    Panel,
    Series,
    bar_figure,
    line_figure,
    save_figure,
)


def _panel(label: str = "roft") -> Panel:
    return Panel(
        title="position error",
        y_label="position error [cm]",
        series=(Series(x=[0, 1, 2, 3], y=[1.0, 2.0, np.nan, 4.0], label=label),),
    )


def test_line_figure_draws_the_data_with_labels_units_and_legend():
    figure = line_figure([_panel(), _panel("naive")], x_label="frame", title="seq")
    first, second = figure.axes
    assert first.get_xlabel() == "frame" and first.get_ylabel() == "position error [cm]"
    assert first.get_title() == "position error" and figure.get_suptitle() == "seq"
    (line,) = first.get_lines()
    np.testing.assert_array_equal(line.get_xdata(), [0, 1, 2, 3])
    np.testing.assert_array_equal(line.get_ydata(), [1.0, 2.0, np.nan, 4.0])  # NaN = a gap
    assert [t.get_text() for t in second.get_legend().get_texts()] == ["naive"]


def test_events_are_vertical_lines_in_every_panel_with_one_legend_entry():
    arrivals = [6.0, 12.0, 18.0]
    figure = line_figure([_panel(), _panel()], x_label="frame", events_x=arrivals)
    for ax in figure.axes:
        events = [
            ln for ln in ax.get_lines() if isinstance(ln, Line2D) and ln.get_color() == EVENT_COLOR
        ]
        assert sorted(float(ln.get_xdata()[0]) for ln in events) == arrivals
        for ln in events:  # vertical: the same x at both ends, spanning the axes' height
            assert ln.get_xdata()[0] == ln.get_xdata()[1]
        texts = [t.get_text() for t in ax.get_legend().get_texts()]
        assert texts.count("pose arrives") == 1 and "roft" in texts


def test_markers_and_integer_ticks_for_parameter_curves():
    panel = Panel(
        title="ADD-AUC vs delay",
        y_label="ADD-AUC [%]",
        series=(
            Series(x=[0, 3, 6], y=[90, 80, 70], label="roft"),
            Series(x=[0, 3, 6], y=[60, 50, 40], label="hold"),
        ),
        y_range=(0.0, 100.0),
    )
    figure = line_figure([panel], x_label="delay [frames]", markers=True, integer_x=True)
    ax = figure.axes[0]
    markers = [ln.get_marker() for ln in ax.get_lines()]
    assert markers[0] != markers[1] and "None" not in markers
    assert ax.get_ylim() == (0.0, 100.0)
    figure.canvas.draw()
    ticks = ax.get_xticks()
    np.testing.assert_array_equal(ticks, np.round(ticks))


def test_bar_figure_groups_and_hatches():
    figure = bar_figure(
        ["cracker", "ALL"],
        [("ADD-AUC", "ADD-AUC [%]", {"sim": [80.0, None], "paper": [78.5, 76.6]})],
        hatched=["paper"],
    )
    ax = figure.axes[0]
    bars = ax.patches
    assert len(bars) == 4
    heights = [b.get_height() for b in bars]
    np.testing.assert_array_equal(heights[:2], [80.0, np.nan])  # None: no bar
    assert heights[2:] == [78.5, 76.6]
    assert not bars[0].get_hatch() and bars[2].get_hatch() == "//"
    assert [t.get_text() for t in ax.get_xticklabels()] == ["cracker", "ALL"]
    assert [t.get_text() for t in figure.legends[0].get_texts()] == ["sim", "paper"]


def test_save_figure_writes_a_png_of_the_figure_size(tmp_path):
    figure = line_figure([_panel()], x_label="frame", columns=1, panel_in=(4.0, 3.0))
    path = save_figure(figure, tmp_path / "sub" / "plot.png")
    image = cv2.imread(str(path))
    assert image.shape == (3 * DPI, 4 * DPI, 3)
    assert not list(path.parent.glob(".*tmp"))  # written atomically, no temp file left


def test_bad_arguments():
    with pytest.raises(ValueError, match="same length"):
        Series(x=[0, 1], y=[0])
    with pytest.raises(ValueError, match="y_range"):
        Panel(title="t", y_label="y", y_range=(1.0, 1.0))
    with pytest.raises(ValueError, match="at least one panel"):
        line_figure([], x_label="x")
    with pytest.raises(ValueError, match="2 categories"):
        bar_figure(["a", "b"], [("t", "y", {"g": [1.0]})])
