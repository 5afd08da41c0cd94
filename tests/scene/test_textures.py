"""Procedural textures: deterministic, detailed everywhere, seamless when tiled."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from roft_sim.errors import ConfigError
from roft_sim.scene.config import TEXTURE_STYLES
from roft_sim.scene.textures import periodic_noise, procedural_texture


@pytest.mark.parametrize("style", TEXTURE_STYLES)
def test_texture_is_deterministic_and_detailed_everywhere(style):
    a = procedural_texture(style, 256, np.random.default_rng(5))
    b = procedural_texture(style, 256, np.random.default_rng(5))
    c = procedural_texture(style, 256, np.random.default_rng(6))
    assert a.shape == (256, 256, 3) and a.dtype == np.uint8
    np.testing.assert_array_equal(a, b)
    assert np.abs(a.astype(int) - c).mean() > 5
    grey = cv2.cvtColor(a, cv2.COLOR_RGB2GRAY).astype(np.float64)
    grad = np.hypot(cv2.Sobel(grey, cv2.CV_64F, 1, 0), cv2.Sobel(grey, cv2.CV_64F, 0, 1))
    blocks = grad.reshape(32, 8, 32, 8).mean(axis=(1, 3))
    assert (blocks > 4.0).mean() > 0.95, "flow needs texture in (nearly) every 8x8 block"


@pytest.mark.parametrize("style", TEXTURE_STYLES)
def test_texture_tiles_without_a_seam(style):
    """The wrap-around step (last column -> first column) is no larger than the largest step
    between adjacent columns inside the tile (same for rows)."""
    img = procedural_texture(style, 256, np.random.default_rng(1)).astype(np.float64)
    for axis in (0, 1):
        steps = np.abs(np.diff(img, axis=axis, append=np.take(img, [0], axis=axis)))
        per_line = steps.mean(axis=tuple(a for a in (0, 1, 2) if a != axis))
        assert per_line[-1] <= 1.05 * per_line[:-1].max(), f"axis {axis}"
        assert per_line[-1] <= 3.0 * np.median(per_line[:-1]) or style in ("wood", "fabric")


def test_periodic_noise_is_periodic_and_normalised():
    n = periodic_noise(64, np.random.default_rng(0), sigma_px=3.0)
    assert abs(n.mean()) < 1e-12 and abs(n.std() - 1) < 1e-12
    rolled = np.roll(n, 1, axis=1)
    assert np.abs(rolled - n)[:, 0].mean() < 2 * np.abs(rolled - n)[:, 1:].mean()


def test_bad_style_and_size_are_errors():
    with pytest.raises(ConfigError, match="unknown texture style 'marble'"):
        procedural_texture("marble", 64, np.random.default_rng(0))
    with pytest.raises(ConfigError, match=">= 16 px"):
        procedural_texture("wood", 8, np.random.default_rng(0))
