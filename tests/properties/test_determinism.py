"""Determinism (metrics_faults_flow.md 4.4, 10): the same seed and schedule give bit-identical
observations and estimates, for every registered tracker, under every fault family."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from property_settings import POSE_ONLY, ROFT_TINY, budget

from roft_sim.faults import load_faults
from roft_sim.testing import FaultedStream, check_determinism, tracker_for
from roft_sim.testing.fault_strategies import fault_configs
from roft_sim.testing.fixtures import analytic_sequence
from roft_sim.testing.stream_strategies import faulted_streams

SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large]
SEQ = analytic_sequence(n_frames=16, width_px=48, height_px=36)
TRACKERS = {
    "roft": ROFT_TINY,
    "pose-only-ukf": POSE_ONLY,
    "naive-delay": POSE_ONLY,
    "detector-hold": None,
}


def _same(u, v) -> bool:
    return (u is None) == (v is None) and (u is None or np.array_equal(u, v, equal_nan=True))


def _observations_equal(a, b) -> bool:
    """Every image, flow, pose and mask of two observation lists is identical."""
    for x, y in zip(a, b, strict=True):
        if not (_same(x.rgb, y.rgb) and _same(x.depth_m, y.depth_m)):
            return False
        if (x.flow is None) != (y.flow is None):
            return False
        if x.flow is not None and not (
            _same(x.flow.flow_px, y.flow.flow_px)
            and _same(x.flow.valid, y.flow.valid)
            and (x.flow.from_k, x.flow.to_k) == (y.flow.from_k, y.flow.to_k)
        ):
            return False
        key = lambda d: (d.capture_k, d.arrival_k, d.detection_id)  # noqa: E731
        if [key(d) for d in x.poses] != [key(d) for d in y.poses]:
            return False
        if [key(m) for m in x.masks] != [key(m) for m in y.masks]:
            return False
        pairs = [(p.T_cam_obj, q.T_cam_obj) for p, q in zip(x.poses, y.poses, strict=True)]
        pairs += [(m.mask, n.mask) for m, n in zip(x.masks, y.masks, strict=True)]
        if not all(np.array_equal(u, v) for u, v in pairs):
            return False
    return True


@settings(max_examples=budget(8, 300), deadline=None, suppress_health_check=SLOW_OK)
@given(stream=faulted_streams(SEQ, fault_configs()))
def test_same_seed_same_observations_and_bit_identical_estimates(stream):
    first = stream.observations()
    again = FaultedStream(sequence=SEQ, faults=stream.faults, seed=stream.seed).observations()
    assert _observations_equal(first, again)
    for name, config in TRACKERS.items():
        result = check_determinism(lambda n=name, c=config: tracker_for(n, SEQ, c), first, runs=3)
        result.raise_if_failed()


@pytest.mark.parametrize("preset", ["chaos", "paper-reference", "bursts"])
def test_presets_are_deterministic(preset):
    stream = FaultedStream(sequence=SEQ, faults=load_faults(preset), seed=7)
    observations = stream.observations()
    for name, config in TRACKERS.items():
        check_determinism(
            lambda n=name, c=config: tracker_for(n, SEQ, c), observations
        ).raise_if_failed()


def test_another_seed_changes_a_random_schedule():
    """The comparison has teeth: another seed gives another schedule of the same preset."""
    faults = load_faults("chaos")
    a = FaultedStream(sequence=SEQ, faults=faults, seed=1).observations()
    b = FaultedStream(sequence=SEQ, faults=faults, seed=2).observations()
    assert not _observations_equal(a, b)
