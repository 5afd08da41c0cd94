"""Golden images of the renderer: rgb, depth and object mask of the three CI scenes at 96x72,
compared with the files in ``tests/golden/<backend>/`` (one folder per OpenGL backend, since EGL
and OSMesa rasterise differently).

Tolerances (a real regression exceeds them, see
:func:`test_the_tolerances_catch_a_one_frame_pose_shift`): rgb RMS <= 2 grey levels; depth RMS
<= 1 mm over the pixels both images see; object masks differ on <= 0.2 % of the pixels. On a
failure the expected, actual and difference images are written to
``tests/golden/failures/<backend>/`` (ignored by git). Regenerate after an intended change with

    pytest tests/render/test_golden_images.py --update-golden

and look at the new images before committing them.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from roft_sim.datasets import GT_MASK_SET
from roft_sim.datasets.atomic_files import atomic_write_bytes
from roft_sim.datasets.image_files import (
    decode_png_mask,
    decode_png_rgb,
    decode_png_u16,
    encode_png_mask,
    encode_png_rgb,
    encode_png_u16,
)

GOLDEN_DIR = Path(__file__).resolve().parent.parent / "golden"
SCENES = ("cracker_box", "mustard_hand_moving_camera", "tomato_off_centre_blur")
N_FRAMES = 12
"""Frames rendered per scene (the same renders serve every test of this module)."""
FRAMES = (0, 11)
"""The frames compared: the first and the last."""
RESOLUTION = (96, 72)
RGB_RMS_TOL = 2.0
"""Largest RMS difference of the rgb images [grey levels, 0-255]."""
DEPTH_RMS_TOL_M = 1e-3
"""Largest RMS depth difference over the pixels both images see [m]."""
MASK_TOL_FRACTION = 0.002
"""Largest share of pixels whose object-mask label differs."""
DEPTH_PNG_SCALE = 10_000
"""Depth is stored as uint16 PNG in units of 0.1 mm (up to 6.55 m)."""

pytestmark = pytest.mark.render


def _rgb_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)))


def _depth_rms_m(a: np.ndarray, b: np.ndarray) -> float:
    both = (a > 0) & (b > 0)
    return float(np.sqrt(np.mean((a[both] - b[both]) ** 2))) if both.any() else 0.0


def _mask_fraction(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.mean(a != b))


def _depth_to_png(depth_m: np.ndarray) -> bytes:
    return encode_png_u16(np.round(depth_m.astype(np.float64) * DEPTH_PNG_SCALE).astype(np.uint16))


def _write_failure(folder: Path, name: str, expected: np.ndarray, actual: np.ndarray) -> None:
    """expected / actual / amplified absolute difference, as PNGs, for a human to look at."""
    if expected.dtype == bool:
        expected, actual = expected.astype(np.uint8) * 255, actual.astype(np.uint8) * 255
    elif expected.dtype != np.uint8:  # depth: scale to grey levels over the scene's range
        far = float(max(expected.max(), actual.max(), 1e-6))
        expected = np.round(255 * expected / far).astype(np.uint8)
        actual = np.round(255 * actual / far).astype(np.uint8)
    diff = np.clip(4 * np.abs(expected.astype(np.int16) - actual.astype(np.int16)), 0, 255)

    def rgb(image: np.ndarray) -> np.ndarray:
        return image if image.ndim == 3 else np.repeat(image[..., None], 3, axis=2)

    for kind, image in (("expected", expected), ("actual", actual), ("diff", diff)):
        data = encode_png_rgb(np.ascontiguousarray(rgb(image.astype(np.uint8))))
        atomic_write_bytes(folder / f"{name}_{kind}.png", data)


@pytest.fixture(scope="module")
def backend() -> str:
    return os.environ.get("MUJOCO_GL", "unknown")


@pytest.mark.parametrize(
    "scene",
    # the box runs by default; the other two scenes (about 15 s each) with --run-slow
    [SCENES[0], *(pytest.param(s, marks=pytest.mark.slow) for s in SCENES[1:])],
)
def test_renders_match_the_golden_images(scene, rendered_sequence_factory, backend, request):
    sequence = rendered_sequence_factory(scene, frames=N_FRAMES, resolution=RESOLUTION)
    folder = GOLDEN_DIR / backend
    update = request.config.getoption("--update-golden")
    failures = []
    for k in FRAMES:
        actual = {
            "rgb": np.asarray(sequence.rgb(k)),
            "depth": np.asarray(sequence.depth(k), dtype=np.float32),
            "mask": np.asarray(sequence.mask(k, GT_MASK_SET), dtype=bool),
        }
        paths = {kind: folder / f"{scene}_k{k}_{kind}.png" for kind in actual}
        if update:
            atomic_write_bytes(paths["rgb"], encode_png_rgb(actual["rgb"]))
            atomic_write_bytes(paths["depth"], _depth_to_png(actual["depth"]))
            atomic_write_bytes(paths["mask"], encode_png_mask(actual["mask"]))
            continue
        if not paths["rgb"].is_file():
            pytest.skip(
                f"no golden images for backend {backend!r} in {folder}; create them with "
                "pytest tests/render/test_golden_images.py --update-golden"
            )
        expected = {
            "rgb": decode_png_rgb(paths["rgb"].read_bytes(), paths["rgb"]),
            "depth": decode_png_u16(paths["depth"].read_bytes(), paths["depth"]).astype(np.float32)
            / DEPTH_PNG_SCALE,
            "mask": decode_png_mask(paths["mask"].read_bytes(), paths["mask"]),
        }
        checks = (
            ("rgb", _rgb_rms(expected["rgb"], actual["rgb"]), RGB_RMS_TOL, "grey levels RMS"),
            (
                "depth",
                _depth_rms_m(expected["depth"], actual["depth"]),
                DEPTH_RMS_TOL_M,
                "m RMS",
            ),
            (
                "mask",
                _mask_fraction(expected["mask"], actual["mask"]),
                MASK_TOL_FRACTION,
                "of pixels differ",
            ),
        )
        for kind, error, tolerance, unit in checks:
            if error > tolerance:
                name = f"{scene}_k{k}_{kind}"
                _write_failure(
                    GOLDEN_DIR / "failures" / backend, name, expected[kind], actual[kind]
                )
                failures.append(f"{name}: {error:.4g} {unit} > {tolerance:g}")
    if failures:
        pytest.fail(
            "renders differ from tests/golden/"
            + backend
            + " (expected/actual/diff PNGs in tests/golden/failures/"
            + backend
            + "; regenerate with --update-golden if the change is intended): "
            + "; ".join(failures)
        )


def test_the_tolerances_catch_a_one_frame_pose_shift(rendered_sequence_factory):
    """A regression as small as rendering the object one frame (33 ms) off in time exceeds every
    tolerance on the fast-moving CI box, so the comparison cannot pass a broken renderer."""
    sequence = rendered_sequence_factory("cracker_box", frames=N_FRAMES, resolution=RESOLUTION)
    shifted = (N_FRAMES - 2, N_FRAMES - 1)
    rgb0, rgb1 = (np.asarray(sequence.rgb(k)) for k in shifted)
    depth0, depth1 = (np.asarray(sequence.depth(k), dtype=np.float32) for k in shifted)
    mask0, mask1 = (np.asarray(sequence.mask(k, GT_MASK_SET), dtype=bool) for k in shifted)
    assert _rgb_rms(rgb0, rgb1) > RGB_RMS_TOL
    assert _depth_rms_m(depth0, depth1) > DEPTH_RMS_TOL_M
    assert _mask_fraction(mask0, mask1) > MASK_TOL_FRACTION
