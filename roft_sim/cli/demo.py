"""``roft-sim demo --out DIR``: the main job on the embedded default, no files needed.

For now the trajectory tour: generate the default synthetic hand-like motion, print its speed
statistics and write it (sampled at 30 fps) with its config into DIR. Later issues extend the
demo to the full pipeline (render, track, score).
"""

from __future__ import annotations

import argparse
import json
import logging
import platform
from pathlib import Path

import numpy as np
import scipy

from roft_sim import __version__
from roft_sim.cli.output_dirs import prepare_output_dir
from roft_sim.cli.trajectory import format_speed_table
from roft_sim.config_files import jsonable
from roft_sim.trajectories import (
    FAST_YCB_CAMERA,
    SyntheticMotionConfig,
    build_trajectory,
    sample_at_rate,
    speed_statistics,
    write_trajectory_csv,
)

__all__ = ["register", "run_trajectory_tour", "DEMO_FPS"]

ORDER = 1

DEMO_FPS = 30
"""Camera rate of the demo [Hz] (Fast-YCB's)."""

_log = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Adds the ``demo`` verb."""
    parser = subparsers.add_parser(
        "demo",
        help="run the main job on the embedded default (no files needed)",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--overwrite", action="store_true", help="replace a non-empty --out")
    parser.set_defaults(func=_run)


def run_trajectory_tour(out_dir: Path) -> dict[str, object]:
    """Generates the default synthetic motion, writes ``trajectory.csv``, ``config.json`` and
    ``speed_statistics.json`` into ``out_dir`` (which must exist), prints the statistics table
    and returns the statistics report."""
    config = SyntheticMotionConfig()
    trajectory = build_trajectory(config, FAST_YCB_CAMERA)
    sample = sample_at_rate(trajectory, DEMO_FPS)
    stats = speed_statistics(sample)
    print(format_speed_table(stats, f"synthetic motion (seed {config.seed}) at {DEMO_FPS} fps"))
    write_trajectory_csv(
        out_dir / "trajectory.csv",
        sample,
        comments=[f"roft-sim {__version__} demo: synthetic T_cam_obj at {DEMO_FPS} fps"],
    )
    metadata = {
        "roft_sim": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "seed": config.seed,
        "fps": DEMO_FPS,
        "camera": jsonable(FAST_YCB_CAMERA),
        "trajectory": jsonable(config),
    }
    (out_dir / "config.json").write_text(json.dumps(metadata, indent=2) + "\n")
    report = stats.report()
    (out_dir / "speed_statistics.json").write_text(json.dumps(report, indent=2) + "\n")
    return report


def _run(args: argparse.Namespace) -> int:
    out_dir = prepare_output_dir(args.out, overwrite=args.overwrite)
    run_trajectory_tour(out_dir)
    print(f"wrote {out_dir / 'trajectory.csv'}, config.json and speed_statistics.json")
    return 0
