"""Hierarchical block matching (roft_sim.sensors.block_matching)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from roft_sim.datasets.base import InMemorySequence
from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.sensors.block_matching import (
    BlockMatchingConfig,
    BlockMatchingFlowSource,
    block_matching_flow,
)
from roft_sim.sensors.flow_sources import NvofLikeFlowSource, make_flow_source

H_PX, W_PX = 96, 128
MARGIN_PX = 24


def _texture(seed: int, h: int = H_PX + 2 * MARGIN_PX, w: int = W_PX + 2 * MARGIN_PX) -> np.ndarray:
    """(h, w) float32 blurred random texture, grey levels 0..255."""
    rng = np.random.default_rng(seed)
    noise = rng.uniform(0.0, 255.0, (h, w)).astype(np.float32)
    return cv2.GaussianBlur(noise, (0, 0), 1.5)


def _moved(img: np.ndarray, dx_px: float, dy_px: float) -> np.ndarray:
    """``img`` translated by (dx, dy): out(p + d) = img(p) (bicubic)."""
    h, w = img.shape
    shift = np.float32([[1, 0, dx_px], [0, 1, dy_px]])
    return cv2.warpAffine(img, shift, (w, h), flags=cv2.INTER_CUBIC)


def _crop(img: np.ndarray) -> np.ndarray:
    return img[MARGIN_PX : MARGIN_PX + H_PX, MARGIN_PX : MARGIN_PX + W_PX]


@pytest.mark.parametrize("d_px", [(3.0, -2.0), (1.25, 0.5), (-0.75, 0.25), (13.5, 6.75)])
def test_translation_is_recovered_within_a_quarter_pixel(d_px: tuple[float, float]) -> None:
    base = _texture(0)
    f = block_matching_flow(_crop(base), _crop(_moved(base, *d_px)))
    assert f.shape == (H_PX // 4, W_PX // 4, 2)
    # blocks whose 8x8 window lands inside the image in both frames (the others match parts
    # of the frame that moved out of view)
    left, top = 4 * np.arange(W_PX // 4) - 2, 4 * np.arange(H_PX // 4) - 2
    cols = (left >= 0) & (left + d_px[0] >= 0) & (left + 8 + np.ceil(d_px[0]) <= W_PX)
    cols &= left + 8 <= W_PX
    rows = (top >= 0) & (top + d_px[1] >= 0) & (top + 8 + np.ceil(d_px[1]) <= H_PX)
    rows &= top + 8 <= H_PX
    inner = f[np.ix_(rows, cols)]
    assert inner.size >= 0.5 * f.size
    err_px = np.abs(inner - np.array(d_px)).max()
    assert err_px <= 0.25


def test_boundary_block_gets_one_of_its_motions_not_their_average() -> None:
    """Left of column 64 a texture moves (-5, -2) px, right of it another texture is static
    (and shows where the left one left): every block, those whose window straddles the boundary
    included, gets one of the two motions (DIS smooths across such a boundary; a block mean
    would give a mix)."""
    left_d, right_d = np.array([-5.0, -2.0]), np.array([0.0, 0.0])
    a, b = _texture(1), _texture(2)
    cut = MARGIN_PX + W_PX // 2
    frame0 = np.where(np.arange(a.shape[1]) < cut, a, b)
    moved = _moved(a, *left_d)
    covered = np.arange(a.shape[1]) < cut + left_d[0]  # where the moving half went
    frame1 = np.where(covered, moved, b)
    f = block_matching_flow(_crop(frame0), _crop(frame1))
    err_left = np.abs(f - left_d).max(axis=2)
    err_right = np.abs(f - right_d).max(axis=2)
    one_of_them = np.minimum(err_left, err_right) <= 0.25
    rows = slice(2, -2)  # away from the top and bottom borders
    # the first two block columns match pixels that left the image
    assert one_of_them[rows, 2:].all(), np.argwhere(~one_of_them[rows, 2:])
    col = (W_PX // 2) // 4  # first block column right of the boundary
    n = f[rows].shape[0]
    np.testing.assert_array_equal(f[rows, col - 1], np.tile(left_d, (n, 1)))  # 6/8 moving
    np.testing.assert_array_equal(f[rows, col], np.tile(right_d, (n, 1)))  # 6/8 static


def test_bad_inputs_fail_with_a_clear_message() -> None:
    grey = np.zeros((32, 32), np.uint8)
    with pytest.raises(ValueError, match="same shape"):
        block_matching_flow(grey, np.zeros((32, 40), np.uint8))
    with pytest.raises(ValueError, match="grey"):
        block_matching_flow(np.zeros((32, 32, 3), np.uint8), grey)
    with pytest.raises(ValueError, match="NaN"):
        block_matching_flow(np.full((32, 32), np.nan, np.float32), grey)
    with pytest.raises(ConfigError, match="window_px"):
        BlockMatchingConfig(window_px=7)


def test_spec_bm_and_its_nvof_like_form_give_quarter_pixel_vectors() -> None:
    base = _texture(3, 64, 80)
    frames = np.stack([np.repeat(img[..., None], 3, 2) for img in (base, _moved(base, 2.5, 1))])
    cam = CameraIntrinsics(
        fx_px=80.0, fy_px=80.0, cx_px=39.5, cy_px=31.5, width_px=80, height_px=64
    )
    seq = InMemorySequence(
        name="shift",
        object_name="texture",
        intrinsics=cam,
        fps=30,
        rgb_frames=list(np.clip(frames, 0, 255).astype(np.uint8)),
        depth_frames=list(np.ones((2, 64, 80), np.float32)),
    )
    bm = make_flow_source("bm", seed=0)
    assert isinstance(bm, BlockMatchingFlowSource)
    nvof = make_flow_source("nvof-like:bm", seed=0)
    assert isinstance(nvof, NvofLikeFlowSource)
    raw, quantised = bm.flow(seq, 0, 1), nvof.flow(seq, 0, 1)
    assert raw.grid_px == 4 and quantised is not None and quantised.grid_px == 4
    np.testing.assert_array_equal(quantised.flow_px, raw.flow_px)  # already on 1/4 px steps
    np.testing.assert_array_equal(np.rint(raw.flow_px * 4) / 4, raw.flow_px)
    assert np.median(np.abs(raw.flow_px - np.array([2.5, 1.0])), axis=(0, 1)).max() <= 0.25


def test_spec_bm_window_and_its_errors() -> None:
    src = make_flow_source("bm:16", seed=0)
    assert isinstance(src, BlockMatchingFlowSource)
    assert src.config.window_px == 16 and src.name == "bm:16"
    assert make_flow_source("nvof-like:bm", seed=0).name == "nvof-like:bm"
    with pytest.raises(ConfigError, match="whole number"):
        make_flow_source("bm:x", seed=0)
    with pytest.raises(ConfigError, match="window_px"):
        make_flow_source("bm:7", seed=0)
