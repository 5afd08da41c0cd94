"""Result tables as plain text, Markdown, CSV and LaTeX.

A table is a list of :class:`Column` (key, header, number format) and a list of rows (mappings
from key to value). Numbers are formatted per column; None and NaN print as ``-`` (``""`` in
CSV, where numbers keep full precision).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

__all__ = [
    "Column",
    "format_cell",
    "text_table",
    "markdown_table",
    "csv_table",
    "latex_table",
    "ERROR_COLUMNS",
    "METRIC_COLUMNS",
    "WALL_CLOCK_COLUMNS",
]

MISSING = "-"


@dataclass(frozen=True, slots=True)
class Column:
    """One table column."""

    key: str
    """Key of the value in each row."""
    header: str
    """Header text (Markdown and plain text; LaTeX escapes it)."""
    fmt: str = ""
    """``format`` spec for numbers, e.g. ``.2f``; empty = ``str``."""
    align: str = "right"
    """``left`` or ``right``."""


ERROR_COLUMNS: tuple[Column, ...] = (
    Column("add_auc_pct", "ADD-AUC %", ".2f"),
    Column("rmse_t_cm", "e_t cm", ".2f"),
    Column("rmse_a_deg", "e_a deg", ".2f"),
    Column("rmse_v_cmps", "e_v cm/s", ".2f"),
    Column("rmse_w_dps", "e_w deg/s", ".2f"),
)
"""The pose and velocity error columns (keys of ``metrics.json`` entries)."""

METRIC_COLUMNS: tuple[Column, ...] = (
    *ERROR_COLUMNS,
    Column("frames", "frames", "d"),
    Column("time_median_ms", "step ms (median)", ".2f"),
    Column("time_p95_ms", "step ms (p95)", ".2f"),
)
"""The metric columns of the ``run`` table (keys of ``metrics.json`` entries)."""

WALL_CLOCK_COLUMNS: tuple[Column, ...] = (
    Column("latency_p50_ms", "latency ms (p50)", ".1f"),
    Column("latency_p95_ms", "(p95)", ".1f"),
    Column("latency_max_ms", "(max)", ".1f"),
    Column("deadline_misses", "missed", "d"),
    Column("frames_dropped_busy", "dropped busy", "d"),
    Column("queue_max", "queue max", "d"),
)
"""The timing columns a ``--clock wall`` run adds to the ``run`` table (docs/wall_clock.md)."""


def format_cell(value: Any, fmt: str = "") -> str:
    """One value as text: numbers with ``fmt``; None, NaN and inf as ``-`` (inf as ``inf``)."""
    if value is None:
        return MISSING
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int | float):
        x = float(value)
        if math.isnan(x):
            return MISSING
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        if fmt:
            return format(int(value) if fmt.endswith("d") else x, fmt)
        return str(value)
    return str(value)


def _cells(columns: Sequence[Column], rows: Sequence[Mapping[str, Any]]) -> list[list[str]]:
    return [[format_cell(row.get(c.key), c.fmt) for c in columns] for row in rows]


def text_table(columns: Sequence[Column], rows: Sequence[Mapping[str, Any]]) -> str:
    """A fixed-width plain-text table (for terminals)."""
    cells = _cells(columns, rows)
    widths = [max([len(c.header)] + [len(r[i]) for r in cells]) for i, c in enumerate(columns)]

    def line(values: Sequence[str]) -> str:
        parts = [
            v.ljust(w) if c.align == "left" else v.rjust(w)
            for v, w, c in zip(values, widths, columns, strict=True)
        ]
        return "  ".join(parts).rstrip()

    out = [line([c.header for c in columns]), "  ".join("-" * w for w in widths)]
    out += [line(r) for r in cells]
    return "\n".join(out) + "\n"


def _md_escape(text: str) -> str:
    return text.replace("|", "\\|")


def markdown_table(columns: Sequence[Column], rows: Sequence[Mapping[str, Any]]) -> str:
    """A GitHub-flavoured Markdown table."""
    cells = _cells(columns, rows)
    head = "| " + " | ".join(_md_escape(c.header) for c in columns) + " |"
    rule = "|" + "|".join(":---" if c.align == "left" else "---:" for c in columns) + "|"
    body = ["| " + " | ".join(_md_escape(v) for v in r) + " |" for r in cells]
    return "\n".join([head, rule, *body]) + "\n"


def csv_table(columns: Sequence[Column], rows: Sequence[Mapping[str, Any]]) -> str:
    """CSV with the column keys as header; numbers at full precision, missing values empty."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([c.key for c in columns])
    for row in rows:
        out = []
        for c in columns:
            v = row.get(c.key)
            if v is None or (isinstance(v, float) and math.isnan(v)):
                out.append("")
            else:
                out.append(repr(v) if isinstance(v, float) else str(v))
        writer.writerow(out)
    return buffer.getvalue()


_LATEX_SPECIAL = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
}


def latex_escape(text: str) -> str:
    """Escapes LaTeX's special characters."""
    return "".join(_LATEX_SPECIAL.get(ch, ch) for ch in text)


def latex_table(
    columns: Sequence[Column],
    rows: Sequence[Mapping[str, Any]],
    *,
    caption: str | None = None,
    label: str | None = None,
) -> str:
    """A ``tabular`` (booktabs rules) in a ``table`` environment."""
    cells = _cells(columns, rows)
    spec = "".join("l" if c.align == "left" else "r" for c in columns)
    lines = [r"\begin{table}[t]", r"\centering"]
    if caption:
        lines.append(rf"\caption{{{latex_escape(caption)}}}")
    if label:
        lines.append(rf"\label{{{label}}}")
    lines += [rf"\begin{{tabular}}{{{spec}}}", r"\toprule"]
    lines.append(" & ".join(latex_escape(c.header) for c in columns) + r" \\")
    lines.append(r"\midrule")
    lines += [" & ".join(latex_escape(v) for v in r) + r" \\" for r in cells]
    lines += [r"\bottomrule", r"\end{tabular}", r"\end{table}"]
    return "\n".join(lines) + "\n"
