"""PNG encoding time and size of the images a generated frame writes, per encoder.

The one source of docs/formats.md's "PNG compression" numbers. Renders ``--frames`` frames of the
generation benchmark's workload (bench_generate.py: the Fast-YCB-like cracker box, default
scenario, procedural stand-in) at ``--resolution``, then encodes each frame's rgb, visible mask
and depth (as BOP's 16-bit 0.1 mm PNG) with:

- ``roft_sim level L``: :mod:`roft_sim.datasets.image_files` at level L (1-3: written here and
  deflated by ISA-L; 4-9: OpenCV's libpng and zlib);
- ``libpng level 1 (before)``: OpenCV with the parameters roft_sim used at level 1 before round
  16 (rgb: Up filter, zlib's run-length strategy; masks: no filter, run-length; 16-bit: libpng's
  defaults), the baseline of the ratios.

Time is CPU time of this thread (``time.thread_time``), so the machine's load hardly changes it;
each cell is the median over ``--repeats`` rounds of the mean per frame; bytes are the mean per
frame. Every encoding is decoded by OpenCV and compared with the image before it is timed.

    python benchmarks/bench_png.py
    python benchmarks/bench_png.py --resolution 1280x720 --frames 8 --repeats 5
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_generate import _scenario  # noqa: E402

from roft_sim.datasets.image_files import (  # noqa: E402
    encode_png_mask,
    encode_png_rgb,
    encode_png_u16,
)

_PREVIOUS_RGB = [
    cv2.IMWRITE_PNG_COMPRESSION, 1,
    cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_UP,
    cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE,
]  # fmt: skip
_PREVIOUS_MASK = [
    cv2.IMWRITE_PNG_COMPRESSION, 1,
    cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE,
    cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE,
]  # fmt: skip
_PREVIOUS_U16 = [cv2.IMWRITE_PNG_COMPRESSION, 1]


def _libpng(image: np.ndarray, params: list[int]) -> bytes:
    ok, buf = cv2.imencode(".png", image, params)
    assert ok
    return buf.tobytes()


def rendered_images(
    resolution: tuple[int, int], frames: int
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(rgb (H, W, 3) uint8, visible mask (H, W) bool, depth (H, W) uint16 [0.1 mm]) per frame."""
    from roft_sim.render import SceneRenderer

    images = []
    with SceneRenderer(_scenario(resolution), segmentation=True) as renderer:
        for k in range(frames):
            f = renderer.render_frame(k)
            assert f.object_mask is not None
            depth = np.round(np.clip(f.depth_m, 0.0, 6.5535) * 1e4).astype(np.uint16)
            images.append((f.rgb, f.object_mask, depth))
    return images


Encoders = tuple[Callable[..., bytes], Callable[..., bytes], Callable[..., bytes]]
"""(rgb, mask, u16) encoders."""


def encoders() -> dict[str, Encoders]:
    """name -> (rgb, mask, u16) encoders."""
    out: dict[str, Encoders] = {
        "libpng level 1 (before)": (
            lambda rgb: _libpng(np.ascontiguousarray(rgb[..., ::-1]), _PREVIOUS_RGB),
            lambda m: _libpng(m.view(np.uint8) * np.uint8(255), _PREVIOUS_MASK),
            lambda d: _libpng(d, _PREVIOUS_U16),
        )
    }
    for level in (1, 2, 3, 6):
        out[f"roft_sim level {level}"] = (
            lambda rgb, lv=level: encode_png_rgb(rgb, level=lv),
            lambda m, lv=level: encode_png_mask(m, level=lv),
            lambda d, lv=level: encode_png_u16(d, level=lv),
        )
    return out


def _check(data: bytes, want: np.ndarray) -> None:
    got = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert got is not None and (got == want).all(), "an encoder changed the pixels"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--resolution", default="640x480", help="WxH (default 640x480)")
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--repeats", type=int, default=7)
    args = p.parse_args(argv)
    w, h = (int(v) for v in args.resolution.lower().split("x"))
    cv2.setNumThreads(1)
    images = rendered_images((w, h), args.frames)
    table = encoders()
    kinds = ("rgb", "mask", "depth u16")
    for coders in table.values():
        for rgb, mask, depth in images[:2]:
            _check(coders[0](rgb), rgb[..., ::-1])
            _check(coders[1](mask), mask.view(np.uint8) * np.uint8(255))
            _check(coders[2](depth), depth)
    times: dict[tuple[str, str], list[float]] = {}
    sizes: dict[tuple[str, str], float] = {}
    for _ in range(args.repeats):
        for name, coders in table.items():
            for kind, encode, index in zip(kinds, coders, range(3), strict=True):
                t0, n = time.thread_time(), 0
                for frame in images:
                    n += len(encode(frame[index]))
                times.setdefault((name, kind), []).append((time.thread_time() - t0) / len(images))
                sizes[(name, kind)] = n / len(images)
    base = "libpng level 1 (before)"
    print(
        f"{w}x{h}, {len(images)} rendered frames, medians of {args.repeats} rounds "
        "(CPU ms per image, kB per image, time ratio to the first row)"
    )
    for kind in kinds:
        print(f"-- {kind}")
        t_base = statistics.median(times[(base, kind)])
        for name in table:
            t = statistics.median(times[(name, kind)])
            print(f"  {name:28s} {1e3 * t:8.2f} ms {sizes[(name, kind)] / 1e3:9.1f} kB"
                  f" {t / t_base:6.2f}x")  # fmt: skip


if __name__ == "__main__":
    main()
