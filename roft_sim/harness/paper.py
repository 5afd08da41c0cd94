"""The ROFT paper's Fast-YCB experiments in simulation (``roft-sim paper``).

:func:`run_paper` runs every row of the paper's Tables I, II and IV (:data:`PAPER_ROWS`, plus
every other registered tracker as an extra Table I column) over the six Fast-YCB-like sequences
under the ``paper`` fault preset, as independent resumable cells, and writes the tables side by
side with the published numbers (:mod:`roft_sim.report.paper_reference`), with a check of the
paper's qualitative findings (:func:`check_findings`).

How the reference evaluation is mirrored (docs/paper.md): frames are aligned by index; per object
the sequences of that object are pooled, ``ALL`` pools the frames of every object; frames
before a tracker's first pose are left out and later frames without one hold the last
(``invalid = "hold"``: the reference's treatment of its DOPE row); velocity is scored from
ROFT's velocity filter (its spatial twist, converted with the ground-truth position).
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from roft_sim.config_files import jsonable
from roft_sim.datasets import open_sequence
from roft_sim.datasets.atomic_files import atomic_write_text
from roft_sim.errors import ConfigError
from roft_sim.executors import Executor
from roft_sim.faults import load_faults
from roft_sim.harness.cells import (
    CELLS_DIR,
    SweepCell,
    execute_cells,
    load_cell_metrics,
)
from roft_sim.harness.inputs import check_inputs
from roft_sim.harness.options import PAPER_INVALID, RunOptions
from roft_sim.harness.outputs import write_json
from roft_sim.harness.paper_seeds import (
    PaperLayout,
    paper_seeds,
    seed_poses,
    uncertainty_json,
    uncertainty_markdown,
)
from roft_sim.harness.run_dataset import find_sequences
from roft_sim.metrics import SequenceMetrics, concatenate_metrics, policy_note
from roft_sim.report.paper_reference import ALL, PaperTables, paper_tables
from roft_sim.report.plotting import bar_figure, save_figure
from roft_sim.report.tables import Column, csv_table, latex_table, markdown_table
from roft_sim.trackers import discover_trackers, get_tracker_spec, load_tracker_config

__all__ = [
    "PaperRow",
    "PAPER_ROWS",
    "REFERENCE_ROWS",
    "attribution_table",
    "PAPER_FAULTS",
    "paper_rows",
    "plan_paper",
    "PaperResult",
    "run_paper",
    "paper_metrics",
    "check_findings",
    "checked_configurations",
    "Finding",
    "PerObjectMotion",
    "per_object_motion",
]

PAPER_FAULTS = "paper"
"""The fault preset of every row: 5 fps networks, results 6 frames late, frame 0 undelayed."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PaperRow:
    """One simulated row of the paper's tables."""

    key: str
    """Short id (cell label)."""
    label: str
    """The paper's name of the row (Table IV / Table I / Table II)."""
    tracker: str
    """Registry name of the tracker."""
    ablation: str | None = None
    """ROFT ablation (:data:`roft_sim.trackers.roft.ABLATIONS`), None for other trackers."""
    poses: str = "auto"
    """Pose set (``gt`` for the ground-truth pose rows)."""
    masks: str = "auto"
    """Mask set (``gt`` for the ground-truth segmentation rows, ``none`` for detector rows)."""
    flow: bool = True
    """Whether the tracker gets optical flow."""
    tables: tuple[str, ...] = ("IV",)
    """The tables the row appears in (``attribution``: the deviation attribution table)."""
    paper_label: str | None = None
    """The paper's row to compare with when it is not ``label`` (the reference-config rows)."""
    deviations: int | None = None
    """Apply the first n of :data:`roft_sim.trackers.roft.DEVIATIONS` to the tracker's default
    configuration (the ``roft-reference`` attribution rows); None: none."""


PAPER_ROWS: tuple[PaperRow, ...] = (
    PaperRow(
        key="roft_gt_mask_pose",
        label="ROFT w/ GT segm. and pose",
        tracker="roft",
        ablation="full",
        poses="gt",
        masks="gt",
    ),
    PaperRow(
        key="roft_gt_pose", label="ROFT w/ GT pose", tracker="roft", ablation="full", poses="gt"
    ),
    PaperRow(
        key="roft_gt_mask", label="ROFT w/ GT segm.", tracker="roft", ablation="full", masks="gt"
    ),
    PaperRow(key="roft", label="ROFT", tracker="roft", ablation="full", tables=("I", "II", "IV")),
    PaperRow(
        key="roft_no_pose_sync",
        label="ROFT w/o pose sync.",
        tracker="roft",
        ablation="no_pose_sync",
    ),
    PaperRow(
        key="roft_no_outlier_rejection",
        label="ROFT w/o outlier rej.",
        tracker="roft",
        ablation="no_outlier_rejection",
    ),
    PaperRow(
        key="roft_no_mask_sync",
        label="ROFT w/o segm. sync.",
        tracker="roft",
        ablation="no_mask_sync",
        tables=("II", "IV"),
    ),
    PaperRow(
        key="roft_no_velocity", label="ROFT w/o velocity", tracker="roft", ablation="no_velocity"
    ),
    PaperRow(key="roft_no_pose", label="ROFT w/o pose", tracker="roft", ablation="no_pose"),
    PaperRow(
        key="detector_ideal",
        label="DOPE (ideal)",
        tracker="detector-ideal",
        masks="none",
        flow=False,
    ),
    PaperRow(
        key="detector",
        label="DOPE",
        tracker="detector-hold",
        masks="none",
        flow=False,
        tables=("I", "IV"),
    ),
)
"""The rows of Tables I, II and IV (in Table IV's order)."""


def _configuration_row(configuration: str, default_key: str) -> str:
    """The key of a configuration's row: our default's row key (``roft``, ``roft_gt_pose``,
    ``roft_no_mask_sync``, ...) with ``roft`` replaced by the configuration's plain row key
    (``roft_reference`` -> ``roft_reference_gt_pose``, ...)."""
    return configuration + default_key.removeprefix("roft")


def _reference_rows() -> tuple[PaperRow, ...]:
    """``roft_reference`` and its Table IV ablation rows (tracker ``roft-reference``), then the
    attribution rows: the reference plus the first n deviations, for n = 1 .. N-1 (n = 0 is
    ``roft_reference``, n = N the default, ``roft``)."""
    from roft_sim.trackers.roft import DEVIATIONS

    rows = []
    for r in PAPER_ROWS:
        if r.tracker != "roft":
            continue
        key = _configuration_row("roft_reference", r.key)
        tables = tuple(t for t in r.tables if t in ("I", "II", "IV"))
        label = r.label.replace("ROFT", "ROFT (reference config)", 1)
        rows.append(
            dataclasses.replace(
                r,
                key=key,
                label=label,
                tracker="roft-reference",
                tables=tables,
                paper_label=r.label,
            )
        )
    for n in range(1, len(DEVIATIONS)):
        rows.append(
            PaperRow(
                key=f"attr_{n:02d}_{DEVIATIONS[n - 1].name}",
                label=f"+ {DEVIATIONS[n - 1].name}",
                tracker="roft-reference",
                ablation="full",
                deviations=n,
                tables=("attribution",),
            )
        )
    return tuple(rows)


REFERENCE_ROWS: tuple[PaperRow, ...] = _reference_rows()
"""The reference-configuration rows and the attribution rows (see :func:`_reference_rows`)."""

_PAPER_TRACKERS = {"roft", "roft-reference", "detector-hold", "detector-ideal"}


def paper_rows(keys: Sequence[str] | None = None, *, plugins: bool = True) -> list[PaperRow]:
    """The rows to run: :data:`PAPER_ROWS` (or those named in ``keys``) and, with ``plugins``,
    one Table I row per other registered tracker (key ``plugin:<name>``).

    Raises:
        ConfigError: an unknown row key (the message lists them).
    """
    rows = list(PAPER_ROWS) + list(REFERENCE_ROWS)
    if plugins:
        for name in sorted(discover_trackers()):
            if name not in _PAPER_TRACKERS:
                rows.append(
                    PaperRow(
                        key=f"plugin:{name}",
                        label=name,
                        tracker=name,
                        masks="auto",
                        tables=("I",),
                    )
                )
    if keys is None:
        return rows
    known = {r.key: r for r in rows}
    unknown = [k for k in keys if k not in known]
    if unknown:
        raise ConfigError(f"unknown paper rows {unknown}; known: {', '.join(known)}")
    return [known[k] for k in keys]


def _tracker_config(row: PaperRow) -> Any:
    spec = get_tracker_spec(row.tracker)
    config = load_tracker_config(spec, None)
    if row.ablation is None:
        return config
    from roft_sim.trackers.roft import ablation_config, apply_deviations

    if row.deviations is not None:
        config = apply_deviations(config, row.deviations)
    return ablation_config(row.ablation, config)


def plan_paper(
    rows: Sequence[PaperRow],
    sequence_paths: Sequence[Path],
    *,
    flow: str,
    seed: int,
    seeds: int = 1,
) -> list[SweepCell]:
    """The cells: every row on every sequence under the ``paper`` faults, for each of the run
    seeds ``seed .. seed + seeds - 1`` (after the first, rows that read the detector get a
    fresh detector draw: :func:`~roft_sim.harness.paper_seeds.seed_poses`).

    Raises:
        ConfigError: a bad seed or flow spec, or a sequence that cannot feed a row's inputs.
    """

    faults = load_faults(PAPER_FAULTS)
    sequences = [(str(Path(p).resolve()), open_sequence(p)) for p in sequence_paths]
    run_seeds = paper_seeds(seed, seeds)
    cells = []
    for row in rows:
        config = _tracker_config(row)
        for (path, seq), s in itertools.product(sequences, run_seeds):
            options = RunOptions(
                tracker=row.tracker,
                tracker_config=config,
                faults=faults,
                flow=flow if row.flow else "none",
                poses=seed_poses(row.poses, s, run_seeds[0]),
                masks=row.masks,
                seed=s,
                include_rgb=False,
                invalid=PAPER_INVALID,
            )
            check_inputs(seq, options)
            cells.append(
                SweepCell.create(
                    label=row.key,
                    fault_label=PAPER_FAULTS,
                    parameter=None,
                    value=None,
                    sequence_path=path,
                    sequence_name=seq.name,
                    options=options,
                )
            )
    return cells


# ------------------------------------------------------------------------------- metrics
RowMetrics = dict[str, dict[str, float | None]]
"""Entry (object name or ALL) -> metric -> value."""

_KEYS = ("add_auc_pct", "rmse_t_cm", "rmse_a_deg", "rmse_v_cmps", "rmse_w_dps", "frames")


def paper_metrics(
    cells: Sequence[SweepCell], records: dict[str, dict[str, Any]], cells_dir: Path
) -> dict[str, RowMetrics]:
    """Per row key: per object (its sequences pooled) and ALL (every frame pooled)."""
    by_row: dict[str, dict[str, list[SequenceMetrics]]] = {}
    for cell in cells:
        m = load_cell_metrics(cells_dir, cell.cell_id)
        if m is None:
            continue
        obj = records[cell.cell_id].get("object", cell.sequence_name)
        by_row.setdefault(cell.label, {}).setdefault(obj, []).append(m)
    out: dict[str, RowMetrics] = {}
    for key, objects in by_row.items():
        entries = {obj: concatenate_metrics(parts) for obj, parts in sorted(objects.items())}
        entries[ALL] = concatenate_metrics([m for parts in objects.values() for m in parts])
        out[key] = {name: {k: m.summary()[k] for k in _KEYS} for name, m in entries.items()}
    return out


# ------------------------------------------------------------------------------- findings
@dataclass(frozen=True, slots=True, kw_only=True)
class Finding:
    """One of the paper's qualitative findings, checked on the simulated numbers."""

    claim: str
    """What the paper finds."""
    configuration: str = "roft"
    """The key of the plain ROFT row whose Table IV rows were checked (``roft``: our default,
    ``roft_reference``: the reference configuration)."""
    holds: bool | None
    """True / False; None when the rows needed were not run."""
    evidence: str
    """The numbers behind the verdict."""


def _all(results: dict[str, RowMetrics], key: str, metric: str) -> float | None:
    row = results.get(key)
    if row is None or ALL not in row:
        return None
    return row[ALL].get(metric)


def _fmt(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.2f}"


def check_findings(results: dict[str, RowMetrics], *, configuration: str = "roft") -> list[Finding]:
    """The paper's qualitative findings (issue 7's 'done means') against ``results`` (ALL).

    Each finding is a list of comparisons; it holds when all hold, is None when a row it needs
    is missing, and its evidence lists the numbers and the comparisons that fail.

    Args:
        results: per row key, the metrics.
        configuration: the key of the plain ROFT row to check; its Table IV rows are that key
            with the default rows' suffixes (as in :func:`table4_order`): ``roft`` checks our
            default, ``roft_reference`` the reference configuration. The evidence names the
            rows by their keys.
    """
    pose_metrics = ("add_auc_pct", "rmse_t_cm", "rmse_a_deg")
    velocity_metrics = ("rmse_v_cmps", "rmse_w_dps")

    def key(default_key: str) -> str:
        return _configuration_row(configuration, default_key)

    roft, ablation_rows = key("roft"), [key(k) for k in _ABLATION_ROWS]
    gt_rows = [key(k) for k in _GT_ROWS]
    worst_rows = {key("roft_no_velocity"), key("roft_no_pose")}

    def better(a: str, b: str, metric: str) -> tuple[str, bool | None]:
        x, y = _all(results, a, metric), _all(results, b, metric)
        verdict = None if x is None or y is None else (x > y if metric == "add_auc_pct" else x < y)
        return f"{a} better than {b} on {metric}", verdict

    def worst_two(metric: str) -> tuple[str, bool | None]:
        rows = [k for k in ablation_rows if _all(results, k, metric) is not None]
        if not worst_rows <= set(rows) or len(rows) < 3:
            return f"worst two on {metric}", None
        order = sorted(
            rows,
            # rows keeps the keys whose _all is not None
            key=lambda k: _all(results, k, metric),  # type: ignore[arg-type, return-value]
            reverse=metric != "add_auc_pct",
        )
        worst = set(order[:2])
        return f"worst two on {metric} are {sorted(worst)}", worst == worst_rows

    def finding(
        claim: str,
        checks: list[tuple[str, bool | None]],
        keys: Sequence[str],
        metrics: Sequence[str],
    ) -> Finding:
        verdicts = [v for _, v in checks]
        holds = None if None in verdicts else all(verdicts)
        numbers = "; ".join(
            f"{k}: " + ", ".join(f"{m} {_fmt(_all(results, k, m))}" for m in metrics) for k in keys
        )
        failed = [text for text, v in checks if v is False]
        evidence = numbers + (f". Fails: {'; '.join(failed)}" if failed else "")
        return Finding(claim=claim, configuration=configuration, holds=holds, evidence=evidence)

    present = [k for k in ablation_rows if k in results]
    no_mask_sync, no_pose_sync = key("roft_no_mask_sync"), key("roft_no_pose_sync")
    return [
        finding(
            "ROFT beats the 5 fps detector (DOPE) on ADD-AUC, e_t and e_a",
            [better(roft, "detector", m) for m in pose_metrics],
            [roft, "detector"],
            pose_metrics,
        ),
        finding(
            "in the ablation, removing velocity or pose is worst (the two worst rows on ADD-AUC, "
            "e_t and e_a)",
            [worst_two(m) for m in pose_metrics],
            present,
            pose_metrics,
        ),
        finding(
            "removing mask sync hurts clearly (worse ADD-AUC, e_t, e_a, e_v and e_w)",
            [better(roft, no_mask_sync, m) for m in (*pose_metrics, *velocity_metrics)],
            [roft, no_mask_sync],
            (*pose_metrics, *velocity_metrics),
        ),
        finding(
            "removing pose sync raises the angular error e_a",
            [better(roft, no_pose_sync, "rmse_a_deg")],
            [roft, no_pose_sync],
            ("rmse_a_deg",),
        ),
        finding(
            "with ground-truth inputs ROFT gets better (each GT row beats ROFT on ADD-AUC, e_t "
            "and e_a)",
            [better(k, roft, m) for k in gt_rows for m in pose_metrics],
            [roft, *gt_rows],
            pose_metrics,
        ),
    ]


def checked_configurations(results: dict[str, RowMetrics]) -> list[str]:
    """The configurations whose findings and Table IV order a run reports: our default
    (``roft``) always, the reference configuration (``roft_reference``) when any of its Table IV
    rows ran."""
    reference = [r.key for r in REFERENCE_ROWS if r.paper_label is not None]
    return ["roft", *(["roft_reference"] if any(k in results for k in reference) else [])]


_GT_ROWS = ("roft_gt_mask_pose", "roft_gt_pose", "roft_gt_mask")
"""The ROFT rows of Table IV fed ground-truth inputs."""
_ABLATION_ROWS = (
    "roft",
    "roft_no_pose_sync",
    "roft_no_outlier_rejection",
    "roft_no_mask_sync",
    "roft_no_velocity",
    "roft_no_pose",
)
"""The ROFT rows of Table IV that remove a component."""


# ------------------------------------------------------------------------------- tables
def _table1(
    results: dict[str, RowMetrics], rows: Sequence[PaperRow], paper: PaperTables, entries: list[str]
) -> dict[str, tuple[list[Column], list[dict[str, Any]]]]:
    sim = [r for r in rows if "I" in r.tables and r.key in results]
    out = {}
    for metric, title, fmt in (
        ("add_auc_pct", "ADD-AUC (%)", ".2f"),
        ("rmse_t_cm", "RMSE e_t (cm)", ".2f"),
        ("rmse_a_deg", "RMSE e_a (deg)", ".2f"),
    ):
        columns = [Column("entry", "object", align="left")]
        columns += [Column(f"sim:{r.key}", f"{r.label} (sim)", fmt) for r in sim]
        columns += [Column(f"paper:{name}", f"{name} (paper)", fmt) for name in paper.table1]
        table_rows = []
        for entry in entries:
            row: dict[str, Any] = {"entry": entry}
            for r in sim:
                row[f"sim:{r.key}"] = results[r.key].get(entry, {}).get(metric)
            for name, metrics in paper.table1.items():
                row[f"paper:{name}"] = metrics[metric].get(entry)
            table_rows.append(row)
        out[title] = (columns, table_rows)
    return out


def _table2(
    results: dict[str, RowMetrics], rows: Sequence[PaperRow], paper: PaperTables, entries: list[str]
) -> tuple[list[Column], list[dict[str, Any]]]:
    """Per object and ALL, e_v and e_w of every Table II row that ran (our default's and the
    reference configuration's, with and without mask sync), then the paper's columns."""
    sim = [r for r in rows if "II" in r.tables and r.key in results]
    columns = [Column("entry", "object", align="left")]
    for metric, unit in (("rmse_v_cmps", "e_v cm/s"), ("rmse_w_dps", "e_w deg/s")):
        for r in sim:
            columns.append(Column(f"sim:{r.key}:{metric}", f"{unit} {r.label} (sim)", ".2f"))
        for name in paper.table2:
            columns.append(Column(f"paper:{name}:{metric}", f"{unit} {name} (paper)", ".2f"))
    table_rows = []
    for entry in entries:
        row: dict[str, Any] = {"entry": entry}
        for metric in ("rmse_v_cmps", "rmse_w_dps"):
            for r in sim:
                row[f"sim:{r.key}:{metric}"] = results[r.key].get(entry, {}).get(metric)
            for name, metrics in paper.table2.items():
                row[f"paper:{name}:{metric}"] = metrics[metric].get(entry)
        table_rows.append(row)
    return columns, table_rows


def _table4(
    results: dict[str, RowMetrics], rows: Sequence[PaperRow], paper: PaperTables
) -> tuple[list[Column], list[dict[str, Any]]]:
    columns = [
        Column("variant", "variant", align="left"),
        Column("sim_add", "ADD-AUC % (sim)", ".2f"),
        Column("sim_t", "e_t cm (sim)", ".2f"),
        Column("sim_a", "e_a deg (sim)", ".2f"),
        Column("sim_v", "e_v cm/s (sim)", ".2f"),
        Column("sim_w", "e_w deg/s (sim)", ".2f"),
        Column("paper_add", "ADD-AUC % (paper)", ".2f"),
        Column("paper_t", "e_t cm (paper)", ".1f"),
        Column("paper_a", "e_a deg (paper)", ".3f"),
        Column("frames", "frames (sim)", "d"),
    ]
    table_rows = []
    for r in rows:
        if "IV" not in r.tables:
            continue
        sim = results.get(r.key, {}).get(ALL, {})
        ref = paper.table4.get(r.paper_label or r.label, {})
        table_rows.append(
            {
                "variant": r.label,
                "sim_add": sim.get("add_auc_pct"),
                "sim_t": sim.get("rmse_t_cm"),
                "sim_a": sim.get("rmse_a_deg"),
                "sim_v": sim.get("rmse_v_cmps"),
                "sim_w": sim.get("rmse_w_dps"),
                "paper_add": ref.get("add_auc_pct"),
                "paper_t": ref.get("rmse_t_cm"),
                "paper_a": ref.get("rmse_a_deg"),
                "frames": sim.get("frames"),
            }
        )
    return columns, table_rows


# ------------------------------------------------------------------------------- figures
BarPanel = tuple[str, str, dict[str, list[float | None]]]


def _bar_panel(
    title: str,
    y_label: str,
    columns: Sequence[Column],
    rows: Sequence[dict[str, Any]],
    keys: Sequence[str],
    labels: Sequence[str],
) -> BarPanel:
    """One panel of a table figure: the table columns ``keys`` as bar groups named ``labels``."""
    titles = {c.key: c.header for c in columns}
    groups = {
        label: [row.get(key) for row in rows] for key, label in zip(keys, labels, strict=True)
    }
    missing = [k for k in keys if k not in titles]
    if missing:
        raise ValueError(f"table has no column {missing[0]!r}; its columns: {', '.join(titles)}")
    return title, y_label, groups


def _write_paper_figures(
    out: Path,
    table1: dict[str, tuple[list[Column], list[dict[str, Any]]]],
    table2: tuple[list[Column], list[dict[str, Any]]],
    table4: tuple[list[Column], list[dict[str, Any]]],
) -> list[Path]:
    """``table1.png``, ``table2.png``, ``table4.png``: the tables as grouped bar charts, the
    simulation solid and the paper's published numbers hatched."""
    written = []
    # Table I: one panel per metric, objects on the x axis, one bar per method
    panels1: list[BarPanel] = []
    entries: list[str] = []
    paper_labels: list[str] = []
    for (title, (columns, rows)), y_label in zip(
        table1.items(), ("ADD-AUC [%]", "RMSE e_t [cm]", "RMSE e_a [deg]"), strict=True
    ):
        keys = [c.key for c in columns[1:]]
        labels = [c.header for c in columns[1:]]
        paper_labels = [c.header for c in columns[1:] if c.key.startswith("paper:")]
        entries = [str(r["entry"]) for r in rows]
        panels1.append(_bar_panel(title, y_label, columns, rows, keys, labels))
    figure = bar_figure(
        entries, panels1, title="Table I: pose tracking (simulation vs paper)", hatched=paper_labels
    )
    written.append(save_figure(figure, out / "table1.png"))
    # Table II: e_v and e_w panels, ROFT with and without mask sync, simulation and paper
    columns, rows = table2
    panels2: list[BarPanel] = []
    for metric, y_label in (("rmse_v_cmps", "RMSE e_v [cm/s]"), ("rmse_w_dps", "RMSE e_w [deg/s]")):
        chosen = [c for c in columns if c.key.endswith(f":{metric}")]
        labels = [
            c.header.split(" ", 2)[-1] for c in chosen
        ]  # "e_v cm/s ROFT (sim)" -> "ROFT (sim)"
        panels2.append(_bar_panel(y_label, y_label, columns, rows, [c.key for c in chosen], labels))
    figure = bar_figure(
        [str(r["entry"]) for r in rows],
        panels2,
        title="Table II: velocity tracking (simulation vs paper)",
        hatched=[c.header.split(" ", 2)[-1] for c in columns if c.key.startswith("paper:")],
    )
    written.append(save_figure(figure, out / "table2.png"))
    # Table IV: variants on the x axis, simulation and paper per metric
    columns, rows = table4
    panels4 = [
        _bar_panel(
            y_label, y_label, columns, rows, [f"sim_{k}", f"paper_{k}"], ["simulation", "paper"]
        )
        for k, y_label in (("add", "ADD-AUC [%]"), ("t", "RMSE e_t [cm]"), ("a", "RMSE e_a [deg]"))
    ]
    figure = bar_figure(
        [str(r["variant"]) for r in rows],
        panels4,
        title="Table IV: ablation, ALL (simulation vs paper)",
        hatched=["paper"],
    )
    written.append(save_figure(figure, out / "table4.png"))
    return written


_SIDE_BY_SIDE = (
    ("DOPE", "detector", "DOPE (5 fps, held)"),
    ("ROFT", "roft_reference", "ROFT, reference config"),
    ("ROFT", "roft", "ROFT, our default"),
)
"""(paper Table I method, sim row key, label) of the side-by-side tables."""


def side_by_side_tables(
    results: dict[str, RowMetrics], paper: PaperTables, entries: Sequence[str]
) -> dict[str, tuple[list[Column], list[dict[str, Any]]]]:
    """Per Table I metric: per object and ALL, for DOPE and for ROFT in the reference and in
    our default configuration, the paper's number, the simulated one and ``sim - paper``.
    A sim row that was not run (e.g. ``roft_reference`` before it is registered) is left out."""
    present = [(m, k, label) for m, k, label in _SIDE_BY_SIDE if k in results]
    out = {}
    for metric, title in (
        ("add_auc_pct", "ADD-AUC (%)"),
        ("rmse_t_cm", "RMSE e_t (cm)"),
        ("rmse_a_deg", "RMSE e_a (deg)"),
    ):
        columns = [Column("entry", "object", align="left")]
        for _, key, label in present:
            columns += [
                Column(f"{key}:paper", f"{label}: paper", ".2f"),
                Column(f"{key}:sim", "sim", ".2f"),
                Column(f"{key}:diff", "sim - paper", "+.2f"),
            ]
        table_rows = []
        for entry in entries:
            row: dict[str, Any] = {"entry": entry}
            for method, key, _ in present:
                ref = paper.table1[method][metric].get(entry)
                sim = results[key].get(entry, {}).get(metric)
                row[f"{key}:paper"] = ref
                row[f"{key}:sim"] = sim
                row[f"{key}:diff"] = None if ref is None or sim is None else sim - ref
            table_rows.append(row)
        out[title] = (columns, table_rows)
    return out


TABLE4_ORDER_ROWS = (*_GT_ROWS, *_ABLATION_ROWS)
"""The nine ROFT rows of Table IV whose order is compared (:func:`table4_order`)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class RowOrder:
    """How the simulated Table IV rows rank against the paper's, for one metric."""

    metric: str
    """``add_auc_pct``, ``rmse_t_cm`` or ``rmse_a_deg``."""
    kendall_tau: float | None
    """Kendall's tau-b between the paper's and the simulated values over the rows run (1: same
    order, -1: reversed); None with fewer than 3 rows."""
    rows: int
    """How many of the nine rows were compared."""
    paper_order: tuple[str, ...]
    """Row keys from best to worst in the paper."""
    sim_order: tuple[str, ...]
    """Row keys from best to worst in the simulation."""


def kendall_tau_b(x: Sequence[float], y: Sequence[float]) -> float:
    """Kendall's rank correlation tau-b of two equally long sequences (ties in either count
    as neither concordant nor discordant and shrink the denominator); NaN when one sequence is
    constant."""
    if len(x) != len(y):
        raise ValueError(f"need sequences of equal length, got {len(x)} and {len(y)}")
    concordant = discordant = ties_x = ties_y = 0
    for i in range(len(x)):
        for j in range(i + 1, len(x)):
            dx, dy = x[i] - x[j], y[i] - y[j]
            if dx == 0 and dy == 0:
                continue
            if dx == 0:
                ties_x += 1
            elif dy == 0:
                ties_y += 1
            elif (dx > 0) == (dy > 0):
                concordant += 1
            else:
                discordant += 1
    n_x = concordant + discordant + ties_x
    n_y = concordant + discordant + ties_y
    if n_x == 0 or n_y == 0:
        return float("nan")
    return (concordant - discordant) / float(np.sqrt(n_x * n_y))


def table4_order(
    results: dict[str, RowMetrics], paper: PaperTables, *, configuration: str = "roft"
) -> list[RowOrder]:
    """Kendall's tau between the paper's and the simulated values of the nine ROFT rows of
    Table IV (:data:`TABLE4_ORDER_ROWS`), per metric (ALL).

    Args:
        results: per row key, the metrics.
        paper: the published numbers.
        configuration: the key of the configuration's plain ROFT row; its Table IV rows are that
            key with the default rows' suffixes (``roft_reference`` -> ``roft_reference``,
            ``roft_reference_gt_pose``, ``roft_reference_no_pose_sync``, ...). The orders name
            the rows by their default keys.
    """
    labels = {r.key: r.label for r in PAPER_ROWS}

    def sim_key(default_key: str) -> str:
        return _configuration_row(configuration, default_key)

    out = []
    for metric in ("add_auc_pct", "rmse_t_cm", "rmse_a_deg"):
        keys = [
            k
            for k in TABLE4_ORDER_ROWS
            if _all(results, sim_key(k), metric) is not None and labels[k] in paper.table4
        ]
        ref = [paper.table4[labels[k]][metric] for k in keys]
        sim = [float(_all(results, sim_key(k), metric)) for k in keys]  # type: ignore[arg-type]
        sign = -1.0 if metric == "add_auc_pct" else 1.0  # best first
        tau = None if len(keys) < 3 else kendall_tau_b(ref, sim)
        out.append(
            RowOrder(
                metric=metric,
                kendall_tau=tau,
                rows=len(keys),
                paper_order=tuple(
                    k for _, k in sorted(zip([sign * v for v in ref], keys, strict=True))
                ),
                sim_order=tuple(
                    k for _, k in sorted(zip([sign * v for v in sim], keys, strict=True))
                ),
            )
        )
    return out


_ATTRIBUTION_METRICS = ("add_auc_pct", "rmse_t_cm", "rmse_a_deg", "rmse_v_cmps", "rmse_w_dps")


def attribution_table(
    results: dict[str, RowMetrics],
) -> tuple[list[Column], list[dict[str, Any]]]:
    """Reference (``roft_reference``), each deviation added in turn (the ``attr_*`` rows), the
    default (``roft``), on ALL, with each metric's change from the row above. Rows not run are
    left out; no table when neither end was run."""
    from roft_sim.trackers.roft import DEVIATIONS

    chain: list[tuple[str, str, str]] = [("roft_reference", "reference", "")]
    for n in range(1, len(DEVIATIONS)):
        d = DEVIATIONS[n - 1]
        chain.append((f"attr_{n:02d}_{d.name}", f"+ {d.name}", d.description))
    last = DEVIATIONS[-1]
    chain.append(("roft", f"+ {last.name} = default", last.description))
    columns = [Column("step", "configuration", align="left")]
    for metric, title in zip(
        _ATTRIBUTION_METRICS,
        ("ADD-AUC %", "e_t cm", "e_a deg", "e_v cm/s", "e_w deg/s"),
        strict=True,
    ):
        columns += [Column(metric, title, ".2f"), Column(f"d:{metric}", "change", "+.2f")]
    columns.append(Column("what", "deviation", align="left"))
    table_rows: list[dict[str, Any]] = []
    previous: dict[str, float | None] | None = None
    if "roft_reference" not in results and "roft" not in results:
        return columns, []
    for key, name, what in chain:
        sim = results.get(key, {}).get(ALL)
        if sim is None:
            continue
        row: dict[str, Any] = {"step": name, "what": what}
        for metric in _ATTRIBUTION_METRICS:
            value = sim.get(metric)
            row[metric] = value
            before = previous.get(metric) if previous is not None else None
            row[f"d:{metric}"] = None if value is None or before is None else value - before
        table_rows.append(row)
        previous = sim
    return columns, table_rows


_STALE_MASK_PAPER_ROW = "ROFT w/o segm. sync."
"""The paper's Table II column of ROFT fed the masks as they arrive (6-12 frames old)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PerObjectMotion:
    """Per object, the configuration's ADD-AUC against the paper's, next to how much larger the
    paper's velocity errors are than the simulation's (:func:`per_object_motion`)."""

    configuration: str
    """The key of the configuration's plain ROFT row (``roft``, ``roft_reference``)."""
    columns: list[Column]
    rows: list[dict[str, Any]]
    """One per object and ALL: ``add_gap`` (sim - paper ADD-AUC points of the plain row) and
    ``<row>:<metric>`` = paper / sim for ``row`` in (``roft``, ``stale_masks``) and ``metric`` in
    (``rmse_v_cmps``, ``rmse_w_dps``); None where a number is missing."""
    rank_correlation: float | None
    """Spearman's rank correlation over the objects (not ALL) between ``add_gap`` and the
    stale-mask e_v ratio; None with fewer than 3 objects having both, or either constant."""


def per_object_motion(
    results: dict[str, RowMetrics],
    paper: PaperTables,
    entries: Sequence[str],
    *,
    configuration: str = "roft_reference",
) -> PerObjectMotion | None:
    """Reads, per object, whether the paper's sequence of that object moved faster than the
    simulated one, from a row that measures motion more than anything else: ROFT with the masks
    as they arrive (``<configuration>_no_mask_sync``, the paper's "w/o segm. sync."). Its
    velocity is read from flow on a mask 6-12 frames old, so its error grows with how far the
    object moves in that delay; the object, its size and the networks are the same in both, so
    a paper / sim ratio of its e_v or e_w above 1 says the paper's sequence moved faster
    relative to its size than ours. Put next to the plain row's ADD-AUC gap, the ratios say how
    much of a per-object difference follows the motion, which a simulator drawing one motion
    distribution for every object cannot reproduce.

    Args:
        results: per row key, per entry, the metrics.
        paper: the published numbers (Table I ROFT, Table II both columns).
        entries: objects then ``ALL``, in the order of the other tables.
        configuration: the key of the configuration's plain ROFT row.

    Returns:
        The table, or None when the configuration's plain or stale-mask row did not run.
    """
    from scipy.stats import spearmanr

    stale = _configuration_row(configuration, "roft_no_mask_sync")
    if configuration not in results or stale not in results:
        return None
    sources = (("roft", configuration, "ROFT"), ("stale_masks", stale, _STALE_MASK_PAPER_ROW))
    columns = [
        Column("entry", "object", align="left"),
        Column("add_gap", f"ADD-AUC sim - paper ({configuration})", "+.2f"),
    ]
    for name, _, label in sources:
        for metric, unit in (("rmse_v_cmps", "e_v"), ("rmse_w_dps", "e_w")):
            columns.append(Column(f"{name}:{metric}", f"{unit} paper / sim ({label})", ".2f"))
    rows: list[dict[str, Any]] = []
    for entry in entries:
        sim_add = results[configuration].get(entry, {}).get("add_auc_pct")
        paper_add = paper.table1["ROFT"]["add_auc_pct"].get(entry)
        row: dict[str, Any] = {
            "entry": entry,
            "add_gap": None if sim_add is None or paper_add is None else sim_add - paper_add,
        }
        for name, key, label in sources:
            for metric in ("rmse_v_cmps", "rmse_w_dps"):
                sim = results[key].get(entry, {}).get(metric)
                ref = paper.table2.get(label, {}).get(metric, {}).get(entry)
                row[f"{name}:{metric}"] = (
                    None if sim is None or ref is None or sim <= 0 else ref / sim
                )
        rows.append(row)
    pairs = [
        (r["add_gap"], r["stale_masks:rmse_v_cmps"])
        for r in rows
        if r["entry"] != ALL
        and r["add_gap"] is not None
        and r["stale_masks:rmse_v_cmps"] is not None
    ]
    rho = None
    gaps, ratios = zip(*pairs, strict=True) if pairs else ((), ())
    if len(pairs) >= 3 and len(set(gaps)) > 1 and len(set(ratios)) > 1:  # else undefined
        rho = float(spearmanr(gaps, ratios).statistic)
    return PerObjectMotion(
        configuration=configuration, columns=columns, rows=rows, rank_correlation=rho
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class PaperResult:
    """What :func:`run_paper` produced."""

    out_dir: Path
    """The output folder."""
    results: dict[str, RowMetrics]
    """Per row key, per object and ALL: the metric scalars."""
    findings: tuple[Finding, ...]
    """The qualitative findings checked."""
    tables_md: Path
    """``tables.md``."""


def _table_entries(results: dict[str, RowMetrics], paper: PaperTables) -> list[str]:
    """The objects that ran, the paper's first in its order, then ``ALL``."""
    objects_run = sorted({e for r in results.values() for e in r if e != ALL})
    entries = [o for o in paper.objects if o in objects_run]
    return entries + [o for o in objects_run if o not in entries] + [ALL]


def _per_object_motions(
    results: dict[str, RowMetrics], paper: PaperTables
) -> list[PerObjectMotion]:
    """:func:`per_object_motion` of each checked configuration whose rows ran, over the objects
    of the other tables."""
    entries = _table_entries(results, paper)
    return [
        m
        for c in checked_configurations(results)
        if (m := per_object_motion(results, paper, entries, configuration=c)) is not None
    ]


def _table4_order_lines(
    results: dict[str, RowMetrics], paper: PaperTables, configurations: Sequence[str]
) -> list[str]:
    """The ``tables.md`` section on the order of the nine ROFT rows (Kendall tau)."""
    md = ["## Table IV: order of the nine ROFT rows (Kendall tau, paper vs sim)", ""]
    for configuration in configurations:
        if configuration not in results:
            continue
        md.append(f"Configuration `{configuration}`:")
        for order in table4_order(results, paper, configuration=configuration):
            tau = "n/a" if order.kendall_tau is None else f"{order.kendall_tau:+.3f}"
            md.append(
                f"- {order.metric}: tau {tau} over {order.rows} rows; paper best to worst "
                f"{', '.join(order.paper_order)}; sim {', '.join(order.sim_order)}"
            )
        md.append("")
    return md


def _per_object_motion_section(out: Path, motions: Sequence[PerObjectMotion]) -> list[str]:
    """The ``tables.md`` section of the per-object motion tables (none without tables); writes
    ``per_object_motion_<configuration>.csv`` for each."""
    if not motions:
        return []
    md = [
        "## Per object: does the difference follow the motion? (paper / sim velocity errors)",
        "",
        "ROFT fed the masks as they arrive (w/o segm. sync.) reads its velocity from flow on "
        "a mask 6-12 frames old, so its velocity error grows with how far the object moves "
        "in that delay; a paper / sim ratio above 1 says the paper's sequence of that object "
        "moved faster relative to its size than the simulated one. Rank correlation: "
        "Spearman's, over the objects, between the ADD-AUC difference and the stale-mask e_v "
        "ratio.",
        "",
    ]
    for motion in motions:
        rho = "n/a" if motion.rank_correlation is None else f"{motion.rank_correlation:+.2f}"
        md += [
            f"Configuration `{motion.configuration}` (rank correlation {rho}):",
            "",
            markdown_table(motion.columns, motion.rows),
        ]
        atomic_write_text(
            out / f"per_object_motion_{motion.configuration}.csv",
            csv_table(motion.columns, motion.rows),
        )
    return md


def _findings_lines(configurations: Sequence[str], findings: Sequence[Finding]) -> list[str]:
    """The ``tables.md`` section of the paper's findings, per configuration."""
    md = ["## The paper's findings, checked", ""]
    for configuration in configurations:
        md.append(f"Configuration `{configuration}`:")
        for f in findings:
            if f.configuration == configuration:
                verdict = {True: "holds", False: "DOES NOT HOLD", None: "not checked"}[f.holds]
                md.append(f"- **{verdict}**: {f.claim}. ({f.evidence})")
        md.append("")
    return md


def write_paper_tables(
    out: Path,
    rows: Sequence[PaperRow],
    results: dict[str, RowMetrics],
    *,
    header: Sequence[str] = (),
) -> tuple[Path, list[Finding]]:
    """Writes ``tables.md``, ``table1_*.csv``, ``table2.csv``, ``table4.csv``, ``tables.tex``,
    the tables as figures (``table1.png``, ``table2.png``, ``table4.png``),
    ``per_object_motion_<configuration>.csv`` for each configuration whose plain and stale-mask
    rows ran (:func:`per_object_motion`), and returns the path of ``tables.md`` and the
    findings."""
    paper = paper_tables()
    entries = _table_entries(results, paper)
    configurations = checked_configurations(results)
    findings = [f for c in configurations for f in check_findings(results, configuration=c)]
    md = [*header]
    tex = []
    md += [f"Every simulated number: {policy_note(PAPER_INVALID)}.", ""]
    md += ["## Table I: pose tracking (simulation vs paper)", ""]
    table1 = _table1(results, rows, paper, entries)
    table2 = _table2(results, rows, paper, entries)
    table4 = _table4(results, rows, paper)
    for i, (title, (cols, trs)) in enumerate(table1.items()):
        md += [f"### {title}", "", markdown_table(cols, trs)]
        atomic_write_text(
            out / f"table1_{['add_auc', 'rmse_t', 'rmse_a'][i]}.csv", csv_table(cols, trs)
        )
        tex.append(latex_table(cols, trs, caption=f"Table I in simulation: {title}"))
    md.append("![Table I](table1.png)\n")
    cols, trs = table2
    md += ["## Table II: velocity tracking (simulation vs paper)", "", markdown_table(cols, trs)]
    atomic_write_text(out / "table2.csv", csv_table(cols, trs))
    tex.append(latex_table(cols, trs, caption="Table II in simulation: velocity RMSE"))
    md.append("![Table II](table2.png)\n")
    cols, trs = table4
    md += ["## Table IV: ablation, ALL (simulation vs paper)", "", markdown_table(cols, trs)]
    atomic_write_text(out / "table4.csv", csv_table(cols, trs))
    tex.append(latex_table(cols, trs, caption="Table IV in simulation: ablation (ALL)"))
    md.append("![Table IV](table4.png)\n")
    _write_paper_figures(out, table1, table2, table4)

    md += ["## Side by side: paper, sim (reference config), sim (our default)", ""]
    for title, (cols, trs) in side_by_side_tables(results, paper, entries).items():
        md += [f"### {title}", "", markdown_table(cols, trs)]
    md += _table4_order_lines(results, paper, configurations)
    cols, trs = attribution_table(results)
    if trs:
        md += [
            "## Attribution: the reference configuration, each deviation added, the default (ALL)",
            "",
            markdown_table(cols, trs),
        ]
        atomic_write_text(out / "attribution.csv", csv_table(cols, trs))
        tex.append(latex_table(cols, trs, caption="Deviations from the reference, one at a time"))
    md += _per_object_motion_section(out, _per_object_motions(results, paper))
    md += _findings_lines(configurations, findings)
    md += [f"Paper numbers: {paper.source}."]
    path = out / "tables.md"
    atomic_write_text(path, "\n".join(md) + "\n")
    atomic_write_text(out / "tables.tex", "\n".join(tex))
    return path, findings


PAPER_LAYOUT = PaperLayout(side_by_side=_SIDE_BY_SIDE, table4_order=table4_order)
"""The paper tables' layout for the intervals over the seeds
(:mod:`roft_sim.harness.paper_seeds`)."""


def _seed_intervals(
    tables_md: Path,
    cells: Sequence[SweepCell],
    records: dict[str, dict[str, Any]],
    cells_dir: Path,
    results: dict[str, RowMetrics],
) -> dict[str, Any]:
    """Appends the section on the intervals over the seeds to ``tables_md``; returns its JSON
    (:mod:`roft_sim.harness.paper_seeds`)."""
    paper = paper_tables()
    by_seed = {
        s: paper_metrics([c for c in cells if c.options.seed == s], records, cells_dir)
        for s in sorted({c.options.seed for c in cells})
    }
    entries = _table_entries(results, paper)
    configurations = checked_configurations(results)
    layout = PAPER_LAYOUT
    section = uncertainty_markdown(by_seed, paper, entries, configurations, layout)
    text = tables_md.read_text(encoding="utf-8")
    atomic_write_text(tables_md, text + "\n" + "\n".join(section))
    return uncertainty_json(by_seed, paper, entries, configurations, layout)


def run_paper(
    sequence_paths: Sequence[Path],
    out_dir: str | Path,
    *,
    rows: Sequence[PaperRow] | None = None,
    flow: str = "auto",
    seed: int = 0,
    seeds: int = 1,
    executor: Executor | None = None,
    progress: bool = False,
    header: Sequence[str] = (),
    extra: dict[str, Any] | None = None,
) -> PaperResult:
    """Runs the rows on the sequences (resumable cells in ``out_dir/cells``) and writes the tables.

    Args:
        sequence_paths: the Fast-YCB-like sequences (paths or dataset roots).
        out_dir: output folder.
        rows: the rows (default: :func:`paper_rows`).
        flow: flow source of the rows that use flow (see ``roft-sim run --flow``).
        seed: run seed (the first of ``seeds``).
        seeds: run every row over this many seeds (fault and detector draws); above 1 the
            tables pool every seed's frames and ``tables.md`` gets the intervals over the seeds
            (:mod:`roft_sim.harness.paper_seeds`).
        executor: where the cells run (default: in this process).
        progress: progress bar over cells.
        header: Markdown lines put before the tables.
        extra: more JSON for ``paper.json`` (e.g. the dataset's generation settings).
    """
    out = Path(out_dir)
    rows = list(rows) if rows is not None else paper_rows()
    paths = find_sequences(sequence_paths)
    cells = plan_paper(rows, paths, flow=flow, seed=seed, seeds=seeds)
    records = execute_cells(cells, out / CELLS_DIR, executor=executor, progress=progress)
    results = paper_metrics(cells, records, out / CELLS_DIR)
    tables, findings = write_paper_tables(out, rows, results, header=header)
    uncertainty = (
        _seed_intervals(tables, cells, records, out / CELLS_DIR, results) if seeds > 1 else None
    )
    motions = {
        m.configuration: {"rows": m.rows, "rank_correlation": m.rank_correlation}
        for m in _per_object_motions(results, paper_tables())
    }
    write_json(
        out / "paper.json",
        {
            "kind": "paper",
            "faults": PAPER_FAULTS,
            "flow": flow,
            "seed": seed,
            "seeds": seeds,
            "uncertainty": uncertainty,
            "rows": [dataclasses.asdict(r) for r in rows],
            "sequences": [str(p) for p in paths],
            "cells": [c.cell_id for c in cells],
            "results": results,
            "findings": [dataclasses.asdict(f) for f in findings],
            "per_object_motion": motions,
            "cell_wall_s": sum(float(r.get("wall_s", 0.0)) for r in records.values()),
            **jsonable(extra or {}),
        },
    )
    return PaperResult(out_dir=out, results=results, findings=tuple(findings), tables_md=tables)
