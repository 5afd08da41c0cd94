"""The in-process executor: units one after the other in the calling process."""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator, Sequence
from typing import TypeVar

from roft_sim.executors.base import WorkerSetup, progress_reporter, unit_result

__all__ = ["SerialExecutor"]

U = TypeVar("U")
R = TypeVar("R")


class SerialExecutor:
    """Runs the units in order in the calling process (one core, debugging, tests).

    The setup's initializer runs once in this process before the first unit and its teardown
    after the last (also when a unit fails or the caller stops iterating).
    """

    workers = 1

    def map_unordered(
        self,
        fn: Callable[[U], R],
        units: Sequence[U],
        *,
        setup: WorkerSetup | None = None,
        on_progress: Callable[[int], None] | None = None,
    ) -> Iterator[tuple[U, R]]:
        """See :meth:`roft_sim.executors.Executor.map_unordered`."""
        if not units:
            return
        previous = progress_reporter(on_progress)
        try:
            if setup is not None and setup.initializer is not None:
                setup.initializer(*setup.initargs)
            for unit in units:
                yield unit, unit_result(unit, functools.partial(fn, unit))
        finally:
            try:
                if setup is not None and setup.teardown is not None:
                    setup.teardown()
            finally:
                progress_reporter(previous)

    def __repr__(self) -> str:
        return "SerialExecutor()"
