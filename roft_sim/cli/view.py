"""``roft-sim view RUN_DIR``: a Rerun recording (``.rrd``) of a ``roft-sim run`` folder; opens the
viewer when a display exists. Needs the ``view`` extra (rerun-sdk). See docs/running.md."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

__all__ = ["register", "has_display"]


def register(subparsers: Any) -> None:
    """Adds the ``view`` verb."""
    parser = subparsers.add_parser(
        "view",
        help="write a Rerun recording (.rrd) of a run folder and open the viewer",
        description="Write a Rerun recording of a roft-sim run folder: per sequence the camera "
        "images, depth, masks (ground truth and the newest delivered), flow, the ground-truth "
        "and estimated poses as 3D frames with the object's model points, each arriving "
        "detection with its delay, and the per-frame errors as time series. Opens the Rerun "
        "viewer when a display exists (unless --no-open), else prints where the file is. Needs "
        "the view extra: pip install -e '.[view]'. See docs/running.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
        "  roft-sim view runs/roft-paper\n"
        "  roft-sim view runs/roft-paper --sequence 003_cracker_box --max-frames 120 --no-open\n"
        "\nexit codes: 0 done, 1 runtime error, 2 not a run folder, rerun-sdk missing or bad "
        "arguments",
    )
    parser.add_argument("results", type=Path, metavar="RUN_DIR", help="a roft-sim run folder")
    parser.add_argument(
        "--out", type=Path, metavar="FILE", help="the .rrd file (default: RUN_DIR/run.rrd)"
    )
    parser.add_argument(
        "--sequence", action="append", metavar="NAME", help="only this sequence (repeatable)"
    )
    parser.add_argument("--max-frames", type=int, metavar="N", help="frames per sequence")
    parser.add_argument("--no-open", action="store_true", help="write the file, open nothing")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.set_defaults(func=_run)


def has_display(environ: dict[str, str] | os._Environ[str]) -> bool:
    """Whether a graphical display is available (X11 or Wayland)."""
    return bool(environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY"))


def _run(args: argparse.Namespace) -> int:
    from roft_sim.harness.rerun_recording import write_run_recording

    out = args.out or args.results / "run.rrd"
    result = write_run_recording(
        args.results, out, sequences=args.sequence, max_frames=args.max_frames
    )
    opened = False
    if not args.no_open and has_display(os.environ):
        subprocess.Popen([sys.executable, "-m", "rerun", str(result.path)])  # the viewer
        opened = True
    if args.json:
        summary = {
            "file": str(result.path),
            "sequences": list(result.sequences),
            "frames": result.frames,
            "opened": opened,
            "notes": list(result.notes),
        }
        print(json.dumps(summary, indent=2))
    else:
        for note in result.notes:
            print(f"note: {note}", file=sys.stderr)
        where = "opened in the Rerun viewer" if opened else "open it with: rerun " + str(out)
        print(f"recording of {len(result.sequences)} sequence(s) in {result.path} ({where})")
    return 0
