"""The Ray executor: units on the actors of a Ray cluster (optional extra ``roft-sim[ray]``).

``ray`` is imported only when a map runs, so nothing else in roft_sim needs it. Each worker is a
Ray actor holding one CPU; it runs the setup's initializer once (so it keeps its renderer across
units, as a local worker process does) and then units, at most two in flight per actor. Ray
starts its worker processes fresh (never forked from the driver), so MuJoCo's OpenGL contexts are
never inherited.

Outputs are written by the units themselves, on the machine that runs them: on a multi-machine
cluster the output folder must be on a filesystem every node mounts at the same path (docs/
scaleout.md). Each actor changes into the driver's working directory when that directory exists
on its node, so relative paths mean the same thing as on the driver.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, TypeVar

from roft_sim.errors import ConfigError
from roft_sim.executors.base import (
    WorkerSetup,
    WorkUnitError,
    drain_progress,
    limit_worker_threads,
    progress_reporter,
    unit_result,
    worker_died,
)

__all__ = ["RayExecutor", "check_ray_installed", "RAY_INSTALL_HINT"]

U = TypeVar("U")
R = TypeVar("R")

RAY_INSTALL_HINT = (
    "install the ray extra on the driver and on every worker node: pip install 'roft-sim[ray]' "
    "(or pip install 'ray>=2.9')"
)
_POLL_S = 0.2
"""How often the driver forwards progress counts while units run [s]."""


def check_ray_installed() -> None:
    """Raises:
    ConfigError: ``ray`` cannot be imported here; the message says what to install.
    """
    if importlib.util.find_spec("ray") is None:
        raise ConfigError(
            f"--executor ray needs Ray, which is not installed: {RAY_INSTALL_HINT}; or use "
            "--executor local"
        )


def _import_ray() -> Any:
    check_ray_installed()
    import ray

    return ray


class _RayWorker:
    """The body of one Ray actor (wrapped with ``ray.remote`` when a map starts)."""

    def __init__(self, setup: WorkerSetup | None, progress: Any, cwd: str | None) -> None:
        if cwd is not None and os.path.isdir(cwd):
            os.chdir(cwd)
        limit_worker_threads()
        progress_reporter(None if progress is None else progress.put_nowait)
        if setup is not None and setup.initializer is not None:
            setup.initializer(*setup.initargs)

    def run(self, fn: Callable[[Any], Any], unit: Any) -> Any:
        return fn(unit)

    def pid(self) -> int:
        return os.getpid()


class RayExecutor:
    """Runs units on Ray actors, one CPU each.

    Args:
        workers: actors (>= 1); None = one per CPU of the cluster.
        address: the cluster to connect to (``ray://host:10001``, ``host:6379``, ``auto`` for the
            cluster already running on this node); None = start a private local Ray instance
            for the run (``ray.init(address="local")``), shut down when the map ends. When Ray
            is already initialised in this process (e.g. by a test), that connection is used
            as it is and left open.
        worker_env: environment variables of the actors (e.g. ``MUJOCO_GL``), merged into the
            job's runtime environment; the actors on other nodes do not inherit the driver's.
        max_restarts: how often a dead actor (killed, out of memory, node lost) is restarted;
            its units in flight are retried as often. A unit that RAISES is never retried.
        init_options: more keyword arguments of ``ray.init``.

    Raises:
        ConfigError: Ray is not installed, or bad arguments.
    """

    def __init__(
        self,
        workers: int | None = None,
        *,
        address: str | None = None,
        worker_env: Mapping[str, str] | None = None,
        max_restarts: int = 1,
        init_options: Mapping[str, Any] | None = None,
    ) -> None:
        check_ray_installed()
        if workers is not None and workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {workers}")
        if max_restarts < 0:
            raise ConfigError(f"max_restarts must be >= 0, got {max_restarts}")
        if address is not None and not address.strip():
            raise ConfigError("--address is empty; give host:port, ray://host:port or auto")
        self._requested = workers
        self._workers = workers
        self.address = address
        self.worker_env = dict(worker_env or {})
        self.max_restarts = int(max_restarts)
        self.init_options = dict(init_options or {})
        self._owned = False

    def __repr__(self) -> str:
        where = self.address or "local"
        return f"RayExecutor(workers={self._requested}, address={where!r})"

    # --------------------------------------------------------------------------- connection
    def _connect(self) -> Any:
        ray = _import_ray()
        if not ray.is_initialized():
            options: dict[str, Any] = {"include_dashboard": False, **self.init_options}
            if self.address is None:
                options.setdefault("num_cpus", self._requested)
                ray.init(address="local", **options)
            else:
                ray.init(address=self.address, **options)
            self._owned = True
        return ray

    def close(self) -> None:
        """Shuts down the Ray instance this executor started (a no-op otherwise)."""
        if self._owned:
            import ray

            ray.shutdown()
            self._owned = False

    def __enter__(self) -> RayExecutor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def workers(self) -> int:
        """Actors used per map (connects to resolve the cluster's CPU count when not given)."""
        if self._workers is None:
            ray = self._connect()
            self._workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        return self._workers

    # --------------------------------------------------------------------------------- map
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
        ray = self._connect()
        try:
            yield from self._map(ray, fn, units, setup, on_progress)
        finally:
            self.close()

    def _map(
        self,
        ray: Any,
        fn: Callable[[U], R],
        units: Sequence[U],
        setup: WorkerSetup | None,
        on_progress: Callable[[int], None] | None,
    ) -> Iterator[tuple[U, R]]:
        from ray.exceptions import RayActorError, RayTaskError, WorkerCrashedError

        progress = None
        if on_progress is not None:
            from ray.util.queue import Empty, Queue

            progress = Queue(actor_options={"num_cpus": 0})

        def drain() -> None:
            if progress is not None:
                drain_progress(progress.get_nowait, Empty, on_progress)

        def unwrapped_result(ref: Any, unit: Any) -> Any:
            """``ray.get(ref)``, with a task's exception raised as itself, not wrapped, and a
            dead actor as :func:`worker_died` (a RoftSimError, so :func:`unit_result` passes it
            through instead of reporting it as the unit's own failure)."""
            death = (RayActorError, WorkerCrashedError)
            try:
                return ray.get(ref)
            except death as e:
                raise died(unit, e) from None
            except RayTaskError as e:
                cause = e.cause if isinstance(e.cause, BaseException) else e
                # some Ray versions wrap a dead actor (ActorDiedError) in a task error
                raise (died(unit, cause) if isinstance(cause, death) else cause) from None

        def died(unit: Any, e: BaseException) -> WorkUnitError:
            first = (str(e).strip().splitlines() or [""])[0][:300]
            detail = f"; Ray: {type(e).__name__}: {first}"
            if self.max_restarts:
                detail += f"; Ray gave up after {self.max_restarts} restart(s)"
            return worker_died(unit, detail)

        options: dict[str, Any] = {
            "num_cpus": 1,
            "max_restarts": self.max_restarts,
            "max_task_retries": self.max_restarts,
        }
        if self.worker_env:
            options["runtime_env"] = {"env_vars": dict(self.worker_env)}
        actor_class = ray.remote(_RayWorker)
        n = min(self.workers, len(units))
        cwd = os.getcwd()
        # One copy of the set-up (e.g. every sequence's scenario and writer) in the object store,
        # referenced by this frame until the map ends, so a restarted actor can read it again.
        setup_ref = ray.put(setup)
        actors = [actor_class.options(**options).remote(setup_ref, progress, cwd) for _ in range(n)]
        fn_ref = ray.put(fn)
        pending = list(reversed(units))
        running: dict[Any, tuple[U, int]] = {}
        load = [0] * n
        try:
            while pending or running:
                while pending and min(load) < 2:
                    i = load.index(min(load))
                    unit = pending.pop()
                    running[actors[i].run.remote(fn_ref, unit)] = (unit, i)
                    load[i] += 1
                ready, _ = ray.wait(list(running), num_returns=1, timeout=_POLL_S)
                drain()
                for ref in ready:
                    unit, i = running.pop(ref)
                    load[i] -= 1
                    result = unit_result(unit, functools.partial(unwrapped_result, ref, unit))
                    yield unit, result
            drain()
        finally:
            for actor in actors:
                with contextlib.suppress(Exception):
                    ray.kill(actor, no_restart=True)
            if progress is not None:
                with contextlib.suppress(Exception):
                    progress.shutdown(force=True)
