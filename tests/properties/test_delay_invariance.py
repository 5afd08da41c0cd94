"""Delay invariance through the real fault pipeline: generated fault configurations, the
ObservationStream, and the trackers as registered.

Property (metrics_faults_flow.md 4.4, 1-3): once every pose captured up to frame k has arrived,
a delay-correct tracker's estimate at k equals (1e-9) that of a run in which every pose arrived
at its capture frame, whatever the delays, jitter, losses, duplicates, stale results, reordering
and outliers. ROFT and pose-only-ukf have it (rollback and replay); naive-delay and ROFT with
pose sync disabled must NOT have it, and hypothesis must find a counterexample for them (the
mutation check that the property has teeth).

tests/trackers/test_roft_tracker.py checks the same replay on hand-built delivery lists; here the
schedules come from roft_sim.testing.fault_strategies through roft_sim.faults.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, Phase, find, given, settings
from hypothesis import strategies as st
from property_settings import HORIZON_FRAMES, POSE_ONLY, ROFT_NO_SYNC, ROFT_TINY, budget

from roft_sim.faults import (
    FaultConfig,
    FixedDelay,
    PoseStreamFaults,
    Rate,
    Reorder,
    UniformDelay,
    load_faults,
)
from roft_sim.testing import FaultedStream, check_delay_invariance, pose_delays, tracker_for
from roft_sim.testing.stream_strategies import faulted_streams, pose_timing_faults

SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large]


def _paper_pose(*faults, first_result="undelayed") -> FaultConfig:
    paper = load_faults("paper")
    return FaultConfig(
        name="regression",
        pose=PoseStreamFaults(first_result=first_result, faults=faults),
        mask=paper.mask,
    )


def _holds(stream: FaultedStream, tracker: str, config=None):
    return check_delay_invariance(
        lambda: tracker_for(tracker, stream.sequence, config),
        stream.observations(),
        max_delay_frames=HORIZON_FRAMES,
    )


@pytest.fixture(scope="module")
def regression_stream(roft_seq):
    """Reordered 10 Hz poses, 4-12 frames late: the kind of schedule that broke naive fusion."""

    def make(*faults, seed=0, first_result="undelayed"):
        faults = _paper_pose(*faults, first_result=first_result)
        return FaultedStream(sequence=roft_seq, faults=faults, seed=seed)

    return make


@settings(max_examples=budget(15, 600), deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_roft_replay_gives_the_zero_delay_estimate(roft_seq, data):
    """ROFT under any pose timing, loss, delivery and outlier faults, and camera/flow faults."""
    stream = data.draw(
        faulted_streams(roft_seq, pose_timing_faults(outliers=True, camera=True)), label="stream"
    )
    _holds(stream, "roft", ROFT_TINY).raise_if_failed()


@settings(max_examples=budget(40, 600), deadline=None, suppress_health_check=SLOW_OK)
@given(data=st.data())
def test_pose_only_ukf_replay_gives_the_zero_delay_estimate(roft_seq, data):
    stream = data.draw(faulted_streams(roft_seq, pose_timing_faults()), label="stream")
    _holds(stream, "pose-only-ukf", POSE_ONLY).raise_if_failed()


@pytest.mark.parametrize(
    "faults",
    [
        (Rate(rate_hz=5), FixedDelay(frames=0)),  # zero-delay equivalence (4.4, 1)
        (Rate(rate_hz=10), FixedDelay(frames=6), Reorder(p=0.5, past_events=2)),
        (Rate(period_frames=2), FixedDelay(frames=HORIZON_FRAMES + 1)),  # all past the horizon
    ],
    ids=["zero-delay", "reordered", "beyond-horizon"],
)
def test_regression_schedules(regression_stream, faults):
    stream = regression_stream(*faults)
    for tracker, config in (("roft", ROFT_TINY), ("pose-only-ukf", POSE_ONLY)):
        result = _holds(stream, tracker, config).raise_if_failed()
        assert result.frames_checked > 0


def test_zero_delay_stream_is_the_undelayed_run(regression_stream):
    """Zero-delay equivalence: with FixedDelay(0) the delayed path IS the zero-delay one: every
    frame settles, and even naive-delay passes."""
    stream = regression_stream(Rate(rate_hz=5), FixedDelay(frames=0))
    obs = stream.observations()
    assert set(pose_delays(obs)) == {0}
    result = _holds(stream, "naive-delay", POSE_ONLY).raise_if_failed()
    assert result.frames_checked == len(obs)


def test_regression_jitter_across_the_horizon(regression_stream):
    """Found while writing the suite: jitter 0-13 frames, the first pose delayed, seed 3. The
    first poses arrive out of order (captures 2, 5, 6 at frame 10, capture 1 at 11: the filter
    initialises, then re-initialises), and the poses of frames 0 and 3 arrive 13 frames late,
    past the 12-frame horizon: the zero-delay run must leave exactly those two out (a tracker
    configured with another horizon than max_delay_frames fails here)."""
    stream = regression_stream(
        UniformDelay(min_frames=0, max_frames=13), seed=3, first_result="delayed"
    )
    delays = pose_delays(stream.observations())
    assert delays.count(13) == 2
    for tracker, config in (("roft", ROFT_TINY), ("pose-only-ukf", POSE_ONLY)):
        _holds(stream, tracker, config).raise_if_failed()


def test_regression_minimal_counterexample_of_apply_as_current(regression_stream):
    """The schedule hypothesis shrinks the mutation check below to: a pose on every frame, each
    one frame late. naive-delay and ROFT without pose sync fuse each pose one frame late; at
    the last frame (settled: its own pose arrives after the end) they differ by centimetres."""
    stream = regression_stream(FixedDelay(frames=1), first_result="delayed")
    for tracker, config in (("naive-delay", POSE_ONLY), ("roft", ROFT_NO_SYNC)):
        result = _holds(stream, tracker, config)
        assert not result.passed and result.worst["position_m"] > 0.005
    _holds(stream, "roft", ROFT_TINY).raise_if_failed()


# --------------------------------------------------------------------------- mutation checks

_FIND = settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=SLOW_OK,
    phases=[Phase.explicit, Phase.generate, Phase.shrink],
)


@pytest.mark.parametrize(
    "tracker, config",
    [
        ("naive-delay", POSE_ONLY),
        # slow: the fixed 1-frame regression stream above already fails ROFT without pose sync
        pytest.param("roft", ROFT_NO_SYNC, marks=pytest.mark.slow),
    ],
    ids=["naive-delay", "roft-without-pose-sync"],
)
def test_apply_as_current_fails_delay_invariance(roft_seq, tracker, config, capsys):
    """The mutation check: hypothesis finds a schedule on which a tracker that fuses delayed
    poses as if they were current differs from the zero-delay run, and shrinks it to a minimal
    one (printed as a timeline: run pytest -s to see it)."""
    strategy = faulted_streams(roft_seq, pose_timing_faults(max_delay_frames=8))
    counterexample = find(strategy, lambda s: not _holds(s, tracker, config).passed, settings=_FIND)
    result = _holds(counterexample, tracker, config)
    assert not result.passed
    print(f"\n{tracker}: minimal counterexample\n{counterexample!r}\n{result.message()}")
    # the shrunk schedule is small and readable: one delayed pose suffices
    assert len(counterexample.faults.pose.faults) <= 2
    assert max(pose_delays(counterexample.observations())) >= 1
    assert "pose run" in repr(counterexample) and "capture" in repr(counterexample)
    # and the delay-correct trackers pass on the very same schedule
    _holds(counterexample, "roft", ROFT_TINY).raise_if_failed()
    _holds(counterexample, "pose-only-ukf", POSE_ONLY).raise_if_failed()
