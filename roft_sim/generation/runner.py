"""Runs a generation: work units on an executor, progress, finalize.

:func:`generate_dataset` is what ``roft-sim generate`` calls. The units run on an executor
(:mod:`roft_sim.executors`): by default in the calling process (``workers == 1``) or in a pool of
``spawn``-started processes (never ``fork``: MuJoCo's OpenGL contexts must not be inherited);
any other executor (Ray) works the same. Every worker owns one
:class:`~roft_sim.generation.SequenceGenerator` at a time (set up by :func:`_init_worker`). Frames
are written atomically by the dataset writers, so an interrupted run (Ctrl-C, a killed worker or
driver, a crash, or ``stop_after_frames``) leaves only complete frames, and ``resume=True``
generates exactly the missing ones, found on disk; the result is byte-identical to an
uninterrupted run. With ``shard`` the run generates only its shard's frames and finalizes
nothing (docs/scaleout.md).
"""

from __future__ import annotations

import logging
import socket
import time
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from roft_sim.datasets import DATASET_FORMATS, open_sequence
from roft_sim.datasets.image_files import PNG_COMPRESSION, check_png_compression
from roft_sim.errors import ConfigError, RoftSimError
from roft_sim.executors import (
    Executor,
    LocalProcessExecutor,
    SerialExecutor,
    Shard,
    WorkerSetup,
    WorkUnitError,
    report_progress,
)
from roft_sim.generation.jobs import (
    ScenarioOverrides,
    SequenceJob,
    prepare_jobs,
    sequence_names_for,
)
from roft_sim.generation.work_units import WorkUnit, plan_shard_units, plan_work_units
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
    shard: Shard | None = None
    """Generate only this shard's frames (``--shard i/N``; :func:`plan_shard_units`) into an
    output other shards write at the same time: implies resuming, finalizes nothing. None = the
    whole run."""
    png_compression: int = PNG_COMPRESSION
    """zlib level 0-9 of the PNG files (fast-ycb, bop): 1 (default) is the fastest that still
    compresses; 3 (the level before) writes files about 4 % smaller in about 1.6x the encoding
    time (docs/formats.md, "PNG compression"). Bytes depend on it; a resumed sequence keeps the
    level it was started with."""
    writer_threads: int = 1
    """Threads per worker that encode and write frames while the next frame is generated
    (OpenCV's PNG encoder, zlib and file writes release the GIL); 0 = write on the generating
    thread. At most ``writer_threads + 1`` generated frames wait in memory per worker."""
    pipelined: bool = True
    """Compute each frame's flow sets and simulated networks on a second thread while the next
    frame renders (:meth:`SequenceGenerator.frames`); the bytes are the same either way."""

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
        check_png_compression(self.png_compression)
        if self.writer_threads < 0:
            raise ConfigError(
                f"writer_threads must be >= 0 (0 = write on the generating thread), got "
                f"{self.writer_threads}"
            )
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
    visibility: dict[str, float] | None = None
    """The object's visible-fraction statistics of the finished sequence (its metadata's
    ``ground_truth_visibility``: mean, min, p10, p50, p90, frames_below_half, frames_hidden),
    None while unfinished or without them."""

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
    """Workers used (processes or Ray actors; 1 = in this process)."""
    format: str
    """Dataset format."""
    shard: Shard | None = None
    """The shard generated (None = the whole run)."""
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
            "shard": None if self.shard is None else str(self.shard),
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
                    "visibility": s.visibility,
                }
                for s in self.sequences
            ],
        }


# ---------------------------------------------------------------------------------- workers
class _WorkerState:
    """The jobs of a run and the one generator a worker holds (its OpenGL contexts)."""

    def __init__(self, jobs: Sequence[SequenceJob], options: GenerationOptions) -> None:
        self.jobs = jobs
        self.options = options
        self._current: tuple[int, Any] | None = None

    def prebuild(self, sequence: int, scenario: Scenario) -> None:
        """Builds the generator of ``sequence`` before its job is known (while the driver
        prepares the jobs); :meth:`generator` checks it against the job like any other."""
        self.close()
        self._current = (sequence, self._build(scenario))

    def _build(self, scenario: Scenario) -> Any:
        from roft_sim.generation.sequence_generator import SequenceGenerator

        return SequenceGenerator(
            scenario, assets_dir=self.options.assets_dir, cache_dir=self.options.cache_dir
        )

    def generator(self, sequence: int) -> Any:
        job = self.jobs[sequence]
        if self._current is None or self._current[0] != sequence:
            self.close()
            self._current = (sequence, self._build(job.scenario))
        gen = self._current[1]
        source = str(gen.renderer.object_assets.source)
        if job.object_source and source != job.object_source:
            self.close()
            raise ConfigError(
                f"{job.sequence_name}: on worker host {socket.gethostname()!r} the object "
                f"{job.scenario.object.name_or_path} loads as {source!r}, but the driver found "
                f"{job.object_source!r} (what the dataset's metadata and model say). Give every "
                "node the same meshes (--assets on shared storage, or the same "
                "`roft-sim assets install` cache) and run again with --resume"
            )
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
    writer_threads: int = 1,
    pipelined: bool = True,
) -> int:
    """Generates and writes the frames of one unit with a generator of ``job``'s scenario.

    Frame k is encoded and written on one of ``writer_threads`` threads while frame k+1 is
    generated; at most ``writer_threads`` frames wait for a writer, so memory stays flat. A
    frame is reported (``report(1)``) once its files are written, in frame order. Each frame's
    files are written atomically by the writer, so the bytes do not depend on the threads.
    ``pipelined`` is passed to the generator's ``frames``.

    Returns:
        Frames written.
    """
    frames = generator.frames(unit.start, unit.stop, pipelined=pipelined)
    written = 0
    if writer_threads == 0:
        for frame in frames:
            job.writer.write_frame(frame)
            written += 1
            if report is not None:
                report(1)
        return written
    with ThreadPoolExecutor(writer_threads, thread_name_prefix="roft-sim-writer") as pool:
        queued: deque[Future[None]] = deque()
        for frame in frames:
            queued.append(pool.submit(job.writer.write_frame, frame))
            while len(queued) > writer_threads or (queued and queued[0].done()):
                queued.popleft().result()
                written += 1
                if report is not None:
                    report(1)
        while queued:
            queued.popleft().result()
            written += 1
            if report is not None:
                report(1)
    return written


_STATE: _WorkerState | None = None
"""The worker's state: set by :func:`_init_worker` in every worker (the calling process for the
in-process executor)."""


def _init_worker(jobs: Sequence[SequenceJob], options: GenerationOptions) -> None:
    global _STATE
    if _STATE is not None and _STATE.options == options:  # started early: keep its generator
        _STATE.jobs = jobs
    else:
        _close_worker()
        _STATE = _WorkerState(jobs, options)


def _start_worker_early(scenarios: Sequence[Scenario], options: GenerationOptions) -> None:
    """Runs in each worker spawned before the jobs are ready (:func:`_prestarted_executor`):
    imports, then the first sequence's generator (object, scene, OpenGL contexts). A failure
    here is left for the driver's checks, or the unit's own set-up, to report."""
    global _STATE
    _STATE = _WorkerState((), options)
    try:
        _STATE.prebuild(0, scenarios[0])
    except Exception:  # noqa: BLE001 - reported where it matters (see the docstring)
        _log.debug("early generator set-up failed; the unit will set it up again", exc_info=True)
        _STATE.close()


def _close_worker() -> None:
    global _STATE
    if _STATE is not None:
        state, _STATE = _STATE, None
        state.close()


def _worker_run(unit: WorkUnit) -> int:
    if _STATE is None:
        raise RuntimeError(
            "generation worker not initialised (run units through an executor "
            "with the WorkerSetup of generate_dataset)"
        )
    return run_work_unit(
        unit,
        _STATE.jobs[unit.sequence],
        _STATE.generator(unit.sequence),
        report=report_progress,
        writer_threads=_STATE.options.writer_threads,
        pipelined=_STATE.options.pipelined,
    )


# ------------------------------------------------------------------------------------ runs
def _progress_bar(total: int, enabled: bool, desc: str = "generate") -> Any:
    from tqdm import tqdm

    return tqdm(
        total=total,
        unit="frame",
        desc=desc,
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


def _frames_of(unit: Any, jobs: Sequence[SequenceJob]) -> str:
    if isinstance(unit, WorkUnit):
        return f"frames {unit.start}-{unit.stop - 1} of {jobs[unit.sequence].sequence_name!r}"
    return f"work unit {unit!r}"


def _generation_error(e: WorkUnitError, jobs: Sequence[SequenceJob]) -> GenerationError:
    where = _frames_of(e.unit, jobs)
    if e.worker_died:
        return GenerationError(
            f"a worker process died (killed, or out of memory) while generating {where}; the "
            "frames written so far are kept: run again with --resume"
        )
    cause = e.cause if e.cause is not None else e
    return GenerationError(
        f"generating {where} failed: {type(cause).__name__}: {cause}; the frames written so far "
        "are kept: fix the cause and run again with --resume"
    )


def _default_executor(options: GenerationOptions, n_units: int) -> Executor:
    if options.workers == 1 or n_units <= 1:
        return SerialExecutor()
    return LocalProcessExecutor(options.workers, start_method=options.start_method)


def _visibility_of(path: Path | None) -> dict[str, float] | None:
    """The visible-fraction statistics in a finished sequence's metadata (None if absent)."""
    if path is None:
        return None
    value = open_sequence(path).metadata().get("ground_truth_visibility")
    return value if isinstance(value, dict) else None


def _prestarted_executor(
    scenarios: Sequence[Scenario], options: GenerationOptions
) -> LocalProcessExecutor | None:
    """Local worker processes started now, each setting up the first sequence's generator
    while the driver loads objects and opens writers (None when the run will not use several
    local workers: one worker, or at most one unit of frames)."""
    units = sum(-(-s.n_frames // options.chunk_frames) for s in scenarios)
    if options.workers == 1 or units <= 1 or options.stop_after_frames is not None:
        return None
    executor = LocalProcessExecutor(
        options.workers,
        start_method=options.start_method,
        initializer=_start_worker_early,
        initargs=(list(scenarios), options),
    )
    executor.start()
    return executor


def generate_dataset(
    scenarios: Sequence[Scenario],
    out_dir: str | Path,
    options: GenerationOptions | None = None,
    *,
    overrides: ScenarioOverrides | None = None,
    sequence_naming: Literal["scenario", "object", "auto"] = "scenario",
    preset: str | None = None,
    prepare_output: Callable[[Path], Any] | None = None,
    on_frames: Callable[[int], None] | None = None,
    executor: Executor | None = None,
) -> GenerationSummary:
    """Generates one sequence per scenario into ``out_dir`` (created if needed).

    Args:
        scenarios: the scenarios (loaded; overrides not yet applied).
        out_dir: dataset root; sequence ``name`` goes to ``out_dir/name/`` (fast-ycb, bop) or
            ``out_dir/name.h5`` (hdf5). Checking that the folder may be written (non-empty,
            ``--overwrite``) is the caller's job; the writers refuse to replace a sequence
            unless ``options.resume`` (or ``options.shard``).
        options: format, workers, resume, shard, ... (default: :class:`GenerationOptions()`).
        overrides: frames / resolution / seed applied to every scenario (default: none).
        sequence_naming: name sequences after the scenario (default) or after its object;
            ``auto`` (``roft-sim generate``): after the object when each scenario has its own,
            else the scenario (the scenario's name is kept in ``metadata.json``,
            ``scenario_name``).
        preset: the preset the scenarios come from (recorded in the metadata).
        prepare_output: called with ``out_dir`` once every scenario is checked (objects
            loaded, trajectories long enough) and before anything is written, e.g. to empty the
            folder for ``--overwrite``.
        on_frames: called in this process with the number of frames just written (as they
            are reported; e.g. for timing).
        executor: where the units run (:mod:`roft_sim.executors`, e.g. a
            :class:`~roft_sim.executors.RayExecutor`); default: this process for
            ``options.workers == 1``, else ``options.workers`` local processes.

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
    early = _prestarted_executor(resolved, options) if executor is None else None
    try:
        jobs = prepare_jobs(
            resolved,
            out,
            fmt=options.format,
            sequence_names=sequence_names_for(resolved, sequence_naming),
            overrides=overrides,
            preset=preset,
            resume=options.resume or options.shard is not None,
            assets_dir=options.assets_dir,
            cache_dir=options.cache_dir,
            gl_backend=options.gl_backend,
            prepare_output=prepare_output,
            shard_run=options.shard is not None,
            png_compression=options.png_compression,
        )
        units = _planned_units(jobs, options)
        progress = _RunProgress(jobs, finalize=options.shard is None)
        if options.shard is None:
            progress.finalize_complete_sequences()
        if executor is None:
            executor = early if early is not None else _default_executor(options, len(units))
        if units:
            _run_units(executor, units, jobs, options, progress, on_frames)
    finally:
        if early is not None:
            early.close()  # a no-op once a map has used the workers
    return GenerationSummary(
        sequences=progress.results(),
        wall_s=time.perf_counter() - t0,
        workers=executor.workers if units else 1,
        format=options.format,
        shard=options.shard,
    )


def _planned_units(jobs: Sequence[SequenceJob], options: GenerationOptions) -> list[WorkUnit]:
    """The work units of the missing frames (the shard's only, with ``options.shard``), cut to
    ``options.stop_after_frames``."""
    if options.shard is None:
        planned = plan_work_units(
            [j.missing_frames for j in jobs], chunk_frames=options.chunk_frames
        )
    else:
        planned = plan_shard_units(
            [j.n_frames for j in jobs],
            [j.sequence_name for j in jobs],
            [j.missing_frames for j in jobs],
            chunk_frames=options.chunk_frames,
            shard=options.shard,
        )
    return _budgeted(planned, options.stop_after_frames)


class _RunProgress:
    """Frames generated and left per sequence; finalizes a sequence when its last frame is in
    (unless ``finalize`` is off: shard runs finalize nothing)."""

    def __init__(self, jobs: Sequence[SequenceJob], *, finalize: bool) -> None:
        self.jobs = jobs
        self.finalize = finalize
        self.generated = [0] * len(jobs)
        self.left = [len(j.missing_frames) for j in jobs]
        self.paths: list[Path | None] = [None] * len(jobs)

    def _finalize(self, i: int) -> None:
        self.paths[i] = Path(self.jobs[i].writer.finalize())
        _log.debug("finished %s", self.paths[i])

    def finalize_complete_sequences(self) -> None:
        """Finalizes the sequences with no frame missing (a resumed, already complete run)."""
        for i, job in enumerate(self.jobs):
            if not job.missing_frames:
                self._finalize(i)

    def unit_done(self, unit: WorkUnit, n: int) -> None:
        self.generated[unit.sequence] += n
        self.left[unit.sequence] -= n
        if self.left[unit.sequence] == 0 and self.finalize:
            self._finalize(unit.sequence)

    def results(self) -> tuple[SequenceResult, ...]:
        return tuple(
            SequenceResult(
                name=j.sequence_name,
                path=self.paths[i],
                n_frames=j.n_frames,
                frames_generated=self.generated[i],
                visibility=_visibility_of(self.paths[i]),
            )
            for i, j in enumerate(self.jobs)
        )


def _run_units(
    executor: Executor,
    units: list[WorkUnit],
    jobs: Sequence[SequenceJob],
    options: GenerationOptions,
    progress: _RunProgress,
    on_frames: Callable[[int], None] | None,
) -> None:
    """Runs the units on the executor's workers with a progress bar; a failed or dead worker
    becomes a :class:`GenerationError`."""
    shard = options.shard
    desc = "generate" if shard is None else f"generate shard {shard}"
    total = sum(u.n_frames for u in units)
    with _progress_bar(total, options.progress, desc) as bar:

        def report(n: int) -> None:
            bar.update(n)
            if on_frames is not None:
                on_frames(n)

        setup = WorkerSetup(_init_worker, (list(jobs), options), teardown=_close_worker)
        try:
            for unit, n in executor.map_unordered(
                _worker_run, units, setup=setup, on_progress=report
            ):
                progress.unit_done(unit, n)
        except WorkUnitError as e:
            raise _generation_error(e, jobs) from e
