"""``roft-sim run`` as a library call: one tracker over the sequences of one or more datasets.

:func:`run_sequences` runs every sequence, writes one folder per sequence
(:mod:`roft_sim.harness.outputs`), ``metrics.json`` (``ALL``, ``MEAN`` and one entry per
sequence) and ``run.json`` (resolved configuration, seeds, inputs, package versions), and returns
a :class:`RunResult`. :func:`~roft_sim.datasets.find_sequences` (re-exported here) expands dataset
roots into sequence paths.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

from roft_sim.config_files import jsonable
from roft_sim.datasets import detect_format, find_sequences, open_sequence
from roft_sim.datasets.base import Sequence as DatasetSequence
from roft_sim.datasets.metadata import package_versions
from roft_sim.errors import ConfigError
from roft_sim.harness.evaluation import SequenceEvaluation, evaluate_run
from roft_sim.harness.inputs import DepthRendererFactory, resolve_object_model
from roft_sim.harness.options import RunOptions
from roft_sim.harness.outputs import write_json, write_sequence_outputs
from roft_sim.harness.reference_layout import (
    REFERENCE_TOP_FOLDERS,
    ReferenceTree,
    check_reference_objects,
    reference_config_name,
    write_reference_tree,
)
from roft_sim.harness.runner import SequenceRun, run_sequence
from roft_sim.harness.wall_clock import WallClock, clock_record
from roft_sim.metrics import POOLED_ALL, POOLED_MEAN, SequenceMetrics, pool_metrics
from roft_sim.metrics.deadlines import pool_deadline_stats
from roft_sim.trackers import TrackerSpec, get_tracker_spec, load_tracker_config

__all__ = [
    "RunResult",
    "OutputLayout",
    "OUTPUT_LAYOUTS",
    "SequenceSource",
    "check_sequence_names",
    "find_sequences",
    "open_sequences",
    "run_sequences",
    "RUN_FILE",
    "METRICS_FILE",
    "tracker_description",
]

RUN_FILE = "run.json"
METRICS_FILE = "metrics.json"
OutputLayout = Literal["ours", "reference"]
OUTPUT_LAYOUTS: tuple[str, ...] = get_args(OutputLayout)
"""``ours``: one folder per sequence (docs/running.md); ``reference``: that, plus the tree the
reference ROFT evaluation reads (:mod:`roft_sim.harness.reference_layout`)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class SequenceSource:
    """A sequence to run and where it came from."""

    sequence: DatasetSequence
    """The (lazy) sequence."""
    path: Path | None = None
    """Its folder or file on disk; None for in-memory sequences."""


@dataclass(frozen=True, slots=True, kw_only=True)
class RunResult:
    """What :func:`run_sequences` did."""

    out_dir: Path
    """The output folder."""
    metrics: dict[str, dict[str, Any]]
    """The content of ``metrics.json``."""
    pooled: dict[str, SequenceMetrics]
    """``ALL``, ``MEAN`` and per-sequence metrics (sequences with ground truth only)."""
    runs: tuple[SequenceRun, ...]
    """The per-sequence runs (estimates, step times, ledgers)."""
    wall_s: float
    """Wall time [s]."""
    reference_tree: ReferenceTree | None = None
    """The reference evaluation's tree, with ``layout="reference"``."""

    @property
    def sequence_names(self) -> list[str]:
        return [r.sequence_name for r in self.runs]


def open_sequences(paths: Sequence[str | Path]) -> list[SequenceSource]:
    """Opens every sequence under ``paths`` (see :func:`find_sequences`)."""
    out = []
    for path in find_sequences(paths):
        detect_format(path)
        out.append(SequenceSource(sequence=open_sequence(path), path=path))
    return out


def check_sequence_names(sources: Sequence[SequenceSource]) -> None:
    """Sequence names must be unique in a run (they name its folders) and not ``ALL`` / ``MEAN``.

    Raises:
        ConfigError: a repeated or reserved name.
    """
    names = [s.sequence.name for s in sources]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        where = {n: [str(s.path) for s in sources if s.sequence.name == n] for n in dup}
        raise ConfigError(
            f"sequence names must be unique within a run; {dup} appear more than once "
            f"({where}); run those datasets separately"
        )
    reserved = {POOLED_ALL, POOLED_MEAN} & set(names)
    if reserved:
        raise ConfigError(f"sequence names {sorted(reserved)} are reserved for pooled metrics")


def tracker_description(spec: TrackerSpec) -> dict[str, Any]:
    """JSON-ready summary of a tracker spec."""
    return {
        "name": spec.name,
        "description": spec.description,
        "detection_mode": spec.detection_mode,
        "needs_depth_renderer": spec.needs_depth_renderer,
        "config_type": f"{spec.config_type.__module__}.{spec.config_type.__qualname__}",
    }


def _sequence_record(source: SequenceSource, run: SequenceRun) -> dict[str, Any]:
    """The ``run.json`` entry of one sequence: where it came from, its size, inputs and seeds."""
    seq = source.sequence
    return {
        "name": seq.name,
        "path": None if source.path is None else str(source.path),
        "format": None if source.path is None else detect_format(source.path),
        "object": seq.object_name,
        "frames": len(seq),
        "fps": int(seq.fps),
        "resolution": [seq.intrinsics.width_px, seq.intrinsics.height_px],
        "inputs": run.inputs,
        "seeds": run.seeds.describe(),
        "depth_renderer_built": run.depth_renderer_built,
        "wall_s": round(run.wall_s, 3),
    }


def _pooled_metrics(
    evaluations: dict[str, SequenceEvaluation],
) -> tuple[dict[str, SequenceMetrics], dict[str, dict[str, Any]]]:
    """ALL and MEAN over the scored sequences, and the ``metrics.json`` entries: ALL, MEAN, then
    one per sequence. After a wall-clock run, ALL and MEAN both carry the timing figures of all
    frames pooled (as they carry the pooled step times)."""
    scored = {n: e.metrics for n, e in evaluations.items() if e.metrics is not None}
    pooled: dict[str, SequenceMetrics] = pool_metrics(scored) if scored else {}
    timed = [e for e in evaluations.values() if e.deadlines is not None]
    timing_entry: dict[str, Any] = {}
    if timed:
        stats = pool_deadline_stats([e.deadlines for e in timed if e.deadlines is not None])
        timing_entry = {"clock": timed[0].figures["clock"]} | stats.summary()
    metrics: dict[str, dict[str, Any]] = {}
    for name in (POOLED_ALL, POOLED_MEAN):
        if name in pooled:
            metrics[name] = pooled[name].summary() | timing_entry
    for name, evaluation in evaluations.items():
        metrics[name] = evaluation.entry()
    return pooled, metrics


def _run_each(
    sources: Sequence[SequenceSource],
    options: RunOptions,
    spec: TrackerSpec,
    out: Path,
    depth_renderer_factory: DepthRendererFactory | None,
    progress: bool,
    on_sequence_done: Callable[[SequenceRun, SequenceEvaluation], None] | None,
    tum: bool,
    clock: WallClock | None,
) -> tuple[list[SequenceRun], dict[str, SequenceEvaluation], list[dict[str, Any]]]:
    """Runs, scores and writes every sequence in turn (one progress bar over all frames; ``tum``:
    TUM files too); returns the runs, their evaluations by name and their ``run.json`` records."""
    from tqdm import tqdm

    total = sum(len(s.sequence) for s in sources)
    runs: list[SequenceRun] = []
    evaluations: dict[str, SequenceEvaluation] = {}
    described = []
    with tqdm(
        total=total, unit="frame", desc=f"run {spec.name}", disable=not progress, leave=False
    ) as bar:
        for source in sources:
            seq = source.sequence
            bar.set_postfix_str(seq.name)
            model = resolve_object_model(seq)
            run = run_sequence(
                seq,
                options,
                spec=spec,
                object_model=model,
                depth_renderer_factory=depth_renderer_factory,
                progress=bar.update,
                clock=clock,
            )
            evaluation = evaluate_run(run, invalid=options.invalid)
            write_sequence_outputs(out / seq.name, run, evaluation, tum=tum)
            runs.append(run)
            evaluations[seq.name] = evaluation
            described.append(_sequence_record(source, run))
            if on_sequence_done is not None:
                on_sequence_done(run, evaluation)

    return runs, evaluations, described


def run_sequences(
    sources: Sequence[SequenceSource],
    options: RunOptions,
    out_dir: str | Path,
    *,
    spec: TrackerSpec | None = None,
    depth_renderer_factory: DepthRendererFactory | None = None,
    progress: bool = False,
    on_sequence_done: Callable[[SequenceRun, SequenceEvaluation], None] | None = None,
    command: Sequence[str] | None = None,
    layout: OutputLayout = "ours",
    reference_config: str | None = None,
    tum: bool = False,
    clock: WallClock | None = None,
) -> RunResult:
    """Runs ``options.tracker`` over every sequence and writes the results into ``out_dir``.

    Args:
        sources: the sequences (e.g. from :func:`open_sequences`).
        options: the run's configuration (``tracker_config`` None = the tracker's defaults).
        out_dir: output folder (created; emptiness is the caller's business).
        spec: the tracker spec (default: looked up by name).
        depth_renderer_factory: see :func:`~roft_sim.harness.runner.run_sequence`.
        progress: show a tqdm progress bar over frames on stderr.
        on_sequence_done: called after each sequence is written.
        command: the command line, recorded in ``run.json``.
        layout: ``"reference"`` also writes the reference evaluation's tree into ``out_dir``
            (one sequence per object, with ground truth; see
            :mod:`~roft_sim.harness.reference_layout`).
        reference_config: its ``<config>`` folder; None = :func:`reference_config_name`.
        tum: also write ``gt.tum`` and ``estimate.tum`` per sequence (evo's TUM format).
        clock: None = simulated time (lockstep, deterministic); a
            :class:`~roft_sim.harness.wall_clock.WallClock` runs against a real clock
            (docs/wall_clock.md).

    Returns:
        The :class:`RunResult`.
    """
    t0 = time.perf_counter()
    if not sources:
        raise ConfigError("no sequence to run")
    check_sequence_names(sources)
    if layout not in OUTPUT_LAYOUTS:
        raise ConfigError(f"unknown output layout {layout!r}; expected one of {OUTPUT_LAYOUTS}")
    if layout == "reference":
        check_reference_objects([s.sequence.object_name for s in sources])
        clash = sorted({s.sequence.name for s in sources} & set(REFERENCE_TOP_FOLDERS))
        if clash:
            raise ConfigError(
                f"sequence names {clash} clash with the reference tree's folders "
                f"{REFERENCE_TOP_FOLDERS}; rename those sequences or drop --layout reference"
            )
    spec = spec if spec is not None else get_tracker_spec(options.tracker)
    if options.tracker_config is None:
        options = options.replace(tracker_config=load_tracker_config(spec, None))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)

    runs, evaluations, described = _run_each(
        sources, options, spec, out, depth_renderer_factory, progress, on_sequence_done, tum, clock
    )
    pooled, metrics = _pooled_metrics(evaluations)
    write_json(out / METRICS_FILE, metrics)
    tree = None
    if layout == "reference":
        config_name = reference_config or reference_config_name(
            runs[0].inputs, spec.name, options.tracker_config
        )
        tree = write_reference_tree(
            out,
            [(r, s.sequence) for r, s in zip(runs, sources, strict=True)],
            config_name=config_name,
        )
    wall_s = time.perf_counter() - t0
    write_json(
        out / RUN_FILE,
        {
            "kind": "run",
            "command": list(command) if command is not None else None,
            "tracker": tracker_description(spec),
            "options": jsonable(options),
            "clock": clock_record(clock),
            "sequences": described,
            "layout": layout,
            "reference_config": None if tree is None else tree.config_name,
            "reference_experiments": None if tree is None else list(tree.experiments),
            "versions": package_versions("mujoco", "scipy"),
            "wall_s": round(wall_s, 3),
        },
    )
    return RunResult(
        out_dir=out,
        metrics=metrics,
        pooled=pooled,
        runs=tuple(runs),
        wall_s=wall_s,
        reference_tree=tree,
    )
