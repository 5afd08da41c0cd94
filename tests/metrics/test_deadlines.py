"""The wall-clock scoring rule on hand-built delivery timelines (no threads, no clock)."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.metrics.deadlines import (
    deadline_stats,
    frame_deadlines_s,
    held_at_deadlines,
    pool_deadline_stats,
)

FPS = 10  # frame k released at k / 10 s, its deadline (k + 1) / 10 s


def test_deadlines_are_the_next_release():
    np.testing.assert_allclose(frame_deadlines_s(3, FPS), [0.1, 0.2, 0.3])


def test_each_frame_scores_the_latest_estimate_delivered_by_its_deadline():
    # estimate of frame:   0     1     2     3     4     5
    delivered = np.array([0.05, 0.25, 0.26, 0.30, np.nan, 0.58])
    held = held_at_deadlines(delivered, frame_deadlines_s(6, FPS))
    # frame 0: est 0 (0.05 <= 0.1); frame 1: still est 0 (est 1 came at 0.25 > 0.2);
    # frame 2: est 3 exactly at its deadline 0.3 counts, and is newer than est 1 and 2;
    # frame 3: est 3; frame 4: est 3 (est 4 never delivered, est 5 at 0.58 > 0.5); frame 5: est 5
    assert held.tolist() == [0, 0, 3, 3, 3, 5]


def test_frames_before_any_delivery_hold_nothing_and_ties_go_to_the_later_estimate():
    delivered = np.array([0.35, 0.35, 0.35, 0.5])
    held = held_at_deadlines(delivered, frame_deadlines_s(4, FPS))
    assert held.tolist() == [-1, -1, -1, 2]


def test_order_of_delivery_not_of_frame_decides():
    # an estimate of an older frame delivered after a newer one replaces it (what a consumer holds)
    held = held_at_deadlines(np.array([0.15, 0.12]), np.array([0.2]))
    assert held.tolist() == [0]


def test_bad_times_are_rejected():
    with pytest.raises(ValueError, match="finite or NaN"):
        held_at_deadlines(np.array([np.inf]), np.array([0.1]))
    with pytest.raises(ValueError, match="1-D"):
        held_at_deadlines(np.zeros((2, 2)), np.array([0.1]))


def test_stats_of_a_timeline():
    release = np.array([0.0, 0.1, 0.2, 0.3]) + np.array([0.0, 0.0, 0.004, 0.0])
    delivered = np.array([0.02, 0.25, 0.26, 0.38])
    seen = np.array([True, False, True, True])
    stats = deadline_stats(
        release_s=release,
        delivered_s=delivered,
        seen=seen,
        dropped_busy=~seen,
        fps=FPS,
        queue_max=None,
    )
    s = stats.summary()
    # latency over the seen frames 0, 2, 3: 20, 56, 80 ms
    assert s["latency_max_ms"] == pytest.approx(80.0)
    assert s["latency_p50_ms"] == pytest.approx(56.0)
    assert s["deadline_misses"] == 1  # frame 1 (0.25 > 0.2)
    assert s["frames_dropped_busy"] == 1
    assert s["frames_without_estimate"] == 0
    assert stats.estimate_age_frames.tolist() == [0, 1, 0, 0]
    assert s["estimate_age_max_frames"] == 1
    assert s["release_lag_max_ms"] == pytest.approx(4.0)
    assert s["queue_max"] is None
    pooled = pool_deadline_stats([stats, stats]).summary()
    assert pooled["deadline_misses"] == 2 and pooled["latency_max_ms"] == pytest.approx(80.0)
