"""Content faults (pose outliers, mask corruption) and camera faults (depth, flow), applied to
single detections and frames. Oracles: geometry by hand, scipy.ndimage morphology, np.roll."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import ndimage

from roft_sim.errors import ConfigError
from roft_sim.faults import (
    CorruptionContext,
    DepthHoles,
    DepthNoise,
    EmptyMask,
    FlowHoles,
    FlowNoise,
    FlowReversed,
    MaskMorphology,
    MaskShift,
    RotationFlip,
    SpuriousBlobs,
    TranslationJump,
    WrongFrameMask,
    WrongObject,
)
from roft_sim.faults.camera import affected_frames
from roft_sim.geometry.camera import CameraIntrinsics, project_points
from roft_sim.geometry.so3 import rotation_angle
from roft_sim.records import FlowField
from roft_sim.testing.strategies import transforms

K = CameraIntrinsics(
    fx_px=500.0, fy_px=500.0, cx_px=319.5, cy_px=239.5, width_px=640, height_px=480
)
CTX = CorruptionContext(intrinsics=K, n_frames=50, read_mask=lambda k: None)
seeds = st.integers(0, 2**32 - 1)


def draw_one(fault, seed=0, capture=10, n_frames=50):
    """Parameters of the first hit among many runs (p is set high by the caller)."""
    captures = np.full(200, capture, dtype=np.int64)
    params = fault.draw(captures, np.random.default_rng(seed), n_frames)
    return next(p for p in params if p is not None)


# ------------------------------------------------------------------ pose outliers


@given(transforms(), seeds)
def test_translation_jump_moves_only_the_translation_by_a_bounded_amount(T, seed):
    fault = TranslationJump(p=1.0, min_m=0.1, max_m=0.3)
    out = fault.apply_pose(T, draw_one(fault, seed), CTX)
    jump = np.linalg.norm(out[:3, 3] - T[:3, 3])
    assert 0.1 - 1e-12 <= jump <= 0.3 + 1e-12
    np.testing.assert_array_equal(out[:3, :3], T[:3, :3])


@given(transforms(), seeds, st.sampled_from(["x", "y", "z"]))
def test_rotation_flip_is_a_half_turn_about_an_object_axis(T, seed, axis):
    fault = RotationFlip(p=1.0, axes=(axis,))
    out = fault.apply_pose(T, draw_one(fault, seed), CTX)
    assert rotation_angle(out[:3, :3], T[:3, :3]) == pytest.approx(np.pi, abs=1e-9)
    # the flip axis, an object axis, is fixed by the flip: its column keeps its direction
    i = "xyz".index(axis)
    np.testing.assert_allclose(out[:3, i], T[:3, i], atol=1e-12)
    np.testing.assert_array_equal(out[:3, 3], T[:3, 3])


@given(seeds)
def test_wrong_object_lies_at_the_drawn_pixel_and_depth(seed):
    fault = WrongObject(p=1.0, min_depth_m=0.4, max_depth_m=0.9)
    params = draw_one(fault, seed)
    out = fault.apply_pose(np.eye(4), params, CTX)
    uv = project_points(K, out[:3, 3])
    expected = np.array(params["uv_rel"]) * [K.width_px - 1, K.height_px - 1]
    np.testing.assert_allclose(uv, expected, atol=1e-9)
    assert 0.4 <= out[2, 3] <= 0.9
    np.testing.assert_allclose(out[:3, :3] @ out[:3, :3].T, np.eye(3), atol=1e-12)


def test_outlier_probability_is_respected():
    fault = TranslationJump(p=0.2)
    params = fault.draw(np.arange(5000), np.random.default_rng(3), 5000)
    hits = sum(p is not None for p in params)
    assert 0.2 * 5000 - 4 * np.sqrt(5000 * 0.16) <= hits <= 0.2 * 5000 + 4 * np.sqrt(5000 * 0.16)


# ------------------------------------------------------------------ masks


def square_mask(h=24, w=32, box=(8, 14, 10, 18)):
    m = np.zeros((h, w), dtype=bool)
    m[box[0] : box[1], box[2] : box[3]] = True
    return m


@given(seeds)
def test_mask_shift_equals_a_zero_filled_roll(seed):
    fault = MaskShift(p=1.0, min_px=1, max_px=6)
    params = draw_one(fault, seed)
    mask = square_mask()
    out = fault.apply_mask(mask, params, CTX)
    du, dv = params["du_px"], params["dv_px"]
    assert (du, dv) != (0, 0) and np.hypot(du, dv) <= 6.5
    padded = np.pad(mask, 10)
    expected = np.roll(np.roll(padded, dv, axis=0), du, axis=1)[10:-10, 10:-10]
    np.testing.assert_array_equal(out, expected)
    assert mask.sum() == 6 * 8  # input untouched


@pytest.mark.parametrize("radius", [-2, -1, 0, 1, 3])
def test_mask_morphology_matches_scipy(radius):
    fault = MaskMorphology(p=1.0, min_radius_px=radius, max_radius_px=radius)
    mask = square_mask()
    mask[0:3, 0:3] = True  # touches the border: outside counts as background
    out = fault.apply_mask(mask, {"radius_px": radius}, CTX)
    r = abs(radius)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)).astype(bool)
    if radius > 0:
        expected = ndimage.binary_dilation(mask, structure=kernel)
    elif radius < 0:
        expected = ndimage.binary_erosion(mask, structure=kernel, border_value=0)
    else:
        expected = mask
    np.testing.assert_array_equal(out, expected)


def test_empty_mask_blobs_and_wrong_frame():
    mask = square_mask()
    assert not EmptyMask(p=1.0).apply_mask(mask, {}, CTX).any()
    blobs = SpuriousBlobs(p=1.0, max_count=3, min_radius_px=2, max_radius_px=4)
    out = blobs.apply_mask(mask, draw_one(blobs), CTX)
    assert (out >= mask).all() and out.sum() > mask.sum()  # a superset with more pixels
    other = square_mask(box=(0, 4, 0, 4))
    ctx = CorruptionContext(
        intrinsics=K, n_frames=50, read_mask=lambda k: other if k == 7 else None
    )
    wrong = WrongFrameMask(p=1.0, max_offset_frames=3)
    np.testing.assert_array_equal(wrong.apply_mask(mask, {"source_k": 7}, ctx), other)
    assert not wrong.apply_mask(mask, {"source_k": 8}, ctx).any()  # a miss there: empty


@given(seeds, st.integers(0, 49), st.integers(1, 10))
def test_wrong_frame_source_is_another_frame_in_range(seed, capture, max_offset):
    fault = WrongFrameMask(p=1.0, max_offset_frames=max_offset)
    source = draw_one(fault, seed, capture=capture)["source_k"]
    assert 0 <= source < 50 and source != capture and abs(source - capture) <= max_offset


# ------------------------------------------------------------------ camera


@given(st.floats(0, 1), st.integers(1, 8), seeds)
def test_affected_frames_cover_whole_bursts(p, burst, seed):
    starts_rng, rng = np.random.default_rng(seed), np.random.default_rng(seed)
    starts = starts_rng.random(200) < p
    hit = affected_frames(200, p, burst, rng)
    expected = np.zeros(200, dtype=bool)
    for k in np.flatnonzero(starts):
        expected[k : k + burst] = True
    np.testing.assert_array_equal(hit, expected)


def test_depth_holes_zero_only_inside_holes_and_copy():
    depth = np.full((48, 64), 0.8, dtype=np.float32)
    fault = DepthHoles(p=1.0, max_count=2, min_radius_px=3, max_radius_px=6)
    out = fault.apply_depth(depth, {"seed": 4})
    assert out.dtype == np.float32 and out.shape == depth.shape
    assert 0 < (out == 0).sum() <= 2 * np.pi * 6 * 6 + 20
    assert set(np.unique(out).tolist()) <= {0.0, np.float32(0.8)}
    assert (depth == np.float32(0.8)).all()  # input untouched


def test_depth_noise_statistics_and_holes_stay_holes():
    depth = np.full((200, 200), 1.0, dtype=np.float32)
    depth[:10] = 0.0
    out = DepthNoise(p=1.0, sd_m=0.01).apply_depth(depth, {"seed": 1})
    assert (out[:10] == 0).all()
    assert np.std(out[10:] - 1.0) == pytest.approx(0.01, rel=0.03)
    assert abs(np.mean(out[10:] - 1.0)) < 3 * 0.01 / np.sqrt(out[10:].size)


def test_flow_faults():
    f = np.zeros((12, 16, 2), dtype=np.float32)
    f[..., 0] = 2.0
    flow = FlowField(flow_px=f, from_k=3, to_k=4, grid_px=4)
    noisy = FlowNoise(p=1.0, sd_px=0.5).apply_flow(flow, {"seed": 2})
    assert np.std(noisy.flow_px - f) == pytest.approx(0.5, rel=0.15)
    holes = FlowHoles(p=1.0, min_radius_px=4, max_radius_px=8).apply_flow(flow, {"seed": 3})
    assert holes.valid is not None and 0 < (~holes.valid).sum() < holes.valid.size
    flipped = FlowReversed(p=1.0).apply_flow(flow, {})
    np.testing.assert_array_equal(flipped.flow_px, -f)
    backward = FlowField(flow_px=-f, from_k=4, to_k=3)
    relabelled = FlowReversed(p=1.0, mode="backward").apply_flow(backward, {"backward": True})
    assert (relabelled.from_k, relabelled.to_k) == (3, 4)
    np.testing.assert_array_equal(relabelled.flow_px, -f)
    assert (flow.flow_px == f).all() and flow.valid is None  # input untouched


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: TranslationJump(p=1.5), r"p must be a probability in \[0, 1\], got 1.5"),
        (lambda: TranslationJump(min_m=0.3, max_m=0.1), "max_m .* must be >= min_m"),
        (lambda: RotationFlip(axes=()), "at least one object axis"),
        (lambda: MaskShift(min_px=0), "min_px must be >= 1"),
        (lambda: MaskMorphology(min_radius_px=3, max_radius_px=1), "swap them"),
        (lambda: WrongFrameMask(max_offset_frames=0), "max_offset_frames must be >= 1"),
        (lambda: DepthNoise(sd_m=0.0), "sd_m must be finite and > 0"),
        (lambda: DepthHoles(burst_frames=0), "burst_frames must be >= 1"),
        (lambda: WrongObject(min_depth_m=0.0), "min_depth_m must be finite and > 0"),
    ],
)
def test_bad_content_and_camera_parameters(make, match):
    with pytest.raises(ConfigError, match=match):
        make()
