"""SequenceGenerator's memo of the pose estimator's unoccluded sample: the same detections as
the estimator run afresh for every frame, with the O(N) estimator run once for every fully
visible frame."""

from __future__ import annotations

import numpy as np
import pytest
from generation_cases import tiny_scenario

from roft_sim.generation import sequence_generator
from roft_sim.generation.sequence_generator import POSE_ESTIMATOR_STREAM, SequenceGenerator
from roft_sim.sensors.pose_estimator import sample_pose_detections

pytestmark = pytest.mark.render


def _fresh(generator: SequenceGenerator, k: int, vis_k: float):
    vis = np.ones(generator.n_frames)
    vis[k] = vis_k
    sample = sample_pose_detections(
        generator.track,
        generator.networks.pose.estimator_for(generator.scenario.object.name_or_path),
        generator.scenario.rng(POSE_ESTIMATOR_STREAM),
        visible_fraction=vis,
    )
    return sample.T_cam_obj[k] if sample.valid[k] else None


def test_unoccluded_detections_are_memoised_and_equal_fresh_ones(monkeypatch):
    calls = []
    real = sequence_generator.sample_pose_detections

    def counting(*args, **kwargs):
        calls.append(kwargs["visible_fraction"].copy())
        return real(*args, **kwargs)

    monkeypatch.setattr(sequence_generator, "sample_pose_detections", counting)
    scenario = tiny_scenario("cracker_box", frames=12)
    with SequenceGenerator(scenario) as generator:
        cases = [(k, 1.0) for k in range(12)] + [(3, 0.4), (7, 0.0), (5, 1.0)]
        got = [generator._pose_detection(k, v) for k, v in cases]
        want = [_fresh(generator, k, v) for k, v in cases]
    # one sample for the twelve fully visible frames, one per partly visible frame
    assert len(calls) == 3 and (calls[0] == 1.0).all()
    assert calls[1][3] == 0.4 and calls[2][7] == 0.0
    for g, w in zip(got, want, strict=True):
        assert (g is None) == (w is None)
        if g is not None:
            np.testing.assert_array_equal(g, w)
    assert any(g is not None for g in got)
