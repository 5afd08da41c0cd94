"""The ``roft-sim`` command line: ``main(argv) -> exit code``.

Each verb lives in its own module of this package and exposes ``register(subparsers)``, which adds
a sub-parser whose ``func(args) -> int`` runs the verb. :data:`VERBS` below lists every verb, one
line each, in the order ``roft-sim --help`` shows them: a new verb is one import and one line.
The CLI stays thin: parse, build the config, call the library. Environment variables are read here
and nowhere else in the package (``ROFT_SIM_ASSETS``, ``ROFT_SIM_CACHE``; ``MUJOCO_GL`` is
MuJoCo's own).

Exit codes: 0 success, 1 runtime error (or stdout closed early, as by ``| head``), 2 usage or
configuration error, 130 interrupted.
"""

from __future__ import annotations

import argparse
import logging
import os
import select
import sys
from collections.abc import Callable, Sequence
from typing import TextIO

from roft_sim import __version__
from roft_sim.cli import (
    assets,
    bag,
    compare,
    dataset,
    demo,
    faults,
    generate,
    paper,
    preview,
    report,
    run,
    sweep,
    trackers,
    trajectory,
    view,
)
from roft_sim.errors import ConfigError, RoftSimError

__all__ = ["main", "build_parser", "VERBS"]

_log = logging.getLogger("roft_sim")

EXIT_OK, EXIT_RUNTIME, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


RegisterVerb = Callable[["argparse._SubParsersAction[argparse.ArgumentParser]"], None]

VERBS: tuple[tuple[str, RegisterVerb], ...] = (
    ("demo", demo.register),
    ("generate", generate.register),
    ("trajectory", trajectory.register),
    ("assets", assets.register),
    ("run", run.register),
    ("sweep", sweep.register),
    ("compare", compare.register),
    ("report", report.register),
    ("view", view.register),
    ("bag", bag.register),
    ("paper", paper.register),
    ("dataset", dataset.register),
    ("preview", preview.register),
    ("faults", faults.register),
    ("trackers", trackers.register),
)
"""Every ``roft-sim`` verb: its name and the function that adds its sub-parser, in help order."""


def build_parser() -> argparse.ArgumentParser:
    """The full argument parser (all verbs registered)."""
    parser = argparse.ArgumentParser(
        prog="roft-sim",
        description="Simulation harness and dataset generator for 6D object pose and velocity "
        "trackers under fast motion, delays and faults.",
    )
    parser.add_argument("--version", action="version", version=f"roft-sim {__version__}")
    parser.add_argument(
        "-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)"
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    subparsers = parser.add_subparsers(dest="verb", metavar="VERB")
    for _, register in VERBS:
        register(subparsers)
    return parser


class _CurrentStderrHandler(logging.StreamHandler[TextIO]):
    """Writes to whatever ``sys.stderr`` is when a record is emitted.

    A plain StreamHandler keeps the stream it was created with; when ``main`` runs in-process
    (tests, notebooks) that stream may be a capture buffer closed long before the next record.
    """

    @property
    def stream(self) -> TextIO:
        return sys.stderr

    @stream.setter
    def stream(self, value: object) -> None:
        pass


def _configure_logging(verbose: int, quiet: bool) -> None:
    """roft_sim's own loggers at INFO (-v too, -vv DEBUG, -q WARNING); other libraries' loggers
    only from WARNING (INFO with -vv)."""
    level = logging.WARNING if quiet else (logging.DEBUG if verbose > 1 else logging.INFO)
    handler = _CurrentStderrHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    others = logging.INFO if verbose > 1 else logging.WARNING
    logging.basicConfig(level=others, handlers=[handler], force=True)
    logging.getLogger("roft_sim").setLevel(level)


def _stdout_reader_gone() -> bool:
    """True when stdout is a pipe whose reader has gone (``roft-sim ... | head``); stdout is
    then pointed at the null device, so that the interpreter's last flush does not fail again."""
    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        gone = any(events & select.POLLERR for _, events in poller.poll(0))  # Linux: no reader
        if gone:
            os.dup2(os.open(os.devnull, os.O_WRONLY), fd)
    except (OSError, ValueError, AttributeError):  # not a real file, or no poll() here
        return False
    return gone


def main(argv: Sequence[str] | None = None) -> int:
    """Runs ``roft-sim`` with ``argv`` (default: ``sys.argv[1:]``) and returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse exits on --help (0) and on usage errors (2)
        return int(e.code or 0)
    if args.verb is None:
        parser.print_help()
        return EXIT_USAGE
    _configure_logging(args.verbose, args.quiet)
    try:
        return int(args.func(args))
    except ConfigError as e:
        print(f"roft-sim {args.verb}: error: {e}", file=sys.stderr)
        return EXIT_USAGE
    except RoftSimError as e:
        print(f"roft-sim {args.verb}: error: {e}", file=sys.stderr)
        return EXIT_RUNTIME
    except KeyboardInterrupt:
        print(f"roft-sim {args.verb}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        if not _stdout_reader_gone():
            raise  # another pipe: not the reader of our output going away
        return EXIT_RUNTIME


if __name__ == "__main__":
    sys.exit(main())
