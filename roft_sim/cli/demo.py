"""``roft-sim demo --out DIR``: the main job on the embedded default, no files needed.

Generates a short Fast-YCB-style sequence (003_cracker_box on fast synthetic hand-like motion,
rendered with MuJoCo, with simulated DOPE-like poses, Mask R-CNN-like masks and NVOF-like flow),
runs ROFT and two baselines on it under the paper's delays (pose and mask networks at 5 fps,
results 6 frames late) and prints how well each tracked. See roft_sim.harness.demo.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from roft_sim.cli.output_dirs import prepare_output_dir

__all__ = ["register"]


PAPER_FAULTS = "paper faults (pose and mask networks at 5 fps, results 6 frames late)"


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds the ``demo`` verb."""
    parser = subparsers.add_parser(
        "demo",
        help="run the main job on the embedded default (no files needed)",
        description=__doc__.split("\n\n")[1] if __doc__ else None,
    )
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--overwrite", action="store_true", help="replace a non-empty --out")
    parser.add_argument(
        "--frames",
        type=int,
        default=150,
        help="frames of the generated sequence (default 150: 5 s at 30 fps)",
    )
    parser.add_argument(
        "--resolution",
        default="640x360",
        metavar="WxH",
        help="render resolution (default 640x360, half of Fast-YCB's 1280x720)",
    )
    parser.add_argument(
        "--trackers",
        default="roft,detector-hold,naive-delay",
        help="comma-separated trackers to compare (default: %(default)s)",
    )
    parser.add_argument(
        "--faults", default="paper", help="fault preset or TOML file (default: paper)"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.set_defaults(func=_run)


MIN_DEMO_FRAMES = 13
"""Fewest frames for two pose deliveries under the ``paper`` faults (frames 0 and 12)."""


def _run(args: argparse.Namespace) -> int:
    from roft_sim.errors import ConfigError
    from roft_sim.generation.jobs import parse_resolution
    from roft_sim.render.gl_backend import require_gl_backend

    resolution = parse_resolution(args.resolution)
    if args.frames < MIN_DEMO_FRAMES:
        raise ConfigError(
            f"--frames must be at least {MIN_DEMO_FRAMES} (two pose deliveries: under the paper "
            f"faults the second pose arrives at frame 12), got {args.frames}"
        )
    trackers = tuple(t.strip() for t in args.trackers.split(",") if t.strip())
    if not trackers:
        raise ConfigError("--trackers is empty; give at least one tracker name")
    from roft_sim.cli.run import resolve_tracker
    from roft_sim.faults import load_faults

    for name in trackers:
        resolve_tracker(name, None)  # unknown names: exit 2 before anything is rendered
    load_faults(args.faults)  # likewise a bad preset name or file
    require_gl_backend(os.environ)
    out = Path(args.out)
    if out.exists() and not out.is_dir():  # cheap checks first; emptying waits for the scenario
        prepare_output_dir(out)

    from roft_sim.harness.demo import DemoSettings, demo_table_rows, run_demo
    from roft_sim.harness.options import default_invalid_policy
    from roft_sim.metrics import policy_note
    from roft_sim.report.tables import METRIC_COLUMNS, Column, text_table

    settings = DemoSettings(
        frames=args.frames,
        resolution=resolution,
        trackers=trackers,
        faults=args.faults,
        progress=not args.no_progress,
    )
    result = run_demo(
        out,
        settings,
        prepare_output=lambda path: prepare_output_dir(
            path, overwrite=args.overwrite, can_resume=False
        ),
    )
    if args.json:
        print(json.dumps({"out": str(out), "metrics": result.metrics}, indent=2))
        return 0
    w, h = resolution
    what = PAPER_FAULTS if args.faults == "paper" else f"faults {args.faults!r}"
    print(f"003_cracker_box, {result.frames} frames at {w}x{h}, {what}:")
    columns = [Column("name", "tracker", align="left"), *METRIC_COLUMNS]
    print(text_table(columns, demo_table_rows(result.metrics)), end="")
    print(policy_note(default_invalid_policy(load_faults(args.faults).name)))
    print(f"dataset: {result.dataset_dir}")
    for name, path in result.run_dirs.items():
        print(f"run {name}: {path}")
    print(f"next: roft-sim report {result.run_dirs[trackers[0]]}   (plots and an overlay video)")
    return 0
