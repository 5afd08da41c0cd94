"""The ROFT paper's published Fast-YCB numbers (Tables I, II, IV), read from
``roft_paper_tables.toml`` (transcribed from the paper; the file names its source).

Every metric is a dict from the entry name (an object name or ``"ALL"``) to the value, in the
units of ``metrics.json``: ``add_auc_pct`` [%], ``rmse_t_cm`` [cm], ``rmse_a_deg`` [deg],
``rmse_v_cmps`` [cm/s], ``rmse_w_dps`` [deg/s].
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from functools import cache
from pathlib import Path

__all__ = ["PaperTables", "paper_tables", "PAPER_TABLES_FILE", "ALL"]

PAPER_TABLES_FILE = Path(__file__).with_name("roft_paper_tables.toml")
"""The data file."""
ALL = "ALL"

_TABLE4_KEYS = ("add_auc_pct", "rmse_t_cm", "rmse_a_deg")

Values = dict[str, float]


@dataclass(frozen=True, slots=True)
class PaperTables:
    """The paper's numbers."""

    source: str
    """Citation of the numbers."""
    objects: tuple[str, ...]
    """The six Fast-YCB objects, in table order."""
    table1: dict[str, dict[str, Values]]
    """Method -> metric -> entry (object or ALL) -> value."""
    table2: dict[str, dict[str, Values]]
    """Method -> velocity metric -> entry -> value."""
    table4: dict[str, dict[str, float]]
    """Variant -> metric -> value (ALL)."""


def _entries(objects: tuple[str, ...], values: list[float], where: str) -> Values:
    if len(values) != len(objects) + 1:
        raise ValueError(f"{PAPER_TABLES_FILE}: {where} needs {len(objects) + 1} values")
    return dict(zip((*objects, ALL), (float(v) for v in values), strict=True))


@cache
def paper_tables() -> PaperTables:
    """Loads the data file (cached)."""
    with PAPER_TABLES_FILE.open("rb") as f:
        data = tomllib.load(f)
    objects = tuple(data["objects"])
    tables = {}
    for name in ("table1", "table2"):
        tables[name] = {
            method: {
                metric: _entries(objects, values, f"{name}.{method}.{metric}")
                for metric, values in metrics.items()
            }
            for method, metrics in data[name].items()
        }
    table4 = {
        variant: dict(zip(_TABLE4_KEYS, (float(v) for v in values), strict=True))
        for variant, values in data["table4"].items()
    }
    return PaperTables(
        source=str(data["source"]),
        objects=objects,
        table1=tables["table1"],
        table2=tables["table2"],
        table4=table4,
    )
