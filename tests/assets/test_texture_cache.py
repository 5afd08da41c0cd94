"""The texture disk cache: a hit gives the drawn image AND leaves the generator where drawing
would have left it; anything that determines the image is part of the key."""

from __future__ import annotations

import numpy as np

import roft_sim.scene.textures
from roft_sim.assets.texture_cache import cached_texture, texture_cache_key
from roft_sim.scene.textures import procedural_texture


class _CountingDraw:
    def __init__(self, style: str = "wood", size_px: int = 64) -> None:
        self.calls = 0
        self.style, self.size_px = style, size_px

    def __call__(self, rng: np.random.Generator) -> np.ndarray:
        self.calls += 1
        return procedural_texture(self.style, self.size_px, rng)


def _two_textures(cache_dir, draw):
    """What the scene builder does: two textures from one generator, then more draws."""
    rng = np.random.default_rng(11)
    code = roft_sim.scene.textures
    first = cached_texture(cache_dir, "a", {"size": 64}, rng, draw, code=code)
    second = cached_texture(cache_dir, "b", {"size": 64}, rng, draw, code=code)
    return first, second, rng.random(4)


def test_a_hit_equals_drawing_and_moves_the_generator_on_as_drawing_does(tmp_path):
    reference = _two_textures(None, _CountingDraw())
    cold_draw, warm_draw = _CountingDraw(), _CountingDraw()
    cold = _two_textures(tmp_path, cold_draw)
    warm = _two_textures(tmp_path, warm_draw)
    assert cold_draw.calls == 2 and warm_draw.calls == 0
    for got in (cold, warm):
        for a, b in zip(got, reference, strict=True):
            np.testing.assert_array_equal(a, b)
    assert len(list((tmp_path / "textures").glob("*.png"))) == 2


def test_the_key_holds_the_parameters_the_generator_state_and_the_code():
    rng = np.random.default_rng(1)
    code = roft_sim.scene.textures
    key = texture_cache_key("t", {"size": 64}, rng, code)
    assert key == texture_cache_key("t", {"size": 64}, np.random.default_rng(1), code)
    assert key != texture_cache_key("t", {"size": 65}, rng, code)
    assert key != texture_cache_key("t", {"size": 64}, np.random.default_rng(2), code)
    assert key != texture_cache_key("t", {"size": 64}, rng, np)  # other drawing code


def test_a_damaged_entry_is_drawn_again(tmp_path):
    draw = _CountingDraw()
    reference = _two_textures(tmp_path, draw)
    for png in (tmp_path / "textures").glob("*.png"):
        png.write_bytes(b"not a png")
    again = _two_textures(tmp_path, draw)
    assert draw.calls == 4
    for a, b in zip(again, reference, strict=True):
        np.testing.assert_array_equal(a, b)
