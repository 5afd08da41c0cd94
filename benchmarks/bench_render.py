"""Render + ground-truth throughput of SceneRenderer on this machine's OpenGL backend.

The scene is the default one (textured table and wall, two lights) with a Fast-YCB object (the
procedural stand-in unless ``--assets DIR`` holds real YCB meshes) on fast synthetic motion, seen
by the Fast-YCB camera (55 deg horizontal field of view) at each resolution. Each mode renders
``--frames`` consecutive frames; frames/s is frames / wall time, and the printed value is the
median over ``--repeats`` runs (after one warm-up frame).

Modes:
- ``rgb+depth``: colour and z-depth, no segmentation (one render pass);
- ``+seg``: plus geom-id segmentation, object mask and body index (two passes): a full
  ground-truth frame except flow;
- ``+seg+flow``: plus exact ground-truth flow from the previous frame;
- ``+seg+flow, msaa4+shadows``: the same with 4x MSAA and shadows (the nicer images).

    python benchmarks/bench_render.py                      # 640x480 and 1280x720
    python benchmarks/bench_render.py --frames 10 --repeats 2 --sizes 640x480
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

from roft_sim.render.gl_backend import require_gl_backend

BACKEND = require_gl_backend(os.environ)  # before anything imports mujoco

import numpy as np  # noqa: E402

from roft_sim.assets import load_object  # noqa: E402
from roft_sim.render import SceneRenderer, ground_truth_flow  # noqa: E402
from roft_sim.scenario import CameraConfig, ObjectConfig, Scenario  # noqa: E402
from roft_sim.scene.config import RenderConfig  # noqa: E402
from roft_sim.trajectories import SyntheticMotionConfig  # noqa: E402

HFOV_RAD = np.radians(55.0)


def scenario_at(width: int, height: int, frames: int, render: RenderConfig) -> Scenario:
    f = width / (2 * np.tan(HFOV_RAD / 2))
    return Scenario(
        name=f"bench_{width}x{height}",
        camera=CameraConfig(
            width_px=width,
            height_px=height,
            fx_px=f,
            fy_px=f,
            cx_px=(width - 1) / 2,
            cy_px=(height - 1) / 2,
            fps=30,
        ),
        object=ObjectConfig(name="003_cracker_box"),
        trajectory=SyntheticMotionConfig(seed=7, duration_s=max(2.0, (frames + 2) / 30 + 0.1)),
        render=render,
        seed=7,
        frames=frames + 1,
    )


def run_mode(renderer: SceneRenderer, frames: int, flow: bool) -> float:
    """Frames per second over frames 1..frames (frame 0 renders first, untimed)."""
    previous = renderer.render_frame(0)
    start = time.perf_counter()
    for k in range(1, frames + 1):
        frame = renderer.render_frame(k)
        if flow:
            ground_truth_flow(previous, frame, renderer.intrinsics)
        previous = frame
    return frames / (time.perf_counter() - start)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=20, help="frames per run (default 20)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per mode (default 3)")
    parser.add_argument(
        "--sizes", nargs="+", default=["640x480", "1280x720"], help="WIDTHxHEIGHT (default both)"
    )
    parser.add_argument("--assets", type=Path, help="folder of real YCB meshes")
    parser.add_argument("--object", default="003_cracker_box", help="registry name")
    args = parser.parse_args(argv)

    assets = load_object(args.object, assets_dir=args.assets)
    print(
        f"MUJOCO_GL={BACKEND}; object {args.object} ({assets.source}, "
        f"{len(assets.mesh.faces)} faces, texture {assets.mesh.texture_rgb.shape[1]}x"
        f"{assets.mesh.texture_rgb.shape[0]}); {args.frames} frames x {args.repeats} runs, "
        "median frames/s"
    )
    modes = [
        ("rgb+depth", RenderConfig(), False, False),
        ("+seg", RenderConfig(), True, False),
        ("+seg+flow", RenderConfig(), True, True),
        ("+seg+flow, msaa4+shadows", RenderConfig(msaa_samples=4, shadows=True), True, True),
    ]
    print(f"{'size':>10} {'mode':<26} {'frames/s':>9} {'ms/frame':>9}")
    for size in args.sizes:
        width, height = (int(v) for v in size.lower().split("x"))
        for label, render, segmentation, flow in modes:
            scenario = scenario_at(width, height, args.frames, render)
            rates = []
            with SceneRenderer(
                scenario, object_assets=assets, segmentation=segmentation
            ) as renderer:
                for _ in range(args.repeats):
                    rates.append(run_mode(renderer, args.frames, flow))
            fps = statistics.median(rates)
            print(f"{size:>10} {label:<26} {fps:9.1f} {1000 / fps:9.1f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
