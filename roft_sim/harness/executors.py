"""Executors: where independent work units run.

An :class:`Executor` maps a picklable top-level function over work units and yields
``(unit, result)`` pairs as they finish, in any order. The sweep and paper runners hand it
:class:`~roft_sim.harness.sweep.SweepCell` units; anything else with independent units can use it
too (an executor knows nothing about what a unit is).

- :class:`SerialExecutor`: in the calling process, in order (debugging, one core, tests).
- :class:`LocalProcessExecutor`: a pool of ``spawn``-started worker processes (never ``fork``:
  MuJoCo's OpenGL contexts must not be inherited), at most two units in flight per worker, so an
  error or Ctrl-C leaves little queued work to cancel.

A later executor (Ray, or ``--shard i/N`` across machines) implements the same protocol; units
must therefore be self-contained (paths, configs and seeds, no open handles) and write their own
results atomically.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Literal, Protocol, TypeVar, runtime_checkable

from roft_sim.errors import ConfigError, RoftSimError

__all__ = [
    "Executor",
    "SerialExecutor",
    "LocalProcessExecutor",
    "WorkUnitError",
    "make_executor",
]

U = TypeVar("U")
R = TypeVar("R")


class WorkUnitError(RoftSimError):
    """A work unit raised, or its worker process died. Units finished before are kept."""


@runtime_checkable
class Executor(Protocol):
    """Runs ``fn(unit)`` for every unit and yields ``(unit, result)`` as each one finishes."""

    workers: int
    """How many units may run at once."""

    def map_unordered(self, fn: Callable[[U], R], units: Sequence[U]) -> Iterator[tuple[U, R]]:
        """Yields ``(unit, fn(unit))`` for every unit, in completion order.

        Raises:
            WorkUnitError: a unit raised (the error names the unit) or a worker died; units
                not yet started are cancelled.
        """
        ...


class SerialExecutor:
    """Runs the units one after the other in the calling process."""

    workers = 1

    def map_unordered(self, fn: Callable[[U], R], units: Sequence[U]) -> Iterator[tuple[U, R]]:
        for unit in units:
            try:
                result = fn(unit)
            except RoftSimError:
                raise
            except Exception as e:
                raise WorkUnitError(f"work unit {unit!r} failed: {type(e).__name__}: {e}") from e
            yield unit, result


class LocalProcessExecutor:
    """A pool of ``workers`` spawned processes on this machine.

    Args:
        workers: worker processes (>= 1).
        start_method: ``spawn`` (default) or ``forkserver``; never ``fork``.
        initializer: called once in every worker with ``initargs`` (e.g. to limit OpenCV's
            threads).
    """

    def __init__(
        self,
        workers: int,
        *,
        start_method: Literal["spawn", "forkserver"] = "spawn",
        initializer: Callable[..., None] | None = None,
        initargs: tuple[Any, ...] = (),
    ) -> None:
        if workers < 1:
            raise ConfigError(f"workers must be >= 1, got {workers}")
        if start_method not in ("spawn", "forkserver"):
            raise ConfigError(f"start_method must be 'spawn' or 'forkserver', got {start_method!r}")
        self.workers = int(workers)
        self.start_method = start_method
        self.initializer = initializer or _limit_threads
        self.initargs = initargs

    def map_unordered(self, fn: Callable[[U], R], units: Sequence[U]) -> Iterator[tuple[U, R]]:
        if not units:
            return
        ctx = multiprocessing.get_context(self.start_method)
        pending = list(reversed(units))
        running: dict[Future[R], U] = {}
        pool = ProcessPoolExecutor(
            max_workers=min(self.workers, len(units)),
            mp_context=ctx,
            initializer=self.initializer,
            initargs=self.initargs,
        )
        try:
            while pending or running:
                while pending and len(running) < 2 * self.workers:
                    unit = pending.pop()
                    running[pool.submit(fn, unit)] = unit
                done, _ = wait(list(running), return_when=FIRST_COMPLETED)
                for future in done:
                    unit = running.pop(future)
                    try:
                        result = future.result()
                    except BrokenProcessPool:
                        raise WorkUnitError(
                            f"a worker process died (killed, or out of memory) while running "
                            f"{unit!r}; finished units are kept: run again to resume"
                        ) from None
                    except RoftSimError:
                        raise
                    except Exception as e:
                        raise WorkUnitError(
                            f"work unit {unit!r} failed: {type(e).__name__}: {e}"
                        ) from e
                    yield unit, result
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def _limit_threads() -> None:
    """Worker initializer: one OpenCV thread per process (the pool provides the parallelism)."""
    import cv2

    cv2.setNumThreads(1)


def make_executor(workers: int) -> Executor:
    """:class:`SerialExecutor` for one worker, else a :class:`LocalProcessExecutor`."""
    if workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    return SerialExecutor() if workers == 1 else LocalProcessExecutor(workers)
