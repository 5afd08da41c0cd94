"""The local executor: a pool of ``spawn``-started worker processes on this machine."""

from __future__ import annotations

import contextlib
import multiprocessing
import queue
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Literal, TypeVar

from roft_sim.errors import ConfigError
from roft_sim.executors.base import (
    WorkerSetup,
    drain_progress,
    limit_worker_threads,
    progress_reporter,
    unit_result,
)

__all__ = ["LocalProcessExecutor"]

U = TypeVar("U")
R = TypeVar("R")

_DIED_DETAIL = ", or its set-up failed: see the log above"
_PROGRESS_POLL_S = 0.2
"""How often the driver forwards progress counts while units run [s]."""


def _start_worker(
    progress: Any,
    initializer: Callable[..., None] | None,
    initargs: tuple[Any, ...],
    setup: WorkerSetup | None,
) -> None:
    """Runs first in every worker process: threads, progress channel, then the initializers."""
    limit_worker_threads()
    progress_reporter(None if progress is None else progress.put)
    if initializer is not None:
        initializer(*initargs)
    if setup is not None and setup.initializer is not None:
        setup.initializer(*setup.initargs)


class LocalProcessExecutor:
    """A pool of ``workers`` processes on this machine, started with ``spawn`` (never ``fork``:
    MuJoCo's OpenGL contexts must not be inherited).

    Every worker runs the setup's initializer once and keeps its state (e.g. a renderer) for all
    the units it runs; at most two units per worker are in flight, so a failure or Ctrl-C leaves
    little queued work to cancel, and then the workers are terminated at once (units write
    atomically, so a unit stopped half-way leaves nothing a rerun would not repair).

    Args:
        workers: worker processes (>= 1).
        start_method: ``spawn`` (default) or ``forkserver``; never ``fork``.
        initializer: called once in every worker with ``initargs`` (before a map's own setup).
        initargs: its arguments.
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
            raise ConfigError(
                f"start_method must be 'spawn' or 'forkserver' (never 'fork'), got {start_method!r}"
            )
        self._workers = int(workers)
        self.start_method = start_method
        self.initializer = initializer
        self.initargs = initargs

    @property
    def workers(self) -> int:
        """Worker processes."""
        return self._workers

    def __repr__(self) -> str:
        return f"LocalProcessExecutor({self._workers}, start_method={self.start_method!r})"

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
        ctx = multiprocessing.get_context(self.start_method)
        progress = ctx.Queue() if on_progress is not None else None
        pending = list(reversed(units))
        running: dict[Future[R], U] = {}

        def drain() -> None:
            if progress is not None:
                drain_progress(progress.get_nowait, queue.Empty, on_progress)

        pool = ProcessPoolExecutor(
            max_workers=min(self._workers, len(units)),
            mp_context=ctx,
            initializer=_start_worker,
            initargs=(progress, self.initializer, self.initargs, setup),
        )
        try:
            while pending or running:
                while pending and len(running) < 2 * self._workers:
                    unit = pending.pop()
                    running[pool.submit(fn, unit)] = unit
                done, _ = wait(
                    list(running),
                    timeout=_PROGRESS_POLL_S if progress is not None else None,
                    return_when=FIRST_COMPLETED,
                )
                drain()
                for future in done:
                    unit = running.pop(future)
                    result = unit_result(
                        unit,
                        future.result,
                        worker_death=(BrokenProcessPool,),
                        death_detail=_DIED_DETAIL,
                    )
                    yield unit, result
            # Workers flush their progress queue when they exit: count everything reported.
            pool.shutdown(wait=True)
            drain()
        except BaseException:
            # Stop now rather than after the units in flight (also when the caller stops
            # iterating). ProcessPoolExecutor has no public terminate; _processes is stable
            # since Python 3.8.
            for proc in list((getattr(pool, "_processes", None) or {}).values()):
                with contextlib.suppress(Exception):
                    proc.terminate()
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
            if progress is not None:
                progress.close()
                progress.join_thread()
