"""``roft-sim compare``: two runs of ``roft-sim run`` on the same data, frame by frame.

Each run folder holds ``run.json`` and, per sequence, ``frame_errors.npz`` (the per-frame errors
behind the metrics) and ``deliveries.npz`` (when each pose arrived); a sweep's cell folder
(``cells/<id>``, with ``cell.json``) is one run of one sequence. The two runs are paired on
the frames both scored; per metric the difference A - B gets a moving-block bootstrap interval
(frames are correlated: :mod:`roft_sim.metrics.statistics`), and a table says where the
position and rotation error differences concentrate (docs/statistics.md):

- *after a pose arrival*: the first half of the pose period after each arrival
  (``0 <= k - a(k) < P/2``, ``a(k)`` the last arrival at or before frame k, ``P`` the median
  interval between arrivals in run A);
- *rest of the pose period*: ``P/2 <= k - a(k) <= 3P/2``;
- *no-detection stretch*: ``k - a(k) > 3P/2`` (a pose is overdue: dropouts, bursts, blackouts)
  or no pose yet;
- *fast motion*: the ground-truth linear or angular speed in the top quarter of the sequence's
  own speeds (read from the dataset named in ``run.json``; left out when it is absent).

The block length of each metric is the Politis-White choice on its per-frame difference series
(squared errors for the RMSEs, the per-frame AUC score for ADD-AUC), the largest over the
sequences, and never shorter than the pose period ``P``: a delayed-detection tracker's error
follows the arrivals (a sawtooth of period P), and a block shorter than P would cut it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError, DatasetFormatError
from roft_sim.harness.cells import CELL_FILE
from roft_sim.harness.outputs import (
    DELIVERIES_FILE,
    FRAME_ERRORS_FILE,
    load_deliveries,
    load_frame_errors,
    read_json,
)
from roft_sim.harness.run_dataset import RUN_FILE
from roft_sim.metrics import SequenceMetrics
from roft_sim.metrics.auc import DEFAULT_MAX_THRESHOLD_M, add_auc_rows
from roft_sim.metrics.statistics import (
    BLOCK_METHOD,
    METRIC_DIRECTIONS,
    Interval,
    block_bootstrap_interval,
    politis_white_block_length,
    verdict_word,
)

F64 = NDArray[np.float64]
Index = NDArray[np.int64]

__all__ = [
    "COMPARE_METRICS",
    "ComparedRun",
    "load_compared_run",
    "check_same_data",
    "MetricDifference",
    "WhereRow",
    "CompareResult",
    "compare_runs",
    "format_compare",
]

COMPARE_METRICS: tuple[tuple[str, str, str], ...] = (
    ("add_auc_pct", "ADD-AUC", "%"),
    ("rmse_t_cm", "e_t", "cm"),
    ("rmse_a_deg", "e_a", "deg"),
    ("rmse_v_cmps", "e_v", "cm/s"),
    ("rmse_w_dps", "e_w", "deg/s"),
)
"""``(key, name, unit)`` of the metrics compared."""

FAST_QUANTILE = 0.75
"""Frames whose ground-truth speed is above this quantile of the sequence's own are fast."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ComparedRun:
    """What :func:`load_compared_run` reads from a run folder."""

    folder: Path
    tracker: str
    """The tracker's registry name."""
    faults: str
    """The fault configuration's name."""
    seed: int
    """The run seed."""
    sequences: dict[str, dict[str, Any]]
    """Per sequence name, its ``run.json`` record (path, object, frames, fps, ...)."""
    metrics: dict[str, SequenceMetrics]
    """Per sequence, the per-frame errors."""
    arrivals: dict[str, Index]
    """Per sequence, the sorted frames at which a pose arrived."""


def _cell_as_run(folder: Path) -> dict[str, Any]:
    """A sweep cell's ``cell.json`` in the shape of ``run.json`` (its one sequence's files lie
    in the cell folder itself)."""
    from roft_sim.datasets import open_sequence

    cell = read_json(folder / CELL_FILE)
    frames: int | None = None  # None: compared by path only
    fps: int | None = None
    try:
        sequence = open_sequence(cell["sequence_path"])
        frames, fps = len(sequence), int(sequence.fps)
    except (DatasetFormatError, OSError):
        pass
    record = {
        "name": cell["sequence"],
        "path": cell["sequence_path"],
        "object": cell.get("object"),
        "frames": frames,
        "fps": fps,
        "folder": ".",
    }
    return {"tracker": {"name": cell["label"]}, "options": cell["options"], "sequences": [record]}


def load_compared_run(folder: str | Path) -> ComparedRun:
    """Reads a ``roft-sim run`` folder, or a cell folder of a sweep (``cells/<id>``).

    Raises:
        ConfigError: not a run or cell folder, or a sequence without per-frame errors (no
            ground truth).
    """
    folder = Path(folder)
    if not ((folder / RUN_FILE).is_file() or (folder / CELL_FILE).is_file()):
        raise ConfigError(
            f"{str(folder)!r} is not a run folder (no {RUN_FILE}); give folders written by "
            "roft-sim run (e.g. out/demo/runs/roft) or sweep cells (SWEEP/cells/<id>)"
        )
    try:
        info = (
            read_json(folder / RUN_FILE) if (folder / RUN_FILE).is_file() else _cell_as_run(folder)
        )
    except DatasetFormatError as e:
        raise ConfigError(str(e)) from None
    sequences = {s["name"]: s for s in info.get("sequences", [])}
    metrics, arrivals = {}, {}
    for name, record in sequences.items():
        path = folder / record.get("folder", name) / FRAME_ERRORS_FILE
        if not path.is_file():
            raise ConfigError(
                f"run {str(folder)!r}: sequence {name!r} has no {FRAME_ERRORS_FILE} (it has no "
                "ground truth, so there are no errors to compare)"
            )
        metrics[name] = load_frame_errors(path)
        deliveries = folder / record.get("folder", name) / DELIVERIES_FILE
        arrivals[name] = (
            np.unique(load_deliveries(deliveries)["pose"].arrival_k)
            if deliveries.is_file()
            else np.zeros(0, dtype=np.int64)
        )
    options = info.get("options", {})
    return ComparedRun(
        folder=folder,
        tracker=str(info.get("tracker", {}).get("name", folder.name)),
        faults=str(options.get("faults", {}).get("name", "?")),
        seed=int(options.get("seed", 0)),
        sequences=sequences,
        metrics=metrics,
        arrivals=arrivals,
    )


def _same_ground_truth(path_a: str | None, path_b: str | None) -> bool:
    """True when both sequences open and have the same ground-truth poses."""
    from roft_sim.datasets import open_sequence

    try:
        gt = [open_sequence(p).ground_truth() for p in (path_a, path_b) if p is not None]
    except (DatasetFormatError, OSError):
        return False
    if len(gt) != 2 or gt[0] is None or gt[1] is None:
        return False
    a, b = gt[0].T_cam_obj, gt[1].T_cam_obj
    return bool(a.shape == b.shape and np.allclose(a, b, atol=1e-9))


def check_same_data(a: ComparedRun, b: ComparedRun) -> list[str]:
    """Checks that two runs tracked the same sequences; returns notes on what differs without
    making the comparison meaningless (another fault configuration or seed).

    Raises:
        ConfigError: other sequences, or sequences of another length, object or content.
    """
    where = f"runs {str(a.folder)!r} and {str(b.folder)!r}"
    if set(a.sequences) != set(b.sequences):
        raise ConfigError(
            f"{where} ran on different data: sequences {sorted(a.sequences)} and "
            f"{sorted(b.sequences)}; compare two runs of the same dataset"
        )
    for name, sa in a.sequences.items():
        sb = b.sequences[name]
        for field_name in ("frames", "object", "fps"):
            if sa.get(field_name) != sb.get(field_name):
                raise ConfigError(
                    f"{where} ran on different data: sequence {name!r} has {field_name} "
                    f"{sa.get(field_name)!r} and {sb.get(field_name)!r}"
                )
        same_path = sa.get("path") is not None and sa.get("path") == sb.get("path")
        if not same_path and not _same_ground_truth(sa.get("path"), sb.get("path")):
            raise ConfigError(
                f"{where} ran on different data: sequence {name!r} comes from "
                f"{sa.get('path')!r} and {sb.get('path')!r}, whose ground truth differs (or "
                "cannot be read); compare two runs of the same dataset"
            )
    notes = []
    if (a.faults, a.seed) != (b.faults, b.seed):
        notes.append(
            f"the runs differ in faults or seed ({a.faults!r} seed {a.seed} vs {b.faults!r} seed "
            f"{b.seed}): their detections arrived differently, so a difference mixes the "
            "trackers with the fault draws"
        )
    return notes


@dataclass(frozen=True, slots=True, kw_only=True)
class _Paired:
    """The frames both runs scored, sequences end to end."""

    names: tuple[str, ...]
    lengths: tuple[int, ...]
    frame: Index
    """(N,) frame index within its sequence."""
    a: dict[str, F64]
    """Per-frame series of A: ``add_m``, ``t_cm``, ``a_deg``, ``v_cmps``, ``w_dps``."""
    b: dict[str, F64]
    since_arrival: F64
    """(N,) frames since the last pose arrival of run A (inf before the first)."""
    fast: NDArray[np.bool_] | None
    """(N,) ground-truth speed in the sequence's top quarter; None without ground truth."""


def _series(m: SequenceMetrics, rows: NDArray[np.intp]) -> dict[str, F64]:
    return {
        "add_m": m.add_m[rows],
        "t_cm": m.t_err_norm_cm[rows],
        "a_deg": m.a_err_deg[rows],
        "v_cmps": np.linalg.norm(m.v_err_cmps[rows], axis=1),
        "w_dps": np.linalg.norm(m.w_err_dps[rows], axis=1),
    }


def _fast_frames(record: dict[str, Any], frames: Index) -> NDArray[np.bool_] | None:
    """Top-quarter ground-truth speed (linear or angular) at ``frames``, or None."""
    from roft_sim.datasets import open_sequence

    path = record.get("path")
    try:
        gt = None if path is None else open_sequence(path).ground_truth()
    except (DatasetFormatError, OSError):
        return None
    if gt is None:
        return None
    fast = np.zeros(len(gt), dtype=bool)
    for speed in (np.linalg.norm(gt.v_obj_mps, axis=1), np.linalg.norm(gt.w_radps, axis=1)):
        fast |= speed > np.quantile(speed, FAST_QUANTILE)
    out: NDArray[np.bool_] = fast[frames]
    return out


def _since(arrivals: Index, frames: Index) -> F64:
    pos = np.searchsorted(arrivals, frames, side="right") - 1
    last = np.where(pos >= 0, arrivals[np.maximum(pos, 0)], -1)
    since: F64 = np.where(pos >= 0, frames - last, np.inf).astype(np.float64)
    return since


def _pair(a: ComparedRun, b: ComparedRun) -> _Paired:
    names, lengths, frames, since, fast_parts = [], [], [], [], []
    sa: dict[str, list[F64]] = {}
    sb: dict[str, list[F64]] = {}
    for name in sorted(a.sequences):
        ma, mb = a.metrics[name], b.metrics[name]
        common, ia, ib = np.intersect1d(ma.frame_index, mb.frame_index, return_indices=True)
        if common.size == 0:
            continue
        names.append(name)
        lengths.append(int(common.size))
        frames.append(common)
        since.append(_since(a.arrivals[name], common))
        fast_parts.append(_fast_frames(a.sequences[name], common))
        for target, m, rows in ((sa, ma, ia), (sb, mb, ib)):
            for key, values in _series(m, rows).items():
                target.setdefault(key, []).append(values)
    if not names:
        raise ConfigError(f"runs {str(a.folder)!r} and {str(b.folder)!r} share no scored frame")
    known = [f for f in fast_parts if f is not None]
    fast: NDArray[np.bool_] | None = (
        np.concatenate(known) if len(known) == len(fast_parts) else None
    )
    return _Paired(
        names=tuple(names),
        lengths=tuple(lengths),
        frame=np.concatenate(frames),
        a={k: np.concatenate(v) for k, v in sa.items()},
        b={k: np.concatenate(v) for k, v in sb.items()},
        since_arrival=np.concatenate(since),
        fast=fast,
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class MetricDifference:
    """One metric of A and B on the paired frames, and A - B with its interval."""

    metric: str
    name: str
    unit: str
    a: float
    b: float
    difference: Interval
    verdict: str
    """A relative to B: better / worse / no detectable difference."""
    block: int
    """Block length [frames] of its bootstrap."""


@dataclass(frozen=True, slots=True, kw_only=True)
class WhereRow:
    """One row of the concentration table: frames of a kind, and the error differences there."""

    category: str
    definition: str
    frames: int
    share: float
    """Fraction of the paired frames."""
    t_cm: Interval
    """Mean position-error difference A - B on these frames [cm]."""
    t_share: float
    """Share of the summed position-error difference over all frames."""
    a_deg: Interval
    """Mean rotation-error difference A - B [deg]."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CompareResult:
    """What :func:`compare_runs` found."""

    run_a: ComparedRun
    run_b: ComparedRun
    frames: int
    """Paired frames."""
    pose_period: int | None
    """Median interval between pose arrivals [frames]; None with fewer than 2 arrivals."""
    metrics: list[MetricDifference]
    where: list[WhereRow]
    plots: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def _statistic(metric: str, paired: _Paired) -> tuple[Callable[[Index], F64], F64]:
    """The vectorised A - B statistic of ``metric`` on resampled frames, and the per-frame
    series its block length is chosen on."""
    if metric == "add_auc_pct":
        a, b = paired.a["add_m"], paired.b["add_m"]

        def auc(index: Index) -> F64:
            diff: F64 = add_auc_rows(a[index]) - add_auc_rows(b[index])
            return diff

        def score(d: F64) -> F64:
            ok = np.isfinite(d) & (d <= DEFAULT_MAX_THRESHOLD_M)
            return np.where(ok, 1.0 - d / DEFAULT_MAX_THRESHOLD_M, 0.0)

        return auc, score(a) - score(b)
    key = {"rmse_t_cm": "t_cm", "rmse_a_deg": "a_deg", "rmse_v_cmps": "v_cmps"}.get(metric, "w_dps")
    ea, eb = paired.a[key], paired.b[key]

    def rmse(index: Index) -> F64:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # a resample with no finite frame
            diff: F64 = np.sqrt(np.nanmean(ea[index] ** 2, axis=1)) - np.sqrt(
                np.nanmean(eb[index] ** 2, axis=1)
            )
        return diff

    return rmse, ea**2 - eb**2


def _block_length(series: F64, paired: _Paired, period: int | None) -> int:
    """The largest Politis-White length over the sequences, at least one pose period."""
    edges = np.cumsum((0, *paired.lengths))
    lengths = [
        politis_white_block_length(series[lo:hi])
        for lo, hi in zip(edges[:-1], edges[1:], strict=True)
    ]
    return max([*lengths, period or 1])


def _metric_rows(
    paired: _Paired, period: int | None, rng: np.random.Generator, n_resamples: int
) -> list[MetricDifference]:
    rows = []
    for metric, name, unit in COMPARE_METRICS:
        statistic, series = _statistic(metric, paired)
        block = _block_length(series, paired, period)
        interval = block_bootstrap_interval(
            statistic, paired.lengths, block, rng=rng, n_resamples=n_resamples
        )
        everything = np.arange(sum(paired.lengths), dtype=np.int64)[None, :]
        a_value = _own_value(metric, paired.a, everything)
        rows.append(
            MetricDifference(
                metric=metric,
                name=name,
                unit=unit,
                a=a_value,
                b=a_value - interval.estimate,
                difference=interval,
                verdict=verdict_word(interval, METRIC_DIRECTIONS[metric]),
                block=block,
            )
        )
    return rows


def _own_value(metric: str, series: dict[str, F64], index: Index) -> float:
    if metric == "add_auc_pct":
        return float(add_auc_rows(series["add_m"][index])[0])
    key = {"rmse_t_cm": "t_cm", "rmse_a_deg": "a_deg", "rmse_v_cmps": "v_cmps"}.get(metric, "w_dps")
    x = series[key][np.isfinite(series[key])]
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan


def _categories(paired: _Paired, period: int | None) -> list[tuple[str, str, NDArray[np.bool_]]]:
    n = paired.frame.size
    out = [("all frames", "every paired frame", np.ones(n, dtype=bool))]
    if period is not None:
        s, half, late = paired.since_arrival, period / 2.0, 1.5 * period
        out += [
            (
                "after a pose arrival",
                f"0-{math.ceil(half) - 1} frames after an arrival (first half of the "
                f"{period}-frame pose period)",
                s < half,
            ),
            (
                "rest of the pose period",
                f"{math.ceil(half)}-{int(late)} frames after",
                (s >= half) & (s <= late),
            ),
            (
                "no-detection stretch",
                f"no pose for more than {late:g} frames, or none yet",
                s > late,
            ),
        ]
    if paired.fast is not None:
        out.append(
            (
                "fast motion",
                f"ground-truth linear or angular speed above its {FAST_QUANTILE:.0%} quantile",
                paired.fast,
            )
        )
    return out


def _masked_mean(d: F64, mask: NDArray[np.bool_]) -> Callable[[Index], F64]:
    """The statistic "mean of ``d`` over the frames in ``mask``" on resampled frames (B, N)."""

    def statistic(index: Index) -> F64:
        w = mask[index] & np.isfinite(d[index])
        with np.errstate(invalid="ignore", divide="ignore"):
            mean: F64 = np.where(w, d[index], 0.0).sum(axis=1) / w.sum(axis=1)
        return mean

    return statistic


def _where_rows(
    paired: _Paired, period: int | None, rng: np.random.Generator, n_resamples: int
) -> list[WhereRow]:
    d_t = paired.a["t_cm"] - paired.b["t_cm"]
    d_a = paired.a["a_deg"] - paired.b["a_deg"]
    block = _block_length(d_t, paired, period)
    total = float(np.nansum(d_t))
    rows = []
    for category, definition, mask in _categories(paired, period):
        t = block_bootstrap_interval(
            _masked_mean(d_t, mask), paired.lengths, block, rng=rng, n_resamples=n_resamples
        )
        a = block_bootstrap_interval(
            _masked_mean(d_a, mask), paired.lengths, block, rng=rng, n_resamples=n_resamples
        )
        rows.append(
            WhereRow(
                category=category,
                definition=definition,
                frames=int(mask.sum()),
                share=float(mask.mean()),
                t_cm=t,
                t_share=float(np.nansum(d_t[mask])) / total if total else math.nan,
                a_deg=a,
            )
        )
    return rows


def _pose_period(arrivals: Sequence[Index]) -> int | None:
    gaps = np.concatenate([np.diff(a) for a in arrivals if a.size > 1] or [np.zeros(0)])
    gaps = gaps[gaps > 0]
    return int(round(float(np.median(gaps)))) if gaps.size else None


def compare_runs(
    run_a: str | Path,
    run_b: str | Path,
    out_dir: str | Path | None = None,
    *,
    seed: int = 0,
    n_resamples: int = 2000,
) -> CompareResult:
    """Compares two runs on the same data frame by frame (module docstring); with ``out_dir``,
    writes one plot per sequence of the per-frame error difference with the pose arrivals.

    Raises:
        ConfigError: not run folders, or runs on different data.
    """
    a, b = load_compared_run(run_a), load_compared_run(run_b)
    notes = check_same_data(a, b)
    if any(not np.array_equal(a.arrivals[n], b.arrivals[n]) for n in a.sequences):
        notes.append(f"the pose arrivals differ between the runs; the table uses {a.tracker}'s")
    paired = _pair(a, b)
    period = _pose_period([a.arrivals[n] for n in paired.names])
    rng = np.random.default_rng(seed)
    result = CompareResult(
        run_a=a,
        run_b=b,
        frames=int(paired.frame.size),
        pose_period=period,
        metrics=_metric_rows(paired, period, rng, n_resamples),
        where=_where_rows(paired, period, rng, n_resamples),
        notes=notes,
    )
    if out_dir is not None:
        result.plots.extend(_plot_differences(a, b, paired, Path(out_dir)))
    return result


def _plot_differences(a: ComparedRun, b: ComparedRun, paired: _Paired, out: Path) -> list[Path]:
    """One figure per sequence: the position and rotation error differences A - B per frame,
    with run A's pose arrivals as dashed lines."""
    from roft_sim.report.plotting import Panel, Series, line_figure, save_figure

    written = []
    edges = np.cumsum((0, *paired.lengths))
    for name, lo, hi in zip(paired.names, edges[:-1], edges[1:], strict=True):
        x = paired.frame[lo:hi]
        panels = []
        for key, title, unit in (
            ("t_cm", "position error", "cm"),
            ("a_deg", "rotation error", "deg"),
        ):
            d = paired.a[key][lo:hi] - paired.b[key][lo:hi]
            series = (
                Series(x=x, y=d, label=f"{a.tracker} - {b.tracker}"),
                Series(x=x, y=np.zeros(x.size), label=None),
            )
            panels.append(
                Panel(title=f"{title} difference", y_label=f"{title} A - B [{unit}]", series=series)
            )
        figure = line_figure(
            panels,
            x_label="frame",
            title=f"{name}: {a.tracker} - {b.tracker} (below 0: {a.tracker} better)",
            columns=1,
            integer_x=True,
            events_x=a.arrivals[name],
            panel_in=(9.0, 2.6),
        )
        written.append(save_figure(figure, out / f"difference_{name}.png"))
    return written


def format_compare(result: CompareResult) -> str:
    """The comparison as Markdown: the metrics with their intervals, then where the error
    differences concentrate."""
    from roft_sim.report.tables import Column, markdown_table

    a, b = result.run_a, result.run_b
    period = "none" if result.pose_period is None else f"{result.pose_period} frames"
    md = [
        f"# {a.tracker} (A, {a.folder}) vs {b.tracker} (B, {b.folder})",
        "",
        f"{result.frames} frames scored by both runs ({len(a.sequences)} "
        f"sequence{'' if len(a.sequences) == 1 else 's'}); pose "
        f"period {period}. Intervals: 95 %, {BLOCK_METHOD}; blocks never shorter than the pose "
        "period (docs/statistics.md).",
        *(f"Note: {n}" for n in result.notes),
        "",
    ]
    rows = [
        {
            "metric": f"{m.name} [{m.unit}]",
            "a": m.a,
            "b": m.b,
            "diff": m.difference.text("+.2f"),
            "verdict": f"A {m.verdict}" if m.verdict != "no detectable difference" else m.verdict,
            "block": m.block,
        }
        for m in result.metrics
    ]
    columns = [
        Column("metric", "metric", align="left"),
        Column("a", f"A: {a.tracker}", ".2f"),
        Column("b", f"B: {b.tracker}", ".2f"),
        Column("diff", "A - B [95 % CI]"),
        Column("verdict", "verdict", align="left"),
        Column("block", "block [frames]", "d"),
    ]
    md += [markdown_table(columns, rows), "## Where the difference is", ""]
    where = [
        {
            "category": w.category,
            "definition": w.definition,
            "frames": w.frames,
            "share": 100.0 * w.share,
            "t": w.t_cm.text("+.2f"),
            "t_share": None if not math.isfinite(w.t_share) else 100.0 * w.t_share + 0.0,
            "a": w.a_deg.text("+.2f"),
        }
        for w in result.where
    ]
    columns = [
        Column("category", "frames of this kind", align="left"),
        Column("definition", "definition", align="left"),
        Column("frames", "frames", "d"),
        Column("share", "% of frames", ".0f"),
        Column("t", "position error A - B [cm] (mean [95 % CI])"),
        Column("t_share", "% of the summed position difference", ".0f"),
        Column("a", "rotation error A - B [deg]"),
    ]
    md += [markdown_table(columns, where)]
    md += [f"![{p.stem}]({p.name})\n" for p in result.plots]
    return "\n".join(md) + "\n"
