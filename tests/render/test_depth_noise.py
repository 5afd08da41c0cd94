"""Depth-noise models: statistics against their formulas, holes, determinism, no mutation."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.config_files import dataclass_from_mapping
from roft_sim.errors import ConfigError
from roft_sim.scene.config import RenderConfig
from roft_sim.sensors.depth_noise import (
    KinectAzureDepthNoise,
    NoDepthNoise,
    RealSenseDepthNoise,
    apply_depth_noise,
    kinect_azure_depth_noise,
    kinect_azure_depth_sigma_m,
    realsense_depth_noise,
    realsense_depth_sigma_m,
)


@pytest.mark.parametrize("z_m", [0.5, 1.0, 2.5])
def test_realsense_noise_follows_the_stereo_error_formula(z_m):
    depth = np.full((200, 300), z_m, np.float32)
    noisy = realsense_depth_noise(depth, np.random.default_rng(0), focal_px=900.0)
    expected = realsense_depth_sigma_m(z_m, focal_px=900.0)  # z^2 0.08 / (900 * 0.055)
    assert expected == pytest.approx(z_m**2 * 0.08 / (900 * 0.055))
    err = noisy[noisy > 0] - z_m
    assert err.std() == pytest.approx(expected, rel=0.03)
    assert abs(err.mean()) < 0.05 * expected + 1e-6


def test_realsense_range_limits_and_holes_stay_holes():
    depth = np.array([[0.0, 0.1, 0.5, 20.0]], np.float32)
    noisy = realsense_depth_noise(depth, np.random.default_rng(0), focal_px=600.0)
    assert noisy[0, 0] == 0 and noisy[0, 1] == 0 and noisy[0, 2] > 0 and noisy[0, 3] == 0


@pytest.mark.parametrize("z_m", [0.4, 1.0, 3.0])
def test_kinect_noise_follows_its_sigma(z_m):
    depth = np.full((200, 300), z_m, np.float32)
    noisy = kinect_azure_depth_noise(depth, np.random.default_rng(1))
    err = noisy[5:-5, 5:-5] - z_m
    expected = kinect_azure_depth_sigma_m(z_m)  # 0.5 mm, 1 mm at 1 m, 3 mm at 3 m
    assert err.std() == pytest.approx(expected, rel=0.03)


def test_kinect_holes_at_large_depth_jumps_and_dark_pixels_only():
    depth = np.full((40, 40), 0.8, np.float32)
    depth[:, 20:] = 2.0  # a 1.2 m jump: holes along it
    rgb = np.full((40, 40, 3), 128, np.uint8)
    rgb[5:10, 5:10] = 5  # dark patch
    noisy = kinect_azure_depth_noise(depth, np.random.default_rng(2), rgb=rgb)
    assert (noisy[:, 19:21] == 0).mean() > 0.9
    assert (noisy[5:10, 5:10] == 0).all()
    assert (noisy[12:, 2:17] > 0).all() and (noisy[:, 23:38] > 0).all()
    small_step = np.full((40, 40), 0.8, np.float32)
    small_step[:, 20:] = 1.2  # 0.4 m: no holes
    assert (kinect_azure_depth_noise(small_step, np.random.default_rng(2)) > 0).all()


def test_kinect_resampling_never_mixes_with_missing_depth():
    depth = np.zeros((50, 50), np.float32)
    depth[10:40, 10:40] = 1.0
    noisy = kinect_azure_depth_noise(depth, np.random.default_rng(3), shift_sigma_px=0.6)
    valid = noisy > 0
    assert np.abs(noisy[valid] - 1.0).max() < 0.01  # no value between 0 and 1 m


def test_apply_is_seeded_does_not_modify_its_input_and_dispatches():
    depth = np.random.default_rng(0).uniform(0.4, 1.5, (30, 40)).astype(np.float32)
    copy = depth.copy()
    for config in (RealSenseDepthNoise(), KinectAzureDepthNoise()):
        a = apply_depth_noise(config, depth, np.random.default_rng(7), fx_px=500.0)
        b = apply_depth_noise(config, depth, np.random.default_rng(7), fx_px=500.0)
        c = apply_depth_noise(config, depth, np.random.default_rng(8), fx_px=500.0)
        np.testing.assert_array_equal(a, b)
        assert not np.array_equal(a, c) and a.dtype == np.float32
    np.testing.assert_array_equal(depth, copy)
    exact = apply_depth_noise(NoDepthNoise(), depth, np.random.default_rng(0), fx_px=500.0)
    np.testing.assert_array_equal(exact, depth)
    assert exact is not depth
    focal = RealSenseDepthNoise(focal_px=2000.0, subpixel_px=0.5)
    lo = apply_depth_noise(focal, depth, np.random.default_rng(1), fx_px=100.0) - depth
    hi = apply_depth_noise(
        RealSenseDepthNoise(subpixel_px=0.5), depth, np.random.default_rng(1), fx_px=100.0
    )
    assert np.abs(lo).mean() < 0.2 * np.abs(hi[hi > 0] - depth[hi > 0]).mean()


def test_configs_load_by_kind_and_reject_bad_values():
    cfg = dataclass_from_mapping(
        RenderConfig, {"depth_noise": {"kind": "realsense", "baseline_m": 0.05}}
    )
    assert cfg.depth_noise == RealSenseDepthNoise(baseline_m=0.05)
    with pytest.raises(ConfigError, match="kind = 'kinect' is not known.*kinect_azure"):
        dataclass_from_mapping(RenderConfig, {"depth_noise": {"kind": "kinect"}})
    with pytest.raises(ConfigError, match="baseline_m must be a positive number"):
        RealSenseDepthNoise(baseline_m=0.0)
    with pytest.raises(ConfigError, match="max_range_m .* must exceed min_range_m"):
        RealSenseDepthNoise(min_range_m=2.0, max_range_m=1.0)
    with pytest.raises(ConfigError, match="dark_threshold must be 0 to 255"):
        KinectAzureDepthNoise(dark_threshold=300)
    with pytest.raises(ValueError, match="finite and >= 0"):
        realsense_depth_noise(np.full((2, 2), -1.0), np.random.default_rng(0), focal_px=1.0)
