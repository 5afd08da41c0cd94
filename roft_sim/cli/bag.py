"""``roft-sim bag``: ROS 2 bags (MCAP) in and out of the harness.

    roft-sim bag export SEQUENCE --faults F [--seed S] --out OUT.mcap
    roft-sim bag export-run RUN_DIR --out EST.mcap
    roft-sim bag score BAG --dataset SEQUENCE --pose-topic T [--twist-topic T] --out RUN

Needs the ``bags`` extra. Everything is described in docs/bags.md.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from roft_sim.cli.output_dirs import check_output_dir, prepare_output_dir
from roft_sim.errors import ConfigError

__all__ = ["register"]

_EXIT_CODES = "\nexit codes: 0 done, 1 runtime error, 2 bad arguments, dataset, topic or output"


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds the ``bag`` verb and its ``export``, ``export-run`` and ``score`` commands."""
    parser = subparsers.add_parser(
        "bag",
        help="ROS 2 bags: export a sequence under faults, export a run, score a recorded bag",
        description="ROS 2 bags in MCAP (profile ros2, CDR, standard messages). See docs/bags.md.",
    )
    commands = parser.add_subparsers(dest="bag_command", metavar="COMMAND", required=True)
    _register_export(commands)
    _register_export_run(commands)
    _register_score(commands)


def _register_export(commands: Any) -> None:
    parser = commands.add_parser(
        "export",
        help="a sequence under faults as a bag: what a run feeds a tracker, logged on arrival",
        description="Write what `roft-sim run` would feed a tracker as a ROS 2 bag: rgb8 and "
        "depth images with CameraInfo per delivered camera frame, the detector's poses "
        "(PoseStamped) and masks (mono8 Image) stamped with their capture time and logged at the "
        "arrival time the fault schedule gives them, and the ground truth on /tf and "
        "/ground_truth/twist. `ros2 bag play` then delivers them late, lost, duplicated or out "
        "of order as the run would. See docs/bags.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n  roft-sim bag export data/box --faults chaos --seed 3 --out box.mcap\n"
        + _EXIT_CODES,
    )
    parser.add_argument("sequence", type=Path, metavar="SEQUENCE", help="a sequence folder/file")
    parser.add_argument(
        "--faults",
        default="paper",
        metavar="PRESET|FILE",
        help="fault preset or file, as roft-sim run (default: paper)",
    )
    parser.add_argument("--seed", type=int, default=0, help="run seed, as roft-sim run (default 0)")
    parser.add_argument(
        "--poses", default="auto", metavar="SET", help="detector pose set, as roft-sim run"
    )
    parser.add_argument("--masks", default="auto", metavar="SET", help="mask set, as roft-sim run")
    parser.add_argument(
        "--depth-encoding",
        choices=("32FC1", "16UC1"),
        default="32FC1",
        help="REP 118 depth: 32FC1 metres, NaN = no return (default), or 16UC1 millimetres, "
        "0 = no return",
    )
    parser.add_argument(
        "--no-ground-truth",
        action="store_true",
        help="leave out /tf and /ground_truth/twist (a bag for a tracker under test only)",
    )
    _add_output_arguments(parser, "the .mcap file to write")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=_export)


def _register_export_run(commands: Any) -> None:
    parser = commands.add_parser(
        "export-run",
        help="a run's estimates as a PoseStamped/TwistStamped bag (bag score gives its metrics)",
        description="Write one sequence's estimates of a roft-sim run folder as a bag on "
        "/tracker/pose (PoseStamped) and /tracker/twist (TwistStamped), stamped and logged at "
        "k / fps, as a ROS 2 tracker would publish them; `roft-sim bag score` on it reproduces "
        "the run's metrics. See docs/bags.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n  roft-sim bag export-run runs/roft --out roft.mcap\n" + _EXIT_CODES,
    )
    parser.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a roft-sim run folder")
    parser.add_argument("--sequence", metavar="NAME", help="the sequence (if the run has several)")
    _add_output_arguments(parser, "the .mcap file to write")
    parser.set_defaults(func=_export_run)


def _register_score(commands: Any) -> None:
    parser = commands.add_parser(
        "score",
        help="score a bag recorded from a tracker with the metrics of roft-sim run",
        description="Score the PoseStamped (and optionally TwistStamped) messages a tracker "
        "published, matched to camera frames by header stamp (k / fps), with the metrics of "
        "roft-sim run against the sequence's ground truth. Writes metrics.json, run.json and "
        "the per-sequence files of a run folder into --out. See docs/bags.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n  roft-sim bag score tracker.mcap --dataset data/box "
        "--pose-topic /tracker/pose --twist-topic /tracker/twist --out runs/bag\n" + _EXIT_CODES,
    )
    parser.add_argument("bag", type=Path, metavar="BAG", help="a .mcap file or a rosbag2 folder")
    parser.add_argument(
        "--dataset", type=Path, required=True, metavar="SEQUENCE", help="the sequence played"
    )
    parser.add_argument("--pose-topic", required=True, help="the tracker's PoseStamped topic")
    parser.add_argument("--twist-topic", help="its TwistStamped topic (default: no velocity)")
    parser.add_argument(
        "--twist-linear",
        choices=("auto", "origin", "spatial"),
        default="auto",
        help="what twist.linear holds: origin = velocity of the object origin, spatial = "
        "v_o = v_obj - w x t (ROFT's); auto (default) = the bag's metadata, else origin",
    )
    parser.add_argument(
        "--invalid",
        choices=("auto", "hold", "failure", "exclude", "as_given"),
        default="auto",
        help="how frames without a pose are scored, as roft-sim run; auto (default) = the "
        "policy the bag's metadata names (export-run), else failure",
    )
    parser.add_argument(
        "--stamp-tolerance-ms",
        type=float,
        default=1.0,
        metavar="MS",
        help="how far a header stamp may be from k / fps (default 1 ms)",
    )
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--overwrite", action="store_true", help="empty a non-empty --out first")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.set_defaults(func=_score)


def _add_output_arguments(parser: argparse.ArgumentParser, what: str) -> None:
    parser.add_argument("--out", type=Path, required=True, metavar="OUT.mcap", help=what)
    parser.add_argument("--overwrite", action="store_true", help="replace an existing file")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")


def _open_one(path: Path) -> Any:
    """The one sequence at ``path`` (a dataset root holding exactly one is accepted)."""
    from roft_sim.errors import DatasetFormatError
    from roft_sim.harness import open_sequences

    try:
        sources = open_sequences([path])
    except DatasetFormatError as e:
        raise ConfigError(str(e)) from None
    if len(sources) != 1:
        names = ", ".join(s.sequence.name for s in sources)
        raise ConfigError(
            f"{str(path)!r} holds {len(sources)} sequences ({names}); give one sequence's path"
        )
    return sources[0].sequence


def _summary(result: Any) -> dict[str, Any]:
    return {
        "bag": str(result.path),
        "size_bytes": result.size_bytes,
        "frames": result.frames,
        "dropped_frames": result.dropped_frames,
        "topics": {
            t: {"type": c.datatype, "messages": c.messages} for t, c in result.topics.items()
        },
        "wall_s": round(result.wall_s, 3),
    }


def _report(result: Any, as_json: bool) -> None:
    summary = _summary(result)
    if as_json:
        print(json.dumps(summary, indent=2))
        return
    for topic, entry in summary["topics"].items():
        print(f"{topic:28s} {entry['type']:32s} {entry['messages']:6d}")
    print(f"bag in {result.path} ({result.size_bytes / 1e6:.1f} MB)", file=sys.stderr)


def _export(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from roft_sim.bags.export import export_options, export_sequence_bag
    from roft_sim.bags.writer import check_bag_path, require_bags_extra
    from roft_sim.faults import load_faults

    require_bags_extra()
    check_bag_path(args.out, overwrite=args.overwrite)
    sequence = _open_one(args.sequence)
    options = export_options(
        load_faults(args.faults), seed=args.seed, poses=args.poses, masks=args.masks
    )
    quiet = args.no_progress or args.quiet or args.json
    with tqdm(total=len(sequence), unit="frame", desc="bag export", disable=quiet) as bar:
        result = export_sequence_bag(
            sequence,
            options,
            args.out,
            depth_encoding=args.depth_encoding,
            ground_truth=not args.no_ground_truth,
            overwrite=args.overwrite,
            progress=bar.update,
        )
    _report(result, args.json)
    return 0


def _export_run(args: argparse.Namespace) -> int:
    from roft_sim.bags.run_export import export_run_bag

    result = export_run_bag(
        args.run_dir, args.out, sequence=args.sequence, overwrite=args.overwrite
    )
    _report(result, args.json)
    return 0


def _score(args: argparse.Namespace) -> int:
    from roft_sim.bags.score import score_bag, write_score_outputs
    from roft_sim.bags.writer import require_bags_extra
    from roft_sim.cli.run import command_record, print_metrics_table
    from roft_sim.metrics import policy_note

    require_bags_extra()
    if not args.stamp_tolerance_ms >= 0:
        raise ConfigError(f"--stamp-tolerance-ms must be >= 0, got {args.stamp_tolerance_ms}")
    sequence = _open_one(args.dataset)
    check_output_dir(args.out, overwrite=args.overwrite, can_resume=False)  # before the scoring
    score = score_bag(
        args.bag,
        sequence,
        pose_topic=args.pose_topic,
        twist_topic=args.twist_topic,
        twist_linear=None if args.twist_linear == "auto" else args.twist_linear,
        invalid=None if args.invalid == "auto" else args.invalid,
        tolerance_ns=round(args.stamp_tolerance_ms * 1e6),
    )
    out = prepare_output_dir(args.out, overwrite=args.overwrite, can_resume=False)
    record = {
        "command": command_record(args),
        "pose_topic": args.pose_topic,
        "twist_topic": args.twist_topic,
        "stamp_tolerance_ms": args.stamp_tolerance_ms,
    }
    write_score_outputs(out, score, sequence, record)
    if args.json:
        print(json.dumps({"out": str(out), "invalid": score.invalid, "metrics": score.metrics}))
    else:
        print_metrics_table(score.metrics, "sequence")
        print(policy_note(score.invalid))
        print(f"results in {out}", file=sys.stderr)
    return 0
