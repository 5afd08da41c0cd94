"""The stress benchmark: trackers x fault presets x metrics under fast captured and synthetic
motion, a hand occluder, a moving camera and noisy flow (issue 14; docs/running.md).

    python benchmarks/bench_robustness.py --quick --out stress-quick --workers 2
    python benchmarks/bench_robustness.py --medium --out stress-medium --workers 2
    python benchmarks/bench_robustness.py --full --out stress-full --workers 16 \
        --trajectories ../shared/trajectories
    python benchmarks/bench_robustness.py --holdout --medium --out stress-holdout --workers 2
    python benchmarks/bench_robustness.py --holdout --medium --random-mixes 30 --out mixes \
        --workers 2

Reads the shipped ``scenarios/sweeps/stress.toml`` (or ``--config``; ``--holdout`` reads the
shipped ``stress_holdout.toml``: captured windows and joints, objects and seeds that neither
split uses, every fault preset at the medium size; run it once a choice made on TUNING has been
reported on EVALUATION, never to choose), renders each sequence once
into ``OUT/data`` (reused by later runs), runs the grid with the sweep machinery into
``OUT/grid`` (parallel, resumable: run the same command again to continue), and prints, per
split (TUNING, EVALUATION, HOLDOUT, named), trackers x presets x metrics pooled over sequences,
flows and seeds, per flow source, per sequence, and the verdict lines (paired: a preset is a
win only when every paired 95 % interval excludes 0; each line says how many replicates it rests
on, and a "Seeds needed" section how many seeds a 2-point ADD-AUC difference needs; ``--seeds``
replaces the size's seeds). The report is also written to ``OUT/report.md``.
``--random-mixes N`` replaces the size's fault presets by N random fault mixes (seeds
``--mix-seed`` .. ``--mix-seed + N - 1``, written to ``OUT/mixes/``; docs/faults.md, "Random
mixes"): a verdict on fault mixes nobody tuned on. Captured sequences
need the shared trajectories folder (``--trajectories``, else ``$ROFT_SIM_TRAJECTORIES``, else
``../shared/trajectories`` beside the repository); without it they are skipped with a note.
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import os
import sys
import time
from pathlib import Path

from roft_sim.cli.trajectory import trajectories_dir_from_args
from roft_sim.datasets.atomic_files import atomic_write_text
from roft_sim.executors import LocalProcessExecutor
from roft_sim.faults.random_mix import fault_mix_toml, random_fault_mix, random_mix_name
from roft_sim.harness.stress import (
    format_stress_report,
    load_stress_config,
    run_stress,
    shipped_holdout_config,
    shipped_stress_config,
)
from roft_sim.render.gl_backend import select_gl_backend


def write_random_mixes(folder: Path, seeds: range) -> tuple[str, ...]:
    """Writes the random fault mix of each seed to ``folder/mix-<seed>.toml`` (the same file
    on every run); returns their paths, the fault specs of the grid."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for seed in seeds:
        path = folder / f"{random_mix_name(seed)}.toml"
        atomic_write_text(path, fault_mix_toml(random_fault_mix(seed)))
        paths.append(str(path.resolve()))
    return tuple(paths)


def _seeds(parser: argparse.ArgumentParser, text: str) -> tuple[int, ...]:
    """``--seeds S1,S2``: distinct integers >= 0 (else a usage error)."""
    try:
        seeds = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        parser.error(f"--seeds must be comma-separated integers, got {text!r}")
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        parser.error(f"--seeds must list distinct integers >= 0, got {text!r}")
    return seeds


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sizes = parser.add_mutually_exclusive_group()
    sizes.add_argument("--quick", action="store_true", help="the quick size (default)")
    sizes.add_argument("--medium", action="store_true", help="the medium size")
    sizes.add_argument("--full", action="store_true", help="the full size")
    files = parser.add_mutually_exclusive_group()
    files.add_argument("--config", type=Path, help="stress file (default: the shipped one)")
    files.add_argument(
        "--holdout",
        action="store_true",
        help="the shipped held-out file (stress_holdout.toml: sequences neither split uses)",
    )
    parser.add_argument("--out", type=Path, default=Path("stress-out"), help="output folder")
    parser.add_argument("--trajectories", type=Path, help="shared captured-motion folder")
    parser.add_argument("--workers", type=int, default=1, help="local worker processes")
    parser.add_argument("--no-per-sequence", action="store_true", help="pooled tables only")
    parser.add_argument("--progress", action="store_true", help="progress bar")
    parser.add_argument(
        "--random-mixes",
        type=int,
        metavar="N",
        help="run N random fault mixes (roft-sim faults random) instead of the size's presets",
    )
    parser.add_argument(
        "--mix-seed", type=int, default=1000, help="seed of the first random mix (default 1000)"
    )
    parser.add_argument(
        "--seeds", metavar="S1,S2", help="run seeds instead of the size's (more replicates)"
    )
    args = parser.parse_args(argv)
    if args.random_mixes is not None and args.random_mixes < 1:
        parser.error(f"--random-mixes must be >= 1, got {args.random_mixes}")
    if args.mix_seed < 0:
        parser.error(f"--mix-seed must be >= 0, got {args.mix_seed}")
    seeds = None if args.seeds is None else _seeds(parser, args.seeds)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    select_gl_backend(os.environ)
    config_path = args.config or (
        shipped_holdout_config() if args.holdout else shipped_stress_config()
    )
    config = load_stress_config(config_path)
    size_name = "full" if args.full else "medium" if args.medium else "quick"
    size = config.full if args.full else config.medium if args.medium else config.quick
    if size is None:
        parser.error(f"the stress file {config_path} has no [{size_name}] size")
    trajectories = trajectories_dir_from_args(args.trajectories)
    if not trajectories.is_dir():
        print(
            f"note: captured motion folder {trajectories} is absent: the captured sequences are "
            "skipped (pass --trajectories DIR)",
            file=sys.stderr,
        )
    if seeds is not None:
        size = dataclasses.replace(size, seeds=seeds)
    if args.random_mixes:
        seeds = range(args.mix_seed, args.mix_seed + args.random_mixes)
        size = dataclasses.replace(size, faults=write_random_mixes(args.out / "mixes", seeds))
    executor = LocalProcessExecutor(args.workers) if args.workers > 1 else None
    t0 = time.perf_counter()
    result = run_stress(
        config,
        size,
        args.out,
        trajectories_dir=trajectories,
        size_name=size_name,
        executor=executor,
        render_workers=args.workers,
        progress=args.progress,
    )
    report = format_stress_report(
        result,
        subject=config.subject,
        baselines=[b for b in config.baselines if b in result.trackers],
        per_sequence=not args.no_per_sequence,
    )
    (args.out / "report.md").write_text(report, encoding="utf-8")
    print(report, end="")
    print(f"\n({time.perf_counter() - t0:.0f} s; results in {args.out})", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
