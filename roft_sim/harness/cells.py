"""Sweep cells: one tracker on one sequence under one fault configuration with one seed.

A :class:`SweepCell` is a self-contained, picklable work unit (sequence path, resolved
:class:`~roft_sim.harness.options.RunOptions`, labels). :func:`run_cell` runs it and writes its
folder ``cells/<cell_id>/`` ATOMICALLY: everything goes into a hidden temporary folder that is
renamed into place only when complete, with ``cell.json`` inside. So a finished cell is never
redone, and a cell interrupted half-way (a crash, Ctrl-C, a killed worker) leaves only a
temporary folder that :func:`execute_cells` removes before running the cell again.

A cell whose tracker process fails (it crashes, hangs or breaks the protocol:
:class:`~roft_sim.trackers.process.TrackerProcessError`) writes ``cells/<cell_id>.error.txt``
instead and the other cells go on; :func:`execute_cells` then raises :class:`CellsFailedError`
naming them. A failed cell has no ``cell.json``, so running the sweep again retries it.

The cell id is readable (tracker, faults, parameter value, sequence, seed) and ends with a hash of
the cell's full resolved configuration, so changing any setting gives new cells instead of reusing
stale results.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import re
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

from roft_sim.config_files import jsonable
from roft_sim.datasets import open_sequence
from roft_sim.errors import RoftSimError
from roft_sim.executors import Executor, SerialExecutor, Shard, select_shard
from roft_sim.harness.evaluation import evaluate_run
from roft_sim.harness.options import RunOptions
from roft_sim.harness.outputs import (
    FRAME_ERRORS_FILE,
    load_frame_errors,
    read_json,
    write_json,
    write_sequence_outputs,
)
from roft_sim.harness.runner import run_sequence
from roft_sim.metrics import SequenceMetrics
from roft_sim.trackers.process import TrackerProcessError

__all__ = [
    "SweepCell",
    "CELLS_DIR",
    "CELL_FILE",
    "ERROR_SUFFIX",
    "CellsFailedError",
    "make_cell_id",
    "run_cell",
    "execute_cells",
    "finished_cells",
    "remove_cell_leftovers",
    "shard_cells",
    "load_cell_metrics",
]

CELLS_DIR = "cells"
CELL_FILE = "cell.json"
ERROR_SUFFIX = ".error.txt"
"""``cells/<cell_id>.error.txt``: why the cell's tracker process failed (removed on success)."""


class CellsFailedError(RoftSimError):
    """Cells whose tracker process failed; every other cell ran (and is kept on disk).

    Attributes:
        failures: ``{cell_id: message}`` of the failed cells.
    """

    def __init__(self, failures: dict[str, str], cells_dir: Path) -> None:
        first_id, first = next(iter(failures.items()))
        super().__init__(
            f"{len(failures)} cell(s) failed, the others finished and are kept; each failure is "
            f"in {cells_dir}/<cell_id>{ERROR_SUFFIX} ({', '.join(failures)}). Fix the tracker and "
            f"run the sweep again with --resume to retry them. The first failure ({first_id}):\n"
            f"{first}"
        )
        self.failures = failures


_UNSAFE = re.compile(r"[^A-Za-z0-9._=+-]+")


@dataclass(frozen=True, slots=True, kw_only=True)
class SweepCell:
    """One independent unit of a sweep (see the module docstring)."""

    cell_id: str
    """Folder name of the cell's results (readable prefix + configuration hash)."""
    label: str
    """Row label of the tracker (its name, or a variant's label such as ``roft w/o pose sync``)."""
    fault_label: str
    """Name of the base fault configuration (before the swept parameter is applied)."""
    parameter: str | None
    """Swept fault parameter (``delay``, ``dropout``) or None."""
    value: float | None
    """Its value in this cell."""
    sequence_path: str
    """Path of the sequence (folder or ``.h5``)."""
    sequence_name: str
    """Name of the sequence."""
    options: RunOptions
    """The resolved run options (tracker, its config, faults, inputs, seed)."""

    @classmethod
    def create(
        cls,
        *,
        label: str,
        fault_label: str,
        parameter: str | None,
        value: float | None,
        sequence_path: str,
        sequence_name: str,
        options: RunOptions,
    ) -> SweepCell:
        """A cell whose ``cell_id`` is derived from its configuration (:func:`make_cell_id`)."""
        fields: dict[str, Any] = {
            "label": label,
            "fault_label": fault_label,
            "parameter": parameter,
            "value": value,
            "sequence_path": sequence_path,
            "sequence_name": sequence_name,
            "options": options,
        }
        return cls(cell_id=make_cell_id(**fields), **fields)

    def __repr__(self) -> str:
        return f"SweepCell({self.cell_id})"

    def describe(self) -> dict[str, Any]:
        """JSON-ready description (the ``cell`` part of ``cell.json``)."""
        return {
            "cell_id": self.cell_id,
            "label": self.label,
            "tracker": self.options.tracker,
            "faults": self.fault_label,
            "parameter": self.parameter,
            "value": self.value,
            "sequence": self.sequence_name,
            "sequence_path": self.sequence_path,
            "seed": self.options.seed,
            "options": jsonable(self.options),
        }


def _safe(text: str) -> str:
    return _UNSAFE.sub("_", text).strip("_") or "x"


def make_cell_id(
    *,
    label: str,
    fault_label: str,
    parameter: str | None,
    value: float | None,
    sequence_name: str,
    sequence_path: str,
    options: RunOptions,
) -> str:
    """``<label>__<faults>[__<param>=<value>]__<sequence>__s<seed>__<hash10>``."""
    content = {
        "label": label,
        "faults": fault_label,
        "parameter": parameter,
        "value": value,
        "sequence": sequence_name,
        "path": sequence_path,
        "options": jsonable(options),
    }
    digest = hashlib.sha1(json.dumps(content, sort_keys=True).encode()).hexdigest()[:10]
    parts = [_safe(label), _safe(fault_label)]
    if parameter is not None:
        parts.append(_safe(f"{parameter}={value:g}"))
    parts += [_safe(sequence_name), f"s{options.seed}", digest]
    return "__".join(parts)


def run_cell(cell: SweepCell, cells_dir: str | Path) -> dict[str, Any]:
    """Runs one cell and moves its complete folder into ``cells_dir/<cell_id>``.

    Returns:
        The cell record (the content of ``cell.json``), or for a cell whose tracker process
        failed, its description with the error under ``"failed"`` (and no ``cell.json``).
    """
    cells_dir = Path(cells_dir)
    final = cells_dir / cell.cell_id
    if (final / CELL_FILE).is_file():
        return cast(dict[str, Any], read_json(final / CELL_FILE))
    tmp = cells_dir / f".{cell.cell_id}.{os.getpid()}.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    t0 = time.perf_counter()
    sequence = open_sequence(cell.sequence_path)
    error_file = cells_dir / f"{cell.cell_id}{ERROR_SUFFIX}"
    try:
        run = run_sequence(sequence, cell.options)
    except TrackerProcessError as e:  # this cell fails; the sweep goes on
        error_file.write_text(f"{e}\n", encoding="utf-8")
        return {**cell.describe(), "failed": str(e)}
    error_file.unlink(missing_ok=True)
    evaluation = evaluate_run(run, invalid=cell.options.invalid)
    write_sequence_outputs(tmp, run, evaluation)
    record = {
        **cell.describe(),
        "object": run.object_name,
        "inputs": run.inputs,
        "seeds": run.seeds.describe(),
        "metrics": evaluation.entry(),
        "wall_s": round(time.perf_counter() - t0, 3),
    }
    write_json(tmp / CELL_FILE, record)
    try:
        os.rename(tmp, final)
    except OSError:
        # another process finished the same cell first: keep its result
        shutil.rmtree(tmp, ignore_errors=True)
        if not (final / CELL_FILE).is_file():
            raise
        return cast(dict[str, Any], read_json(final / CELL_FILE))
    return record


def finished_cells(cells_dir: str | Path, *, clean: bool = False) -> dict[str, dict[str, Any]]:
    """Records of the finished cells in ``cells_dir``, by cell id.

    Args:
        clean: also delete what interrupted cells left behind (hidden temporary folders, and
            cell folders without ``cell.json``). Only while no cell is running there.
    """
    cells_dir = Path(cells_dir)
    out: dict[str, dict[str, Any]] = {}
    if not cells_dir.is_dir():
        return out
    for path in sorted(cells_dir.iterdir()):
        if not path.is_dir():
            continue
        if path.name.startswith(".") or not (path / CELL_FILE).is_file():
            if clean:
                shutil.rmtree(path, ignore_errors=True)
            continue
        out[path.name] = read_json(path / CELL_FILE)
    return out


def load_cell_metrics(cells_dir: str | Path, cell_id: str) -> SequenceMetrics | None:
    """The per-frame metrics of a finished cell (None when its sequence has no ground truth)."""
    path = Path(cells_dir) / cell_id / FRAME_ERRORS_FILE
    return load_frame_errors(path) if path.is_file() else None


def remove_cell_leftovers(cells_dir: str | Path, cell_ids: Sequence[str]) -> None:
    """Deletes what interrupted runs of these cells left behind (their hidden temporary folders,
    their folders without ``cell.json``), and nothing else: other shards may be running other
    cells in the same folder."""
    cells_dir = Path(cells_dir)
    if not cells_dir.is_dir():
        return
    wanted = set(cell_ids)
    for path in cells_dir.iterdir():
        if not path.is_dir():
            continue
        if path.name.startswith("."):
            cell_id = path.name[1:].rsplit(".", 2)[0]  # .<cell_id>.<pid>.tmp
            if cell_id in wanted and path.name.endswith(".tmp"):
                shutil.rmtree(path, ignore_errors=True)
        elif path.name in wanted and not (path / CELL_FILE).is_file():
            shutil.rmtree(path, ignore_errors=True)


def shard_cells(cells: Sequence[SweepCell], shard: Shard | None) -> list[SweepCell]:
    """The cells of ``shard`` (all when None): the cells sorted by id, dealt round-robin (cell
    ``p`` of the sorted list goes to shard ``p mod N``), so every tracker's cells spread over
    the shards; the same on every machine and in every rerun (docs/scaleout.md)."""
    return select_shard(cells, shard, key=lambda c: c.cell_id, layout="round-robin")


def execute_cells(
    cells: Sequence[SweepCell],
    cells_dir: str | Path,
    *,
    executor: Executor | None = None,
    progress: bool = False,
    on_done: Callable[[SweepCell, dict[str, Any]], None] | None = None,
    shard: Shard | None = None,
) -> dict[str, dict[str, Any]]:
    """Runs the cells that are not finished yet; returns the records of the finished ``cells``
    (all of them when ``shard`` is None).

    Finished cells (a folder with ``cell.json``, found on disk) are not run again; leftovers of
    interrupted cells are deleted first and those cells run again. With ``shard``, only that
    shard's cells (:func:`shard_cells`) run, and only their leftovers are deleted, so shards can
    share ``cells_dir``; without it every leftover is deleted, so run it only while no shard is
    running there.

    Raises:
        CellsFailedError: tracker processes failed in some cells; all the others ran.
        WorkUnitError: a cell failed otherwise (finished cells are kept; run again to resume).
    """
    cells_dir = Path(cells_dir)
    cells_dir.mkdir(parents=True, exist_ok=True)
    ids = [c.cell_id for c in cells]
    dup = sorted({i for i in ids if ids.count(i) > 1})
    if dup:
        raise ValueError(f"cell ids must be unique, got duplicates {dup}")
    mine = shard_cells(cells, shard)
    if shard is None:
        done = finished_cells(cells_dir, clean=True)
    else:
        done = finished_cells(cells_dir)
        remove_cell_leftovers(cells_dir, [c.cell_id for c in mine if c.cell_id not in done])
    todo = [c for c in mine if c.cell_id not in done]
    records = {i: done[i] for i in ids if i in done}
    failures: dict[str, str] = {}
    executor = executor or SerialExecutor()
    from tqdm import tqdm

    with tqdm(
        total=len(mine),
        initial=len(mine) - len(todo),
        unit="cell",
        desc="cells" if shard is None else f"cells of shard {shard}",
        disable=not progress,
        leave=False,
    ) as bar:
        fn = functools.partial(run_cell, cells_dir=cells_dir)
        for cell, record in executor.map_unordered(fn, todo):
            bar.update(1)
            if "failed" in record:
                failures[cell.cell_id] = record["failed"]
                continue
            records[cell.cell_id] = record
            if on_done is not None:
                on_done(cell, record)
    if failures:
        raise CellsFailedError(failures, cells_dir)
    return {i: records[i] for i in ids if i in records}
