"""Runs a generation: work units on local worker processes, progress, finalize.

:func:`generate_dataset` is what ``roft-sim generate`` calls. With ``workers == 1`` the units run
in the calling process; otherwise in a pool of ``spawn``-started processes (never ``fork``:
MuJoCo's OpenGL contexts must not be inherited), each owning one
:class:`~roft_sim.generation.SequenceGenerator` at a time. Frames are written atomically by the
dataset writers, so an interrupted run (Ctrl-C, a killed worker, a crash, or
``stop_after_frames``) leaves only complete frames, and ``resume=True`` generates exactly the
missing ones; the result is byte-identical to an uninterrupted run.
"""

from __future__ import annotations

import contextlib
import logging
import multiprocessing
import queue
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from roft_sim.datasets import DATASET_FORMATS
from roft_sim.errors import ConfigError, RoftSimError
from roft_sim.generation.jobs import (
    ScenarioOverrides,
    SequenceJob,
    prepare_jobs,
    sequence_name_for,
)
from roft_sim.generation.work_units import WorkUnit, plan_work_units
from roft_sim.scenario import Scenario

__all__ = [
    "GenerationError",
    "GenerationOptions",
    "SequenceResult",
    "GenerationSummary",
    "generate_dataset",
    "run_work_unit",
]

_log = logging.getLogger(__name__)


class GenerationError(RoftSimError):
    """A generation run failed after it started writing (a worker raised or died). Frames
    already written are kept; resume the run to complete it."""


@dataclass(frozen=True, slots=True, kw_only=True)
class GenerationOptions:
    """How a run generates and writes (not what: that is the scenarios)."""

    format: Literal["fast-ycb", "bop", "hdf5"] = "fast-ycb"
    """Dataset format."""
    workers: int = 1
    """Worker processes; 1 = generate in the calling process."""
    chunk_frames: int = 32
    """Most frames per work unit (see :func:`~roft_sim.generation.plan_work_units`)."""
    resume: bool = False
    """Continue unfinished sequences (and keep finished ones) instead of refusing them."""
    assets_dir: Path | None = None
    """Folder of real YCB meshes searched first."""
    cache_dir: Path | None = None
    """The asset cache (installed meshes, procedural textures); None = none."""
    gl_backend: str | None = None
    """The OpenGL backend in use (``egl``/``osmesa``), recorded in the metadata; the caller
    chose it (the library never reads the environment)."""
    progress: bool = True
    """Show a tqdm progress bar (frames/s, ETA) on stderr."""
    stop_after_frames: int | None = None
    """Write at most this many frames in this run, then return without finalizing unfinished
    sequences (time-sliced runs; tests of resume). None = all."""
    start_method: Literal["spawn", "forkserver"] = "spawn"
    """How worker processes start (never ``fork``)."""

    def __post_init__(self) -> None:
        if self.format not in DATASET_FORMATS:
            raise ConfigError(
                f"unknown dataset format {self.format!r}; expected one of "
                f"{', '.join(DATASET_FORMATS)}"
            )
        if self.workers < 1:
            raise ConfigError(f"--workers must be >= 1, got {self.workers}")
        if self.chunk_frames < 1:
            raise ConfigError(f"--chunk-frames must be >= 1, got {self.chunk_frames}")
        if self.stop_after_frames is not None and self.stop_after_frames < 0:
            raise ConfigError(f"stop_after_frames must be >= 0, got {self.stop_after_frames}")
        if self.start_method not in ("spawn", "forkserver"):
            raise ConfigError(
                f"start_method must be 'spawn' or 'forkserver' (never 'fork'), got "
                f"{self.start_method!r}"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class SequenceResult:
    """What a run did to one sequence."""

    name: str
    """Sequence name."""
    path: Path | None
    """The finished sequence (folder or ``.h5``), None while unfinished."""
    n_frames: int
    """Frames of the sequence."""
    frames_generated: int
    """Frames generated in this run (0 when it was already complete)."""

    @property
    def finished(self) -> bool:
        """The sequence is finalized."""
        return self.path is not None


@dataclass(frozen=True, slots=True, kw_only=True)
class GenerationSummary:
    """What :func:`generate_dataset` did."""

    sequences: tuple[SequenceResult, ...]
    """Per sequence, in run order."""
    wall_s: float
    """Wall time of the generation [s] (preparation included)."""
    workers: int
    """Worker processes used."""
    format: str
    """Dataset format."""
    frames_generated: int = field(init=False)
    """Frames generated in this run, all sequences."""

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "frames_generated", sum(s.frames_generated for s in self.sequences)
        )

    @property
    def finished(self) -> bool:
        """Every sequence is finalized."""
        return all(s.finished for s in self.sequences)

    @property
    def frames_per_s(self) -> float:
        """Frames generated per second of wall time."""
        return self.frames_generated / self.wall_s if self.wall_s > 0 else 0.0

    def report(self) -> dict[str, Any]:
        """JSON-able summary (``roft-sim generate --json``)."""
        return {
            "format": self.format,
            "workers": self.workers,
            "wall_s": round(self.wall_s, 3),
            "frames_generated": self.frames_generated,
            "frames_per_s": round(self.frames_per_s, 3),
            "finished": self.finished,
            "sequences": [
                {
                    "name": s.name,
                    "path": None if s.path is None else str(s.path),
                    "n_frames": s.n_frames,
                    "frames_generated": s.frames_generated,
                    "finished": s.finished,
                }
                for s in self.sequences
            ],
        }


# ---------------------------------------------------------------------------------- workers
class _WorkerState:
    """The jobs of a run and the one generator a worker holds (its OpenGL contexts)."""

    def __init__(
        self,
        jobs: Sequence[SequenceJob],
        options: GenerationOptions,
        report: Callable[[int], None] | None,
    ) -> None:
        self.jobs = jobs
        self.options = options
        self.report = report
        self._current: tuple[int, Any] | None = None

    def generator(self, sequence: int) -> Any:
        from roft_sim.generation.sequence_generator import SequenceGenerator

        if self._current is not None and self._current[0] == sequence:
            return self._current[1]
        self.close()
        gen = SequenceGenerator(
            self.jobs[sequence].scenario,
            assets_dir=self.options.assets_dir,
            cache_dir=self.options.cache_dir,
        )
        self._current = (sequence, gen)
        return gen

    def close(self) -> None:
        if self._current is not None:
            self._current[1].close()
            self._current = None


def run_work_unit(
    unit: WorkUnit,
    job: SequenceJob,
    generator: Any,
    *,
    report: Callable[[int], None] | None = None,
) -> int:
    """Generates and writes the frames of one unit with a generator of ``job``'s scenario.

    Returns:
        Frames written.
    """
    written = 0
    for frame in generator.frames(unit.start, unit.stop):
        job.writer.write_frame(frame)
        written += 1
        if report is not None:
            report(1)
    return written


_STATE: _WorkerState | None = None


def _init_worker(jobs: Sequence[SequenceJob], options: GenerationOptions, progress: Any) -> None:
    global _STATE
    import cv2

    cv2.setNumThreads(1)  # one core per worker; DIS gives the same flow with any thread count
    _STATE = _WorkerState(jobs, options, progress.put)


def _worker_run(unit: WorkUnit) -> int:
    assert _STATE is not None, "worker not initialised"
    return run_work_unit(
        unit, _STATE.jobs[unit.sequence], _STATE.generator(unit.sequence), report=_STATE.report
    )


# ------------------------------------------------------------------------------------ runs
def _progress_bar(total: int, enabled: bool) -> Any:
    from tqdm import tqdm

    return tqdm(
        total=total,
        unit="frame",
        desc="generate",
        disable=not enabled,
        dynamic_ncols=True,
        smoothing=0.05,
    )


def _budgeted(units: list[WorkUnit], budget: int | None) -> list[WorkUnit]:
    """The first units, the last one cut, holding ``budget`` frames (all when None)."""
    if budget is None:
        return units
    out = []
    left = budget
    for u in units:
        if left <= 0:
            break
        take = min(left, u.n_frames)
        out.append(WorkUnit(u.sequence, u.start, u.start + take))
        left -= take
    return out


def _unit_failed(unit: WorkUnit, jobs: Sequence[SequenceJob], e: Exception) -> GenerationError:
    return GenerationError(
        f"generating frames {unit.start}-{unit.stop - 1} of "
        f"{jobs[unit.sequence].sequence_name!r} failed: {type(e).__name__}: {e}; the frames "
        "written so far are kept: fix the cause and run again with --resume"
    )


def _run_in_process(
    units: list[WorkUnit],
    jobs: Sequence[SequenceJob],
    options: GenerationOptions,
    report: Callable[[int], None],
    on_unit_done: Callable[[WorkUnit, int], None],
) -> None:
    state = _WorkerState(jobs, options, report)
    try:
        for unit in units:
            try:
                n = run_work_unit(
                    unit, jobs[unit.sequence], state.generator(unit.sequence), report=report
                )
            except RoftSimError:
                raise
            except Exception as e:
                raise _unit_failed(unit, jobs, e) from e
            on_unit_done(unit, n)
    finally:
        state.close()


def _run_in_pool(
    units: list[WorkUnit],
    jobs: Sequence[SequenceJob],
    options: GenerationOptions,
    report: Callable[[int], None],
    on_unit_done: Callable[[WorkUnit, int], None],
) -> None:
    ctx = multiprocessing.get_context(options.start_method)
    progress = ctx.Queue()
    pending = list(reversed(units))
    running: dict[Future[int], WorkUnit] = {}

    def drain() -> None:
        with contextlib.suppress(queue.Empty):
            while True:
                report(progress.get_nowait())

    executor = ProcessPoolExecutor(
        max_workers=min(options.workers, len(units)),
        mp_context=ctx,
        initializer=_init_worker,
        initargs=(list(jobs), options, progress),
    )
    try:
        while pending or running:
            # Keep two units per worker in flight: load balance without a long queue to cancel.
            while pending and len(running) < 2 * options.workers:
                unit = pending.pop()
                running[executor.submit(_worker_run, unit)] = unit
            done, _ = wait(list(running), timeout=0.2, return_when=FIRST_COMPLETED)
            drain()
            for fut in done:
                unit = running.pop(fut)
                try:
                    n = fut.result()
                except BrokenProcessPool:
                    raise GenerationError(
                        "a worker process died (killed, or out of memory) while generating "
                        f"frames {unit.start}-{unit.stop - 1} of "
                        f"{jobs[unit.sequence].sequence_name!r}; the frames written so far are "
                        "kept: run again with --resume"
                    ) from None
                except RoftSimError:
                    raise
                except Exception as e:
                    raise _unit_failed(unit, jobs, e) from e
                on_unit_done(unit, n)
        drain()
    except BaseException:
        # Stop now rather than after the units in flight: frames are atomic, so a worker
        # stopped in the middle of one leaves no trace a resume would not repair.
        # (ProcessPoolExecutor has no public terminate; _processes is stable since 3.8.)
        for proc in list(getattr(executor, "_processes", {}).values()):
            proc.terminate()
        raise
    finally:
        executor.shutdown(wait=True, cancel_futures=True)
        progress.close()
        progress.join_thread()


def generate_dataset(
    scenarios: Sequence[Scenario],
    out_dir: str | Path,
    options: GenerationOptions | None = None,
    *,
    overrides: ScenarioOverrides | None = None,
    sequence_naming: Literal["scenario", "object"] = "scenario",
    preset: str | None = None,
    prepare_output: Callable[[Path], Any] | None = None,
    on_frames: Callable[[int], None] | None = None,
) -> GenerationSummary:
    """Generates one sequence per scenario into ``out_dir`` (created if needed).

    Args:
        scenarios: the scenarios (loaded; overrides not yet applied).
        out_dir: dataset root; sequence ``name`` goes to ``out_dir/name/`` (fast-ycb, bop) or
            ``out_dir/name.h5`` (hdf5). Checking that the folder may be written (non-empty,
            ``--overwrite``) is the caller's job; the writers refuse to replace a sequence
            unless ``options.resume``.
        options: format, workers, resume, ... (default: :class:`GenerationOptions()`).
        overrides: frames / resolution / seed applied to every scenario (default: none).
        sequence_naming: name sequences after the scenario or after its object.
        preset: the preset the scenarios come from (recorded in the metadata).
        prepare_output: called with ``out_dir`` once every scenario is checked (objects
            loaded, trajectories long enough) and before anything is written, e.g. to empty the
            folder for ``--overwrite``.
        on_frames: called in this process with the number of frames just written (as they
            are reported; e.g. for timing).

    Returns:
        A :class:`GenerationSummary`.

    Raises:
        ConfigError: bad options, scenarios or outputs (nothing is generated).
        GenerationError: a worker failed or died (written frames are kept; resume).
    """
    t0 = time.perf_counter()
    options = options if options is not None else GenerationOptions()
    overrides = overrides if overrides is not None else ScenarioOverrides()
    if not scenarios:
        raise ConfigError("no scenario to generate; give at least one scenario file or a preset")
    out = Path(out_dir)
    resolved = [overrides.apply(s) for s in scenarios]
    jobs = prepare_jobs(
        resolved,
        out,
        fmt=options.format,
        sequence_names=[sequence_name_for(s, sequence_naming) for s in resolved],
        overrides=overrides,
        preset=preset,
        resume=options.resume,
        assets_dir=options.assets_dir,
        cache_dir=options.cache_dir,
        gl_backend=options.gl_backend,
        prepare_output=prepare_output,
    )
    units = _budgeted(
        plan_work_units([j.missing_frames for j in jobs], chunk_frames=options.chunk_frames),
        options.stop_after_frames,
    )
    generated = [0] * len(jobs)
    left = [len(j.missing_frames) for j in jobs]
    paths: list[Path | None] = [None] * len(jobs)

    def finalize(i: int) -> None:
        paths[i] = Path(jobs[i].writer.finalize())
        _log.debug("finished %s", paths[i])

    def on_unit_done(unit: WorkUnit, n: int) -> None:
        generated[unit.sequence] += n
        left[unit.sequence] -= n
        if left[unit.sequence] == 0:
            finalize(unit.sequence)

    for i, job in enumerate(jobs):
        if not job.missing_frames:
            finalize(i)
    total = sum(u.n_frames for u in units)
    workers = 1 if options.workers == 1 or len(units) <= 1 else options.workers
    if units:
        with _progress_bar(total, options.progress) as bar:

            def report(n: int) -> None:
                bar.update(n)
                if on_frames is not None:
                    on_frames(n)

            if workers == 1:
                _run_in_process(units, jobs, options, report, on_unit_done)
            else:
                _run_in_pool(units, jobs, options, report, on_unit_done)
    return GenerationSummary(
        sequences=tuple(
            SequenceResult(
                name=j.sequence_name,
                path=paths[i],
                n_frames=j.n_frames,
                frames_generated=generated[i],
            )
            for i, j in enumerate(jobs)
        ),
        wall_s=time.perf_counter() - t0,
        workers=workers,
        format=options.format,
    )
