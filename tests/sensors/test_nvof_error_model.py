"""The NVOF error model (flow spec ``nvof-model``): each error term against its own oracle."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import norm

from roft_sim.datasets.base import InMemorySequence
from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.records import FlowField
from roft_sim.sensors.flow_sources import (
    FLOW_SOURCE_SPECS,
    StoredFlowSource,
    frame_rng,
    make_flow_source,
)
from roft_sim.sensors.networks import FlowSetConfig, parse_generation_flow_source
from roft_sim.sensors.nvof_error_model import (
    NvofErrorModelConfig,
    NvofErrorModelFlowSource,
    nvof_error_model,
)

QUIET = NvofErrorModelConfig(sigma_px=0.0, relative_sigma=0.0, failure_rate_per_16px=0.0)
"""The model with its boundary jitter alone."""


def _uniform(h: int, w: int, u: float, v: float) -> np.ndarray:
    flow = np.empty((h, w, 2), np.float32)
    flow[..., 0], flow[..., 1] = u, v
    return flow


def test_smooth_motion_is_exact_up_to_the_quarter_pixel_whatever_the_jitter() -> None:
    exact = _uniform(64, 96, 3.3, -1.1)
    flow, valid = nvof_error_model(exact, QUIET, frame_rng(0, 0, 1))
    assert flow.shape == (16, 24, 2) and flow.dtype == np.float32 and valid.all()
    np.testing.assert_array_equal(flow[..., 0], 3.25)  # 3.3 on NVOF's 1/4 px steps
    np.testing.assert_array_equal(flow[..., 1], -1.0)


def test_a_static_scene_is_read_exactly_with_the_default_noise() -> None:
    flow, _ = nvof_error_model(
        np.zeros((64, 96, 2), np.float32), NvofErrorModelConfig(), frame_rng(3, 4, 5)
    )
    np.testing.assert_array_equal(flow, 0.0)


def test_motion_spills_across_a_boundary_with_the_gaussian_jitter_s_probability() -> None:
    # columns < 200 move 4 px right, the rest is static: a vertical motion boundary at x = 199.5
    h, w, edge = 400, 400, 200
    exact = np.zeros((h, w, 2), np.float32)
    exact[:, :edge, 0] = 4.0
    config = QUIET
    moving = np.zeros((h // 4, w // 4))
    for k in range(8):
        flow, _ = nvof_error_model(exact, config, frame_rng(1, k, k + 1))
        moving += flow[..., 0] == 4.0
    moving /= 8
    sigma = config.boundary_jitter_px
    for block in range(44, 56):
        centre = block * 4 + 1.5
        # the rounded jittered column lands left of the edge: centre + e <= edge - 0.5
        expected = norm.cdf((edge - 0.5 - centre) / sigma)
        n = h // 4 * 8
        assert (
            abs(moving[:, block].mean() - expected)
            < 4 * np.sqrt(expected * (1 - expected) / n) + 1e-3
        )
    # far from the boundary nothing spills
    assert moving[:, :40].min() == 1.0 and moving[:, 60:].max() == 0.0


def test_moving_blocks_get_the_stated_gaussian_error() -> None:
    config = dataclasses.replace(
        NvofErrorModelConfig(), failure_rate_per_16px=0.0, precision_px=1 / 32
    )
    exact = _uniform(400, 400, 2.0, 0.0)
    errors = np.concatenate(
        [
            (nvof_error_model(exact, config, frame_rng(2, k, k + 1))[0] - exact[::4, ::4]).reshape(
                -1, 2
            )
            for k in range(4)
        ]
    )
    speed = 2.0
    sigma = np.hypot(
        config.sigma_px * (1 - np.exp(-speed / config.static_speed_px)),
        config.relative_sigma * speed,
    )
    expected = np.sqrt(sigma**2 + (1 / 32) ** 2 / 12)  # plus the S10.5 rounding's
    assert np.allclose(errors.mean(axis=0), 0.0, atol=0.01)
    assert np.allclose(errors.std(axis=0), expected, rtol=0.05)


def test_large_displacements_fail_at_the_stated_rate_within_the_stated_disc() -> None:
    config = NvofErrorModelConfig(sigma_px=0.0, relative_sigma=0.0, failure_rate_per_16px=0.2)
    exact = _uniform(400, 400, 32.0, 0.0)  # twice 16 px: failure probability 0.4
    err = np.linalg.norm(
        nvof_error_model(exact, config, frame_rng(4, 0, 1))[0] - exact[::4, ::4], axis=2
    )
    failed = err > 0.2
    # a failure lands within 0.2 px of the truth with probability (0.2 / 32)^2: negligible
    assert abs(failed.mean() - 0.4) < 4 * np.sqrt(0.4 * 0.6 / failed.size)
    assert err.max() <= 32.0 + 0.125


def test_unknown_flow_gives_invalid_zero_blocks_and_known_blocks_stay_valid() -> None:
    exact = _uniform(16, 16, 1.0, 1.0)
    exact[:4, :4] = np.nan  # block (0, 0) has no known pixel
    exact[4:8, 4:6] = np.nan  # block (1, 1) has some
    flow, valid = nvof_error_model(exact, NvofErrorModelConfig(), frame_rng(0, 0, 1))
    assert not valid[0, 0] and valid.sum() == 15
    np.testing.assert_array_equal(flow[0, 0], 0.0)
    assert np.isfinite(flow).all()


def test_a_validity_mask_gives_the_same_blocks_as_nan_marked_unknown_flow() -> None:
    """``known_px`` (what the source passes for a per-pixel FlowField) is the NaN path's twin:
    the values under a False are never read, whatever they are."""
    rng = np.random.default_rng(5)
    config = NvofErrorModelConfig()
    for trial in range(30):
        h, w = (int(v) for v in rng.integers(5, 70, 2))
        exact = (rng.normal(0.0, 1.0, (h, w, 2)) * rng.choice([0.1, 5.0, 40.0])).astype(np.float32)
        known = rng.random((h, w)) > rng.choice([0.0, 0.1, 0.6])
        known[: rng.integers(0, h)] &= bool(rng.random() > 0.3)
        with_nan = np.where(known[..., None], exact, np.float32(np.nan))
        with_garbage = np.where(known[..., None], exact, np.float32(rng.choice([0.0, 1e30])))
        a = nvof_error_model(with_nan, config, frame_rng(3, trial, trial + 1))
        b = nvof_error_model(with_garbage, config, frame_rng(3, trial, trial + 1), known_px=known)
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
    with pytest.raises(ValueError, match="known_px"):
        nvof_error_model(exact, config, frame_rng(0, 0, 1), known_px=known[:-1])


def _sequence(exact: np.ndarray, n: int = 4) -> InMemorySequence:
    h, w = exact.shape[:2]
    cam = CameraIntrinsics(
        fx_px=100.0, fy_px=100.0, cx_px=w / 2, cy_px=h / 2, width_px=w, height_px=h
    )
    flows = [None] + [FlowField(flow_px=exact, from_k=k - 1, to_k=k) for k in range(1, n)]
    return InMemorySequence(
        name="seq",
        object_name="obj",
        intrinsics=cam,
        fps=30,
        rgb_frames=[np.zeros((h, w, 3), np.uint8)] * n,
        depth_frames=[np.ones((h, w), np.float32)] * n,
        flows={"gt": flows},
    )


def test_the_source_is_a_pure_function_of_seed_and_frame_pair() -> None:
    rng = np.random.default_rng(0)
    exact = rng.normal(0, 3, (32, 48, 2)).astype(np.float32)
    seq = _sequence(exact)
    a = NvofErrorModelFlowSource(seed=7, exact=StoredFlowSource("gt"))
    b = NvofErrorModelFlowSource(seed=7, exact=StoredFlowSource("gt"))
    later = a.flow(seq, 2, 3)
    b.flow(seq, 0, 1)  # another pair first changes nothing
    assert later is not None and later.grid_px == 4 and (later.from_k, later.to_k) == (2, 3)
    np.testing.assert_array_equal(later.flow_px, b.flow(seq, 2, 3).flow_px)  # type: ignore[union-attr]
    assert not np.array_equal(later.flow_px, a.flow(seq, 1, 2).flow_px)  # type: ignore[union-attr]
    other_seed = NvofErrorModelFlowSource(seed=8, exact=StoredFlowSource("gt")).flow(seq, 2, 3)
    assert not np.array_equal(later.flow_px, other_seed.flow_px)  # type: ignore[union-attr]
    assert a.flow(seq, 0, 2) is None  # a stored set has no stride 2


def test_the_spec_builds_the_source_and_rejects_arguments() -> None:
    assert "nvof-model" in FLOW_SOURCE_SPECS
    src = make_flow_source("nvof-model", seed=3)
    assert isinstance(src, NvofErrorModelFlowSource) and src.name == "nvof-model" and src.seed == 3
    with pytest.raises(ConfigError, match="unknown flow source 'nvof-model:2'"):
        make_flow_source("nvof-model:2", seed=0)


def test_generation_flow_sets_take_the_model_and_its_table() -> None:
    assert parse_generation_flow_source("nvof-model").kind == "nvof-model"
    with pytest.raises(ConfigError, match="nvof-like cannot wrap nvof-model"):
        parse_generation_flow_source("nvof-like:nvof-model")
    config = FlowSetConfig(
        set_name="hw_like",
        source="nvof-model",
        encoding="s10.5",
        nvof_model=NvofErrorModelConfig(boundary_jitter_px=2.0),
    )
    assert config.nvof_model.boundary_jitter_px == 2.0


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("boundary_jitter_px", -1.0, "boundary_jitter_px must be a finite number >= 0"),
        ("sigma_px", float("nan"), "sigma_px must be a finite number >= 0"),
        ("static_speed_px", 0.0, "static_speed_px must be > 0"),
        ("grid_px", 0, "grid_px must be >= 1"),
        ("precision_px", 0.1, "whole multiple of 1/32 px"),
    ],
)
def test_bad_parameters_say_what_was_given(field: str, value: float, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        NvofErrorModelConfig(**{field: value})  # type: ignore[arg-type]


def test_by_default_the_exact_flow_is_the_stored_gt_set_else_the_rigid_motion_field() -> None:
    exact = _uniform(32, 48, 2.0, 1.0)
    seq = _sequence(exact)
    default = NvofErrorModelFlowSource(seed=1).flow(seq, 0, 1)
    stored = NvofErrorModelFlowSource(seed=1, exact=StoredFlowSource("gt")).flow(seq, 0, 1)
    assert default is not None and stored is not None
    np.testing.assert_array_equal(default.flow_px, stored.flow_px)
    # stride 2 has no stored flow: the rigid motion field, which needs ground-truth poses
    with pytest.raises(ConfigError, match="no ground-truth poses"):
        NvofErrorModelFlowSource(seed=1).flow(seq, 0, 2)
