"""The executor protocol, worker set-up, progress reports from inside units, and the error type.

An :class:`Executor` maps a picklable top-level function over independent work units and yields
``(unit, result)`` pairs as they finish, in any order. It knows nothing about what a unit is:
generation hands it frame ranges (:class:`roft_sim.generation.WorkUnit`), sweeps hand it cells
(:class:`roft_sim.harness.cells.SweepCell`). Units must be self-contained (paths, configs, seeds;
no open handles) and write their own results atomically, so that whatever runs them, and however
often a run is interrupted, the output on disk is the same.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar, runtime_checkable

from roft_sim.errors import RoftSimError

__all__ = [
    "unit_result",
    "drain_progress",
    "Executor",
    "WorkerSetup",
    "WorkUnitError",
    "report_progress",
    "progress_reporter",
    "unit_failed",
]

U = TypeVar("U")
R = TypeVar("R")


class WorkUnitError(RoftSimError):
    """A work unit raised, or the worker running it died. Units finished before are kept on disk
    (that is the units' contract), so running the same work again resumes it.

    Attributes:
        unit: the unit that failed (for a dead worker: a unit it was running).
        cause: the exception the unit raised (None when the worker died).
        worker_died: the worker process ended (killed, out of memory, ``os._exit``, a crash in
            native code) instead of the unit raising.
    """

    def __init__(
        self,
        message: str,
        *,
        unit: Any = None,
        cause: BaseException | None = None,
        worker_died: bool = False,
    ) -> None:
        super().__init__(message)
        self.unit = unit
        self.cause = cause
        self.worker_died = worker_died


def unit_failed(unit: Any, cause: BaseException) -> WorkUnitError:
    """The :class:`WorkUnitError` for a unit that raised ``cause``."""
    return WorkUnitError(
        f"work unit {unit!r} failed: {type(cause).__name__}: {cause}", unit=unit, cause=cause
    )


def unit_result(
    unit: U,
    get_result: Callable[[], R],
    *,
    worker_death: tuple[type[BaseException], ...] = (),
    death_detail: str = "",
) -> R:
    """The one dispatch rule of every executor: ``get_result()`` (the unit's function, or its
    future's result); a :class:`RoftSimError` passes through as it is (a user-facing error), an
    exception of a ``worker_death`` type becomes :func:`worker_died` (with ``death_detail``), any
    other exception :func:`unit_failed`, naming the unit."""
    try:
        return get_result()
    except worker_death:
        raise worker_died(unit, death_detail) from None
    except RoftSimError:
        raise
    except Exception as e:
        raise unit_failed(unit, e) from e


def drain_progress(
    get_nowait: Callable[[], int],
    empty: type[BaseException],
    on_progress: Callable[[int], None] | None,
) -> None:
    """Hands every progress count waiting in a queue (``get_nowait`` raising ``empty`` when
    there is none) to ``on_progress``; nothing when there is no callback."""
    if on_progress is None:
        return
    while True:
        try:
            count = get_nowait()
        except empty:
            return
        on_progress(count)


def worker_died(unit: Any, detail: str = "") -> WorkUnitError:
    """The :class:`WorkUnitError` for a worker that died while running ``unit``."""
    return WorkUnitError(
        f"a worker process died (killed, or out of memory{detail}) while running {unit!r}; "
        "finished units are kept: run again to resume",
        unit=unit,
        worker_died=True,
    )


@dataclass(frozen=True, slots=True)
class WorkerSetup:
    """What every worker does before its first unit and after its last.

    Worker state (e.g. a renderer kept alive across units) lives in module globals of the
    function's module, set by ``initializer``: every executor runs the initializer once per
    worker process (in-process executors: once in the calling process) and then any number of
    units there. All three must be picklable top-level functions and arguments.
    """

    initializer: Callable[..., None] | None = None
    """Called once per worker with ``initargs`` before its first unit."""
    initargs: tuple[Any, ...] = ()
    """Arguments of ``initializer``."""
    teardown: Callable[[], None] | None = None
    """Called after the last unit where the worker outlives the run (in-process executors);
    worker processes release their resources when they exit."""


@runtime_checkable
class Executor(Protocol):
    """Runs ``fn(unit)`` for every unit and yields ``(unit, result)`` as each one finishes."""

    @property
    def workers(self) -> int:
        """How many units may run at once."""
        ...

    def map_unordered(
        self,
        fn: Callable[[U], R],
        units: Sequence[U],
        *,
        setup: WorkerSetup | None = None,
        on_progress: Callable[[int], None] | None = None,
    ) -> Iterator[tuple[U, R]]:
        """Yields ``(unit, fn(unit))`` for every unit, in completion order.

        Args:
            fn: a picklable top-level function (or ``functools.partial`` of one).
            units: picklable, self-contained units.
            setup: per-worker initializer and teardown (see :class:`WorkerSetup`).
            on_progress: called in THIS process with the counts that units pass to
                :func:`report_progress` (e.g. frames written), as they arrive.

        Raises:
            WorkUnitError: a unit raised (the error names the unit) or a worker died; units not
                yet started are cancelled and the workers stopped. A
                :class:`~roft_sim.errors.RoftSimError` raised by a unit is re-raised as it is.
        """
        ...


# ------------------------------------------------------------------- progress from inside a unit
_REPORTER: Callable[[int], None] | None = None


def report_progress(n: int = 1) -> None:
    """Called inside a unit: ``n`` more things (frames, steps) are done. The executor forwards
    the count to the driver's ``on_progress``; without a listener it does nothing."""
    if _REPORTER is not None:
        _REPORTER(n)


def progress_reporter(reporter: Callable[[int], None] | None) -> Callable[[int], None] | None:
    """Sets where :func:`report_progress` sends counts in this process; returns the previous
    target (executors call it when a worker starts, and the serial executor around a map)."""
    global _REPORTER
    previous, _REPORTER = _REPORTER, reporter
    return previous


def limit_worker_threads() -> None:
    """Worker-process set-up shared by the process executors: OpenCV on one thread (the
    executor provides the parallelism; DIS gives the same flow with any thread count)."""
    import cv2

    cv2.setNumThreads(1)
