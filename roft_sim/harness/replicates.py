"""Replicates of a grid (sweep, stress benchmark, paper run): the cells that differ only in the
sequence and the seed, kept apart so that every summary can give a mean with its confidence
interval and every comparison of two trackers can be paired cell by cell.

A replicate is one cell's metric scalars (its ``metrics.json`` entry). Two trackers are paired
on the cells they share a key with (sequence, seed and, where it varies, the flow source: the
same sequence under the same fault draw). The statistics are in
:mod:`roft_sim.metrics.statistics`; docs/statistics.md explains them.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Hashable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from roft_sim.metrics import SequenceMetrics
from roft_sim.metrics.statistics import (
    METRIC_DIRECTIONS,
    METRIC_RANGES,
    Interval,
    PairedComparison,
    mean_interval,
    paired_comparison,
)

__all__ = [
    "REPLICATE_METRICS",
    "replicate_scalars",
    "distinct_replicates",
    "stable_rng",
    "replicate_intervals",
    "interval_fields",
    "PairedSet",
    "paired_set",
]

REPLICATE_METRICS: tuple[str, ...] = (
    "add_auc_pct",
    "rmse_t_cm",
    "rmse_a_deg",
    "rmse_v_cmps",
    "rmse_w_dps",
)
"""The metrics summarised over replicates (keys of ``metrics.json`` entries)."""


def replicate_scalars(metrics: SequenceMetrics | Mapping[str, Any]) -> dict[str, float]:
    """The :data:`REPLICATE_METRICS` of one cell as floats (NaN where the cell has none)."""
    summary = metrics.summary() if isinstance(metrics, SequenceMetrics) else metrics
    out = {}
    for key in REPLICATE_METRICS:
        value = summary.get(key)
        out[key] = math.nan if value is None else float(value)
    return out


def _fingerprint(*scalars: Mapping[str, float]) -> tuple[float | None, ...]:
    """The metric values of ``scalars``, NaN and missing as None (so that equal cells match)."""
    values = (s.get(m, math.nan) for s in scalars for m in REPLICATE_METRICS)
    return tuple(None if math.isnan(v) else float(v) for v in values)


def _distinct_keys(
    keys: Sequence[Any], mark: Callable[[Any], tuple[float | None, ...]]
) -> list[Any]:
    """``keys`` (``(sequence, ..., seed)``: the seed last) with each group of keys that differ
    only in the seed and all have the same ``mark`` reduced to its first key."""
    groups: dict[Hashable, list[Any]] = {}
    for key in keys:
        groups.setdefault(tuple(key[:-1]), []).append(key)
    out = []
    for members in groups.values():
        same = len({mark(k) for k in members}) == 1
        out += members[:1] if same else members
    return out


def distinct_replicates(
    keyed: Mapping[Any, Mapping[str, float]],
) -> dict[Any, Mapping[str, float]]:
    """``keyed`` (cell key ``(sequence, ..., seed)``, the seed last -> scalars) with the cells
    of a sequence (and flow, ...) that differ only in the seed counted once when they all have
    the same scalars: when no seed changed anything (deterministic faults, flow and tracker) the
    seeds are no replicates, and counting them would narrow the interval. Where the seeds
    differ at all, every cell counts, coincident ones included (they are draws of the law)."""
    keys = _distinct_keys(list(keyed), lambda k: _fingerprint(keyed[k]))
    return {k: keyed[k] for k in keys}


def stable_rng(key: Hashable) -> np.random.Generator:
    """A generator seeded from ``repr(key)`` (CRC-32), so that a group's interval does not
    depend on which other groups a summary holds or their order."""
    return np.random.default_rng(zlib.crc32(repr(key).encode("utf-8")))


def replicate_intervals(
    replicates: Sequence[Mapping[str, float]],
    key: Hashable,
    metrics: Sequence[str] = REPLICATE_METRICS,
) -> dict[str, Interval]:
    """Per metric, the mean over ``replicates`` with its interval, cut to the metric's range
    (rng from ``key``)."""
    rng = stable_rng(key)
    unbounded = (-math.inf, math.inf)
    return {
        m: mean_interval(
            [r.get(m, math.nan) for r in replicates],
            rng=rng,
            bounds=METRIC_RANGES.get(m, unbounded),
        )
        for m in metrics
    }


def interval_fields(intervals: Mapping[str, Interval], fmt: str = ".2f") -> dict[str, Any]:
    """Table fields of the intervals: ``<metric>_mean``, ``_lo``, ``_hi`` (numbers; None when
    missing) and ``<metric>_ci`` (text, ``"12.30 [11.02, 13.51]"``)."""

    def num(x: float) -> float | None:
        return x if math.isfinite(x) else None

    out: dict[str, Any] = {}
    for metric, interval in intervals.items():
        out[f"{metric}_mean"] = num(interval.estimate)
        out[f"{metric}_lo"] = num(interval.low)
        out[f"{metric}_hi"] = num(interval.high)
        out[f"{metric}_ci"] = interval.text(fmt)
    return out


@dataclass(frozen=True, slots=True, kw_only=True)
class PairedSet:
    """Tracker A against tracker B on the cells they share."""

    a: str
    """Label of A."""
    b: str
    """Label of B."""
    pairs: int
    """Cells paired."""
    comparisons: dict[str, PairedComparison]
    """Per metric, A - B (:func:`~roft_sim.metrics.statistics.paired_comparison`)."""


def paired_set(
    a_label: str,
    b_label: str,
    a: Mapping[Any, Mapping[str, float]],
    b: Mapping[Any, Mapping[str, float]],
    key: Hashable,
    metrics: Sequence[str] = REPLICATE_METRICS,
) -> PairedSet:
    """Pairs the replicates of A and B by their cell keys ``(sequence, ..., seed)`` and
    compares each metric (rng from ``key``); cells that only one of them has are left out, and
    a sequence whose pairs are all alike counts once (see :func:`distinct_replicates`)."""
    shared = _distinct_keys([k for k in a if k in b], lambda k: _fingerprint(a[k], b[k]))
    rng = stable_rng(key)
    comparisons = {
        m: paired_comparison(
            [a[k].get(m, math.nan) for k in shared],
            [b[k].get(m, math.nan) for k in shared],
            m,
            rng=rng,
        )
        for m in metrics
        if m in METRIC_DIRECTIONS
    }
    return PairedSet(a=a_label, b=b_label, pairs=len(shared), comparisons=comparisons)
