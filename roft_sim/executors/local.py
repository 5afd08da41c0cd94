"""The local executor: a pool of ``spawn``-started worker processes on this machine."""

from __future__ import annotations

import contextlib
import functools
import multiprocessing
import queue
import uuid
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


_SETUPS_DONE: set[str] = set()
"""Tokens of the map set-ups this worker process has run (pools started by ``start()``)."""


def _spawned() -> None:
    """A no-op task: submitting one makes the pool spawn a worker now."""


def _run_after_setup(token: str, setup: WorkerSetup, fn: Callable[[U], R], unit: U) -> R:
    """Runs the map's set-up once per worker process (the first time a unit of the map lands
    there), then ``fn(unit)``: how a pool started before the map learns the map's set-up."""
    if token not in _SETUPS_DONE:
        if setup.initializer is not None:
            setup.initializer(*setup.initargs)
        _SETUPS_DONE.add(token)
    return fn(unit)


class LocalProcessExecutor:
    """A pool of ``workers`` processes on this machine, started with ``spawn`` (never ``fork``:
    MuJoCo's OpenGL contexts must not be inherited).

    Every worker runs the setup's initializer once and keeps its state (e.g. a renderer) for all
    the units it runs. :meth:`start` spawns the workers ahead of the map (each runs the
    executor's ``initializer``, e.g. imports and a renderer), so that their start-up overlaps
    what the caller prepares meanwhile; the map's own set-up then runs in each worker before its
    first unit; at most two units per worker are in flight, so a failure or Ctrl-C leaves
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
        self._started: tuple[ProcessPoolExecutor, Any] | None = None

    def start(self) -> None:
        """Spawns the worker processes now (idempotent); the next :meth:`map_unordered` runs
        on them and shuts them down when it ends. Call :meth:`close` if no map follows."""
        if self._started is not None:
            return
        ctx = multiprocessing.get_context(self.start_method)
        progress = ctx.Queue()
        pool = ProcessPoolExecutor(
            max_workers=self._workers,
            mp_context=ctx,
            initializer=_start_worker,
            initargs=(progress, self.initializer, self.initargs, None),
        )
        self._started = (pool, progress)
        for _ in range(self._workers):  # no worker is idle yet: each submit spawns one
            pool.submit(_spawned)

    def close(self) -> None:
        """Stops workers started by :meth:`start` that no map has used (idempotent)."""
        if self._started is not None:
            pool, progress = self._started
            self._started = None
            _terminate(pool)
            pool.shutdown(wait=True, cancel_futures=True)
            progress.close()
            progress.join_thread()

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
            self.close()
            return
        if self._started is not None:  # workers already running: their set-up comes with fn
            pool, progress = self._started
            self._started = None
            if setup is not None:
                fn = functools.partial(_run_after_setup, uuid.uuid4().hex, setup, fn)
        else:
            ctx = multiprocessing.get_context(self.start_method)
            progress = ctx.Queue() if on_progress is not None else None
            pool = ProcessPoolExecutor(
                max_workers=min(self._workers, len(units)),
                mp_context=ctx,
                initializer=_start_worker,
                initargs=(progress, self.initializer, self.initargs, setup),
            )
        pending = list(reversed(units))
        running: dict[Future[R], U] = {}

        def drain() -> None:
            if progress is not None:
                drain_progress(progress.get_nowait, queue.Empty, on_progress)

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
            # iterating).
            _terminate(pool)
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
            if progress is not None:
                progress.close()
                progress.join_thread()


def _terminate(pool: ProcessPoolExecutor) -> None:
    """Terminates a pool's worker processes at once. ProcessPoolExecutor has no public
    terminate; ``_processes`` is stable since Python 3.8."""
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        with contextlib.suppress(Exception):
            proc.terminate()
