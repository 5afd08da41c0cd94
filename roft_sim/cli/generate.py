"""``roft-sim generate``: render scenarios into datasets (fast-ycb, bop, hdf5).

    roft-sim generate SCENARIO.toml [...] --out DIR [options]
    roft-sim generate --preset fast-ycb --out DIR [--frames N] [--resolution 640x480]

One sequence per scenario (named after the scenario; after the object for ``--preset
fast-ycb``), rendered with exact ground truth and the scenario's simulated networks on every
frame. Parallel worker processes or a Ray cluster (``--executor ray``), ``--shard i/N`` for array
jobs, a progress bar, atomic per-frame writes, ``--resume``. Everything is described in
docs/generate.md and docs/scaleout.md.

:func:`add_executor_arguments`, :func:`executor_from_args` and :func:`shard_from_args` are
shared with ``roft-sim sweep``.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roft_sim.cli.assets import assets_dir_from_args
from roft_sim.cli.output_dirs import prepare_output_dir
from roft_sim.errors import ConfigError

if TYPE_CHECKING:  # the generation and executor modules load only when a verb runs
    from roft_sim.executors import Shard
    from roft_sim.generation.runner import GenerationSummary

__all__ = ["register", "add_executor_arguments", "executor_from_args", "shard_from_args"]


_log = logging.getLogger(__name__)

_FORMATS = ("fast-ycb", "bop", "hdf5")


def _preset_help() -> str:
    from roft_sim.generation.presets import PRESETS

    return "; ".join(f"{p.name}: {p.description}" for p in PRESETS.values())


def _add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """How ``generate`` runs: workers and executor, chunks, overwrite/resume, assets, output."""
    add_executor_arguments(
        parser,
        workers_help="workers, each rendering with its own OpenGL context: local processes "
        "(default 1 = in this process) or, with --executor ray, Ray actors (default: one per "
        "CPU of the cluster)",
        shard_help="generate only shard i of N (1-based, e.g. 2/4) of the frame chunks, for "
        "array jobs sharing --out; the same command with --resume and no --shard finalizes "
        "the sequences once every shard has finished (docs/scaleout.md)",
    )
    parser.add_argument(
        "--chunk-frames",
        type=int,
        default=32,
        help="most frames per work unit handed to a worker (default 32)",
    )
    parser.add_argument(
        "--png-compression",
        type=int,
        metavar="LEVEL",
        help="compression level 0-9 of the PNG files (fast-ycb, bop; default 1, the fastest; "
        "1-3 deflated by ISA-L, 4-9 by libpng/zlib: smaller, much slower; docs/formats.md)",
    )
    parser.add_argument("--overwrite", action="store_true", help="empty a non-empty --out first")
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted run in --out: keep finished sequences and complete "
        "frames, generate only the missing frames (same scenarios and options required)",
    )
    parser.add_argument(
        "--assets",
        type=Path,
        help="folder of real YCB meshes searched first (default $ROFT_SIM_ASSETS; then the "
        "cache, $ROFT_SIM_CACHE or ~/.cache/roft_sim; else procedural stand-ins)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar (also with -q)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds the ``generate`` verb."""
    parser = subparsers.add_parser(
        "generate",
        help="render scenarios into a dataset (fast-ycb, bop or hdf5)",
        description="Render scenario files (or a preset) into a dataset: rgb, depth, exact "
        "ground truth (pose, velocity, masks, optical flow) and simulated networks (DOPE-like "
        "poses, Mask R-CNN-like masks, flow sets) on every frame. Same scenario and seed give a "
        "byte-identical dataset on the same render backend, whatever --workers. See "
        "docs/generate.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
        "  roft-sim generate scenarios/ci/cracker_box.toml --out data/ci\n"
        "  roft-sim generate --preset fast-ycb --out data/fast_ycb --workers 2\n"
        "  roft-sim generate --preset fast-ycb --out data/small --frames 60 "
        "--resolution 640x360\n"
        "  roft-sim generate --preset fast-ycb --out data/fast_ycb --resume   # after Ctrl-C\n"
        "  roft-sim generate --preset fast-ycb --out /shared/fy --executor ray --address auto\n"
        "  roft-sim generate --preset fast-ycb --out /shared/fy --shard 2/4   # array job 2 of 4\n"
        "  roft-sim generate --preset fast-ycb --out /shared/fy --resume      # after all shards\n"
        "\nexit codes: 0 done, 1 a worker failed (frames kept: --resume), 2 bad arguments, "
        "scenario or output, 130 interrupted (frames kept: --resume)",
    )
    parser.add_argument(
        "scenarios",
        nargs="*",
        type=Path,
        metavar="SCENARIO",
        help="scenario TOML files (docs/scenarios.md); one sequence each",
    )
    parser.add_argument(
        "--preset",
        help=f"generate a shipped set of scenarios instead of files ({_preset_help()})",
    )
    parser.add_argument(
        "--out", type=Path, required=True, help="output dataset root (one sequence per scenario)"
    )
    parser.add_argument(
        "--format",
        default="fast-ycb",
        help="dataset format: fast-ycb (ROFT's layout, default), bop, or hdf5 (one .h5 per "
        "sequence)",
    )
    parser.add_argument(
        "--frames",
        type=int,
        help="frames per sequence (replaces the scenarios' frames/duration_s; must fit the "
        "trajectory)",
    )
    parser.add_argument(
        "--resolution",
        metavar="WxH",
        help="render at WIDTHxHEIGHT px, e.g. 640x480; the intrinsics are scaled, so the field "
        "of view is kept",
    )
    parser.add_argument(
        "--seed",
        type=int,
        help="scenario seed (textures, depth noise, simulated networks; the trajectory keeps its "
        "own seed); default: each scenario's seed",
    )
    _add_run_arguments(parser)
    parser.set_defaults(func=_run)


def add_executor_arguments(
    parser: argparse.ArgumentParser, *, workers_help: str, shard_help: str
) -> None:
    """Adds ``--workers``, ``--executor``, ``--address`` and ``--shard`` (generate, sweep)."""
    parser.add_argument("--workers", type=int, default=None, help=workers_help)
    parser.add_argument(
        "--executor",
        default="local",
        metavar="{local,ray}",
        help="where the work units run: local processes (default) or a Ray cluster (needs the "
        "ray extra: pip install 'roft-sim[ray]')",
    )
    parser.add_argument(
        "--address",
        metavar="ADDR",
        help="with --executor ray: the cluster to use (host:6379, ray://host:10001, or auto for "
        "the one running on this node); default: a private local Ray instance",
    )
    parser.add_argument("--shard", metavar="i/N", help=shard_help)


def shard_from_args(args: argparse.Namespace) -> Any:
    """The :class:`~roft_sim.executors.Shard` of ``--shard`` (None without it).

    Raises:
        ConfigError: a malformed ``--shard``, or ``--shard`` with ``--overwrite`` (a shard must
            never empty the folder other shards write into).
    """
    from roft_sim.executors import Shard

    if args.shard is None:
        return None
    shard = Shard.parse(args.shard)
    if args.overwrite:
        raise ConfigError(
            f"--shard {args.shard} with --overwrite: shards write into the same --out, so one "
            "must not empty it; empty it once before starting the shards"
        )
    return shard


def executor_from_args(args: argparse.Namespace) -> Any:
    """The executor of ``--executor``/``--workers``/``--address``. Ray actors get this
    process's OpenGL backend variables (``MUJOCO_GL``, ``PYOPENGL_PLATFORM``): workers on other
    nodes do not inherit the driver's environment.

    Raises:
        ConfigError: bad values, ``--address`` without ``--executor ray``, Ray not installed.
    """
    from roft_sim.executors import make_executor

    env = {k: os.environ[k] for k in ("MUJOCO_GL", "PYOPENGL_PLATFORM") if os.environ.get(k)}
    return make_executor(args.workers, kind=args.executor, address=args.address, worker_env=env)


def _scenario_paths(args: argparse.Namespace) -> tuple[list[Path], str | None]:
    from roft_sim.generation.presets import preset_scenario_paths

    if args.preset is not None and args.scenarios:
        raise ConfigError("give scenario files or --preset, not both")
    if args.preset is not None:
        return preset_scenario_paths(args.preset), args.preset
    if not args.scenarios:
        raise ConfigError(
            "no scenario given: pass scenario files (e.g. scenarios/ci/cracker_box.toml) or "
            "--preset fast-ycb"
        )
    for path in args.scenarios:
        if not path.is_file():
            raise ConfigError(f"scenario file {str(path)!r} does not exist; check the path")
    return list(args.scenarios), None


def _print_summary(
    args: argparse.Namespace, summary: GenerationSummary, shard: Shard | None
) -> None:
    """What ``generate`` prints: the JSON summary, a shard's progress, or one line per sequence
    (stdout) and the throughput (stderr)."""
    if args.json:
        print(json.dumps(summary.report(), indent=2))
    elif shard is not None:
        for s in summary.sequences:
            print(f"{args.out / s.name}: {s.frames_generated} frames generated now")
        print(
            f"shard {shard}: {summary.frames_generated} frames in {summary.wall_s:.1f} s; once "
            "every shard has finished, run the same command without --shard and with --resume "
            "to finalize the sequences",
            file=sys.stderr,
        )
    else:
        for s in summary.sequences:
            print(f"{s.path} ({s.n_frames} frames, {s.frames_generated} generated now)")
            if s.visibility is not None:
                v = s.visibility
                print(
                    f"  object visible fraction: mean {v['mean']:.3f}, p10 {v['p10']:.3f}, "
                    f"p50 {v['p50']:.3f}, min {v['min']:.3f}; "
                    f"{100 * v['frames_below_half']:.1f} % of frames below half visible"
                )
        print(
            f"{summary.frames_generated} frames in {summary.wall_s:.1f} s "
            f"({summary.frames_per_s:.2f} frames/s, {summary.workers} worker"
            f"{'s' if summary.workers > 1 else ''})",
            file=sys.stderr,
        )


def _run(args: argparse.Namespace) -> int:
    from roft_sim.assets import default_cache_dir
    from roft_sim.render.gl_backend import require_gl_backend, start_gl_probe

    # the backend's probe (a subprocess of about a second) runs while the library is imported
    # and the scenarios are loaded; require_gl_backend below waits for it
    start_gl_probe(os.environ)
    if args.format not in _FORMATS:
        raise ConfigError(
            f"unknown --format {args.format!r}; expected one of {', '.join(_FORMATS)}"
        )
    paths, preset = _scenario_paths(args)
    # Validate everything that can be checked before touching the output.
    from roft_sim.generation import (
        PRESETS,
        GenerationOptions,
        ScenarioOverrides,
        generate_dataset,
        parse_resolution,
    )
    from roft_sim.scenario import load_scenario

    overrides = ScenarioOverrides(
        frames=args.frames,
        resolution=None if args.resolution is None else parse_resolution(args.resolution),
        seed=args.seed,
    )
    scenarios = [load_scenario(p) for p in paths]
    for scenario in scenarios:
        overrides.apply(scenario)  # fails here, before the output is touched
    assets_dir = assets_dir_from_args(args)
    if args.overwrite and args.resume:
        raise ConfigError("--overwrite and --resume contradict each other; pick one")
    shard = shard_from_args(args)
    executor_from_args(args)  # checks --executor/--workers/--address (and Ray) first
    backend = require_gl_backend(os.environ)  # before MuJoCo is imported
    executor = executor_from_args(args)  # again: Ray actors get the backend just chosen
    options = GenerationOptions(
        format=args.format,
        workers=args.workers or 1,
        chunk_frames=args.chunk_frames,
        resume=args.resume,
        assets_dir=assets_dir,
        cache_dir=default_cache_dir(os.environ),
        gl_backend=backend,
        progress=not (args.no_progress or args.quiet),
        shard=shard,
        **({} if args.png_compression is None else {"png_compression": args.png_compression}),
    )
    if args.out.exists() and not args.out.is_dir():
        raise ConfigError(f"output {str(args.out)!r} is a file; give a directory path")
    shared = shard is not None  # other shards write into --out at the same time
    if (
        not (args.overwrite or args.resume or shared)
        and args.out.is_dir()
        and any(args.out.iterdir())
    ):
        prepare_output_dir(args.out)  # raises the standard "not empty" error
    summary = generate_dataset(
        scenarios,
        args.out,
        options,
        overrides=overrides,
        sequence_naming=PRESETS[preset].sequence_names if preset else "auto",
        preset=preset,
        prepare_output=lambda out: prepare_output_dir(
            out, overwrite=args.overwrite, resume=args.resume or shared
        ),
        # local: let generate_dataset choose (in this process when there is one unit)
        executor=None if args.executor == "local" else executor,
    )
    _print_summary(args, summary, shard)
    return 0
