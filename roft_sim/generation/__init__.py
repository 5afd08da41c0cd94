"""Dataset generation: scenarios -> rendered frames with exact ground truth and simulated
networks -> datasets on disk (``roft-sim generate``; docs/generate.md).

- :func:`generate_dataset`: the run (writers, work units, worker processes, progress, resume).
- :class:`SequenceGenerator`: one scenario's frames as ``DatasetFrame`` objects (imported lazily:
  it imports MuJoCo, so ``MUJOCO_GL`` must be chosen first).
- :func:`plan_work_units` / :class:`WorkUnit` / :func:`plan_shard_units`: the unit of work and
  ``--shard i/N``.
- :func:`shipped_scenarios_dir`, :data:`PRESETS`, :func:`preset_scenario_paths`: shipped scenarios.
"""

from __future__ import annotations

import importlib
from typing import Any

from roft_sim.generation.jobs import (
    ScenarioOverrides,
    SequenceJob,
    generation_metadata,
    parse_resolution,
    sequence_name_for,
)
from roft_sim.generation.presets import (
    PRESETS,
    Preset,
    preset_scenario_paths,
    shipped_scenarios_dir,
    with_fast_ycb_motion,
)
from roft_sim.generation.runner import (
    GenerationError,
    GenerationOptions,
    GenerationSummary,
    SequenceResult,
    generate_dataset,
    run_work_unit,
)
from roft_sim.generation.work_units import (
    WorkUnit,
    parse_shard,
    plan_shard_units,
    plan_work_units,
    shard_work_units,
)

__all__ = [
    "generate_dataset",
    "GenerationOptions",
    "GenerationSummary",
    "GenerationError",
    "SequenceResult",
    "ScenarioOverrides",
    "SequenceJob",
    "generation_metadata",
    "parse_resolution",
    "sequence_name_for",
    "run_work_unit",
    "WorkUnit",
    "plan_work_units",
    "shard_work_units",
    "plan_shard_units",
    "parse_shard",
    "PRESETS",
    "Preset",
    "preset_scenario_paths",
    "shipped_scenarios_dir",
    "with_fast_ycb_motion",
    "SequenceGenerator",
    "ground_truth_track",
    "visible_fraction",
]

_LAZY = {
    "SequenceGenerator": "roft_sim.generation.sequence_generator",
    "ground_truth_track": "roft_sim.generation.sequence_generator",
    "visible_fraction": "roft_sim.generation.sequence_generator",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'roft_sim.generation' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)
