"""The colour pipe of the flow-picture statistics, on hand-made flows with a known halo."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from roft_sim.sensors.flow_picture import (
    fast_ycb_readme_panels,
    flow_picture_stats,
    middlebury_wheel,
    relative_flow_from_rgb,
    rgb_from_flow,
    thumbnail,
)

H, W = 360, 640
"""A 16:9 frame, shrunk 2.56 times to the README panels' 250 px width."""


def _box_scene() -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 2) flow [px]: a 160x120 px box moving by (6, -3) px on a static background,
    and its (H, W) float mask."""
    mask = np.zeros((H, W))
    mask[120:240, 240:400] = 1.0
    flow = np.zeros((H, W, 2))
    flow[mask > 0] = (6.0, -3.0)
    return flow, mask


def _stats(flow: np.ndarray, mask: np.ndarray):
    return flow_picture_stats(thumbnail(rgb_from_flow(flow), 250), thumbnail(mask, 250))


def test_the_wheel_is_the_middlebury_one():
    wheel = middlebury_wheel()
    assert wheel.shape == (55, 3)
    # segment starts: red, yellow, green, cyan, blue, magenta (colorcode.cpp, flow_vis)
    for index, colour in (
        (0, (1, 0, 0)),
        (15, (1, 1, 0)),
        (21, (0, 1, 0)),
        (25, (0, 1, 1)),
        (36, (0, 0, 1)),
        (49, (1, 0, 1)),
    ):
        np.testing.assert_allclose(wheel[index], colour)
    assert (wheel.max(axis=1) == 1).all() and (wheel.min(axis=1) == 0).all()


def test_colours_decode_back_to_the_flow_over_its_largest_vector():
    flow = np.random.default_rng(0).normal(0.0, 5.0, (30, 40, 2))
    rel = relative_flow_from_rgb(rgb_from_flow(flow))
    largest = np.hypot(flow[..., 0], flow[..., 1]).max()
    np.testing.assert_allclose(rel, flow / largest, atol=0.01)
    # flow_vis: rightwards is red, zero is white
    rgb = rgb_from_flow(np.array([[[1.0, 0.0], [0.0, 0.0]]]))
    np.testing.assert_array_equal(rgb[0], [[255, 0, 0], [255, 255, 255]])


def test_a_sharp_flow_shows_only_the_shrink_and_a_smoothed_one_a_halo():
    flow, mask = _box_scene()
    sharp = _stats(flow, mask)
    # nothing outside but the shrink's partial pixels, full flow two rings in
    assert sharp.outside_rings[0] < 0.3 and max(sharp.outside_rings[1:]) < 0.01
    assert sharp.inside_rings[1:] == pytest.approx((1.0, 1.0, 1.0), abs=0.02)
    assert sharp.interior_residual < 0.02 and sharp.spurious_fraction == 0.0
    # a Gaussian smoothing of 8 px (3 thumbnail px) spreads the flow over the boundary
    smooth = _stats(cv2.GaussianBlur(flow, (0, 0), 8.0), mask)
    assert smooth.outside_rings[1] > 0.2 and smooth.outside_rings[2] > 0.05
    assert smooth.inside_rings[0] < sharp.inside_rings[0] - 0.05
    assert smooth.outside_rings[0] > sharp.outside_rings[0] + 0.1


def test_blotches_and_background_blobs_are_counted():
    flow, mask = _box_scene()
    noisy = flow.copy()
    rng = np.random.default_rng(1)
    noisy[mask > 0] += cv2.resize(rng.normal(0.0, 2.0, (12, 16, 2)), (W, H))[mask > 0]
    noisy[10:40, 20:60] = (5.0, 0.0)  # a spurious blob on the static background
    stats = _stats(noisy, mask)
    assert stats.interior_residual > 0.1
    far_px = stats.background_pixels
    blob_px = (30 / 2.56) * (40 / 2.56)
    assert stats.spurious_fraction == pytest.approx(blob_px / far_px, rel=0.3)


def test_a_rotation_is_not_a_blotch_nor_a_halo():
    """The rings and the residual are read against the interior's affine field."""
    _, mask = _box_scene()
    yy, xx = np.indices((H, W), dtype=np.float64)
    flow = np.stack([0.05 * (yy - 180.0) + 4.0, -0.05 * (xx - 320.0)], axis=2) * mask[..., None]
    stats = _stats(flow, mask)
    assert stats.interior_residual < 0.03 and stats.interior_magnitude_cv > 0.2
    assert max(stats.outside_rings[1:]) < 0.01


def test_readme_panels_are_cut_out_and_checked():
    figure = np.zeros((141, 1000, 3), np.uint8)
    figure[:, 500:750] = 255
    figure[50:90, 850:900] = 255
    flow, mask = fast_ycb_readme_panels(figure)
    assert flow.shape == (141, 246, 3) and (flow == 255).all()
    assert mask.shape == (141, 246) and mask.sum() == 40 * 50
    with pytest.raises(ValueError, match="four 250 px panels"):
        fast_ycb_readme_panels(figure[:, :900])
