"""``roft-sim report RESULTS_DIR``: a self-contained report (Markdown, PNG plots, overlay videos)
of a ``roft-sim run`` or ``roft-sim sweep`` folder. See docs/running.md."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from roft_sim.errors import ConfigError

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds the ``report`` verb."""
    parser = subparsers.add_parser(
        "report",
        help="write a Markdown report with plots and overlay videos of a run or sweep folder",
        description="Write report.md with the configuration, metrics and synchronisation "
        "figures, per-frame error plots with pose arrivals, ADD accuracy curves and, per "
        "sequence, an overlay video (object silhouette at the estimate and the ground truth over "
        "the rgb, the delayed masks the tracker received, arrival markers) with stills. For a "
        "sweep folder: its summary tables and plots. See docs/running.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
        "  roft-sim report runs/roft-paper\n"
        "  roft-sim report runs/roft-paper --max-video-frames 300 --video-scale 0.5\n"
        "  roft-sim report sweeps/delay --out reports/delay\n"
        "\nexit codes: 0 done, 1 runtime error, 2 not a results folder or bad arguments",
    )
    parser.add_argument("results", type=Path, metavar="RESULTS_DIR", help="run or sweep folder")
    parser.add_argument(
        "--out", type=Path, help="report folder (default: RESULTS_DIR/report; replaced files)"
    )
    parser.add_argument("--no-video", action="store_true", help="skip the overlay videos")
    parser.add_argument(
        "--max-video-frames", type=int, metavar="N", help="frames per video (default: all)"
    )
    parser.add_argument(
        "--video-scale",
        type=float,
        metavar="S",
        help="scale of the video frames (default 1, or 0.5 above 960 px wide)",
    )
    parser.add_argument(
        "--sequence",
        action="append",
        metavar="NAME",
        help="only this sequence (repeatable; default: all)",
    )
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    from roft_sim.harness.report_builder import ReportOptions, build_report

    if not args.results.is_dir():
        raise ConfigError(
            f"results folder {str(args.results)!r} does not exist; give the --out folder of "
            "roft-sim run or roft-sim sweep"
        )
    out = args.out if args.out is not None else args.results / "report"
    flag = "--out" if args.out is not None else "the default report folder"
    if out.exists() and not out.is_dir():
        raise ConfigError(
            f"{flag} {str(out)!r} is a file; the report is a folder (report.md, plots/, "
            "videos/): give a folder path, or remove the file"
        )
    blocker = next((p for p in out.parents if p.exists() and not p.is_dir()), None)
    if blocker is not None:
        raise ConfigError(
            f"{flag} {str(out)!r} lies under {str(blocker)!r}, which is a file; give a folder path"
        )
    options = ReportOptions(
        video=not args.no_video,
        max_video_frames=args.max_video_frames,
        video_scale=args.video_scale,
        sequences=tuple(args.sequence) if args.sequence else None,
    )
    result = build_report(args.results, out_dir=args.out, options=options)
    if args.json:
        print(
            json.dumps(
                {
                    "report": str(result.markdown),
                    "files": [str(p) for p in result.files],
                    "notes": list(result.notes),
                },
                indent=2,
            )
        )
    else:
        print(result.markdown)
        for note in result.notes:
            print(f"note: {note}", file=sys.stderr)
    return 0
