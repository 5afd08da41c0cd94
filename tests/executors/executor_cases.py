"""Shared helpers of the executor tests (imported as ``from executor_cases import ...``).

Unit functions live here, at module level, so that spawned worker processes and Ray actors can
import them by name (the Ray fixture puts this folder on the actors' ``PYTHONPATH``).

- :func:`square`, :func:`count_in_worker` (+ :func:`start_counting`): plain units and per-worker
  state.
- :func:`write_unit`: a unit that writes its result file atomically and reports progress.
- :func:`die_on`, :func:`die_once`, :func:`run_or_die`: units whose worker process hard-exits
  (``os._exit``).
- :func:`write_box_dataset`: two tiny analytic Fast-YCB sequences with a detector pose set.
- :func:`tiny_ci_scenario`, :func:`tree_hashes`, :func:`sweep_hashes`: byte-identity checks.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from roft_sim.executors import report_progress

# ------------------------------------------------------------------------------------ units
_COUNT: dict[str, Any] = {}


def square(x: int) -> int:
    return x * x


def start_counting(tag: str) -> None:
    """Worker initializer: per-worker state that units read and change."""
    _COUNT.clear()
    _COUNT.update(tag=tag, pid=os.getpid(), calls=0)


def stop_counting() -> None:
    """Worker teardown."""
    _COUNT.clear()


def count_in_worker(x: int) -> tuple[int, str, int, int]:
    """``(x, tag, pid, calls so far in this worker)``; raises when the worker was not set up."""
    if "tag" not in _COUNT:
        raise RuntimeError("worker not initialised")
    _COUNT["calls"] += 1
    report_progress(2)
    return x, _COUNT["tag"], _COUNT["pid"], _COUNT["calls"]


def fail_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("three is not allowed")
    return x


def unit_bytes(i: int) -> bytes:
    """The content unit ``i`` writes (deterministic)."""
    return hashlib.sha256(f"unit {i}".encode()).digest() * 64


def write_unit(unit: tuple[str, int]) -> int:
    """Writes ``<folder>/<i>.bin`` atomically (temp file + rename) unless it exists; reports 3
    progress counts. The contract every real unit follows."""
    folder, i = unit
    final = Path(folder) / f"{i}.bin"
    if final.is_file():
        return 0
    tmp = Path(folder) / f".{i}.bin.{os.getpid()}.tmp"
    data = unit_bytes(i)
    with open(tmp, "wb") as f:
        f.write(data[: len(data) // 2])
        f.flush()
        report_progress(1)
        f.write(data[len(data) // 2 :])
    os.replace(tmp, final)
    report_progress(2)
    return len(data)


def die_on(victim: int, unit: tuple[str, int]) -> int:
    """:func:`write_unit`, but the worker hard-exits half-way through writing unit ``victim``
    (a temp file is left behind, as by a crash)."""
    folder, i = unit
    if i == victim:
        tmp = Path(folder) / f".{i}.bin.{os.getpid()}.tmp"
        tmp.write_bytes(unit_bytes(i)[:100])
        os._exit(17)
    return write_unit(unit)


def die_once(marker_dir: str, unit: tuple[str, int]) -> int:
    """:func:`write_unit`, but the first attempt at unit 2 hard-exits its worker (a marker file
    remembers the attempt across processes)."""
    folder, i = unit
    marker = Path(marker_dir) / f"died_{i}"
    if i == 2 and not marker.exists():
        marker.write_text("x")
        os._exit(17)
    return write_unit(unit)


def run_or_die(victim_id: str, fn: Any, cell: Any) -> Any:
    """``fn(cell)``, but the worker hard-exits half-way through sweep cell ``victim_id`` (its
    temporary folder is left behind, as by a crash)."""
    if cell.cell_id == victim_id:
        cells_dir = Path(fn.keywords["cells_dir"])
        tmp = cells_dir / f".{cell.cell_id}.{os.getpid()}.tmp"
        tmp.mkdir(parents=True)
        (tmp / "pose_estimate.txt").write_text("0 0 0\n")
        os._exit(17)
    return fn(cell)


def written_units(folder: Path) -> dict[str, bytes]:
    """Every file in ``folder`` (temp files included) -> bytes."""
    return {p.name: p.read_bytes() for p in sorted(Path(folder).iterdir()) if p.is_file()}


# --------------------------------------------------------------------------------- datasets
def write_box_dataset(root: Path, n_frames: int = 12) -> Path:
    """Two analytic box sequences (64x48) with a detector pose set ``dope`` (the ground truth
    offset by 4 mm and with two misses), as Fast-YCB folders under ``root``."""
    import dataclasses

    from roft_sim.datasets import write_sequence
    from roft_sim.datasets.base import DetectorPoses
    from roft_sim.testing.analytic_scene import analytic_box_sequence, default_intrinsics

    for i, name in enumerate(("box_a", "box_b")):
        base = analytic_box_sequence(
            n_frames=n_frames, intrinsics=default_intrinsics(64, 48), name=name
        )
        gt = base.ground_truth()
        T = gt.T_cam_obj.copy()
        T[:, :3, 3] += np.random.default_rng(10 + i).normal(0.004, 0.002, (n_frames, 3))
        valid = np.ones(n_frames, dtype=bool)
        valid[[3, 7]] = False
        T[~valid] = np.eye(4)
        seq = dataclasses.replace(
            base, detector_pose_sets={"dope": DetectorPoses(T_cam_obj=T, valid=valid)}
        )
        write_sequence(seq, "fast-ycb", root)
    return root


def tiny_ci_scenario(name: str = "cracker_box", *, frames: int = 5, resolution=(96, 72)):
    """A shipped CI scenario with few frames at a tiny resolution."""
    from roft_sim.generation import ScenarioOverrides, shipped_scenarios_dir
    from roft_sim.scenario import load_scenario

    scenario = load_scenario(shipped_scenarios_dir() / "ci" / f"{name}.toml")
    return ScenarioOverrides(frames=frames, resolution=resolution).apply(scenario)


def ci_scenario_file(name: str = "cracker_box") -> Path:
    from roft_sim.generation import shipped_scenarios_dir

    return shipped_scenarios_dir() / "ci" / f"{name}.toml"


# ------------------------------------------------------------------------------- hashing
def tree_hashes(root: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``root``."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(Path(root).rglob("*"))
        if p.is_file()
    }


_TIMING_FILES = {"execution_times.txt", "timing.csv"}


def _is_timing_key(key: str) -> bool:
    return key == "wall_s" or key.startswith("time_") or key.endswith("_times_s")


def _without_timing(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items() if not _is_timing_key(k)}
    if isinstance(value, list):
        return [_without_timing(v) for v in value]
    return value


def sweep_hashes(root: Path) -> dict[str, str]:
    """SHA-256 of every file of a sweep folder, with what measures wall time left out: the
    timing files (``execution_times.txt``, ``timing.csv``), the timing keys of JSON files
    (``wall_s``, ``time_*``) and the ``*_times_s`` arrays of ``.npz`` files. Every other byte of
    every file (estimates, deliveries, metrics, summaries, cells.csv, sweep.json) counts."""
    out: dict[str, str] = {}
    for p in sorted(Path(root).rglob("*")):
        if not p.is_file() or p.name in _TIMING_FILES:
            continue
        rel = str(p.relative_to(root))
        if p.suffix == ".json":
            data = json.dumps(_without_timing(json.loads(p.read_text())), sort_keys=True)
            out[rel] = hashlib.sha256(data.encode()).hexdigest()
        elif p.suffix == ".npz":
            h = hashlib.sha256()
            with np.load(p) as arrays:
                for name in sorted(arrays.files):
                    if not _is_timing_key(name):
                        a = arrays[name]
                        h.update(name.encode() + a.dtype.str.encode() + str(a.shape).encode())
                        h.update(np.ascontiguousarray(a).tobytes())
            out[rel] = h.hexdigest()
        else:
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out
