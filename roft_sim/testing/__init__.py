"""Public test toolkit: property tests of trackers and filters under injected delays and faults.

The names below are importable from ``roft_sim.testing`` directly; they are loaded on first use
(PEP 562), so importing the package, which the pytest plugin does in every pytest run, costs
nothing. None of them imports hypothesis; the strategies live in
:mod:`roft_sim.testing.stream_strategies`, :mod:`roft_sim.testing.fault_strategies`,
:mod:`roft_sim.testing.trajectory_strategies` and :mod:`roft_sim.testing.strategies`.

- assertions: :func:`assert_pose_close`, :func:`assert_quat_close`,
  :func:`assert_rotation_close`, :func:`assert_twist_close` (unit-bearing tolerances);
- streams: :class:`FaultedStream`, :func:`poses_at_capture`, :func:`reschedule_poses`,
  :func:`settled_frames`, :func:`tracker_for`;
- properties: :func:`check_delay_invariance`, :func:`check_same_estimates`,
  :func:`check_horizon_rule`, :func:`check_determinism`, :func:`check_error_bounded`,
  :func:`check_recovery` (each returns a :class:`PropertyResult`);
- well-formedness: :func:`check_well_formed`, :func:`assert_well_formed`;
- consistency: :func:`check_consistency`, :func:`check_error_consistency`,
  :func:`assert_consistent`; Monte-Carlo scenarios :class:`ConstantVelocityPoseModel`,
  :func:`draw_pose_scenario`, :func:`run_pose_monte_carlo`;
- sequences: :func:`analytic_sequence`, :func:`render_tiny_sequence`.

See docs/testing.md.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS: dict[str, str] = {
    # assertions
    "assert_pose_close": "assertions",
    "assert_quat_close": "assertions",
    "assert_rotation_close": "assertions",
    "assert_twist_close": "assertions",
    # streams
    "FaultedStream": "streams",
    "poses_at_capture": "streams",
    "reschedule_poses": "streams",
    "permute_pose_arrivals": "streams",
    "settled_frames": "streams",
    "pose_delays": "streams",
    "tracker_for": "streams",
    # properties
    "Tolerance": "tracker_properties",
    "EXACT": "tracker_properties",
    "REPLAY_EXACT": "tracker_properties",
    "PropertyResult": "tracker_properties",
    "estimate_differences": "tracker_properties",
    "check_same_estimates": "tracker_properties",
    "check_delay_invariance": "tracker_properties",
    "check_horizon_rule": "tracker_properties",
    "check_determinism": "tracker_properties",
    "pose_errors": "tracker_properties",
    "check_error_bounded": "tracker_properties",
    "check_recovery": "tracker_properties",
    # well-formedness
    "WellFormedReport": "well_formed",
    "check_well_formed": "well_formed",
    "assert_well_formed": "well_formed",
    # consistency
    "ConsistencyResult": "consistency_checks",
    "check_consistency": "consistency_checks",
    "check_error_consistency": "consistency_checks",
    "assert_consistent": "consistency_checks",
    "ConstantVelocityPoseModel": "monte_carlo",
    "PoseScenario": "monte_carlo",
    "MonteCarloRuns": "monte_carlo",
    "draw_pose_scenario": "monte_carlo",
    "run_pose_monte_carlo": "monte_carlo",
    # sequences
    "analytic_sequence": "fixtures",
    "render_tiny_sequence": "fixtures",
}

__all__ = [
    "ConsistencyResult",
    "ConstantVelocityPoseModel",
    "EXACT",
    "FaultedStream",
    "MonteCarloRuns",
    "PoseScenario",
    "PropertyResult",
    "REPLAY_EXACT",
    "Tolerance",
    "WellFormedReport",
    "analytic_sequence",
    "assert_consistent",
    "assert_pose_close",
    "assert_quat_close",
    "assert_rotation_close",
    "assert_twist_close",
    "assert_well_formed",
    "check_consistency",
    "check_delay_invariance",
    "check_determinism",
    "check_error_bounded",
    "check_error_consistency",
    "check_horizon_rule",
    "check_recovery",
    "check_same_estimates",
    "check_well_formed",
    "draw_pose_scenario",
    "estimate_differences",
    "permute_pose_arrivals",
    "pose_delays",
    "pose_errors",
    "poses_at_capture",
    "render_tiny_sequence",
    "reschedule_poses",
    "run_pose_monte_carlo",
    "settled_frames",
    "tracker_for",
]


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'roft_sim.testing' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"roft_sim.testing.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})


if TYPE_CHECKING:  # pragma: no cover - static imports for type checkers and IDEs
    from roft_sim.testing.assertions import (
        assert_pose_close,
        assert_quat_close,
        assert_rotation_close,
        assert_twist_close,
    )
    from roft_sim.testing.consistency_checks import (
        ConsistencyResult,
        assert_consistent,
        check_consistency,
        check_error_consistency,
    )
    from roft_sim.testing.fixtures import analytic_sequence, render_tiny_sequence
    from roft_sim.testing.monte_carlo import (
        ConstantVelocityPoseModel,
        MonteCarloRuns,
        PoseScenario,
        draw_pose_scenario,
        run_pose_monte_carlo,
    )
    from roft_sim.testing.streams import (
        FaultedStream,
        permute_pose_arrivals,
        pose_delays,
        poses_at_capture,
        reschedule_poses,
        settled_frames,
        tracker_for,
    )
    from roft_sim.testing.tracker_properties import (
        EXACT,
        REPLAY_EXACT,
        PropertyResult,
        Tolerance,
        check_delay_invariance,
        check_determinism,
        check_error_bounded,
        check_horizon_rule,
        check_recovery,
        check_same_estimates,
        estimate_differences,
        pose_errors,
    )
    from roft_sim.testing.well_formed import (
        WellFormedReport,
        assert_well_formed,
        check_well_formed,
    )
