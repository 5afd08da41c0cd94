"""Order invariance within the buffer horizon, and the horizon rule, on generated schedules.

- Order invariance (metrics_faults_flow.md 4.4, 3): the same poses, delivered in any other order
  within the horizon, give the same estimates (1e-9) at every frame where both runs have received
  every pose captured so far.
- Horizon rule (4.4, 4): a pose older than the horizon is dropped, reported (id and counter) and
  changes no estimate, bit for bit. naive-delay must break it (it files every pose under its
  arrival frame, so no pose is ever too old).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from property_settings import HORIZON_FRAMES, POSE_ONLY, ROFT_TINY, budget

from roft_sim.records import PoseDetection
from roft_sim.testing import (
    check_horizon_rule,
    check_same_estimates,
    permute_pose_arrivals,
    reschedule_poses,
    settled_frames,
    tracker_for,
)
from roft_sim.testing.stream_strategies import faulted_streams, pose_timing_faults
from roft_sim.trackers import run_tracker

SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large]
TRACKERS = [("roft", ROFT_TINY), ("pose-only-ukf", POSE_ONLY)]


def _within_horizon(observations):
    """The observations without the poses the tracker must drop as too old (or from the future),
    so that every permutation of the rest delivers the same set of usable poses."""
    return reschedule_poses(
        observations,
        lambda d: d.arrival_k if 0 <= d.arrival_k - d.capture_k <= HORIZON_FRAMES else None,
    )


@pytest.mark.parametrize("tracker, config", TRACKERS, ids=[t for t, _ in TRACKERS])
@settings(max_examples=budget(15, 500), deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_any_arrival_order_within_the_horizon_gives_the_same_estimates(
    roft_seq, tracker, config, data
):
    stream = data.draw(faulted_streams(roft_seq, pose_timing_faults()), label="stream")
    base = _within_horizon(stream.observations())
    n_deliveries = sum(len(o.poses) for o in base)
    order = data.draw(st.permutations(range(n_deliveries)), label="arrival order")
    permuted = permute_pose_arrivals(base, order, max_delay_frames=HORIZON_FRAMES)
    both = settled_frames(base) & settled_frames(permuted)
    result = check_same_estimates(
        lambda: tracker_for(tracker, roft_seq, config),
        base,
        permuted,
        frames=both,
        name="order invariance",
    )
    result.raise_if_failed()


def test_a_fixed_permutation_is_checked_on_the_last_frame(roft_seq):
    """A regression example: five poses delivered in reverse order at the end of the horizon."""
    from roft_sim.testing import FaultedStream

    stream = FaultedStream(sequence=roft_seq, faults=_every_third_frame(), seed=0)
    base = _within_horizon(stream.observations())
    n = sum(len(o.poses) for o in base)
    reverse = list(reversed(range(n)))
    permuted = permute_pose_arrivals(base, reverse, max_delay_frames=HORIZON_FRAMES)
    assert [d.capture_k for o in permuted for d in o.poses] != [
        d.capture_k for o in base for d in o.poses
    ]
    last = np.zeros(len(base), dtype=bool)
    last[-1] = True
    for tracker, config in TRACKERS:
        result = check_same_estimates(
            lambda t=tracker, c=config: tracker_for(t, roft_seq, c), base, permuted, frames=last
        )
        assert result.raise_if_failed().frames_checked == 1


def _every_third_frame():
    from roft_sim.faults import FaultConfig, FixedDelay, PoseStreamFaults, Rate, load_faults

    return FaultConfig(
        name="every third frame, 4 late",
        pose=PoseStreamFaults(faults=(Rate(period_frames=3), FixedDelay(frames=4))),
        mask=load_faults("paper").mask,
    )


@st.composite
def _late_poses(draw, n_frames: int):
    """A pose captured at c, arriving more than the horizon later."""
    c = draw(st.integers(0, n_frames - HORIZON_FRAMES - 2))
    a = draw(st.integers(c + HORIZON_FRAMES + 1, n_frames - 1))
    return c, a


@pytest.mark.parametrize("tracker, config", TRACKERS, ids=[t for t, _ in TRACKERS])
@settings(max_examples=budget(12, 400), deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_poses_older_than_the_horizon_are_dropped_counted_and_change_nothing(
    roft_seq, tracker, config, data
):
    stream = data.draw(
        faulted_streams(roft_seq, pose_timing_faults(max_delay_frames=8)), label="stream"
    )
    c, a = data.draw(_late_poses(len(roft_seq)), label="late pose (capture, arrival)")
    late = PoseDetection(
        capture_k=c,
        arrival_k=a,
        T_cam_obj=roft_seq.detector_poses("gt").T_cam_obj[c].copy(),
        detection_id=10**6,
    )
    result = check_horizon_rule(
        lambda: tracker_for(tracker, roft_seq, config),
        stream.observations(),
        late,
        horizon_frames=HORIZON_FRAMES,
        counter="total_poses_dropped_too_old",
    )
    result.raise_if_failed()


def test_naive_delay_breaks_the_horizon_rule(roft_seq):
    """Mutation check: naive-delay fuses the too-old pose as if it were current."""
    stream = _every_third_frame()
    from roft_sim.testing import FaultedStream

    obs = FaultedStream(sequence=roft_seq, faults=stream, seed=0).observations()
    late = PoseDetection(
        capture_k=2,
        arrival_k=20,
        T_cam_obj=roft_seq.detector_poses("gt").T_cam_obj[2].copy(),
        detection_id=10**6,
    )
    result = check_horizon_rule(
        lambda: tracker_for("naive-delay", roft_seq, POSE_ONLY),
        obs,
        late,
        horizon_frames=HORIZON_FRAMES,
        counter="total_poses_dropped_too_old",
    )
    assert not result.passed
    assert "is not in dropped_pose_ids" in result.violations[0]
    assert any("went from 0 to 0, not +1" in v for v in result.violations)
    # it was judged as a current pose (fused, or rejected by a distance gate where the config
    # has one), not dropped for its age
    with_late = list(obs)
    with_late[20] = dataclasses.replace(obs[20], poses=(*obs[20].poses, late))
    judged = run_tracker(tracker_for("naive-delay", roft_seq, POSE_ONLY), with_late)[20]
    assert late.detection_id in judged.accepted_pose_ids + judged.rejected_pose_ids
