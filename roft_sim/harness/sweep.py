"""``roft-sim sweep``: a grid of runs (trackers x fault configurations x a swept fault parameter x
sequences x seeds), run as independent cells in parallel, resumable, summarised in tables and
plots.

A sweep file (TOML; paths relative to the file)::

    name = "delay"
    datasets = ["../data/ci"]                  # sequences or dataset roots
    trackers = ["roft", "naive-delay", "pose-only-ukf"]
    faults = ["paper"]                         # base fault presets or files
    seeds = [0]
    flow = "auto"                              # poses, masks, init, invalid, include_rgb too
    flows = ["stored:nvof_1_slow", "dis"]      # optional: flow sources as a grid dimension

    [parameter]                                # optional: a swept fault parameter
    name = "delay"                             # delay [frames] | dropout [probability]
    values = [0, 2, 4, 6, 8, 10, 12, 14, 16, 18, 20]
    streams = ["pose", "mask"]

    [[variants]]                               # optional: extra tracker rows with settings
    label = "roft w/o pose sync"
    name = "roft"
    config = "roft_no_sync.toml"

``delay = d`` replaces every delay fault of the chosen streams of the base configuration by a
fixed delay of ``d`` frames; ``dropout = p`` adds an independent loss with probability ``p`` per
result (the same seed loses a superset of results as ``p`` grows, so curves stay smooth).

Outputs (docs/running.md): ``cells/<cell_id>/`` (one run folder per cell), ``summary.md``,
``summary.csv``, ``summary.tex`` (one row per tracker x faults x parameter value: each metric as
the mean over the replicates, the sequence x seed cells, with its 95 % confidence interval and
the number of replicates; ``summary.csv`` also has the "ALL" metrics pooled over their frames),
``paired.csv`` (every tracker against the first on the same cells: mean difference, interval,
verdict; docs/statistics.md), ``cells.csv`` (one row per cell), ``timing.csv`` (step times;
kept apart so the summary files are identical whenever the estimates are), ``plots/`` (error
versus the parameter with interval bands, per-frame error traces with pose arrivals) and
``sweep.json``.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from roft_sim.config_files import dataclass_from_mapping, jsonable, load_toml
from roft_sim.datasets import open_sequence
from roft_sim.errors import ConfigError
from roft_sim.executors import Executor, Shard
from roft_sim.faults import BernoulliDropout, FaultConfig, FixedDelay, load_faults
from roft_sim.harness.cells import (
    CELLS_DIR,
    SweepCell,
    execute_cells,
    load_cell_metrics,
)
from roft_sim.harness.inputs import check_inputs
from roft_sim.harness.options import InitPolicy, RunOptions
from roft_sim.harness.outputs import DELIVERIES_FILE, load_deliveries
from roft_sim.harness.replicates import (
    REPLICATE_METRICS,
    distinct_replicates,
    interval_fields,
    paired_set,
    replicate_intervals,
    replicate_scalars,
)
from roft_sim.harness.robust_start import RobustStartConfig
from roft_sim.harness.run_dataset import find_sequences
from roft_sim.metrics import (
    InvalidPolicy,
    SequenceMetrics,
    concatenate_metrics,
    policy_note,
    step_time_stats,
)
from roft_sim.metrics.statistics import CONFIDENCE, INTERVAL_METHOD
from roft_sim.report.plotting import Panel, Series, line_figure, save_figure
from roft_sim.report.tables import (
    ERROR_COLUMNS,
    Column,
    csv_table,
    latex_table,
    markdown_table,
)
from roft_sim.trackers import get_tracker_spec, load_tracker_config

__all__ = [
    "TrackerVariant",
    "SweptParameter",
    "SweepConfig",
    "SWEPT_PARAMETERS",
    "load_sweep_config",
    "parse_parameter",
    "apply_parameter",
    "plan_sweep",
    "SweepResult",
    "run_sweep",
    "summarize_cells",
    "SUMMARY_COLUMNS",
    "SUMMARY_CSV_COLUMNS",
    "paired_rows",
]

SWEPT_PARAMETERS: dict[str, str] = {
    "delay": "fixed delay [frames] of the chosen streams (replaces their delay faults)",
    "dropout": "independent loss probability per result of the chosen streams (added)",
}
"""The fault parameters a sweep can vary, with what they do."""

_DELAY_KINDS = ("delay", "uniform_delay", "lognormal_delay", "empirical_delay")


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackerVariant:
    """A tracker row with its own settings (``[[variants]]``)."""

    label: str
    """Row label (unique in the sweep)."""
    name: str
    """Registry name of the tracker, or ``process:<command line>`` (docs/process.md)."""
    config: Path | None = None
    """TOML file of its settings (relative to the sweep file); None = defaults."""

    def __post_init__(self) -> None:
        if not self.label.strip():
            raise ConfigError("a variant needs a non-empty label")


@dataclass(frozen=True, slots=True, kw_only=True)
class SweptParameter:
    """A fault parameter varied over a list of values (``[parameter]``)."""

    name: Literal["delay", "dropout"]
    """``delay`` [frames] or ``dropout`` [probability per result]."""
    values: tuple[float, ...]
    """The values, in plot order."""
    streams: tuple[Literal["pose", "mask"], ...] = ("pose", "mask")
    """The detection streams it acts on."""

    def __post_init__(self) -> None:
        if self.name not in SWEPT_PARAMETERS:
            raise ConfigError(
                f"unknown swept parameter {self.name!r}; expected one of "
                f"{', '.join(SWEPT_PARAMETERS)}"
            )
        if not self.values:
            raise ConfigError(f"parameter {self.name!r} needs at least one value")
        if not self.streams or any(s not in ("pose", "mask") for s in self.streams):
            raise ConfigError(f"parameter streams must be pose and/or mask, got {self.streams}")
        for v in self.values:
            if not math.isfinite(v):
                raise ConfigError(f"parameter {self.name!r}: value {v} is not finite")
            if self.name == "delay" and (v < 0 or v != int(v)):
                raise ConfigError(f"delay values are whole frames >= 0, got {v}")
            if self.name == "dropout" and not 0 <= v <= 1:
                raise ConfigError(f"dropout values are probabilities in [0, 1], got {v}")
        if len(set(self.values)) != len(self.values):
            raise ConfigError(f"parameter {self.name!r} lists a value twice: {self.values}")


@dataclass(frozen=True, slots=True, kw_only=True)
class SweepConfig:
    """A sweep: the grid and the inputs every cell shares (see the module docstring)."""

    name: str = "sweep"
    """Shown in the summary."""
    datasets: tuple[Path, ...] = ()
    """Sequences or dataset roots."""
    trackers: tuple[str, ...] = ()
    """Registry names of trackers run with their default settings."""
    variants: tuple[TrackerVariant, ...] = ()
    """Trackers with settings, each its own row."""
    faults: tuple[str, ...] = ("paper",)
    """Base fault presets or files (each a grid value)."""
    parameter: SweptParameter | None = None
    """The swept fault parameter, or None."""
    seeds: tuple[int, ...] = (0,)
    """Run seeds (each a grid value; pooled in the summary)."""
    flow: str = "auto"
    """Flow source for every cell (see ``roft-sim run --flow``); ignored when ``flows`` is
    given."""
    flows: tuple[str, ...] = ()
    """Flow sources as a grid dimension (each a value; the summary gets a ``flow`` column);
    empty = ``flow`` alone."""
    poses: str = "auto"
    """Pose set for every cell."""
    masks: str = "auto"
    """Mask set for every cell."""
    init: InitPolicy = "first-detection"
    """Initial condition."""
    robust_start: RobustStartConfig = field(default_factory=RobustStartConfig)
    """Settings of ``init = "robust"`` (``[robust_start]``)."""
    invalid: InvalidPolicy = "failure"
    """How frames without a pose are scored: ``failure``, ``exclude``, ``as_given`` or ``hold``
    (the reference's DOPE policy; docs/metrics.md). Every summary names it."""
    include_rgb: bool = True
    """Hand rgb images to the trackers."""
    extra: dict[str, Any] = field(default_factory=dict)
    """Free-form notes copied into ``sweep.json``."""

    def __post_init__(self) -> None:
        if not self.datasets:
            raise ConfigError("a sweep needs at least one dataset (datasets = [...])")
        if not self.trackers and not self.variants:
            raise ConfigError("a sweep needs at least one tracker (trackers = [...])")
        if not self.faults:
            raise ConfigError("a sweep needs at least one fault configuration (faults = [...])")
        if not self.seeds or any(s < 0 for s in self.seeds):
            raise ConfigError(f"seeds must be a non-empty list of integers >= 0, got {self.seeds}")
        if len(set(self.flows)) != len(self.flows):
            raise ConfigError(f"flows lists a source twice: {self.flows}")
        labels = [*self.trackers, *(v.label for v in self.variants)]
        dup = sorted({x for x in labels if labels.count(x) > 1})
        if dup:
            raise ConfigError(f"tracker labels must be unique in a sweep, repeated: {dup}")


def load_sweep_config(path: str | Path) -> SweepConfig:
    """Loads a sweep file (strict TOML; paths relative to the file)."""
    path = Path(path)
    config = dataclass_from_mapping(SweepConfig, load_toml(path), where=str(path))
    base = path.resolve().parent

    def rel(p: Path | None) -> Path | None:
        return None if p is None else (p if p.is_absolute() else base / p)

    return dataclasses.replace(
        config,
        datasets=tuple(rel(p) for p in config.datasets),  # type: ignore[misc]
        variants=tuple(dataclasses.replace(v, config=rel(v.config)) for v in config.variants),
    )


def parse_parameter(text: str, *, streams: Sequence[str] = ("pose", "mask")) -> SweptParameter:
    """``delay=0:20:2`` (start:stop:step, stop included) or ``dropout=0,0.1,0.3`` (a list).

    Raises:
        ConfigError: not ``NAME=VALUES``, or bad values.
    """
    name, sep, values = text.partition("=")
    if not sep or not values.strip():
        raise ConfigError(
            f"--param {text!r}: expected NAME=VALUES, e.g. delay=0:20:2 or dropout=0,0.1,0.2"
        )
    try:
        if ":" in values:
            parts = [float(x) for x in values.split(":")]
            if len(parts) != 3 or parts[2] <= 0 or parts[1] < parts[0]:
                raise ValueError
            start, stop, step = parts
            count = int(math.floor((stop - start) / step + 1e-9)) + 1
            numbers = tuple(round(start + i * step, 12) for i in range(count))
        else:
            numbers = tuple(float(x) for x in values.split(","))
    except ValueError:
        raise ConfigError(
            f"--param {text!r}: values must be start:stop:step (step > 0) or a comma list of "
            "numbers"
        ) from None
    return SweptParameter(
        name=name.strip(),  # type: ignore[arg-type]
        values=numbers,
        streams=tuple(streams),  # type: ignore[arg-type]
    )


def apply_parameter(faults: FaultConfig, parameter: SweptParameter, value: float) -> FaultConfig:
    """The fault configuration ``faults`` with ``parameter = value`` (see the module docstring)."""
    changes: dict[str, Any] = {}
    for stream in parameter.streams:
        cfg = faults.detection_stream(stream)
        if parameter.name == "delay":
            kept = tuple(f for f in cfg.faults if getattr(f, "kind", None) not in _DELAY_KINDS)
            new = (*kept, FixedDelay(frames=int(value)))
        else:
            new = (*cfg.faults, BernoulliDropout(p=float(value)))
        # mypy types replace() on a union of dataclasses with the meet of the field types (Never)
        changes[stream] = dataclasses.replace(cfg, faults=new)  # type: ignore[arg-type]
    label = f"{faults.name}+{parameter.name}={value:g}"
    return dataclasses.replace(faults, name=label, **changes)


def _tracker_rows(config: SweepConfig) -> list[tuple[str, str, Any]]:
    """``(label, tracker, config instance)`` per tracker row: the label is the registry name
    (for ``process:<command>``, the name made from the command) or the variant's label; the
    tracker is the name as given, which :func:`get_tracker_spec` resolves in every worker."""
    rows = []
    for name in config.trackers:
        spec = get_tracker_spec(name)
        rows.append((spec.name, name, load_tracker_config(spec, None)))
    for v in config.variants:
        spec = get_tracker_spec(v.name)
        if v.config is not None and not Path(v.config).is_file():
            raise ConfigError(f"variant {v.label!r}: config file {str(v.config)!r} does not exist")
        rows.append((v.label, v.name, load_tracker_config(spec, v.config)))
    return rows


def plan_sweep(config: SweepConfig) -> list[SweepCell]:
    """Every cell of the grid, in (tracker, faults, value, flow, sequence, seed) order.

    Raises:
        ConfigError: unknown tracker, fault preset, bad dataset path, inputs a sequence cannot
            feed (pose / mask / stored flow set), or a grid value listed twice.
    """
    trackers = _tracker_rows(config)
    base_faults = [(spec, load_faults(spec)) for spec in config.faults]
    paths = find_sequences(config.datasets)
    sequences = [(str(p.resolve()), open_sequence(p)) for p in paths]
    values: list[float | None] = list(config.parameter.values) if config.parameter else [None]
    shared = RunOptions(  # what every cell shares; each cell sets tracker, faults and seed
        tracker=trackers[0][1],
        faults=base_faults[0][1],
        flow=config.flow,
        poses=config.poses,
        masks=config.masks,
        init=config.init,
        robust_start=config.robust_start,
        include_rgb=config.include_rgb,
        invalid=config.invalid,
    )
    flows = list(config.flows) or [config.flow]
    for _, seq in sequences:
        for flow in flows:
            check_inputs(seq, shared.replace(flow=flow))
    cells = []
    for label, name, tracker_config in trackers:
        for fault_label, faults in base_faults:
            for value in values:
                cell_faults = (
                    faults
                    if value is None or config.parameter is None
                    else apply_parameter(faults, config.parameter, value)
                )
                for flow, (path, seq) in itertools.product(flows, sequences):
                    cell_faults.check_camera_rate(int(seq.fps))
                    for seed in config.seeds:
                        options = shared.replace(
                            tracker=name,
                            tracker_config=tracker_config,
                            faults=cell_faults,
                            seed=int(seed),
                            flow=flow,
                        )
                        parameter = config.parameter.name if config.parameter else None
                        cells.append(
                            SweepCell.create(
                                label=label,
                                fault_label=fault_label,
                                parameter=parameter,
                                value=value,
                                sequence_path=path,
                                sequence_name=seq.name,
                                options=options,
                            )
                        )
    counts = Counter(c.cell_id for c in cells)
    repeated = sorted(i for i, n in counts.items() if n > 1)
    if repeated:
        raise ConfigError(
            f"the sweep grid has the cell {repeated[0]!r} more than once ({len(repeated)} "
            "repeated): a dataset (or sequence), fault configuration or seed is listed twice; "
            "list each once"
        )
    return cells


# --------------------------------------------------------------------------------- summary
_GROUP_COLUMNS: tuple[Column, ...] = (
    Column("tracker", "tracker", align="left"),
    Column("faults", "faults", align="left"),
    Column("flow", "flow", align="left"),
    Column("value", "value", "g"),
    Column("sequences", "sequences", "d"),
    Column("replicates", "n", "d"),
    Column("frames", "frames", "d"),
)
SUMMARY_COLUMNS: tuple[Column, ...] = (
    *_GROUP_COLUMNS,
    *(Column(f"{c.key}_ci", f"{c.header} mean [95 % CI]") for c in ERROR_COLUMNS),
)
"""Columns of ``summary.md`` and ``summary.tex``: per metric the mean over the replicates with
its interval (deterministic: no timing)."""
SUMMARY_CSV_COLUMNS: tuple[Column, ...] = (
    *_GROUP_COLUMNS,
    *ERROR_COLUMNS,
    *(
        Column(f"{k}_{part}", f"{k}_{part}")
        for k in REPLICATE_METRICS
        for part in ("mean", "lo", "hi")
    ),
)
"""Columns of ``summary.csv``: the pooled ALL metrics, then per metric the replicate mean and
the bounds of its interval."""

_CELL_COLUMNS: tuple[Column, ...] = (
    Column("cell_id", "cell", align="left"),
    Column("tracker", "tracker", align="left"),
    Column("faults", "faults", align="left"),
    Column("flow", "flow", align="left"),
    Column("value", "value", "g"),
    Column("sequence", "sequence", align="left"),
    Column("seed", "seed", "d"),
    Column("frames", "frames", "d"),
    *ERROR_COLUMNS,
)

_TIMING_COLUMNS: tuple[Column, ...] = (
    Column("tracker", "tracker", align="left"),
    Column("faults", "faults", align="left"),
    Column("flow", "flow", align="left"),
    Column("value", "value", "g"),
    Column("steps", "steps", "d"),
    Column("time_median_ms", "step ms (median)", ".3f"),
    Column("time_p95_ms", "step ms (p95)", ".3f"),
    Column("time_mean_ms", "step ms (mean)", ".3f"),
)

_METRIC_KEYS = ("add_auc_pct", "rmse_t_cm", "rmse_a_deg", "rmse_v_cmps", "rmse_w_dps")


@dataclass(frozen=True, slots=True, kw_only=True)
class SweepResult:
    """What :func:`run_sweep` produced."""

    out_dir: Path
    """The sweep folder."""
    cells: tuple[SweepCell, ...]
    """The planned cells (all shards)."""
    records: dict[str, dict[str, Any]]
    """``cell.json`` of every finished cell, by id (every cell unless ``shard``)."""
    summary_rows: list[dict[str, Any]]
    """One row per tracker x faults x value: the pooled ALL metrics, the number of replicates
    and each metric's replicate mean and interval (:data:`SUMMARY_CSV_COLUMNS`); empty for a
    shard run, which writes no summary."""
    plots: list[Path]
    """The plots written."""
    shard: Shard | None = None
    """The shard this run ran (None = the whole sweep, summary written)."""
    shard_cells: tuple[SweepCell, ...] = ()
    """The cells of ``shard`` (empty when ``shard`` is None)."""


def _group_key(cell: SweepCell) -> tuple[str, str, float | None, str]:
    return (cell.label, cell.fault_label, cell.value, cell.options.flow)


def summarize_cells(
    cells: Sequence[SweepCell], cells_dir: Path
) -> tuple[
    list[dict[str, Any]],
    list[dict[str, Any]],
    dict[tuple[str, str, float | None, str], SequenceMetrics],
]:
    """Summary rows (per tracker x faults x value x flow), timing rows, and the pooled metrics.

    Each row has the pooled "ALL" metrics (the per-frame errors of every sequence and seed of a
    group concatenated: the reference's ALL row), ``replicates`` (the cells with metrics, less
    those that repeat another seed of their sequence exactly:
    :func:`~roft_sim.harness.replicates.distinct_replicates`) and per metric the mean over the
    replicates with its 95 % interval (:func:`~roft_sim.harness.replicates.interval_fields`).
    """
    groups: dict[tuple[str, str, float | None, str], list[SweepCell]] = {}
    for cell in cells:
        groups.setdefault(_group_key(cell), []).append(cell)
    rows, timing, pooled = [], [], {}
    for key, members in groups.items():
        loaded = [(c, load_cell_metrics(cells_dir, c.cell_id)) for c in members]
        finished = [(c, m) for c, m in loaded if m is not None]
        parts = [m for _, m in finished]
        distinct = distinct_replicates(
            {(c.sequence_name, c.options.seed): replicate_scalars(m) for c, m in finished}
        )
        label, fault_label, value, flow = key
        row: dict[str, Any] = {
            "tracker": label,
            "faults": fault_label,
            "flow": flow,
            "value": value,
            "sequences": len({c.sequence_name for c in members}),
        }
        row["replicates"] = len(distinct)
        if parts:
            m = concatenate_metrics(parts)
            pooled[key] = m
            summary = m.summary()
            row |= {"frames": summary["frames"]} | {k: summary[k] for k in _METRIC_KEYS}
            intervals = replicate_intervals(list(distinct.values()), key)
            row |= interval_fields(intervals)
            if m.step_times_s is not None:
                t = step_time_stats(m.step_times_s)
                timing.append(
                    {
                        "tracker": label,
                        "faults": fault_label,
                        "flow": flow,
                        "value": value,
                        "steps": t.steps,
                        "time_median_ms": t.median_ms,
                        "time_p95_ms": t.p95_ms,
                        "time_mean_ms": t.mean_ms,
                    }
                )
        rows.append(row)
    return rows, timing, pooled


def _cell_rows(
    cells: Sequence[SweepCell], records: dict[str, dict[str, Any]]
) -> list[dict[str, Any]]:
    rows = []
    for c in cells:
        metrics = records[c.cell_id].get("metrics", {})
        rows.append(
            {
                "cell_id": c.cell_id,
                "tracker": c.label,
                "faults": c.fault_label,
                "flow": c.options.flow,
                "value": c.value,
                "sequence": c.sequence_name,
                "seed": c.options.seed,
                "frames": metrics.get("frames"),
                **{k: metrics.get(k) for k in _METRIC_KEYS},
            }
        )
    return rows


PAIRED_COLUMNS: tuple[Column, ...] = (
    Column("tracker", "tracker", align="left"),
    Column("versus", "versus", align="left"),
    Column("faults", "faults", align="left"),
    Column("flow", "flow", align="left"),
    Column("value", "value", "g"),
    Column("pairs", "pairs", "d"),
    *(Column(f"{c.key}_paired", f"{c.header} A - B [95 % CI]") for c in ERROR_COLUMNS),
)
"""Columns of the paired table of ``summary.md``."""
PAIRED_CSV_COLUMNS: tuple[Column, ...] = (
    *PAIRED_COLUMNS[:6],
    *(
        Column(f"{k}_{part}", f"{k}_{part}")
        for k in REPLICATE_METRICS
        for part in ("diff", "lo", "hi", "verdict")
    ),
)
"""Columns of ``paired.csv``."""


def paired_rows(
    cells: Sequence[SweepCell], records: dict[str, dict[str, Any]]
) -> list[dict[str, Any]]:
    """Every tracker row against the first one (the sweep's first tracker), per faults x value
    x flow, paired on the cells with the same sequence and seed (the same fault draw): per
    metric the mean difference A - B, its 95 % interval and the verdict word."""
    labels = list(dict.fromkeys(c.label for c in cells))
    if len(labels) < 2:
        return []
    by_group: dict[tuple[str, float | None, str], dict[str, dict[Any, dict[str, float]]]] = {}
    for c in cells:
        metrics = records.get(c.cell_id, {}).get("metrics")
        if metrics is None:
            continue
        group = by_group.setdefault((c.fault_label, c.value, c.options.flow), {})
        group.setdefault(c.label, {})[(c.sequence_name, c.options.seed)] = replicate_scalars(
            metrics
        )
    rows = []
    for (fault_label, value, flow), trackers in by_group.items():
        reference = trackers.get(labels[0])
        if reference is None:
            continue
        for label in labels[1:]:
            if label not in trackers:
                continue
            key = (label, labels[0], fault_label, value, flow)
            pairs = paired_set(label, labels[0], trackers[label], reference, key, REPLICATE_METRICS)
            row: dict[str, Any] = {
                "tracker": label,
                "versus": labels[0],
                "faults": fault_label,
                "flow": flow,
                "value": value,
                "pairs": pairs.pairs,
            }
            for metric, comparison in pairs.comparisons.items():
                d = comparison.difference
                row[f"{metric}_paired"] = f"{d.text('+.2f')} {comparison.verdict}"
                row[f"{metric}_diff"] = d.estimate if math.isfinite(d.estimate) else None
                row[f"{metric}_lo"] = d.low if d.has_interval else None
                row[f"{metric}_hi"] = d.high if d.has_interval else None
                row[f"{metric}_verdict"] = comparison.verdict
            rows.append(row)
    return rows


def _columns(
    parameter: str | None, columns: Sequence[Column], *, with_flow: bool = False
) -> list[Column]:
    columns = [c for c in columns if with_flow or c.key != "flow"]
    if parameter is None:
        return [c for c in columns if c.key != "value"]
    return [Column(c.key, parameter, c.fmt) if c.key == "value" else c for c in columns]


_PARAMETER_AXIS = {"delay": "delay [frames]", "dropout": "dropout probability"}
_PANELS = (
    ("add_auc_pct", "ADD-AUC", "%"),
    ("rmse_t_cm", "position RMSE", "cm"),
    ("rmse_a_deg", "rotation RMSE", "deg"),
    ("rmse_v_cmps", "velocity RMSE", "cm/s"),
)


def _column(rows: Sequence[dict[str, Any]], key: str) -> list[float]:
    """``row[key]`` of each row, NaN where missing."""
    return [np.nan if r.get(key) is None else float(r[key]) for r in rows]


def plot_error_vs_parameter(rows: Sequence[dict[str, Any]], parameter: str, path: Path) -> Path:
    """A 2x2 figure of the metrics versus the swept parameter: one line per tracker (and base
    fault configuration when there are several) through the replicate means, with a band over
    their 95 % intervals."""
    fault_labels = sorted({r["faults"] for r in rows})
    lines: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        name = r["tracker"] if len(fault_labels) == 1 else f"{r['tracker']} ({r['faults']})"
        lines.setdefault(name, []).append(r)
    panels = []
    for key, title, unit in _PANELS:
        series = []
        for name, members in lines.items():
            members = sorted(members, key=lambda r: r["value"])
            series.append(
                Series(
                    x=[r["value"] for r in members],
                    y=_column(members, f"{key}_mean"),
                    label=name,
                    band_low=_column(members, f"{key}_lo"),
                    band_high=_column(members, f"{key}_hi"),
                )
            )
        panels.append(
            Panel(
                title=f"{title} vs {parameter}", y_label=f"{title} [{unit}]", series=tuple(series)
            )
        )
    figure = line_figure(
        panels,
        x_label=_PARAMETER_AXIS.get(parameter, parameter),
        markers=True,
        integer_x=parameter == "delay",
    )
    return save_figure(figure, path)


def plot_error_traces(
    cells: Sequence[SweepCell], cells_dir: Path, path: Path, *, title: str
) -> Path:
    """Per-frame position and rotation error of several cells of ONE sequence (one line each),
    with the pose arrivals of the first cell that gets detections through the fault stream."""
    position: list[Series] = []
    rotation: list[Series] = []
    arrivals = None
    for cell in cells:
        m = load_cell_metrics(cells_dir, cell.cell_id)
        if m is None:
            continue
        position.append(Series(x=m.frame_index, y=m.t_err_norm_cm, label=cell.label))
        rotation.append(Series(x=m.frame_index, y=m.a_err_deg, label=cell.label))
        spec = get_tracker_spec(cell.options.tracker)
        deliveries = cells_dir / cell.cell_id / DELIVERIES_FILE
        if arrivals is None and spec.detection_mode == "stream" and deliveries.is_file():
            arrivals = np.unique(load_deliveries(deliveries)["pose"].arrival_k)
    panels = [
        Panel(title="position error", y_label="position error [cm]", series=tuple(position)),
        Panel(title="rotation error", y_label="rotation error [deg]", series=tuple(rotation)),
    ]
    figure = line_figure(
        panels,
        x_label="frame",
        title=title,
        columns=1,
        integer_x=True,
        events_x=arrivals,
        panel_in=(11.2, 3.2),
    )
    return save_figure(figure, path)


def _trace_groups(cells: Sequence[SweepCell]) -> list[tuple[str, list[SweepCell]]]:
    """The cells traced: first sequence and seed; per base faults, the first, middle and last
    parameter value."""
    if not cells:
        return []
    first_seq, first_seed = cells[0].sequence_name, cells[0].options.seed
    chosen = [c for c in cells if c.sequence_name == first_seq and c.options.seed == first_seed]
    values = sorted({c.value for c in chosen if c.value is not None})
    if values:
        keep = {values[0], values[len(values) // 2], values[-1]}
        chosen = [c for c in chosen if c.value in keep]
    groups: dict[tuple[str, float | None], list[SweepCell]] = {}
    for c in chosen:
        groups.setdefault((c.fault_label, c.value), []).append(c)
    out = []
    for (fault_label, value), members in groups.items():
        name = fault_label if value is None else f"{fault_label} {members[0].parameter}={value:g}"
        out.append((name, members))
    return out


def _safe_name(text: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "-_=." else "_" for ch in text)


_INTERVAL_NOTE = (
    f"Each metric: the mean over the n replicates (the sequence x seed cells of a row) with its "
    f"{CONFIDENCE:.0%} confidence interval ({INTERVAL_METHOD}; docs/statistics.md); "
    "summary.csv also has the ALL metrics, pooled over the frames of every replicate."
)


def _paired_section(
    cells: Sequence[SweepCell],
    records: dict[str, dict[str, Any]],
    out_dir: Path,
    parameter: str | None,
    with_flow: bool,
) -> list[str]:
    """Writes ``paired.csv`` and returns the Markdown of the paired table (none with a single
    tracker)."""
    from roft_sim.datasets.atomic_files import atomic_write_text

    rows = paired_rows(cells, records)
    if not rows:
        return []
    atomic_write_text(
        out_dir / "paired.csv",
        csv_table(_columns(parameter, PAIRED_CSV_COLUMNS, with_flow=with_flow), rows),
    )
    return [
        f"## Paired: each tracker against {rows[0]['versus']} on the same cells",
        "",
        "Mean difference A - B over the cells with the same sequence and seed (the same fault "
        f"draw), its {CONFIDENCE:.0%} interval and the verdict: better / worse only when the "
        "interval excludes 0 (ADD-AUC higher is better, the errors lower).",
        "",
        markdown_table(_columns(parameter, PAIRED_COLUMNS, with_flow=with_flow), rows),
        "",
    ]


def write_summary(
    config_name: str,
    cells: Sequence[SweepCell],
    records: dict[str, dict[str, Any]],
    out_dir: Path,
    *,
    parameter: str | None,
    plots: bool = True,
    cells_dir: Path | None = None,
) -> tuple[list[dict[str, Any]], list[Path]]:
    """Writes ``summary.{md,csv,tex}``, ``paired.csv`` (with two trackers or more),
    ``cells.csv``, ``timing.csv`` and the plots into ``out_dir`` (the cells are read from
    ``cells_dir``, default ``out_dir/cells``)."""
    from roft_sim.datasets.atomic_files import atomic_write_text

    cells_dir = cells_dir if cells_dir is not None else out_dir / CELLS_DIR
    rows, timing, _ = summarize_cells(cells, cells_dir)
    with_flow = len({c.options.flow for c in cells}) > 1
    columns = _columns(parameter, SUMMARY_COLUMNS, with_flow=with_flow)
    written: list[Path] = []
    if plots:
        plot_dir = out_dir / "plots"
        if parameter is not None:
            written.append(
                plot_error_vs_parameter(rows, parameter, plot_dir / f"error_vs_{parameter}.png")
            )
        for name, members in _trace_groups(cells):
            seq = members[0].sequence_name
            written.append(
                plot_error_traces(
                    members,
                    cells_dir,
                    plot_dir / f"trace_{_safe_name(name)}_{_safe_name(seq)}.png",
                    title=f"{seq}, {name}",
                )
            )
    md = [f"# Sweep: {config_name}", ""]
    md.append(
        f"{len(cells)} cells: {len({c.label for c in cells})} trackers x "
        f"{len({(c.fault_label, c.value) for c in cells})} fault configurations x "
        + (f"{len({c.options.flow for c in cells})} flow sources x " if with_flow else "")
        + f"{len({c.sequence_name for c in cells})} sequences x "
        f"{len({c.options.seed for c in cells})} seeds. {_INTERVAL_NOTE}"
    )
    md += ["", markdown_table(columns, rows), ""]
    md += [policy_note(p) for p in sorted({c.options.invalid for c in cells})]
    md.append("")
    md += _paired_section(cells, records, out_dir, parameter, with_flow)
    for p in written:
        md.append(f"![{p.stem}]({p.relative_to(out_dir).as_posix()})\n")
    atomic_write_text(out_dir / "summary.md", "\n".join(md))
    csv_columns = _columns(parameter, SUMMARY_CSV_COLUMNS, with_flow=with_flow)
    atomic_write_text(out_dir / "summary.csv", csv_table(csv_columns, rows))
    atomic_write_text(
        out_dir / "summary.tex",
        latex_table(columns, rows, caption=f"Sweep {config_name}: replicate means, 95 % intervals"),
    )
    atomic_write_text(
        out_dir / "cells.csv",
        csv_table(
            _columns(parameter, _CELL_COLUMNS, with_flow=with_flow), _cell_rows(cells, records)
        ),
    )
    atomic_write_text(
        out_dir / "timing.csv",
        csv_table(_columns(parameter, _TIMING_COLUMNS, with_flow=with_flow), timing),
    )
    return rows, written


def run_sweep(
    config: SweepConfig,
    out_dir: str | Path,
    *,
    executor: Executor | None = None,
    progress: bool = False,
    plots: bool = True,
    shard: Shard | None = None,
) -> SweepResult:
    """Plans the grid, runs the unfinished cells, writes the summary and plots.

    Resumable: run it again on the same ``out_dir`` and only the missing cells run (what is
    finished is read from disk). With ``shard`` only that shard's cells run
    (:func:`~roft_sim.harness.cells.shard_cells`) and no summary is written: once every shard
    has finished, a run without ``shard`` on the same folder writes it (and runs any cell still
    missing).

    Raises:
        ConfigError: bad configuration (before anything runs).
        CellsFailedError: tracker processes failed in some cells (all the others ran).
        WorkUnitError: a cell failed otherwise (finished cells are kept).
    """
    from roft_sim.datasets.atomic_files import atomic_write_text

    out = Path(out_dir)
    cells = plan_sweep(config)
    out.mkdir(parents=True, exist_ok=True)
    plan = json.dumps(
        {"kind": "sweep", "config": jsonable(config), "cells": [c.cell_id for c in cells]},
        indent=2,
        allow_nan=False,
    )
    plan_path = out / "sweep.json"
    # Shards share the folder: leave an identical plan alone instead of racing to rewrite it.
    if not (plan_path.is_file() and plan_path.read_text(encoding="utf-8") == plan + "\n"):
        atomic_write_text(plan_path, plan + "\n")
    records = execute_cells(
        cells, out / CELLS_DIR, executor=executor, progress=progress, shard=shard
    )
    if shard is not None:
        from roft_sim.harness.cells import shard_cells

        return SweepResult(
            out_dir=out,
            cells=tuple(cells),
            records=records,
            summary_rows=[],
            plots=[],
            shard=shard,
            shard_cells=tuple(shard_cells(cells, shard)),
        )
    parameter = config.parameter.name if config.parameter else None
    rows, written = write_summary(
        config.name, cells, records, out, parameter=parameter, plots=plots
    )
    return SweepResult(
        out_dir=out, cells=tuple(cells), records=records, summary_rows=rows, plots=written
    )
