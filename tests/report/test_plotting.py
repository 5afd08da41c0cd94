"""OpenCV line plots: nice ticks, the axis mapping, lines, markers, legend, PNG output."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from roft_sim.report.plotting import LinePlot, nice_ticks, save_png, stack_images, tick_labels


@pytest.mark.parametrize(
    ("lo", "hi", "expected"),
    [
        (0.0, 9.3, [0, 2, 4, 6, 8, 10]),
        (0.13, 0.87, [0, 0.2, 0.4, 0.6, 0.8, 1.0]),
        (-3.0, 47.0, [-10, 0, 10, 20, 30, 40, 50]),
        (0.0, 12.0, [0.0, 2.5, 5.0, 7.5, 10.0, 12.5]),
        (5.0, 5.0, [4.4, 4.6, 4.8, 5.0, 5.2, 5.4, 5.6]),  # widened by 10 %: step 1/5 of 1.0
        (0.0, 0.0, [-1.0, -0.5, 0.0, 0.5, 1.0]),
    ],
)
def test_nice_ticks_hand_cases(lo, hi, expected):
    np.testing.assert_allclose(nice_ticks(lo, hi), expected, atol=1e-12)


def test_integer_ticks_are_whole_numbers():
    np.testing.assert_array_equal(nice_ticks(0, 12, integer=True), [0, 5, 10, 15])
    np.testing.assert_array_equal(nice_ticks(0, 3, integer=True), [0, 1, 2, 3])


@given(
    st.floats(-1e6, 1e6, allow_nan=False),
    st.floats(1e-4, 1e4, allow_nan=False),
    st.integers(2, 12),
)
def test_nice_ticks_cover_the_range_evenly(lo, relative_span, max_ticks):
    hi = lo + relative_span * max(1.0, abs(lo))  # spans a plot can show (>= 1e-4 of the values)
    ticks = nice_ticks(lo, hi, max_ticks=max_ticks)
    step = ticks[1] - ticks[0]
    assert ticks[0] <= lo + 1e-9 * max(1, abs(lo)) and ticks[-1] >= hi - 1e-9 * max(1, abs(hi))
    np.testing.assert_allclose(np.diff(ticks), step, rtol=1e-6, atol=1e-9 * max(1, abs(hi)))
    mantissa = step / 10 ** np.floor(np.log10(step))
    assert min(abs(mantissa - m) for m in (1, 2, 2.5, 5, 10)) < 1e-6
    assert len(ticks) <= 2 * max_ticks + 1


def test_tick_labels_use_just_enough_decimals():
    assert tick_labels([0, 2.5, 5, 7.5]) == ["0.0", "2.5", "5.0", "7.5"]
    assert tick_labels([0, 10, 20]) == ["0", "10", "20"]
    assert tick_labels([0.1, 0.2]) == ["0.1", "0.2"]


def test_nice_ticks_reject_bad_ranges():
    with pytest.raises(ValueError, match="lo <= hi"):
        nice_ticks(2.0, 1.0)
    with pytest.raises(ValueError, match="finite"):
        nice_ticks(0.0, float("inf"))


def test_axis_mapping_puts_limits_on_the_frame():
    plot = LinePlot(width_px=400, height_px=300, x_range=(0.0, 10.0), y_range=(-1.0, 1.0))
    left, top, right, bottom = plot.plot_area_px
    u, v = plot.data_to_px([0.0, 10.0, 5.0], [-1.0, 1.0, 0.0])
    np.testing.assert_allclose(u, [left, right, (left + right) / 2])
    np.testing.assert_allclose(v, [bottom, top, (top + bottom) / 2])


@pytest.mark.parametrize("marker", ["o", "s", "^", "d", "x"])
def test_a_marker_lands_on_the_pixel_the_mapping_predicts(marker):
    color = (10, 200, 30)
    plot = LinePlot(width_px=420, height_px=320, title="t", x_label="x", y_label="y")
    x, y = np.array([1.0, 4.0, 7.5]), np.array([2.0, -3.0, 11.0])
    plot.add_line(x, y, marker=marker, line=False, color=color)
    image = plot.render()
    u, v = plot.data_to_px(x, y)
    for ui, vi in zip(u, v, strict=True):
        assert tuple(image[int(round(vi)), int(round(ui))]) == color
    # the axis limits are nice numbers around the data
    assert plot.x_limits == (0.0, 8.0) and plot.y_limits[0] <= -3.0 and plot.y_limits[1] >= 11.0


def test_lines_follow_the_data_and_break_at_nan():
    color = (200, 20, 20)
    plot = LinePlot(width_px=400, height_px=300, x_range=(0.0, 4.0), y_range=(0.0, 4.0))
    plot.add_line([0, 1, 2, 3, 4], [1, 1, np.nan, 3, 3], color=color, width_px=3)
    image = plot.render()

    def colour_at(x, y):
        u, v = plot.data_to_px(x, y)
        return image[int(round(float(v))), int(round(float(u)))]

    assert tuple(colour_at(0.5, 1.0)) == color  # on the first segment
    assert tuple(colour_at(3.5, 3.0)) == color  # on the last segment
    # nothing drawn across the gap (between x = 1 and 3 at any height the line would pass)
    gap = [tuple(colour_at(2.0, y)) for y in np.linspace(0.5, 3.5, 7)]
    assert color not in gap


def test_events_span_the_plot_height():
    plot = LinePlot(width_px=400, height_px=300, x_range=(0.0, 10.0), y_range=(0.0, 1.0))
    plot.add_events([5.0], color=(0, 0, 250))
    image = plot.render()
    u, _ = plot.data_to_px(5.0, 0.0)
    _, top, _, bottom = plot.plot_area_px
    column = image[top + 2 : bottom - 1, int(round(float(u)))]
    assert (column[:, 2] > 150).all() and (column[:, 0] < 120).all()


def test_legend_avoids_the_data():
    plot = LinePlot(width_px=400, height_px=300, x_range=(0.0, 10.0), y_range=(0.0, 10.0))
    plot.add_line([0, 10], [9, 9], label="a long legend label")  # across the top
    plot.add_line([0, 3], [1, 1], label="b")  # bottom left
    image = plot.render()
    left, top, right, bottom = plot.plot_area_px
    frame = np.all(image == 180, axis=2)  # the legend's grey frame
    assert not frame[top : (top + bottom) // 2].any()
    assert frame[(top + bottom) // 2 : bottom, (left + right) // 2 : right].any()


def test_save_png_round_trip_and_stacking(tmp_path):
    a = LinePlot(width_px=300, height_px=200).add_line([0, 1], [0, 1]).render()
    b = LinePlot(width_px=250, height_px=200).add_line([0, 1], [1, 0]).render()
    both = stack_images([a, b], direction="horizontal")
    assert both.shape == (200, 550, 3)
    tall = stack_images([a, b])
    assert tall.shape == (400, 300, 3) and (tall[200:, 250:] == 255).all()
    path = save_png(tmp_path / "p" / "plot.png", both)
    back = cv2.imread(str(path))[..., ::-1]
    np.testing.assert_array_equal(back, both)


def test_bad_plot_arguments():
    with pytest.raises(ValueError, match="at least"):
        LinePlot(width_px=50, height_px=300)
    with pytest.raises(ValueError, match="x_range"):
        LinePlot(x_range=(1.0, 1.0))
    plot = LinePlot()
    with pytest.raises(ValueError, match="same length"):
        plot.add_line([0, 1], [0])
    with pytest.raises(ValueError, match="unknown marker"):
        plot.add_line([0], [0], marker="*")
