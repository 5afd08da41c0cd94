"""``roft-sim run``: one tracker over datasets under faults; writes estimates and metrics.

    roft-sim run DATASET... --tracker NAME [--faults PRESET|FILE] [--flow SPEC] [--out DIR]
                 [--clock sim|wall [--when-busy drop|queue] [--time-scale S]]

Everything is described in docs/running.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from roft_sim.cli.output_dirs import prepare_output_dir
from roft_sim.errors import ConfigError, PluginError

if TYPE_CHECKING:
    from roft_sim.metrics import InvalidPolicy

__all__ = [
    "register",
    "resolve_tracker",
    "build_run_options",
    "build_clock",
    "add_input_arguments",
    "command_record",
    "print_metrics_table",
    "resolve_invalid_policy",
]

AUTO_INVALID = "auto"
"""``--invalid auto``: ``hold`` under the ``paper`` faults, else ``failure``
(:func:`roft_sim.harness.options.default_invalid_policy`)."""


def resolve_invalid_policy(choice: str, faults_name: str) -> InvalidPolicy:
    """``--invalid``: ``auto`` becomes ``hold`` under the ``paper`` preset, else ``failure``.

    Raises:
        ConfigError: an unknown policy.
    """
    from roft_sim.harness.options import default_invalid_policy
    from roft_sim.metrics import INVALID_POLICIES

    if choice == AUTO_INVALID:
        return default_invalid_policy(faults_name)
    if choice not in INVALID_POLICIES:
        raise ConfigError(f"unknown --invalid {choice!r}; expected auto or {INVALID_POLICIES}")
    return cast("InvalidPolicy", choice)


def add_input_arguments(parser: argparse.ArgumentParser, *, sweep: bool = False) -> None:
    """The options shared by ``run`` and ``sweep``: faults, inputs, initial condition, seed
    (``sweep``: faults and seeds are comma-separated lists and have no default here)."""
    if not sweep:
        parser.add_argument(
            "--faults",
            default="paper",
            metavar="PRESET|FILE",
            help="fault preset (roft-sim faults list) or fault TOML file, 'a+b' composes "
            "(default: paper = 5 fps networks, 6 frames late)",
        )
    parser.add_argument(
        "--flow",
        default="auto",
        metavar="SPEC",
        help="flow source: gt, gt+noise, dis[:preset], bm (block matching, NVOF's method), "
        "nvof-like:<inner> (e.g. nvof-like:bm), nvof-model (exact flow with the error model "
        "fitted to NVIDIA hardware flow), stored:<set>, nvof-hw (real NVIDIA hardware "
        "flow; needs an NVIDIA GPU), none, or auto (default: the stored nvof_1_slow set, else "
        "another stored set, else dis)",
    )
    parser.add_argument(
        "--poses",
        default="auto",
        metavar="SET",
        help="detector pose set: a set of the dataset, gt (ground-truth poses as detections), "
        "none, or auto (default: dope, else the first non-gt set)",
    )
    parser.add_argument(
        "--masks",
        default="auto",
        metavar="SET",
        help="mask set: a set of the dataset, gt (ground-truth masks), none, or auto "
        "(default: the first detector set)",
    )
    parser.add_argument(
        "--init",
        default="first-detection",
        choices=("first-detection", "robust", "gt"),
        help="initial condition: the first pose that arrives (default, as the reference), the "
        "first pose that passes a depth-rendering test against the measured depth (robust; the "
        "run log says when and why it waited), or the ground truth of frame 0",
    )
    if not sweep:
        parser.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    if sweep:
        parser.add_argument(
            "--invalid",
            default="failure",
            choices=("failure", "exclude", "as_given", "hold"),
            help="how frames without a tracker pose are scored (default failure: ADD = inf, "
            "left out of the RMSEs; exclude: dropped; hold: the reference's DOPE policy, frames "
            "before the first pose left out, later gaps hold the last pose); the summary names it",
        )
    else:
        parser.add_argument(
            "--invalid",
            default=AUTO_INVALID,
            choices=(AUTO_INVALID, "hold", "failure", "exclude", "as_given"),
            help="how frames without a tracker pose are scored: hold (the reference's DOPE "
            "policy: frames before the first pose left out, later gaps hold the last pose), "
            "failure (ADD = inf, left out of the RMSEs), exclude (dropped), as_given; default "
            "auto = hold under the paper faults, failure otherwise",
        )
    parser.add_argument(
        "--no-rgb",
        action="store_true",
        help="do not hand rgb images to the tracker (faster for trackers that ignore them)",
    )


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds the ``run`` verb."""
    parser = subparsers.add_parser(
        "run",
        help="run a tracker over datasets under faults; write estimates and metrics",
        description="Run one tracker over every sequence of the given datasets (ours in any "
        "format, or the real Fast-YCB) under a fault configuration. Writes one folder per "
        "sequence (pose_estimate.txt, velocity_estimate.txt in the reference's formats, "
        "estimates.npz, metrics.json), metrics.json (ALL, MEAN, per sequence) and run.json, and "
        "prints a table. See docs/running.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
        "  roft-sim run data/fast_ycb --tracker roft --out runs/roft\n"
        "  roft-sim run data/fast_ycb/003_cracker_box --tracker detector-hold --faults paper\n"
        "  roft-sim run data/ci --tracker roft --faults bursts --flow dis --seed 3 --json\n"
        "\nexit codes: 0 done, 1 runtime error, 2 bad arguments, dataset or output",
    )
    parser.add_argument(
        "datasets",
        nargs="+",
        type=Path,
        metavar="DATASET",
        help="sequence folders/.h5 files or dataset roots holding several sequences",
    )
    _add_tracker_arguments(parser)
    add_input_arguments(parser)
    parser.add_argument(
        "--out",
        type=Path,
        help="output folder (default: runs/<tracker>-<faults>); must be empty or absent",
    )
    parser.add_argument("--overwrite", action="store_true", help="empty a non-empty --out first")
    parser.add_argument(
        "--clock",
        choices=("sim", "wall"),
        default="sim",
        help="sim (default): the tracker is stepped in lockstep with simulated time, "
        "deterministic; wall: frames and detections are released in real time at the camera "
        "rate, the tracker runs in its own thread, and each frame is scored with the estimate "
        "delivered by its deadline (docs/wall_clock.md)",
    )
    parser.add_argument(
        "--when-busy",
        choices=("drop", "queue"),
        help="with --clock wall: frames released while the tracker is busy are dropped (default; "
        "it then takes the newest) or queued (it takes them all, in order, late)",
    )
    parser.add_argument(
        "--time-scale",
        type=float,
        metavar="S",
        help="with --clock wall: wall seconds per second of the run's clock (default 1); 2 gives "
        "the tracker twice the time per frame, 0.5 half (a slower machine, a faster camera)",
    )
    parser.add_argument(
        "--layout",
        choices=("ours", "reference"),
        default="ours",
        help="ours (default): one folder per sequence; reference: also the tree the reference "
        "ROFT evaluation (hsp-iit/roft evaluation/evaluate.py) scores unchanged, run from --out "
        "(results/ROFT_results/fastycb/<config>/<object>/, dataset/fast-ycb/<object>/, "
        "YCB_Video_Models/models/<object>/points.xyz; one sequence per object)",
    )
    parser.add_argument(
        "--reference-config",
        metavar="NAME",
        help="the <config> folder of --layout reference (default: full_mask_<masks>_of_<flow>"
        "_pose_<poses>, plus the reference's ablation suffix for ROFT or _<tracker>)",
    )
    parser.add_argument(
        "--tum",
        action="store_true",
        help="also write TUM trajectories (gt.tum, estimate.tum per sequence) for evo_ape/evo_rpe",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.set_defaults(func=_run)


def _add_tracker_arguments(parser: argparse.ArgumentParser) -> None:
    """``--tracker``, ``--tracker-config``, ``--tracker-name``."""
    parser.add_argument(
        "--tracker",
        required=True,
        help='tracker name (roft-sim trackers), or "process:<command line>": a tracker in a '
        "child process speaking the tracker process protocol (docs/process.md)",
    )
    parser.add_argument(
        "--tracker-config", type=Path, metavar="FILE", help="TOML file of tracker settings"
    )
    parser.add_argument(
        "--tracker-name",
        metavar="NAME",
        help="with --tracker process:...: the name of the tracker in the outputs (default: made "
        "from the command, e.g. process-roft)",
    )


def resolve_tracker(name: str, config_path: Path | None) -> tuple[Any, Any]:
    """``(spec, config)`` of tracker ``name``; unknown names are usage errors (exit 2)."""
    from roft_sim.trackers import get_tracker_spec, load_tracker_config

    try:
        spec = get_tracker_spec(name)
    except PluginError as e:
        raise ConfigError(str(e)) from None
    if config_path is not None and not config_path.is_file():
        raise ConfigError(f"--tracker-config {str(config_path)!r} does not exist")
    return spec, load_tracker_config(spec, config_path)


def _renamed(spec: Any, tracker: str, name: str | None) -> Any:
    """``spec`` named ``name`` (``--tracker-name``, only for ``process:`` trackers)."""
    if name is None:
        return spec
    from roft_sim.trackers import PROCESS_PREFIX

    if not tracker.startswith(PROCESS_PREFIX):
        raise ConfigError(
            f"--tracker-name names a {PROCESS_PREFIX}... tracker; {tracker!r} is registered "
            "under its own name"
        )
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9._+-]*", name):
        raise ConfigError(
            f"--tracker-name {name!r}: use letters, digits and . _ + - (it names folders)"
        )
    return dataclasses.replace(spec, name=name)


def build_run_options(args: argparse.Namespace, tracker: str, config: Any) -> Any:
    """:class:`~roft_sim.harness.RunOptions` from the shared arguments."""
    from roft_sim.faults import load_faults
    from roft_sim.harness import RunOptions

    faults = load_faults(args.faults)
    return RunOptions(
        tracker=tracker,
        tracker_config=config,
        faults=faults,
        flow=args.flow,
        poses=args.poses,
        masks=args.masks,
        init=args.init,
        seed=args.seed,
        include_rgb=not args.no_rgb,
        invalid=resolve_invalid_policy(args.invalid, faults.name),
    )


def build_clock(args: argparse.Namespace) -> Any:
    """The :class:`~roft_sim.harness.wall_clock.WallClock` of ``--clock wall``, None for ``sim``.

    Raises:
        ConfigError: ``--when-busy`` or ``--time-scale`` without ``--clock wall``, or a time
            scale that is not finite and > 0.
    """
    from roft_sim.harness.wall_clock import WallClock

    if args.clock != "wall":
        given = [
            name
            for name, value in (("--when-busy", args.when_busy), ("--time-scale", args.time_scale))
            if value is not None
        ]
        if given:
            raise ConfigError(
                f"{' and '.join(given)} only apply to a real clock; add --clock wall (got "
                f"--clock {args.clock})"
            )
        return None
    return WallClock(
        time_scale=1.0 if args.time_scale is None else args.time_scale,
        when_busy=args.when_busy or "drop",
    )


def _check_inputs(sources: list[Any], options: Any) -> None:
    """Validates the sequence names and every sequence's inputs before anything is written."""
    from roft_sim.harness.inputs import check_inputs
    from roft_sim.harness.run_dataset import check_sequence_names

    check_sequence_names(sources)
    for source in sources:
        check_inputs(source.sequence, options)


def command_record(args: argparse.Namespace) -> list[str]:
    """The parsed command line as ``["run", "--key=value", ...]`` for ``run.json``."""
    out = [str(args.verb)]
    for key, value in sorted(vars(args).items()):
        if key in ("func", "verb") or value is None or value is False:
            continue
        out.append(f"--{key}={value}" if value is not True else f"--{key}")
    return out


def print_metrics_table(metrics: dict[str, dict[str, Any]], first_header: str) -> None:
    """Prints the per-sequence + ALL + MEAN table of a ``metrics.json`` on stdout (with the
    timing columns of a wall-clock run when its entries have them)."""
    from roft_sim.report.tables import METRIC_COLUMNS, WALL_CLOCK_COLUMNS, Column, text_table

    order = [n for n in metrics if n not in ("ALL", "MEAN")] + [
        n for n in ("ALL", "MEAN") if n in metrics
    ]
    rows = [{"name": n, **metrics[n]} for n in order]
    columns = [Column("name", first_header, align="left"), *METRIC_COLUMNS]
    if any("latency_p50_ms" in row for row in rows):
        columns += WALL_CLOCK_COLUMNS
    print(text_table(columns, rows), end="")


def clock_note(clock: Any) -> str:
    """One line under the table of a wall-clock run: the clock and what its columns mean."""
    when_busy = (
        "dropped while busy (the tracker takes the newest)"
        if clock.when_busy == "drop"
        else "queued while busy"
    )
    return (
        f"clock: wall, time scale {clock.time_scale:g}, frames {when_busy}; each frame scored with "
        "the estimate delivered by the next frame's release; latency from release to delivery "
        "[ms, run clock]; missed = frames whose own estimate was late (docs/wall_clock.md)"
    )


def interval_velocity_summaries(sources: list[Any]) -> dict[str, dict[str, Any]]:
    """Per sequence with ground truth, the e_v / e_w that the exact interval motion gives at the
    camera's frame rate (:mod:`roft_sim.metrics.interval_velocity`), as JSON-ready dicts."""
    from roft_sim.metrics import interval_velocity_errors

    out = {}
    for source in sources:
        truth = source.sequence.ground_truth()
        if truth is not None:
            out[source.sequence.name] = interval_velocity_errors(truth).summary()
    return out


def print_interval_velocity_table(summaries: dict[str, dict[str, Any]]) -> None:
    """Prints :func:`interval_velocity_summaries` under a line saying what they are."""
    from roft_sim.report.tables import Column, text_table

    if not summaries:
        return
    print(
        "velocity from the exact interval motion, scored like e_v [cm/s] / e_w [deg/s]: held = "
        "the interval mean as the velocity at its end, extrapolated = carried half an interval "
        "forward, fitted = last 3 interval means fitted to the truth itself (docs/metrics.md)"
    )
    columns = [Column("name", "sequence", align="left")] + [
        Column(f"{how}_{unit}", f"{what} {how}", ".2f")
        for what, unit in (("e_v", "v_cmps"), ("e_w", "w_dps"))
        for how in ("held", "extrapolated", "fitted")
    ]
    print(text_table(columns, [{"name": n, **s} for n, s in summaries.items()]), end="")


def _print_reference_note(tree: Any) -> None:
    from roft_sim.harness.reference_layout import REFERENCE_EXPERIMENTS, REFERENCE_ROFT_CONFIG

    where = f"reference tree in {tree.root} (config {tree.config_name})"
    if "exp_fastycb_roft" in tree.experiments:
        print(
            f"{where}: from there, python <roft>/evaluation/evaluate.py --experiment-name "
            "exp_fastycb_roft --metric-name mix",
            file=sys.stderr,
        )
    elif tree.experiments:
        others = sorted(
            {c for e in tree.experiments for c in REFERENCE_EXPERIMENTS[e]} - {tree.config_name}
        )
        print(
            f"{where}: read by the reference's {', '.join(tree.experiments)} together with the "
            f"configs {', '.join(others)} (merge the trees of those runs, then run "
            "python <roft>/evaluation/evaluate.py --experiment-name <experiment> from there)",
            file=sys.stderr,
        )
    else:
        print(
            f"{where}: no experiment of the reference's evaluation reads this config (evaluate.py "
            "would stop on the first file it opens, execution_times.txt, of the config its "
            f"experiment names); rerun with --reference-config {REFERENCE_ROFT_CONFIG} to have "
            "exp_fastycb_roft score this run as its ROFT row",
            file=sys.stderr,
        )
    if tree.missing_objects:
        print(
            f"note: the reference evaluation loads all six Fast-YCB objects; this tree lacks "
            f"{', '.join(tree.missing_objects)} (merge the trees of runs over those)",
            file=sys.stderr,
        )


def _run(args: argparse.Namespace) -> int:
    from roft_sim.errors import DatasetFormatError
    from roft_sim.harness import open_sequences, run_sequences

    spec, config = resolve_tracker(args.tracker, args.tracker_config)
    spec = _renamed(spec, args.tracker, args.tracker_name)
    options = build_run_options(args, args.tracker, config)
    clock = build_clock(args)
    try:
        sources = open_sequences(args.datasets)
    except DatasetFormatError as e:
        raise ConfigError(str(e)) from None
    _check_inputs(sources, options)
    out = args.out or Path("runs") / f"{spec.name}-{options.faults.name}".replace("/", "_")
    if out.is_dir() and any(out.iterdir()) and not args.overwrite:
        raise ConfigError(
            f"output directory {str(out)!r} is not empty; pass --overwrite to replace it or "
            "choose another --out"
        )
    out = prepare_output_dir(out, overwrite=args.overwrite)
    if spec.needs_depth_renderer:
        from roft_sim.render.gl_backend import select_gl_backend

        select_gl_backend(os.environ)  # before MuJoCo is imported (lazily, on the first render)
    result = run_sequences(
        sources,
        options,
        out,
        spec=spec,
        progress=not (args.no_progress or args.quiet or args.json),
        command=command_record(args),
        layout=args.layout,
        reference_config=args.reference_config,
        tum=args.tum,
        clock=clock,
    )
    if args.json:
        from roft_sim.harness.wall_clock import clock_record

        summary = {
            "out": str(out),
            "clock": clock_record(clock),
            "invalid": options.invalid,
            "metrics": result.metrics,
            "interval_velocity": interval_velocity_summaries(sources),
        }
        if result.reference_tree is not None:
            summary["reference"] = {
                "config": result.reference_tree.config_name,
                "experiments": list(result.reference_tree.experiments),
                "missing_objects": list(result.reference_tree.missing_objects),
            }
        print(json.dumps(summary, indent=2))
    else:
        from roft_sim.metrics import policy_note

        print_metrics_table(result.metrics, "sequence")
        print(policy_note(options.invalid))
        if clock is not None:
            print(clock_note(clock))
        print_interval_velocity_table(interval_velocity_summaries(sources))
        print(f"results in {out}", file=sys.stderr)
        if result.reference_tree is not None:
            _print_reference_note(result.reference_tree)
    return 0
