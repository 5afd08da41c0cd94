"""``roft-sim preview SCENARIO --out preview.mp4|.avi|.gif``: a short video of a scenario, rgb |
depth | object mask | ground-truth flow side by side, to look at a scene before generating a
dataset. ``.mp4`` uses OpenCV's mp4v codec, ``.gif`` OpenCV's animated-image writer."""

from __future__ import annotations

import argparse
import logging
import os
from pathlib import Path

from roft_sim.cli.assets import assets_dir_from_args, cache_dir_from_args
from roft_sim.errors import ConfigError

__all__ = ["register"]


_log = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``preview``."""
    parser = subparsers.add_parser(
        "preview",
        help="write a short rgb | depth | mask | flow video of a scenario",
        description=__doc__.split("\n\n")[0].split(": ", 1)[-1] if __doc__ else None,
    )
    parser.add_argument("scenario", type=Path, help="scenario TOML file")
    parser.add_argument("--out", type=Path, required=True, help="video file: .mp4, .avi or .gif")
    parser.add_argument(
        "--frames", type=int, default=60, help="number of frames (default 60; 0 = all)"
    )
    parser.add_argument("--start", type=int, default=0, help="first frame (default 0)")
    parser.add_argument(
        "--scale",
        type=float,
        default=None,
        help="resize factor of each panel (default: 0.5 above 640 px wide, else 1)",
    )
    parser.add_argument(
        "--flow-max-px",
        type=float,
        default=None,
        help="flow magnitude shown at full colour [px] (default: from the first flow field)",
    )
    parser.add_argument(
        "--assets", type=Path, help="folder of real YCB meshes (default $ROFT_SIM_ASSETS)"
    )
    parser.add_argument(
        "--cache", type=Path, help="asset cache (default $ROFT_SIM_CACHE or ~/.cache/roft_sim)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roft_sim.render.gl_backend import require_gl_backend

    out: Path = args.out
    if out.exists() and not args.overwrite:
        raise ConfigError(f"{str(out)!r} exists; pass --overwrite to replace it")
    if not out.parent.is_dir():
        raise ConfigError(f"folder {str(out.parent)!r} of --out does not exist; create it first")
    if args.frames < 0:
        raise ConfigError(f"--frames must be >= 0 (0 = all), got {args.frames}")
    from roft_sim.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    assets_dir = assets_dir_from_args(args)
    backend = require_gl_backend(os.environ)  # before anything imports mujoco
    from roft_sim.render.preview import write_preview
    from roft_sim.render.scene_renderer import SceneRenderer

    cache_dir = cache_dir_from_args(args)
    scale = args.scale
    if scale is None:
        scale = 0.5 if scenario.intrinsics.width_px > 640 else 1.0
    _log.info("rendering %s with MUJOCO_GL=%s", scenario.name, backend)
    with SceneRenderer(scenario, assets_dir=assets_dir, cache_dir=cache_dir) as renderer:
        _log.info("object %s: %s mesh", scenario.object.name_or_path, renderer.object_assets.source)
        written = write_preview(
            renderer,
            out,
            frames=args.frames or None,
            start=args.start,
            scale=scale,
            flow_max_px=args.flow_max_px,
            progress=not args.no_progress,
        )
    print(f"wrote {written} frames to {out}")
    return 0
