"""roft_sim.testing.streams: faulted streams, re-timed detections, settled frames, trackers."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis.vendor.pretty import pretty

from roft_sim.errors import ConfigError, PluginError
from roft_sim.faults import (
    FaultConfig,
    FixedDelay,
    PoseStreamFaults,
    Rate,
    load_faults,
    schedule_detections,
)
from roft_sim.records import Observation, PoseDetection
from roft_sim.testing import (
    ConstantVelocityPoseModel,
    FaultedStream,
    draw_pose_scenario,
    permute_pose_arrivals,
    pose_delays,
    poses_at_capture,
    reschedule_poses,
    settled_frames,
    tracker_for,
)
from roft_sim.testing.analytic_scene import AnalyticBoxDepthRenderer
from roft_sim.testing.fixtures import analytic_sequence
from roft_sim.trackers.roft import RoftTracker


def _observations(n: int, deliveries: list[tuple[int, int, int]]) -> list[Observation]:
    """n empty frames with pose deliveries (capture, arrival, id), in the listed order."""
    poses: dict[int, list[PoseDetection]] = {}
    for c, a, i in deliveries:
        T = np.eye(4)
        T[0, 3] = c  # tells the capture frame apart
        poses.setdefault(a, []).append(
            PoseDetection(capture_k=c, arrival_k=a, T_cam_obj=T, detection_id=i)
        )
    empty = {"rgb": None, "depth_m": None, "flow": None}
    return [Observation(k=k, t_s=k / 30, poses=tuple(poses.get(k, ())), **empty) for k in range(n)]


def _arrivals(observations) -> list[tuple[int, int, int]]:
    """(capture, arrival, id) of every delivery, in delivery order."""
    return [(d.capture_k, d.arrival_k, d.detection_id) for o in observations for d in o.poses]


@pytest.fixture(scope="module")
def seq():
    return analytic_sequence(n_frames=12, width_px=32, height_px=24)


def test_faulted_stream_materialises_the_schedule_and_prints_its_timeline(seq):
    faults = load_faults("paper")
    stream = FaultedStream(sequence=seq, faults=faults, seed=5)
    observations = stream.observations()
    assert [o.k for o in observations] == list(range(12))
    assert observations[0].flow is None and observations[1].flow.from_k == 0
    expected = schedule_detections(12, faults, 5)
    assert _arrivals(observations) == [
        (e.reported_capture_k, e.arrival_k, e.detection_id) for e in expected.pose
    ]
    text = repr(stream)
    for line in faults.describe_lines():
        assert line in text
    assert "pose run" in text and "capture reported  arrival(s)" in text
    assert pretty(stream) == text  # hypothesis prints a drawn stream as its timeline
    assert stream.timeline().startswith("sequence 'analytic_box', seed 5")


def test_faulted_stream_rejects_a_bad_seed(seq):
    with pytest.raises(ConfigError, match="seed must be an integer >= 0, got -1"):
        FaultedStream(sequence=seq, faults=load_faults("none"), seed=-1)


def test_reschedule_moves_drops_and_keeps_delivery_order():
    obs = _observations(6, [(0, 2, 0), (1, 2, 1), (3, 5, 2)])
    out = reschedule_poses(obs, lambda d: None if d.detection_id == 1 else d.capture_k + 1)
    assert _arrivals(out) == [(0, 1, 0), (3, 4, 2)]
    assert _arrivals(obs) == [(0, 2, 0), (1, 2, 1), (3, 5, 2)]  # inputs untouched
    together = reschedule_poses(obs, lambda d: 5)
    assert _arrivals(together) == [(0, 5, 0), (1, 5, 1), (3, 5, 2)]


def test_reschedule_errors_name_the_problem():
    obs = _observations(4, [(0, 1, 0)])
    with pytest.raises(ValueError, match="moved to frame 4, outside the 4 observed frames"):
        reschedule_poses(obs, lambda d: 4)
    with pytest.raises(ValueError, match="position 0 holds frame 1"):
        reschedule_poses(obs[1:], lambda d: 0)


def test_poses_at_capture_honours_the_horizon_and_drops_future_poses():
    obs = _observations(20, [(0, 3, 0), (2, 15, 1), (9, 8, 2), (5, 5, 3)])
    assert _arrivals(poses_at_capture(obs)) == [(0, 0, 0), (2, 2, 1), (5, 5, 3)]
    assert _arrivals(poses_at_capture(obs, max_delay_frames=10)) == [(0, 0, 0), (5, 5, 3)]
    assert pose_delays(obs) == [3, 0, -1, 13]


def test_settled_frames_by_hand():
    # capture 0 at 0; capture 2 at 5; capture 3 at 4; capture 6 at 19 (13 late)
    obs = _observations(20, [(0, 0, 0), (3, 4, 1), (2, 5, 2), (6, 19, 3)])
    expected = np.zeros(20, bool)
    expected[[0, 1, 5]] = True
    expected[19] = True
    np.testing.assert_array_equal(settled_frames(obs), expected)
    with_horizon = expected.copy()
    with_horizon[5:] = True  # the 13-frame-late pose is past a 10-frame horizon: ignored
    np.testing.assert_array_equal(settled_frames(obs, max_delay_frames=10), with_horizon)
    assert not settled_frames(_observations(5, [])).any()  # no pose: nothing to compare


def test_permute_pose_arrivals_swaps_and_clips_to_the_horizon():
    obs = _observations(12, [(0, 1, 0), (2, 4, 1), (3, 9, 2)])
    out = permute_pose_arrivals(obs, [2, 1, 0])
    assert sorted(_arrivals(out)) == [(0, 9, 0), (2, 4, 1), (3, 3, 2)]  # 1 < capture 3: clipped
    clipped = permute_pose_arrivals(obs, [2, 1, 0], max_delay_frames=5)
    assert sorted(_arrivals(clipped)) == [(0, 5, 0), (2, 4, 1), (3, 3, 2)]
    with pytest.raises(ValueError, match=r"permutation of range\(3\)"):
        permute_pose_arrivals(obs, [0, 0, 1])


def test_permute_pose_arrivals_reorders_deliveries_within_a_frame():
    """Regression: two poses delivered at one frame, swapped, arrive in the swapped order (the
    within-frame order used to stay the original one, so such permutations tested nothing)."""
    obs = _observations(8, [(1, 4, 0), (2, 4, 1), (3, 6, 2)])
    assert _arrivals(permute_pose_arrivals(obs, [1, 0, 2])) == [(2, 4, 1), (1, 4, 0), (3, 6, 2)]
    assert _arrivals(permute_pose_arrivals(obs, [0, 1, 2])) == _arrivals(obs)
    # delivery 0 takes the slot of delivery 2 (frame 6), delivery 2 the slot of delivery 0 (frame
    # 4, before delivery 1's slot); delivery 1 keeps its slot
    assert _arrivals(permute_pose_arrivals(obs, [2, 1, 0])) == [(3, 4, 2), (2, 4, 1), (1, 6, 0)]


def test_tracker_for_injects_the_analytic_renderer_and_finds_names(seq):
    roft = tracker_for("roft", seq)
    assert isinstance(roft, RoftTracker)
    assert isinstance(roft._context.depth_renderer, AnalyticBoxDepthRenderer)
    assert roft._context.intrinsics == seq.intrinsics and roft._context.fps == seq.fps
    scenario = draw_pose_scenario(
        ConstantVelocityPoseModel(), n_frames=3, rng=np.random.default_rng(0)
    )
    assert tracker_for("pose-only-ukf", scenario.sequence) is not None
    with pytest.raises(PluginError, match="no tracker named 'nope'"):
        tracker_for("nope", seq)


def test_faults_only_on_poses_leave_the_mask_stream_alone(seq):
    paper = load_faults("paper")
    faults = FaultConfig(
        pose=PoseStreamFaults(faults=(Rate(period_frames=2), FixedDelay(frames=3))),
        mask=paper.mask,
    )
    a = FaultedStream(sequence=seq, faults=faults, seed=0).observations()
    b = FaultedStream(sequence=seq, faults=paper, seed=0).observations()
    assert [len(o.masks) for o in a] == [len(o.masks) for o in b]
    assert set(pose_delays(a)) == {3}
