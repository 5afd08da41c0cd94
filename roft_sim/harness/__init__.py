"""The harness: runs trackers over datasets under faults, sweeps, the paper's experiments.

- :class:`RunOptions`: what one run does (tracker, faults, inputs, initial condition, seed).
- :func:`run_sequence`: the run loop over one sequence -> :class:`SequenceRun`.
- :func:`evaluate_run`: its metrics and synchronisation figures.
- :func:`run_sequences` / :func:`open_sequences`: ``roft-sim run`` as a library call.
- :mod:`roft_sim.harness.outputs`: the files a run writes and their readers.
- :class:`WallClock`: run the tracker against a real clock instead (docs/wall_clock.md).

See docs/running.md.
"""

from roft_sim.harness.evaluation import SequenceEvaluation, evaluate_run
from roft_sim.harness.inputs import (
    LazyDepthRenderer,
    ResolvedInputs,
    WithGroundTruthPoses,
    mujoco_depth_renderer,
    resolve_inputs,
    resolve_object_model,
)
from roft_sim.harness.options import AUTO, GT_SET, NO_SET, RunOptions
from roft_sim.harness.run_dataset import (
    METRICS_FILE,
    RUN_FILE,
    RunResult,
    SequenceSource,
    find_sequences,
    open_sequences,
    run_sequences,
)
from roft_sim.harness.runner import SeedPlan, SequenceRun, run_sequence, seed_plan
from roft_sim.harness.wall_clock import WallClock

__all__ = [
    "AUTO",
    "GT_SET",
    "NO_SET",
    "METRICS_FILE",
    "RUN_FILE",
    "RunOptions",
    "RunResult",
    "SeedPlan",
    "SequenceEvaluation",
    "SequenceRun",
    "SequenceSource",
    "WallClock",
    "LazyDepthRenderer",
    "ResolvedInputs",
    "WithGroundTruthPoses",
    "evaluate_run",
    "find_sequences",
    "mujoco_depth_renderer",
    "open_sequences",
    "resolve_inputs",
    "resolve_object_model",
    "run_sequence",
    "run_sequences",
    "seed_plan",
]
