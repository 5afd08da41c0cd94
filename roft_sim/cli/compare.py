"""``roft-sim compare RUN_A RUN_B --out DIR``: two runs on the same data, frame by frame.

Paired differences of each metric with moving-block bootstrap intervals, a plot per sequence of
the per-frame error difference with the pose arrivals, and a table of where the difference
concentrates. See docs/statistics.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from roft_sim.cli.output_dirs import prepare_output_dir
from roft_sim.errors import ConfigError

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds the ``compare`` verb."""
    parser = subparsers.add_parser(
        "compare",
        help="compare two runs on the same data frame by frame, with confidence intervals",
        description="Pair two roft-sim run folders (or two sweep cells) on the frames both "
        "scored: each metric's difference A - B with a 95 % moving-block bootstrap interval "
        "and a verdict (better / worse / no detectable difference), a plot per sequence of the "
        "per-frame error difference with the pose arrivals, and where the difference "
        "concentrates (after a pose arrival, in no-detection stretches, during fast motion). "
        "Writes compare.md, compare.json and the plots into --out. See docs/statistics.md.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="example:\n"
        "  roft-sim compare out/demo/runs/roft out/demo/runs/detector-hold --out out/compare\n"
        "\nexit codes: 0 done, 1 runtime error, 2 bad arguments (e.g. runs on different data)",
    )
    parser.add_argument("run_a", type=Path, metavar="RUN_A", help="run folder of tracker A")
    parser.add_argument("run_b", type=Path, metavar="RUN_B", help="run folder of tracker B")
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--overwrite", action="store_true", help="empty a non-empty --out first")
    parser.add_argument(
        "--resamples", type=int, default=2000, help="bootstrap resamples (default 2000)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the resamples (default 0)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    parser.set_defaults(func=_run)


def _summary(result: Any) -> dict[str, Any]:
    return {
        "run_a": str(result.run_a.folder),
        "run_b": str(result.run_b.folder),
        "frames": result.frames,
        "pose_period": result.pose_period,
        "metrics": [
            {
                "metric": m.metric,
                "a": m.a if math.isfinite(m.a) else None,
                "b": m.b if math.isfinite(m.b) else None,
                "difference": m.difference.json_fields(),
                "verdict": m.verdict,
                "block": m.block,
            }
            for m in result.metrics
        ],
        "where": [
            {
                "category": w.category,
                "definition": w.definition,
                "frames": w.frames,
                "t_cm": w.t_cm.json_fields(),
                "a_deg": w.a_deg.json_fields(),
            }
            for w in result.where
        ],
        "plots": [str(p) for p in result.plots],
        "notes": result.notes,
    }


def _run(args: argparse.Namespace) -> int:
    from roft_sim.harness.compare import (
        check_same_data,
        compare_runs,
        format_compare,
        load_compared_run,
    )

    if args.resamples < 100:
        raise ConfigError(f"--resamples must be >= 100, got {args.resamples}")
    check_same_data(load_compared_run(args.run_a), load_compared_run(args.run_b))
    out = prepare_output_dir(args.out, overwrite=args.overwrite, can_resume=False)
    result = compare_runs(args.run_a, args.run_b, out, seed=args.seed, n_resamples=args.resamples)
    text = format_compare(result)
    (out / "compare.md").write_text(text, encoding="utf-8")
    summary = _summary(result)
    (out / "compare.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(text, end="")
        print(f"comparison in {out}", file=sys.stderr)
    return 0
