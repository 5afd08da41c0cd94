"""Re-export of :mod:`roft_sim.executors`, where the executors live now (one abstraction for
``generate`` and ``sweep``; docs/scaleout.md). Kept because ``roft_sim.harness.paper`` and
``roft_sim.cli.paper`` import from here."""

from roft_sim.executors import (
    Executor,
    LocalProcessExecutor,
    RayExecutor,
    SerialExecutor,
    WorkerSetup,
    WorkUnitError,
    make_executor,
)

__all__ = [
    "Executor",
    "SerialExecutor",
    "LocalProcessExecutor",
    "RayExecutor",
    "WorkerSetup",
    "WorkUnitError",
    "make_executor",
]
