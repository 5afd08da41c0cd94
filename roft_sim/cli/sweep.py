"""``roft-sim sweep``: a grid of runs in parallel processes, resumable, with tables and plots.

    roft-sim sweep --config sweep.toml --out DIR [--workers N] [--resume]
    roft-sim sweep DATASET... --trackers roft,naive-delay --param delay=0:20:2 --out DIR
    roft-sim sweep --config sweep.toml --out DIR --executor ray [--address ADDR]
    roft-sim sweep --config sweep.toml --out DIR --shard 2/4      # then: --resume, no --shard

Everything is described in docs/running.md and docs/scaleout.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from roft_sim.cli.generate import add_executor_arguments, executor_from_args, shard_from_args
from roft_sim.cli.output_dirs import prepare_output_dir
from roft_sim.cli.run import add_input_arguments
from roft_sim.errors import ConfigError, DatasetFormatError, PluginError

__all__ = ["register"]


_GRID_FLAGS = ("datasets", "trackers", "faults", "param", "seeds")
_INPUT_FLAGS = ("flow", "poses", "masks", "init", "invalid", "no_rgb")


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds the ``sweep`` verb."""
    parser = subparsers.add_parser(
        "sweep",
        help="run a grid of trackers x faults x a swept fault parameter x datasets",
        description="Run every combination of trackers, fault configurations (optionally with a "
        "swept delay or dropout rate), sequences and seeds as independent cells in parallel "
        "processes. Finished cells are kept and never redone (--resume continues an interrupted "
        "sweep). Writes summary.{md,csv,tex} (each metric's mean over the sequence x seed "
        "replicates with its 95 % interval), paired.csv (every tracker against the first on the "
        "same cells), cells.csv, timing.csv and plots/ (error vs the parameter, per-frame error "
        "traces with pose arrivals). See docs/running.md and docs/statistics.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="examples (sweeps/delay.toml: a sweep file you write, format in docs/running.md):\n"
        "  roft-sim sweep --config sweeps/delay.toml --out sweeps/delay --workers 2\n"
        "  roft-sim sweep data/ci --trackers roft,naive-delay,pose-only-ukf "
        "--param delay=0:20:2 --out sweeps/delay\n"
        "  roft-sim sweep data/ci --trackers roft,detector-hold --param dropout=0,0.2,0.4,0.6 "
        "--out sweeps/dropout\n"
        "  roft-sim sweep --config sweeps/delay.toml --out sweeps/delay --resume\n"
        "  roft-sim sweep --config sweeps/delay.toml --out /shared/delay --executor ray "
        "--address auto\n"
        "  roft-sim sweep --config sweeps/delay.toml --out /shared/delay --shard 2/4  "
        "# array job 2 of 4\n"
        "  roft-sim sweep --config sweeps/delay.toml --out /shared/delay --resume   "
        "# summary, after all shards\n"
        "\nexit codes: 0 done, 1 a cell failed (finished cells kept: --resume), 2 bad arguments "
        "or output, 130 interrupted (finished cells kept: --resume)",
    )
    parser.add_argument(
        "datasets",
        nargs="*",
        type=Path,
        metavar="DATASET",
        help="sequences or dataset roots (or give them in --config)",
    )
    parser.add_argument("--config", type=Path, metavar="FILE", help="sweep TOML file")
    parser.add_argument(
        "--trackers",
        metavar="A,B",
        help="comma-separated tracker names (roft-sim trackers) or process:<command line> "
        "(docs/process.md)",
    )
    parser.add_argument(
        "--faults",
        metavar="P1,P2",
        help="comma-separated base fault presets or files (default: paper)",
    )
    parser.add_argument(
        "--param",
        metavar="NAME=VALUES",
        help="swept fault parameter: delay=START:STOP:STEP (frames, stop included) or "
        "dropout=P1,P2,... (probability per result)",
    )
    parser.add_argument(
        "--param-streams",
        default="pose,mask",
        metavar="S1,S2",
        help="streams the swept parameter acts on (default pose,mask)",
    )
    parser.add_argument("--seeds", metavar="S1,S2", help="comma-separated run seeds (default 0)")
    add_input_arguments(parser, sweep=True)
    parser.set_defaults(**{name: None for name in _INPUT_FLAGS})
    parser.add_argument("--out", type=Path, required=True, help="sweep output folder")
    add_executor_arguments(
        parser,
        workers_help="workers: local processes (default 1 = in this process) or, with "
        "--executor ray, Ray actors (default: one per CPU of the cluster)",
        shard_help="run only shard i of N (1-based, e.g. 2/4) of the cells, for array jobs "
        "sharing --out; no summary is written: once every shard has finished, the same "
        "command with --resume and no --shard writes it (docs/scaleout.md)",
    )
    parser.add_argument("--overwrite", action="store_true", help="empty a non-empty --out first")
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue the sweep in --out: finished cells are kept, the others run",
    )
    parser.add_argument("--no-plots", action="store_true", help="skip the plots")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.set_defaults(func=_run)


def _split(text: str) -> list[str]:
    return [x.strip() for x in text.split(",") if x.strip()]


def _config_from_flags(args: argparse.Namespace) -> Any:
    from roft_sim.harness.sweep import SweepConfig, parse_parameter

    if not args.datasets:
        raise ConfigError("give DATASET paths (or --config FILE)")
    if not args.trackers:
        raise ConfigError("give --trackers A,B (or --config FILE)")
    try:
        seeds = tuple(int(s) for s in _split(args.seeds or "0"))
    except ValueError:
        raise ConfigError(f"--seeds {args.seeds!r}: expected integers, e.g. 0,1,2") from None
    inputs = {name: getattr(args, name) for name in _INPUT_FLAGS if name != "no_rgb"}
    extra = {k: v for k, v in inputs.items() if v is not None}
    if args.no_rgb:
        extra["include_rgb"] = False
    return SweepConfig(
        name=args.out.name,
        datasets=tuple(args.datasets),
        trackers=tuple(_split(args.trackers)),
        faults=tuple(_split(args.faults or "paper")),
        parameter=(
            parse_parameter(args.param, streams=_split(args.param_streams)) if args.param else None
        ),
        seeds=seeds,
        **extra,
    )


def _load_config(args: argparse.Namespace) -> Any:
    from roft_sim.harness.sweep import load_sweep_config

    if args.config is None:
        return _config_from_flags(args)
    given = [f for f in (*_GRID_FLAGS, *_INPUT_FLAGS) if getattr(args, f, None)]
    if given:
        flags = ", ".join(
            "DATASET" if f == "datasets" else f"--{f.replace('_', '-')}" for f in given
        )
        raise ConfigError(
            f"--config {str(args.config)!r} defines the whole grid; drop {flags} or put them in "
            "the file"
        )
    if not args.config.is_file():
        raise ConfigError(f"--config {str(args.config)!r} does not exist")
    return load_sweep_config(args.config)


def _run(args: argparse.Namespace) -> int:
    from roft_sim.harness.sweep import plan_sweep, run_sweep

    config = _load_config(args)
    try:
        plan_sweep(config)  # validates trackers, faults and datasets before the output is touched
    except (DatasetFormatError, PluginError) as e:
        raise ConfigError(str(e)) from None
    shard = shard_from_args(args)
    from roft_sim.render.gl_backend import select_gl_backend

    select_gl_backend(os.environ)  # workers inherit it; MuJoCo loads only if a tracker renders
    executor = executor_from_args(args)
    # Shards share --out: each keeps what is there (finished cells of every shard).
    out = prepare_output_dir(
        args.out, overwrite=args.overwrite, resume=args.resume or shard is not None
    )
    result = run_sweep(
        config,
        out,
        executor=executor,
        progress=not (args.no_progress or args.quiet or args.json),
        plots=not args.no_plots,
        shard=shard,
    )
    if shard is not None:
        done = sum(c.cell_id in result.records for c in result.shard_cells)
        if args.json:
            print(
                json.dumps(
                    {
                        "out": str(out),
                        "cells": len(result.cells),
                        "shard": str(shard),
                        "shard_cells": len(result.shard_cells),
                        "shard_cells_finished": done,
                        "summary": None,
                    },
                    indent=2,
                )
            )
        print(
            f"shard {shard}: {done} of its {len(result.shard_cells)} cells finished (the sweep "
            f"has {len(result.cells)}) in {out}; once every shard has finished, run the same "
            "command without --shard and with --resume to write the summary",
            file=sys.stderr,
        )
        return 0
    if args.json:
        print(
            json.dumps(
                {
                    "out": str(out),
                    "cells": len(result.cells),
                    "summary": result.summary_rows,
                    "plots": [str(p) for p in result.plots],
                },
                indent=2,
            )
        )
    else:
        print((out / "summary.md").read_text(encoding="utf-8"), end="")
        print(f"sweep results in {out}", file=sys.stderr)
    return 0
