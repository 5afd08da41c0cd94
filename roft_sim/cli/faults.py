"""``roft-sim faults``: list the fault presets, or show what one does as a timeline.

- ``roft-sim faults list``: every preset in ``scenarios/faults/`` with its one-line description.
- ``roft-sim faults show PRESET|FILE [--frames 60] [--seed 0] [--fps 30] [--width 60] [--json]``:
  the faults configured, then a per-frame strip and, per detection stream, capture -> arrival of
  every network run with drops, duplicates, outliers and other injected faults marked. Detector
  misses of a dataset are not simulated here (every frame counts as detected).
- ``roft-sim faults random [--seed 0] [--out FILE]``: a random fault mix
  (:mod:`roft_sim.faults.random_mix`) as a fault file, printed or written.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from roft_sim.config_files import jsonable
from roft_sim.errors import ConfigError

__all__ = ["register"]


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        "faults",
        help="list fault presets or show a preset's timeline",
        description="Fault presets: list them, or print a timeline of what one does.",
    )
    verbs = parser.add_subparsers(dest="faults_verb", metavar="ACTION")
    lst = verbs.add_parser("list", help="list the presets with one-line descriptions")
    lst.set_defaults(func=_run_list)
    show = verbs.add_parser(
        "show",
        help="print the timeline of a preset or fault file",
        description="Prints capture -> arrival per stream for a preset or a fault TOML file.",
    )
    show.add_argument("faults", metavar="PRESET|FILE", help="preset name or path to a .toml")
    show.add_argument("--frames", type=int, default=60, help="camera frames (default 60)")
    show.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    show.add_argument("--fps", type=int, default=30, help="camera rate in Hz (default 30)")
    show.add_argument(
        "--width", type=int, default=60, help="frames per line of the strip (default 60)"
    )
    show.add_argument(
        "--ideal",
        action="store_true",
        help="the 'detector ideal' baseline: every frame's detection at its own frame",
    )
    show.add_argument("--json", action="store_true", help="print the schedule as JSON instead")
    show.set_defaults(func=_run_show)
    rnd = verbs.add_parser(
        "random",
        help="draw a random fault mix (a fault file) from a seed",
        description="Draws a fault file from every fault kind at random (docs/faults.md, "
        "'Random mixes'); the same seed gives the same file. Prints it, or writes it with --out.",
    )
    rnd.add_argument("--seed", type=int, default=0, help="mix seed (default 0)")
    rnd.add_argument("--out", type=Path, help="write the fault file here instead of printing it")
    rnd.set_defaults(func=_run_random)
    parser.set_defaults(func=lambda args: _no_action(parser))


def _no_action(parser: argparse.ArgumentParser) -> int:
    parser.print_help()
    return 2


def _run_list(args: argparse.Namespace) -> int:
    from roft_sim.faults import fault_presets_dir, list_fault_presets

    presets = list_fault_presets()
    if not presets:
        raise ConfigError(f"no fault presets found in {fault_presets_dir()}")
    width = max(len(name) for name, _ in presets)
    for name, description in presets:
        print(f"{name:<{width}}  {description}")
    return 0


MAX_SHOW_FRAMES = 100_000
"""Longest timeline ``faults show`` prints (about 5 MB of text)."""


def _run_show(args: argparse.Namespace) -> int:
    from roft_sim.faults import format_timeline, load_faults, schedule_detections

    if not 1 <= args.frames <= MAX_SHOW_FRAMES:
        raise ConfigError(
            f"--frames must be in 1..{MAX_SHOW_FRAMES} (a timeline to read), got {args.frames}; "
            "for statistics over long runs use `roft-sim run` and its metrics.json"
        )
    if args.width < 10:
        raise ConfigError(f"--width must be >= 10 frames per line, got {args.width}")
    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    faults = load_faults(args.faults)
    schedule = schedule_detections(
        args.frames, faults, args.seed, fps=args.fps, ideal_detections=args.ideal
    )
    if args.json:
        print(json.dumps({"faults": jsonable(faults), "schedule": jsonable(schedule)}, indent=1))
        return 0
    header = [f"fault preset {faults.name!r}: {faults.description}".rstrip(": ")]
    header += [f"  {line}" for line in faults.describe_lines()]
    seed_note = (
        f"fault seed {faults.seed} (fixed by the file)"
        if faults.seed is not None
        else (f"seed {args.seed}")
    )
    header += [seed_note + (", detector ideal" if args.ideal else ""), ""]
    print(format_timeline(schedule, header=tuple(header), width=args.width), end="")
    return 0


def _run_random(args: argparse.Namespace) -> int:
    from roft_sim.datasets.atomic_files import atomic_write_text
    from roft_sim.faults.random_mix import fault_mix_toml, random_fault_mix

    if args.seed < 0:
        raise ConfigError(f"--seed must be >= 0, got {args.seed}")
    text = fault_mix_toml(random_fault_mix(args.seed))
    if args.out is None:
        print(text, end="")
        return 0
    if args.out.is_dir():
        raise ConfigError(f"--out {args.out} is a folder; give a file path such as mix.toml")
    atomic_write_text(args.out, text)
    print(f"wrote {args.out} (use it as --faults {args.out}; roft-sim faults show {args.out})")
    return 0
