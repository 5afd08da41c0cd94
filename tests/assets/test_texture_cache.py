"""The texture disk cache: a hit gives the drawn image AND leaves the generator where drawing
would have left it; anything that determines the image is part of the key."""

from __future__ import annotations

import io

import numpy as np
import pytest

import roft_sim.scene.textures
from roft_sim.assets.texture_cache import (
    cached_texture,
    load_cached_image,
    save_cached_image,
    texture_cache_key,
)
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
    assert len(list((tmp_path / "textures").glob("*.npy"))) == 2


def test_the_key_holds_the_parameters_the_generator_state_and_the_code():
    rng = np.random.default_rng(1)
    code = roft_sim.scene.textures
    key = texture_cache_key("t", {"size": 64}, rng, code)
    assert key == texture_cache_key("t", {"size": 64}, np.random.default_rng(1), code)
    assert key != texture_cache_key("t", {"size": 65}, rng, code)
    assert key != texture_cache_key("t", {"size": 64}, np.random.default_rng(2), code)
    assert key != texture_cache_key("t", {"size": 64}, rng, np)  # other drawing code


@pytest.mark.parametrize(
    "damage",
    [
        lambda data: b"not an npy file",
        lambda data: data[:-100],  # cut short
        lambda data: _npy_bytes(np.zeros((4, 4), dtype=np.uint8)),  # not an (H, W, 3) image
        lambda data: _npy_bytes(np.zeros((4, 4, 3), dtype=np.float32)),  # not uint8
    ],
)
def test_a_damaged_entry_is_drawn_again(tmp_path, damage):
    draw = _CountingDraw()
    reference = _two_textures(tmp_path, draw)
    for entry in (tmp_path / "textures").glob("*.npy"):
        entry.write_bytes(damage(entry.read_bytes()))
    again = _two_textures(tmp_path, draw)
    assert draw.calls == 4
    for a, b in zip(again, reference, strict=True):
        np.testing.assert_array_equal(a, b)
    _two_textures(tmp_path, draw)  # the entry was written again: a hit
    assert draw.calls == 4


def _npy_bytes(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def test_the_cache_file_is_the_raw_image_and_reads_back_bit_for_bit(tmp_path):
    image = np.random.default_rng(2).integers(0, 256, (37, 53, 3), dtype=np.uint8)
    path = tmp_path / "x.npy"
    save_cached_image(path, image)
    back = load_cached_image(path)
    assert back is not None and back.dtype == np.uint8 and back.flags.c_contiguous
    np.testing.assert_array_equal(back, image)
    np.testing.assert_array_equal(np.load(path, allow_pickle=False), image)
    assert load_cached_image(tmp_path / "absent.npy") is None


def test_an_entry_of_the_earlier_png_format_is_drawn_again_and_removed(tmp_path):
    """Earlier versions wrote <name>-<key>.png beside the same state file: such an entry is a
    miss (drawn, written as .npy), and its PNG is deleted."""
    draw = _CountingDraw()
    reference = _two_textures(tmp_path, draw)
    for entry in (tmp_path / "textures").glob("*.npy"):
        entry.with_suffix(".png").write_bytes(b"an old PNG entry")
        entry.unlink()
    again = _two_textures(tmp_path, draw)
    assert draw.calls == 4
    for a, b in zip(again, reference, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not list((tmp_path / "textures").glob("*.png"))
    assert len(list((tmp_path / "textures").glob("*.npy"))) == 2
