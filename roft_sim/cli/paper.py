"""``roft-sim paper``: the ROFT paper's Fast-YCB Tables I, II and IV in simulation.

    roft-sim paper --out DIR [--resolution 640x480] [--frames N] [--motion FAST_YCB_DIR]
                   [--flow SPEC] [--reuse DATASET]

Generates the six Fast-YCB-like sequences (``roft-sim generate --preset fast-ycb``) into
``DIR/dataset`` (or reuses a dataset), runs every row and writes the tables beside the paper's
numbers. See docs/paper.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from roft_sim.cli.assets import assets_dir_from_args
from roft_sim.cli.output_dirs import prepare_output_dir
from roft_sim.errors import ConfigError, DatasetFormatError

if TYPE_CHECKING:  # the harness loads only when the verb runs
    from roft_sim.harness.paper import PaperResult
    from roft_sim.scenario import Scenario

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds the ``paper`` verb."""
    parser = subparsers.add_parser(
        "paper",
        help="reproduce the ROFT paper's Fast-YCB tables (I, II, IV) in simulation",
        description="Generate (or reuse) the six Fast-YCB-like sequences, run the paper's rows "
        "(DOPE-like detector at 5 fps, DOPE ideal, ROFT, every Table IV ablation, ground-truth "
        "input rows, the same ROFT rows with the reference's settings, the attribution rows, "
        "other installed trackers) under the paper's delays, and write Tables I, II and IV side "
        "by side with the published numbers, an attribution table (reference, each deviation "
        "added, default), and a check of the paper's findings. "
        "Resumable: finished frames and cells are kept. See docs/paper.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples:\n"
        "  roft-sim paper --out paper/full                      # 1280x720, 880 frames\n"
        "  roft-sim paper --out paper/small --resolution 640x480 --frames 300 --workers 2\n"
        "  roft-sim paper --out paper/dis --reuse paper/small/dataset --flow dis\n"
        "  roft-sim paper --out paper/motion --motion /data/fast-ycb   # Fast-YCB's own motion\n"
        "  roft-sim paper --out paper/small --resume            # after an interruption\n"
        "\nexit codes: 0 done, 1 runtime error, 2 bad arguments or output, 130 interrupted",
    )
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument(
        "--resolution",
        metavar="WxH",
        help="render resolution of the generated sequences (default: the preset's 1280x720)",
    )
    parser.add_argument(
        "--frames", type=int, help="frames per generated sequence (default: the preset's 880)"
    )
    parser.add_argument(
        "--reuse",
        type=Path,
        metavar="DATASET_DIR",
        help="use this Fast-YCB-like dataset (ours or the real Fast-YCB) instead of generating",
    )
    parser.add_argument(
        "--motion",
        type=Path,
        metavar="FAST_YCB_DIR",
        help="move each object along its own sequence's captured motion in this Fast-YCB "
        "dataset (<DIR>/<object>/gt/poses.txt, e.g. the real Fast-YCB) instead of the preset's "
        "synthetic motion; not with --reuse",
    )
    parser.add_argument(
        "--flow",
        default="auto",
        metavar="SPEC",
        help="flow source of the rows that use flow (default auto: the stored nvof_1_slow set, "
        "our hardware-fitted NVOF-like flow; or nvof-like:dis, dis, gt, nvof-hw on an NVIDIA "
        "GPU, ...)",
    )
    parser.add_argument(
        "--rows",
        metavar="K1,K2",
        help="only these rows (keys: roft, detector, detector_ideal, roft_no_pose_sync, ..., "
        "roft_reference, roft_reference_no_pose_sync, ..., attr_01_horizon, ...; default all)",
    )
    parser.add_argument(
        "--no-plugins", action="store_true", help="do not add the other installed trackers"
    )
    parser.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    seeds_help = "every row over N seeds (fresh detector draws), numbers with 95 %% intervals"
    parser.add_argument("--seeds", type=int, default=1, metavar="N", help=seeds_help)
    parser.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument(
        "--assets",
        type=Path,
        help="folder of real YCB meshes for generation (default $ROFT_SIM_ASSETS; else the "
        "cache; else procedural stand-ins)",
    )
    parser.add_argument("--overwrite", action="store_true", help="empty a non-empty --out first")
    parser.add_argument(
        "--resume", action="store_true", help="continue in --out (keep its dataset and cells)"
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.set_defaults(func=_run)


def _generate(args: argparse.Namespace, out: Path, progress: bool) -> tuple[Path, dict[str, Any]]:
    from roft_sim.assets import default_cache_dir
    from roft_sim.generation import (
        PRESETS,
        GenerationOptions,
        ScenarioOverrides,
        generate_dataset,
        parse_resolution,
    )
    from roft_sim.render.gl_backend import require_gl_backend

    overrides = ScenarioOverrides(
        frames=args.frames,
        resolution=None if args.resolution is None else parse_resolution(args.resolution),
    )
    scenarios = _preset_scenarios(args.motion)
    for scenario in scenarios:
        overrides.apply(scenario)
    assets = assets_dir_from_args(args)
    backend = require_gl_backend(os.environ)
    dataset = out / "dataset"
    t0 = time.perf_counter()
    summary = generate_dataset(
        scenarios,
        dataset,
        GenerationOptions(
            workers=args.workers,
            resume=True,
            assets_dir=assets,
            cache_dir=default_cache_dir(os.environ),
            gl_backend=backend,
            progress=progress,
        ),
        overrides=overrides,
        sequence_naming=PRESETS["fast-ycb"].sequence_names,
        preset="fast-ycb",
    )
    info = {
        "generated": True,
        "frames_generated": summary.frames_generated,
        "generation_wall_s": round(time.perf_counter() - t0, 1),
        "resolution": args.resolution or "preset (1280x720)",
        "frames": args.frames or "preset (880)",
        "motion": "preset" if args.motion is None else str(args.motion),
    }
    return dataset, info


def _preset_scenarios(motion: Path | None) -> list[Scenario]:
    """The ``fast-ycb`` preset's scenarios, each replaying its object's motion from the Fast-YCB
    dataset ``motion`` when given (:func:`~roft_sim.generation.with_fast_ycb_motion`).

    Raises:
        ConfigError: ``motion`` is not a folder, lacks an object's poses, or one is malformed.
    """
    from roft_sim.generation import preset_scenario_paths, with_fast_ycb_motion
    from roft_sim.scenario import load_scenario

    scenarios = [load_scenario(p) for p in preset_scenario_paths("fast-ycb")]
    if motion is None:
        return scenarios
    if not motion.is_dir():
        raise ConfigError(f"--motion {str(motion)!r} is not a folder; give a Fast-YCB dataset root")
    try:
        return [with_fast_ycb_motion(s, motion) for s in scenarios]
    except DatasetFormatError as e:
        raise ConfigError(f"--motion: {e}") from None


def _print_result(
    args: argparse.Namespace, out: Path, result: PaperResult, timing: dict[str, float]
) -> None:
    """The JSON summary (``--json``), or the tables (stdout) and where they are (stderr)."""
    if args.json:
        print(
            json.dumps(
                {
                    "out": str(out),
                    "tables": str(result.tables_md),
                    "findings": [
                        {
                            "claim": f.claim,
                            "configuration": f.configuration,
                            "holds": f.holds,
                            "evidence": f.evidence,
                        }
                        for f in result.findings
                    ],
                    "wall_s": timing,
                },
                indent=2,
            )
        )
    else:
        print(result.tables_md.read_text(encoding="utf-8"), end="")
        print(
            f"tables in {result.tables_md} (dataset {timing['dataset_s']} s, runs "
            f"{timing['runs_s']} s)",
            file=sys.stderr,
        )


def _header(args: argparse.Namespace, dataset: Path) -> list[str]:
    """The Markdown lines above the tables: the dataset, faults, flow and seeds."""
    return [
        "# The ROFT paper in simulation",
        "",
        f"Dataset: `{dataset}` ({'reused' if args.reuse else 'generated'}); faults `paper` "
        f"(5 fps networks, 6 frames late, frame 0 undelayed); flow `{args.flow}`; "
        + (
            f"seed {args.seed}"
            if args.seeds == 1
            else f"seeds {args.seed}-{args.seed + args.seeds - 1} (pooled in the tables)"
        )
        + ". Frames without a tracker pose are left out (as the reference evaluation "
        "does before the first detection). How simulation differs from the paper's setting: "
        "docs/paper.md.",
        "",
    ]


def _run(args: argparse.Namespace) -> int:
    from roft_sim.executors import make_executor
    from roft_sim.harness.paper import paper_rows, plan_paper, run_paper
    from roft_sim.harness.run_dataset import find_sequences

    if args.reuse is not None and (args.frames is not None or args.resolution is not None):
        raise ConfigError("--reuse takes the dataset as it is; drop --frames / --resolution")
    if args.reuse is not None and args.motion is not None:
        raise ConfigError(
            "--motion sets the motion of the sequences to generate; --reuse generates none: "
            "drop one of them"
        )
    rows = paper_rows(
        [k.strip() for k in args.rows.split(",") if k.strip()] if args.rows else None,
        plugins=not args.no_plugins,
    )
    executor = make_executor(args.workers)
    # Everything that can be checked is checked before --out is touched (--overwrite empties it).
    if args.seed < 0 or args.seeds < 1:
        raise ConfigError(
            f"seed must be >= 0 and --seeds must be >= 1, got --seed {args.seed} --seeds "
            f"{args.seeds}"
        )
    if args.flow not in ("auto", "none"):
        from roft_sim.sensors.flow_sources import make_flow_source

        make_flow_source(args.flow, seed=0)
    if args.reuse is not None:
        try:
            paths = find_sequences([args.reuse])
            plan_paper(rows, paths, flow=args.flow, seed=args.seed, seeds=args.seeds)
        except DatasetFormatError as e:
            raise ConfigError(str(e)) from None
    else:
        from roft_sim.generation import ScenarioOverrides, parse_resolution

        assets_dir_from_args(args)
        ScenarioOverrides(
            frames=args.frames,
            resolution=None if args.resolution is None else parse_resolution(args.resolution),
        )
        if args.motion is not None:
            _preset_scenarios(args.motion)  # every object's motion file is there and readable
    out = prepare_output_dir(args.out, overwrite=args.overwrite, resume=args.resume)
    progress = not (args.no_progress or args.quiet or args.json)
    t0 = time.perf_counter()
    if args.reuse is not None:
        dataset, info = args.reuse, {"generated": False, "dataset": str(args.reuse)}
        from roft_sim.render.gl_backend import select_gl_backend

        select_gl_backend(os.environ)
    else:
        dataset, info = _generate(args, out, progress)
    t1 = time.perf_counter()
    header = _header(args, dataset)
    result = run_paper(
        [dataset],
        out,
        rows=rows,
        flow=args.flow,
        seed=args.seed,
        seeds=args.seeds,
        executor=executor,
        progress=progress,
        header=header,
        extra={"dataset": info, "command": vars_for_json(args)},
    )
    t2 = time.perf_counter()
    timing = {"dataset_s": round(t1 - t0, 1), "runs_s": round(t2 - t1, 1)}
    _print_result(args, out, result, timing)
    return 0


def vars_for_json(args: argparse.Namespace) -> dict[str, Any]:
    """The parsed arguments as JSON-ready values."""
    return {
        k: (str(v) if isinstance(v, Path) else v)
        for k, v in vars(args).items()
        if k not in ("func",)
    }
