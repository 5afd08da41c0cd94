"""``roft-sim trajectory stats|export``: inspect and export captured or synthetic motion.

- ``stats FILE --format F`` (or ``--synthetic``): duration, rate and speed statistics, as a
  table or (``--json``) a JSON object.
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

ORDER = 10

_log = logging.getLogger(__name__)

SYNTHETIC_STATS_RATE_HZ = 120.0
"""Rate at which ``stats --synthetic`` samples the motion unless ``--fps`` is given [Hz]."""


def _add_source_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("file", nargs="?", type=Path, help="trajectory file (or --synthetic)")
    parser.add_argument("--format", choices=TRAJECTORY_FILE_FORMATS, help="format of FILE")
    parser.add_argument("--joint", help="BVH: joint to follow, e.g. CC_Base_L_Hand")
    parser.add_argument("--relative-to", help="BVH: follow the joint relative to this one")
    parser.add_argument("--object-id", type=int, help="BOP: obj_id to follow")
    parser.add_argument(
        "--sample-rate-hz", type=float, help="Fast-YCB/BOP: frame rate of the file (default 30)"
    )
    parser.add_argument("--lowpass-hz", type=float, help="zero-phase low-pass cut-off [Hz]")
    parser.add_argument(
        "--drift-window-s", type=float, help="subtract a moving average of the position [s]"
    )
    parser.add_argument(
        "--window-s", type=float, nargs=2, metavar=("START", "END"), help="keep this time span"
    )
    parser.add_argument("--speed-scale", type=float, default=1.0, help="play faster (>1)/slower")
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
        help="fail when less of the placed motion stays in view (export default 0.5; stats "
        "only reports it)",
    )
    parser.add_argument(
        "--synthetic", action="store_true", help="use the synthetic generator instead of a file"
    )
    parser.add_argument("--seed", type=int, default=0, help="synthetic: seed (default 0)")
    parser.add_argument(
        "--duration-s", type=float, default=10.0, help="synthetic: duration [s] (default 10)"
    )


def register(subparsers: argparse._SubParsersAction) -> None:
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
        help="also count samples where the spline bridges gaps in the file's time stamps",
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
        ConfigError: contradictory or missing arguments.
    """
    working_distance_m = (float(args.working_distance_m[0]), float(args.working_distance_m[1]))
    if args.synthetic:
        if args.file is not None or args.format is not None:
            raise ConfigError("give either FILE --format ... or --synthetic, not both")
        return SyntheticMotionConfig(
            seed=args.seed, duration_s=args.duration_s, working_distance_m=working_distance_m
        )
    if args.file is None or args.format is None:
        raise ConfigError("give FILE and --format (tum, bvh, fast-ycb, bop, csv), or --synthetic")
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
        speed_scale=args.speed_scale,
        placement=placement,
    )


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
    return config, build_trajectory(config, FAST_YCB_CAMERA)


def _run_stats(args: argparse.Namespace) -> int:
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
