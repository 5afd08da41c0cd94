"""The main job on the embedded default: generate a short Fast-YCB-style sequence, track it
under the paper's delays with ROFT and baselines, and compare.

Nothing beyond the installed package is needed: the object is the procedural stand-in of
003_cracker_box (or the real YCB mesh when one is installed), the motion is the seeded synthetic
hand-like motion of the shipped Fast-YCB scenario, and the simulated networks and flow are those
of a generated dataset (DOPE-like poses and Mask R-CNN-like masks at 5 fps, 6 frames late; the
NVOF-like DIS flow stored with the dataset).
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from roft_sim.config_files import jsonable
from roft_sim.faults import load_faults
from roft_sim.generation import GenerationOptions, generate_dataset
from roft_sim.generation.jobs import ScenarioOverrides
from roft_sim.generation.presets import preset_scenario_paths
from roft_sim.harness.options import RunOptions, default_invalid_policy
from roft_sim.harness.run_dataset import open_sequences, run_sequences
from roft_sim.scenario import load_scenario

__all__ = ["DemoSettings", "DemoResult", "run_demo", "DEMO_OBJECT"]

DEMO_OBJECT = "003_cracker_box"
"""The object of the demo's sequence (its shipped Fast-YCB scenario)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class DemoSettings:
    """What the demo does; the defaults run in about a minute on two CPU cores."""

    frames: int = 150
    """Frames of the generated sequence (5 s at 30 fps)."""
    resolution: tuple[int, int] = (640, 360)
    """Render resolution (width, height) [px]; the Fast-YCB intrinsics (1280x720) are scaled to
    it (half size: square pixels, fx = fy = 614.7 px)."""
    trackers: tuple[str, ...] = ("roft", "detector-hold", "naive-delay")
    """Trackers to compare, run one after the other on the same observation stream."""
    faults: str = "paper"
    """Fault preset (or TOML file) of the runs."""
    seed: int = 0
    """Seed of the runs (the sequence keeps its scenario's seed)."""
    progress: bool = True
    """Show progress bars on stderr."""


@dataclass(frozen=True, slots=True, kw_only=True)
class DemoResult:
    """What the demo produced."""

    dataset_dir: Path
    """The generated Fast-YCB-style dataset (one sequence folder)."""
    run_dirs: dict[str, Path]
    """Tracker name -> its run folder (estimates, metrics.json, ...)."""
    metrics: dict[str, dict[str, Any]]
    """Tracker name -> the sequence's metrics (add_auc_pct, rmse_t_cm, ... see docs/metrics.md)."""
    frames: int
    """Frames generated and tracked."""


def run_demo(
    out_dir: str | Path,
    settings: DemoSettings | None = None,
    *,
    prepare_output: Callable[[Path], Any] | None = None,
) -> DemoResult:
    """Runs the demo into ``out_dir`` (which must exist and be empty, or hold a previous demo,
    unless ``prepare_output`` makes it so).

    Writes ``dataset/`` (Fast-YCB layout), ``runs/<tracker>/`` (one ``roft-sim run`` folder each)
    and ``summary.json``. ``prepare_output`` is called with ``out_dir`` once the scenario is
    checked (trajectory long enough for ``settings.frames``) and before anything is written,
    e.g. to create or empty the folder; so a bad setting leaves the folder untouched.
    """
    s = settings or DemoSettings()
    out = Path(out_dir)
    scenario_path = next(p for p in preset_scenario_paths("fast-ycb") if DEMO_OBJECT in p.name)
    scenario = load_scenario(scenario_path)
    dataset = out / "dataset"
    generate_dataset(
        [scenario],
        dataset,
        GenerationOptions(progress=s.progress),
        overrides=ScenarioOverrides(frames=s.frames, resolution=s.resolution),
        sequence_naming="object",
        preset="fast-ycb",
        prepare_output=None if prepare_output is None else (lambda _dataset: prepare_output(out)),
    )
    sources = open_sequences([dataset])
    faults = load_faults(s.faults)
    run_dirs: dict[str, Path] = {}
    metrics: dict[str, dict[str, Any]] = {}
    for tracker in s.trackers:
        run_dir = out / "runs" / tracker
        result = run_sequences(
            sources,
            RunOptions(
                tracker=tracker,
                faults=faults,
                seed=s.seed,
                invalid=default_invalid_policy(faults.name),
            ),
            run_dir,
            progress=s.progress,
        )
        run_dirs[tracker] = run_dir
        metrics[tracker] = result.metrics[DEMO_OBJECT]
    summary = {
        "scenario": f"{scenario_path.parent.name}/{scenario_path.name}",
        "settings": jsonable(s),
        "dataset": "dataset",
        "runs": {name: str(path.relative_to(out)) for name, path in run_dirs.items()},
        "metrics": metrics,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return DemoResult(dataset_dir=dataset, run_dirs=run_dirs, metrics=metrics, frames=s.frames)


def demo_table_rows(metrics: dict[str, dict[str, Any]]) -> Sequence[dict[str, Any]]:
    """Rows ``{"name": tracker, **metrics}`` for :data:`roft_sim.report.tables.METRIC_COLUMNS`."""
    return [{"name": name, **m} for name, m in metrics.items()]
