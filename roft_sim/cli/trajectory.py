"""``roft-sim trajectory stats|export``: inspect and export captured or synthetic motion.

- ``stats FILE --format F`` (or ``--synthetic``): duration, rate and speed statistics, as a
  table or (``--json``) a JSON object.
- ``stats --hand-motion [--trajectories DIR] [--split tuning|evaluation|both]``: the captured
  hand-object motion of the split (pooled speed and acceleration percentiles) side by side with
  the continuous and the bursty synthetic profiles.
- ``export FILE --format F --fps 30 --out traj.csv`` (or ``--synthetic``): the PLACED
  trajectory ``T_cam_obj`` sampled at ``t_k = k / fps``, as the trajectory CSV.

Placement uses the Fast-YCB reference camera (1280x720, fx = fy = 1229.4 px) and an object
radius of 0.1 m.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import sys
from pathlib import Path

from roft_sim import __version__
from roft_sim.config_files import jsonable
from roft_sim.errors import ConfigError
from roft_sim.trajectories import (
    FAST_YCB_CAMERA,
    TRAJECTORY_FILE_FORMATS,
    CapturedMotionConfig,
    CapturedTrajectory,
    ContinuousMotionConfig,
    PlacementConfig,
    SpeedStatistics,
    SyntheticMotionConfig,
    Trajectory,
    TrajectoryConfig,
    build_trajectory,
    sample_at_rate,
    speed_statistics,
    write_trajectory_csv,
)

__all__ = ["register", "format_speed_table", "trajectory_config_from_args"]


_log = logging.getLogger(__name__)

SYNTHETIC_STATS_RATE_HZ = 120.0
"""Rate at which ``stats --synthetic`` samples the motion unless ``--fps`` is given [Hz]."""

MAX_SYNTHETIC_DURATION_S = 3600.0
"""Longest ``--synthetic --duration-s`` [s]: an hour already takes about 2 s and 300 MB to
sample at 120 Hz (a 40 MB CSV at 30 Hz), far beyond any tracking sequence; a longer value is
taken for a typo (milliseconds for seconds) instead of running for minutes."""

MAX_SAMPLES = 1_000_000
"""Most samples one ``stats --fps`` or ``export`` may take (about 700 MB while sampling); more
(a huge ``--fps``, or a tiny ``--speed-scale``) is refused instead of running out of memory."""

_FILE_ONLY_OPTIONS = (
    ("joint", "--joint"),
    ("relative_to", "--relative-to"),
    ("object_id", "--object-id"),
    ("sample_rate_hz", "--sample-rate-hz"),
    ("lowpass_hz", "--lowpass-hz"),
    ("drift_window_s", "--drift-window-s"),
    ("window_s", "--window-s"),
    ("speed_scale", "--speed-scale"),
    ("min_in_view_fraction", "--min-in-view-fraction"),
    ("include_gaps", "--include-gaps"),
)
"""Options of a trajectory FILE (``Namespace`` name, flag): refused with ``--synthetic``."""

_SYNTHETIC_ONLY_OPTIONS = (
    ("seed", "--seed"),
    ("duration_s", "--duration-s"),
    ("profile", "--profile"),
)
"""Options of ``--synthetic`` (``Namespace`` name, flag): refused with a FILE."""


def _add_source_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", nargs="?", type=Path, help="trajectory file (or --synthetic)")
    parser.add_argument("--format", choices=TRAJECTORY_FILE_FORMATS, help="format of FILE")
    parser.add_argument("--joint", help="BVH: joint to follow, e.g. CC_Base_L_Hand")
    parser.add_argument("--relative-to", help="BVH: follow the joint relative to this one")
    parser.add_argument("--object-id", type=int, help="BOP: obj_id to follow")
    parser.add_argument(
        "--sample-rate-hz", type=float, help="Fast-YCB/BOP: frame rate of the file (default 30)"
    )
    parser.add_argument("--lowpass-hz", type=float, help="file: zero-phase low-pass cut-off [Hz]")
    parser.add_argument(
        "--drift-window-s", type=float, help="file: subtract a moving average of the position [s]"
    )
    parser.add_argument(
        "--window-s",
        type=float,
        nargs=2,
        metavar=("START", "END"),
        help="file: keep this time span [s]",
    )
    parser.add_argument(
        "--speed-scale", type=float, help="file: play faster (>1) or slower (<1) (default 1)"
    )
    parser.add_argument(
        "--working-distance-m",
        type=float,
        nargs=2,
        default=(0.4, 0.9),
        metavar=("NEAR", "FAR"),
        help="depth range of the placed object [m] (default 0.4 0.9, as Fast-YCB)",
    )
    parser.add_argument(
        "--min-in-view-fraction",
        type=float,
        help="file: fail when less of the placed motion stays in view (export default 0.5; "
        "stats only reports it)",
    )
    parser.add_argument(
        "--synthetic", action="store_true", help="use the synthetic generator instead of a file"
    )
    parser.add_argument(
        "--profile",
        choices=("bursty", "continuous"),
        help="synthetic: bursty (minimum-jerk bursts with rests, the default) or continuous "
        "(keeps turning; fitted to captured hand motion)",
    )
    parser.add_argument("--seed", type=int, help="synthetic: seed, >= 0 (default 0)")
    parser.add_argument(
        "--duration-s",
        type=float,
        help=f"synthetic: duration [s], at most {MAX_SYNTHETIC_DURATION_S:g} (default 10)",
    )


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``trajectory stats`` and ``trajectory export``."""
    parser = subparsers.add_parser(
        "trajectory",
        help="inspect or export captured and synthetic object motion",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    verbs = parser.add_subparsers(dest="trajectory_verb", metavar="ACTION", required=True)
    stats = verbs.add_parser("stats", help="duration, rate and speed statistics")
    _add_source_arguments(stats)
    stats.add_argument(
        "--fps",
        type=float,
        help="sample at this rate [Hz] (default: the file's samples; synthetic: 120)",
    )
    stats.add_argument(
        "--include-gaps",
        action="store_true",
        help="file: also count samples where the spline bridges gaps in its time stamps",
    )
    stats.add_argument(
        "--hand-motion",
        action="store_true",
        help="captured hand-object motion (TUM VI rooms, CMU hands) pooled per split, side by "
        "side with the continuous and bursty synthetic profiles",
    )
    stats.add_argument(
        "--trajectories",
        type=Path,
        help="--hand-motion: folder of the shared captures, with tum/ and bvh/ (default "
        "$ROFT_SIM_TRAJECTORIES, else ../shared/trajectories beside the repository)",
    )
    stats.add_argument(
        "--split",
        choices=("tuning", "evaluation", "both"),
        default="both",
        help="--hand-motion: which captures (tuning: TUM room1 + CMU 02_05, synthetic seeds "
        "0-9; evaluation: TUM room2, room4 + CMU 02_06, seeds 100-109; default both)",
    )
    stats.add_argument("--json", action="store_true", help="print a JSON object")
    stats.set_defaults(func=_run_stats)
    export = verbs.add_parser("export", help="write the placed trajectory as CSV")
    _add_source_arguments(export)
    export.add_argument("--fps", type=float, default=30.0, help="sample rate [Hz] (default 30)")
    export.add_argument("--out", type=Path, required=True, help="output CSV file")
    export.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    export.set_defaults(func=_run_export)


def trajectory_config_from_args(
    args: argparse.Namespace, *, default_min_in_view_fraction: float = 0.5
) -> TrajectoryConfig:
    """The trajectory config that the command-line arguments describe.

    Raises:
        ConfigError: contradictory, missing or out-of-range arguments, or an option of the
            other source (a file's ``--lowpass-hz`` with ``--synthetic``, ``--seed`` with a file).
    """
    working_distance_m = (float(args.working_distance_m[0]), float(args.working_distance_m[1]))
    if args.synthetic:
        if args.file is not None or args.format is not None:
            raise ConfigError("give either FILE --format ... or --synthetic, not both")
        _refuse_options(args, _FILE_ONLY_OPTIONS, "a trajectory FILE, not to --synthetic")
        seed = 0 if args.seed is None else args.seed
        if seed < 0:
            raise ConfigError(f"--seed must be an integer >= 0, got {seed}; e.g. --seed 0")
        duration_s = 10.0 if args.duration_s is None else args.duration_s
        if not (math.isfinite(duration_s) and 0 < duration_s <= MAX_SYNTHETIC_DURATION_S):
            raise ConfigError(
                f"--duration-s must be a positive number of seconds, at most "
                f"{MAX_SYNTHETIC_DURATION_S:g} (an hour), got {duration_s}"
            )
        if getattr(args, "profile", None) == "continuous":
            return ContinuousMotionConfig(
                seed=seed, duration_s=duration_s, working_distance_m=working_distance_m
            )
        return SyntheticMotionConfig(
            seed=seed, duration_s=duration_s, working_distance_m=working_distance_m
        )
    if args.file is None or args.format is None:
        raise ConfigError("give FILE and --format (tum, bvh, fast-ycb, bop, csv), or --synthetic")
    _refuse_options(args, _SYNTHETIC_ONLY_OPTIONS, "--synthetic, not to a FILE")
    fraction = args.min_in_view_fraction
    placement = PlacementConfig(
        working_distance_m=working_distance_m,
        min_in_view_fraction=default_min_in_view_fraction if fraction is None else fraction,
    )
    return CapturedMotionConfig(
        path=args.file,
        format=args.format,
        joint=args.joint,
        relative_to=args.relative_to,
        object_id=args.object_id,
        sample_rate_hz=args.sample_rate_hz,
        lowpass_hz=args.lowpass_hz,
        remove_drift_window_s=args.drift_window_s,
        window_s=None if args.window_s is None else tuple(args.window_s),
        speed_scale=1.0 if args.speed_scale is None else args.speed_scale,
        placement=placement,
    )


def _refuse_options(
    args: argparse.Namespace, options: tuple[tuple[str, str], ...], applies_to: str
) -> None:
    values = [(getattr(args, name, None), flag) for name, flag in options]
    given = [flag for value, flag in values if value is not None and value is not False]
    if given:
        verb, pronoun = ("apply", "them") if len(given) > 1 else ("applies", "it")
        raise ConfigError(f"{', '.join(given)} {verb} only to {applies_to}; remove {pronoun}")


def format_speed_table(stats: SpeedStatistics, title: str) -> str:
    """A small text table of speed statistics (linear in m/s, angular in deg/s)."""
    lin, ang = stats.linear_speed_mps, stats.angular_speed_dps
    excluded = (
        f" ({stats.excluded_samples} in bridged gaps left out)" if stats.excluded_samples else ""
    )
    return "\n".join(
        [
            title,
            f"  duration {stats.duration_s:.3f} s, rate {stats.rate_hz:.3f} Hz, "
            f"{stats.num_samples} samples{excluded}",
            f"  {'':18}{'peak':>9}{'p95':>9}{'median':>9}",
            f"  {'linear [m/s]':18}{lin.peak:9.3f}{lin.p95:9.3f}{lin.median:9.3f}",
            f"  {'angular [deg/s]':18}{ang.peak:9.1f}{ang.p95:9.1f}{ang.median:9.1f}",
        ]
    )


def _build(
    args: argparse.Namespace, default_min_in_view_fraction: float
) -> tuple[TrajectoryConfig, Trajectory]:
    if args.fps is not None and not (math.isfinite(args.fps) and args.fps > 0):
        raise ConfigError(f"--fps must be a positive number of samples per second, got {args.fps}")
    config = trajectory_config_from_args(
        args, default_min_in_view_fraction=default_min_in_view_fraction
    )
    trajectory = build_trajectory(config, FAST_YCB_CAMERA)
    span_s = trajectory.end_s - trajectory.start_s
    if args.fps is not None and span_s * args.fps >= MAX_SAMPLES:
        raise ConfigError(
            f"--fps {args.fps:g} over {span_s:g} s gives more than {MAX_SAMPLES} samples; "
            "lower --fps (or the duration)"
        )
    return config, trajectory


HAND_MOTION_DURATION_S = 30.0
"""Length of each synthetic motion pooled by ``stats --hand-motion`` [s]."""


def trajectories_dir_from_args(given: Path | None) -> Path:
    """``--trajectories``, else ``$ROFT_SIM_TRAJECTORIES``, else ``../shared/trajectories``
    beside the repository."""
    from roft_sim.trajectories import default_trajectories_dir

    if given is not None:
        return given
    if os.environ.get("ROFT_SIM_TRAJECTORIES"):
        return Path(os.environ["ROFT_SIM_TRAJECTORIES"]).expanduser()
    return default_trajectories_dir()


def _run_hand_motion_stats(args: argparse.Namespace) -> int:
    from roft_sim.trajectories.statistics import (
        SPLIT_SEEDS,
        captured_distribution,
        fit_error,
        format_distribution_table,
        synthetic_distribution,
    )

    if args.file is not None or args.synthetic:
        raise ConfigError("--hand-motion compares the shared captures; drop FILE / --synthetic")
    folder = trajectories_dir_from_args(args.trajectories)
    if not folder.is_dir():
        raise ConfigError(
            f"captured motion folder {str(folder)!r} does not exist; pass --trajectories DIR "
            "(the shared trajectories folder, with tum/ and bvh/) or set $ROFT_SIM_TRAJECTORIES"
        )
    splits = ("tuning", "evaluation") if args.split == "both" else (args.split,)
    reports = []
    for split in splits:
        seeds = SPLIT_SEEDS[split]
        seed_text = f"seeds {seeds[0]}-{seeds[-1]}"
        captured = captured_distribution(split, folder, FAST_YCB_CAMERA)  # type: ignore[arg-type]
        continuous = synthetic_distribution(
            f"continuous ({seed_text})",
            ContinuousMotionConfig(duration_s=HAND_MOTION_DURATION_S),
            seeds,
            FAST_YCB_CAMERA,
        )
        bursty = synthetic_distribution(
            f"bursty ({seed_text})",
            SyntheticMotionConfig(duration_s=HAND_MOTION_DURATION_S),
            seeds,
            FAST_YCB_CAMERA,
        )
        errors = {d.name: fit_error(captured, d) for d in (continuous, bursty)}
        reports.append((split, captured, continuous, bursty, errors))
    if args.json:
        out = {
            split: {
                "captured": c.report(),
                "continuous": k.report(),
                "bursty": b.report(),
                "fit_error_rms_log": {"continuous": e[k.name], "bursty": e[b.name]},
            }
            for split, c, k, b, e in reports
        }
        json.dump(out, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    for split, c, k, b, e in reports:
        print(
            f"{split.upper()} split: captured hand-object motion vs synthetic profiles "
            f"(30 Hz samples, {HAND_MOTION_DURATION_S:g} s per seed)"
        )
        print(format_distribution_table([c, k, b]))
        print(
            "  fit error (RMS log ratio over the 12 percentiles): "
            + ", ".join(f"{name} {value:.2f}" for name, value in e.items())
        )
        print()
    return 0


def _run_stats(args: argparse.Namespace) -> int:
    if args.hand_motion:
        return _run_hand_motion_stats(args)
    if args.trajectories is not None or args.split != "both":
        raise ConfigError("--trajectories and --split apply only to --hand-motion")
    # speeds do not depend on the placement: report how much stays in view, never fail on it
    config, trajectory = _build(args, default_min_in_view_fraction=0.0)
    if args.fps is not None:
        sample = sample_at_rate(trajectory, args.fps)
    elif isinstance(trajectory, CapturedTrajectory):
        sample = trajectory.sample_knots()
    else:
        sample = sample_at_rate(trajectory, SYNTHETIC_STATS_RATE_HZ)
    gaps = (
        trajectory.bridged_intervals_s
        if isinstance(trajectory, CapturedTrajectory) and not args.include_gaps
        else ()
    )
    stats = speed_statistics(sample, exclude_intervals_s=gaps)
    source = trajectory.source if isinstance(trajectory, CapturedTrajectory) else "synthetic"
    if args.json:
        report = {"source": source, **stats.report()}
        if isinstance(trajectory, CapturedTrajectory):
            report["in_view_fraction"] = trajectory.in_view_fraction
        report["config"] = jsonable(config)
        json.dump(report, sys.stdout, indent=2)
        sys.stdout.write("\n")
    else:
        print(format_speed_table(stats, source))
        if isinstance(trajectory, CapturedTrajectory):
            print(f"  placed in view: {100 * trajectory.in_view_fraction:.0f} % of the samples")
    return 0


def _run_export(args: argparse.Namespace) -> int:
    if args.out.is_dir():
        raise ConfigError(
            f"--out must be a file path, {str(args.out)!r} is a folder; give e.g. "
            f"{str(args.out / 'trajectory.csv')!r}"
        )
    if args.out.exists() and not args.overwrite:
        raise ConfigError(f"{str(args.out)!r} exists; pass --overwrite to replace it")
    if args.out.parent and not args.out.parent.is_dir():
        raise ConfigError(f"folder {str(args.out.parent)!r} of --out does not exist; create it")
    config, trajectory = _build(args, default_min_in_view_fraction=0.5)
    sample = sample_at_rate(trajectory, args.fps)
    camera = jsonable(FAST_YCB_CAMERA)
    write_trajectory_csv(
        args.out,
        sample,
        comments=[
            f"roft-sim {__version__} trajectory export: T_cam_obj sampled at {args.fps:g} Hz",
            f"camera: {json.dumps(camera)}",
            f"config: {json.dumps(jsonable(config))}",
        ],
    )
    _log.info("wrote %d samples to %s", len(sample), args.out)
    return 0
