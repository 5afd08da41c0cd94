"""End-point errors per kind of pixel against hand-made flows with known errors."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.datasets.base import InMemorySequence
from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.records import FlowField
from roft_sim.sensors.flow_accuracy import (
    flow_error_breakdown,
    flow_pixel_categories,
    sequence_flow_errors,
)

H, W = 40, 60


def _field(flow: np.ndarray, valid=None, grid_px: int = 1) -> FlowField:
    return FlowField(
        flow_px=flow.astype(np.float32), from_k=0, to_k=1, grid_px=grid_px, valid=valid
    )


def _scene():
    """Left half static, right half moving by (20, 0) px; textured except a flat top band."""
    truth = np.zeros((H, W, 2))
    truth[:, 30:, 0] = 20.0
    grey = np.random.default_rng(0).uniform(0, 255, (H, W))
    grey[:8] = 128.0
    return truth, grey


def test_categories_find_the_boundary_the_large_motion_and_the_flat_band():
    truth, grey = _scene()
    cats = flow_pixel_categories(truth, grey, None, boundary_px=2)
    assert cats["motion_boundary"][:, 27:33].all() and not cats["motion_boundary"][:, :27].any()
    assert not cats["motion_boundary"][:, 33:].any()
    assert cats["large_displacement"][:, 30:].all() and not cats["large_displacement"][:, :30].any()
    assert cats["low_texture"][:4].all() and not cats["low_texture"][15:].any()


def test_errors_land_in_the_category_they_were_put_in():
    truth, grey = _scene()
    estimate = truth.copy()
    estimate[:, 29:31, 0] = 10.0  # a block mixing both motions: 10 px off on 2 columns
    summary = flow_error_breakdown(_field(estimate), _field(truth), grey)
    assert summary["all"].pixels == H * W
    assert summary["all"].mean_epe_px == pytest.approx(10.0 * 2 / W)
    boundary = flow_pixel_categories(truth, grey, None)["motion_boundary"]
    assert summary["motion_boundary"].pixels == boundary.sum()
    assert summary["motion_boundary"].mean_epe_px == pytest.approx(10.0 * 2 * H / boundary.sum())
    assert summary["motion_boundary"].fl_pct == pytest.approx(100.0 * 2 * H / boundary.sum())
    assert summary["low_texture"].pixels == 4 * W  # the 9-px window leaves the flat band at row 4


def test_fl_needs_both_3_px_and_5_percent_and_invalid_estimates_are_counted_apart():
    truth = np.full((H, W, 2), 100.0)  # |F| = 141 px: 5 % is 7.1 px
    estimate = truth + np.array([4.0, 0.0])  # 4 px: > 3 px but < 5 %
    valid = np.ones((H, W), bool)
    valid[:10] = False
    grey = np.random.default_rng(1).uniform(0, 255, (H, W))
    s = flow_error_breakdown(_field(estimate, valid), _field(truth), grey)["all"]
    assert s.fl_pct == 0.0 and s.mean_epe_px == pytest.approx(4.0)
    assert s.pixels == 30 * W and s.invalid_pct == pytest.approx(25.0)
    worse = flow_error_breakdown(_field(truth + 10.0), _field(truth), grey)["all"]
    assert worse.fl_pct == 100.0


def test_grid_estimates_are_read_as_consumers_read_them_and_pairs_must_match():
    truth, grey = _scene()
    coarse = truth[::4, ::4]
    s = flow_error_breakdown(_field(coarse, grid_px=4), _field(truth), grey)["all"]
    # block 7 (columns 28-31) holds column 28's vector: columns 30 and 31 are 20 px off
    assert s.mean_epe_px == pytest.approx(20.0 * 2 / W)
    other = FlowField(flow_px=truth.astype(np.float32), from_k=1, to_k=2)
    with pytest.raises(ConfigError, match="same frame pair"):
        flow_error_breakdown(other, _field(truth), grey)


class _TwoFrames:
    """The part of a Sequence that sequence_flow_errors reads: frames 0 and 1, one flow."""

    name = "two_frames"

    def __init__(self, estimate: np.ndarray, truth: np.ndarray, grey: np.ndarray) -> None:
        self._flows = {
            "est": FlowField(flow_px=estimate.astype(np.float32), from_k=0, to_k=1),
            "gt": FlowField(flow_px=truth.astype(np.float32), from_k=0, to_k=1),
        }
        self._rgb = np.repeat(grey.astype(np.uint8)[..., None], 3, axis=2)

    def __len__(self) -> int:
        return 2

    def flow_sets(self) -> tuple[str, ...]:
        return tuple(self._flows)

    def flow(self, k: int, flow_set: str) -> FlowField | None:
        return self._flows[flow_set] if k == 1 else None

    def rgb(self, k: int) -> np.ndarray:
        return self._rgb

    def mask_sets(self) -> tuple[str, ...]:
        return ()


def test_sequence_errors_pool_the_frame_pairs_and_name_missing_sets():
    from roft_sim.sensors.flow_accuracy import sequence_flow_errors

    truth, grey = _scene()
    grey = np.round(grey)
    estimate = truth + 0.5
    seq = _TwoFrames(estimate, truth, grey)
    pooled = sequence_flow_errors(seq, "est", "gt")  # type: ignore[arg-type]
    single = flow_error_breakdown(_field(estimate), _field(truth), grey)
    assert pooled == single
    with pytest.raises(ConfigError, match="no flow set 'nvof_1_slow'"):
        sequence_flow_errors(seq)  # type: ignore[arg-type]


def _pair(flow: np.ndarray, k: int) -> FlowField:
    return FlowField(flow_px=flow.astype(np.float32), from_k=k - 1, to_k=k)


def test_sequence_errors_pool_the_frames_and_use_the_stored_mask():
    """Three frames: the estimate is 2 px off on frame pair 0->1 and 6 px off on 1->2, on the
    right half only; the ground-truth masks cover that half, so ``object`` sees every error."""
    truth = np.zeros((H, W, 2))
    off_1, off_2 = truth.copy(), truth.copy()
    off_1[:, 30:, 0] = 2.0
    off_2[:, 30:, 1] = 6.0
    mask = np.zeros((H, W), bool)
    mask[:, 30:] = True
    grey = np.random.default_rng(2).uniform(0, 255, (H, W)).astype(np.uint8)
    sequence = InMemorySequence(
        name="pooled",
        object_name="none",
        intrinsics=CameraIntrinsics(
            fx_px=50.0, fy_px=50.0, cx_px=29.5, cy_px=19.5, width_px=W, height_px=H
        ),
        fps=30,
        rgb_frames=[np.repeat(grey[..., None], 3, axis=2)] * 3,
        depth_frames=[np.ones((H, W), np.float32)] * 3,
        gt_masks=[mask] * 3,
        flows={
            "gt": [None, _pair(truth, 1), _pair(truth, 2)],
            "estimate": [None, _pair(off_1, 1), _pair(off_2, 2)],
        },
    )
    summary = sequence_flow_errors(sequence, "estimate", "gt")
    assert summary["all"].pixels == 2 * H * W
    assert summary["all"].mean_epe_px == pytest.approx((2.0 + 6.0) / 4)
    assert summary["object"].pixels == 2 * H * 30
    assert summary["object"].mean_epe_px == pytest.approx((2.0 + 6.0) / 2)
    assert summary["object"].fl_pct == pytest.approx(50.0)  # only the 6 px pair is > 3 px
    only_second = sequence_flow_errors(sequence, "estimate", "gt", frames=[2])
    assert only_second["object"].mean_epe_px == pytest.approx(6.0)
    with pytest.raises(ConfigError, match="no flow set 'nvof_1_slow'; it has gt, estimate"):
        sequence_flow_errors(sequence, "nvof_1_slow", "gt")
