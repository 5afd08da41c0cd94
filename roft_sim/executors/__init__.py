"""Executors: where the independent work units of ``roft-sim generate`` and ``sweep`` run.

One abstraction for both verbs (docs/scaleout.md):

- :class:`Executor`: ``map_unordered(fn, units, setup=, on_progress=)`` yields ``(unit, result)``
  as units finish; :class:`WorkerSetup` gives each worker an initializer (generation keeps one
  MuJoCo renderer per worker) and :func:`report_progress` sends counts from inside a unit to the
  driver's progress bar.
- :class:`SerialExecutor` (in the calling process), :class:`LocalProcessExecutor` (``spawn``-started
  processes on this machine) and :class:`RayExecutor` (actors of a Ray cluster; optional extra
  ``roft-sim[ray]``, imported only when used). :func:`make_executor` builds one from the
  command-line flags.
- :class:`Shard` / :func:`select_shard`: ``--shard i/N``, a deterministic split of the units among
  N independent jobs (array jobs of a cluster scheduler), no Ray needed.

Units write their own results atomically and skip what is already on disk, so the output is the
same whatever executor ran them, and an interrupted run (a dead worker, a killed driver) resumes
by running it again.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Literal

from roft_sim.errors import ConfigError
from roft_sim.executors.base import (
    Executor,
    WorkerSetup,
    WorkUnitError,
    report_progress,
)
from roft_sim.executors.local import LocalProcessExecutor
from roft_sim.executors.ray_executor import RayExecutor, check_ray_installed
from roft_sim.executors.serial import SerialExecutor
from roft_sim.executors.sharding import (
    SHARD_LAYOUTS,
    Shard,
    parse_shard,
    select_shard,
    shard_positions,
)

__all__ = [
    "Executor",
    "WorkerSetup",
    "WorkUnitError",
    "report_progress",
    "SerialExecutor",
    "LocalProcessExecutor",
    "RayExecutor",
    "check_ray_installed",
    "EXECUTOR_KINDS",
    "make_executor",
    "Shard",
    "parse_shard",
    "select_shard",
    "shard_positions",
    "SHARD_LAYOUTS",
]

EXECUTOR_KINDS = ("local", "ray")
"""Values of ``--executor``."""


def make_executor(
    workers: int | None = 1,
    *,
    kind: Literal["local", "ray"] = "local",
    address: str | None = None,
    start_method: Literal["spawn", "forkserver"] = "spawn",
    worker_env: Mapping[str, str] | None = None,
) -> Executor:
    """The executor the command-line flags ask for.

    Args:
        workers: ``local``: worker processes, 1 (or None) = :class:`SerialExecutor` in this
            process; ``ray``: actors, None = one per CPU of the cluster.
        kind: ``local`` or ``ray``.
        address: Ray cluster address (``ray`` only); None = a private local Ray instance.
        start_method: local worker start method (``spawn`` or ``forkserver``; never ``fork``).
        worker_env: environment variables for Ray actors (local workers inherit this process's).

    Raises:
        ConfigError: bad values, ``address`` without ``ray``, or Ray not installed (the message
            says what to install).
    """
    if workers is not None and workers < 1:
        raise ConfigError(f"--workers must be >= 1, got {workers}")
    if kind == "local":
        if address is not None:
            raise ConfigError(
                f"--address {address!r} is the address of a Ray cluster; add --executor ray "
                "(or drop --address to run on local processes)"
            )
        if workers is None or workers == 1:
            return SerialExecutor()
        return LocalProcessExecutor(workers, start_method=start_method)
    if kind == "ray":
        return RayExecutor(workers, address=address, worker_env=worker_env)
    raise ConfigError(f"unknown --executor {kind!r}; expected one of {', '.join(EXECUTOR_KINDS)}")
