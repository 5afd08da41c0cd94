"""``roft-sim paper --seeds N``: every row over N fault and detector seeds, with intervals.

Seeds ``s0 .. s0 + N - 1`` (``s0`` = ``--seed``) are run seeds (fault stream, tracker, flow
noise); the first keeps the dataset's stored detector draw, so ``--seeds 1`` is the plain run,
and each further seed ``s`` feeds rows that read the detector's poses a fresh draw
``redraw:<s>`` (:mod:`roft_sim.harness.pose_sets`): under the ``paper`` preset, whose rate
and delay are fixed, the detector draw is what varies.

Per row, per object and ALL, the metric of each seed (its frames pooled as in the tables) gives
a mean over the seeds with its 95 % interval
(:func:`~roft_sim.metrics.statistics.mean_interval`); Kendall's tau of the Table IV order gets
a percentile bootstrap interval over the seeds. A difference from the paper lies inside the
noise when the paper's number is inside the interval; the paper's own run-to-run noise is not
known and not counted, so this is the least noise there is. docs/statistics.md.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from roft_sim.harness.pose_sets import redraw_set
from roft_sim.harness.replicates import stable_rng
from roft_sim.metrics.statistics import (
    INTERVAL_METHOD,
    METRIC_RANGES,
    bootstrap_percentile_interval,
    mean_interval,
)
from roft_sim.report.paper_reference import ALL, PaperTables
from roft_sim.report.tables import Column, markdown_table

__all__ = [
    "paper_seeds",
    "seed_poses",
    "PaperLayout",
    "noise_tables",
    "tau_intervals",
    "uncertainty_markdown",
    "uncertainty_json",
]

RowMetrics = dict[str, dict[str, float | None]]
BySeed = dict[int, dict[str, RowMetrics]]
OrderFunction = Callable[..., Any]
"""``table4_order(results, paper, *, configuration=...)`` of :mod:`roft_sim.harness.paper`."""


@dataclass(frozen=True)
class PaperLayout:
    """What the paper run's tables are made of, handed in by :mod:`roft_sim.harness.paper`
    (which imports this module, not the other way round)."""

    side_by_side: Sequence[tuple[str, str, str]]
    """The rows shown next to the paper's: ``(paper method, row key, label)``."""
    table4_order: OrderFunction
    """The Table IV order of a configuration's rows (with Kendall's tau)."""


"""Seed -> row key -> entry (object or ALL) -> metric -> value."""

_METRICS = (
    ("add_auc_pct", "ADD-AUC (%)"),
    ("rmse_t_cm", "RMSE e_t (cm)"),
    ("rmse_a_deg", "RMSE e_a (deg)"),
)


def paper_seeds(seed: int, count: int) -> tuple[int, ...]:
    """The run seeds of ``--seed seed --seeds count``."""
    return tuple(range(seed, seed + count))


def seed_poses(row_poses: str, seed: int, first_seed: int) -> str:
    """The pose set of a row under ``seed``: a fresh detector draw for rows that read the
    detector (``auto``) under every seed but the first; otherwise the row's own."""
    return redraw_set(seed) if row_poses == "auto" and seed != first_seed else row_poses


def _values(by_seed: BySeed, row: str, entry: str, metric: str) -> list[float]:
    out = []
    for results in by_seed.values():
        value = results.get(row, {}).get(entry, {}).get(metric)
        out.append(math.nan if value is None else float(value))
    return out


def noise_tables(
    by_seed: BySeed, paper: PaperTables, entries: Sequence[str], layout: PaperLayout
) -> dict[str, tuple[list[Column], list[dict[str, Any]]]]:
    """Per Table I metric, per object and ALL, for DOPE and ROFT (reference config, our
    default): the paper's number, the simulated mean over the seeds with its interval, sim -
    paper, and whether the paper's number lies inside the interval."""
    run = {k for results in by_seed.values() for k in results}
    present = [(m, k, label) for m, k, label in layout.side_by_side if k in run]
    out = {}
    for metric, title in _METRICS:
        columns = [Column("entry", "object", align="left")]
        for _, key, label in present:
            columns += [
                Column(f"{key}:paper", f"{label}: paper", ".2f"),
                Column(f"{key}:sim", "sim mean [95 % CI]"),
                Column(f"{key}:diff", "sim - paper", "+.2f"),
                Column(f"{key}:noise", "inside the noise"),
            ]
        rows = []
        for entry in entries:
            row: dict[str, Any] = {"entry": entry}
            for method, key, _ in present:
                ref = paper.table1[method][metric].get(entry)
                sim = mean_interval(
                    _values(by_seed, key, entry, metric),
                    rng=stable_rng((key, entry, metric)),
                    bounds=METRIC_RANGES[metric],
                )
                row[f"{key}:paper"] = ref
                row[f"{key}:sim"] = sim.text(".2f")
                for part, value in (("mean", sim.estimate), ("lo", sim.low), ("hi", sim.high)):
                    row[f"{key}:sim_{part}"] = value if math.isfinite(value) else None
                row[f"{key}:diff"] = None if ref is None else sim.estimate - ref
                row[f"{key}:inside"] = (
                    None if ref is None or not sim.has_interval else not (sim.excludes(ref))
                )
                row[f"{key}:noise"] = {True: "yes", False: "no", None: "-"}[row[f"{key}:inside"]]
            rows.append(row)
        out[title] = (columns, rows)
    return out


def tau_intervals(
    by_seed: BySeed, paper: PaperTables, configurations: Sequence[str], layout: PaperLayout
) -> list[dict[str, Any]]:
    """Per configuration and metric, Kendall's tau of the Table IV order on the mean over the
    seeds, with its percentile bootstrap interval over the seeds."""
    table4_order = layout.table4_order

    seeds = list(by_seed)
    rows = sorted({k for results in by_seed.values() for k in results})

    def tau(configuration: str, metric: str, index: Any) -> float:
        chosen = [seeds[int(i)] for i in index]
        mean: dict[str, RowMetrics] = {}
        for row in rows:
            values = [by_seed[s].get(row, {}).get(ALL, {}).get(metric) for s in chosen]
            known = [float(v) for v in values if v is not None]
            if known:
                mean[row] = {ALL: {metric: float(np.mean(known))}}
        order = next(
            o for o in table4_order(mean, paper, configuration=configuration) if o.metric == metric
        )
        return math.nan if order.kendall_tau is None else float(order.kendall_tau)

    out = []
    for configuration in configurations:
        for metric, _ in _METRICS:
            interval = bootstrap_percentile_interval(
                functools.partial(tau, configuration, metric),
                len(seeds),
                rng=stable_rng(("tau", configuration, metric)),
            )
            out.append({"configuration": configuration, "metric": metric, "tau": interval})
    return out


def _inside_sentences(tables: dict[str, tuple[list[Column], list[dict[str, Any]]]]) -> list[str]:
    """One line per side-by-side row and metric: the entries inside and outside the noise."""
    lines = []
    for title, (columns, rows) in tables.items():
        keys = [c.key.removesuffix(":paper") for c in columns if c.key.endswith(":paper")]
        labels = {c.key.removesuffix(":paper"): c.header.removesuffix(": paper") for c in columns}
        for key in keys:
            inside = [r["entry"] for r in rows if r.get(f"{key}:inside") is True]
            outside = [
                f"{r['entry']} ({r[f'{key}:diff']:+.2f})"
                for r in rows
                if r.get(f"{key}:inside") is False
            ]
            lines.append(
                f"- {labels[key]}, {title}: inside the noise: {', '.join(inside) or 'none'}; "
                f"outside: {', '.join(outside) or 'none'}"
            )
    return lines


def uncertainty_markdown(
    by_seed: BySeed,
    paper: PaperTables,
    entries: Sequence[str],
    configurations: Sequence[str],
    layout: PaperLayout,
) -> list[str]:
    """The ``tables.md`` section of a run over several seeds (module docstring)."""
    seeds = list(by_seed)
    tables = noise_tables(by_seed, paper, entries, layout)
    md = [
        f"## Over {len(seeds)} seeds: which differences from the paper are inside the noise",
        "",
        f"Seeds {', '.join(map(str, seeds))}: run seeds (faults, tracker, flow noise) and, after "
        "the first, a fresh draw of the DOPE-like detector for every row that reads it. Each "
        f"number: the mean over the seeds with its 95 % interval ({INTERVAL_METHOD}); the "
        "tables above pool the frames of every seed. A difference from the paper is inside the "
        "noise when the paper's number lies in the interval (the paper's own run-to-run noise "
        "is unknown and not counted).",
        "",
        *_inside_sentences(tables),
        "",
    ]
    for title, (columns, rows) in tables.items():
        md += [f"### {title}", "", markdown_table(columns, rows)]
    md += ["### Kendall tau of the Table IV order, with its interval over the seeds", ""]
    for t in tau_intervals(by_seed, paper, configurations, layout):
        md.append(f"- `{t['configuration']}`, {t['metric']}: tau {t['tau'].text('+.3f')}")
    return [*md, ""]


def uncertainty_json(
    by_seed: BySeed,
    paper: PaperTables,
    entries: Sequence[str],
    configurations: Sequence[str],
    layout: PaperLayout,
) -> dict[str, Any]:
    """The same as JSON-ready data for ``paper.json``."""

    return {
        "seeds": list(by_seed),
        "method": INTERVAL_METHOD,
        "by_seed": {str(s): results for s, results in by_seed.items()},
        "noise": {
            title: [
                {k: v for k, v in r.items() if not k.endswith((":noise", ":sim"))} for r in rows
            ]
            for title, (_, rows) in noise_tables(by_seed, paper, entries, layout).items()
        },
        "kendall_tau": [
            {"configuration": t["configuration"], "metric": t["metric"], **t["tau"].json_fields()}
            for t in tau_intervals(by_seed, paper, configurations, layout)
        ],
    }
