"""Synchronisation figures (arrivals, recovery, outlier catches) and step-time statistics."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.metrics import (
    error_around_arrivals,
    error_band,
    outlier_rejection_stats,
    outlier_rejection_stats_from_estimates,
    recovery_frames,
    step_time_stats,
)
from roft_sim.records import Estimate


def test_error_around_arrivals_on_a_sawtooth():
    # Error grows by 1 per frame since the last arrival (every 6 frames), reset at arrival.
    err = np.tile(np.arange(6.0), 10)
    arrivals = np.arange(6, 60, 6)
    eff = error_around_arrivals(err, arrivals, window=3)
    assert eff.arrivals == 9
    np.testing.assert_allclose(eff.mean_at_offset, [3, 4, 5, 0, 1, 2])
    assert eff.before_mean == pytest.approx(4.0) and eff.after_mean == pytest.approx(1.0)
    assert eff.ratio == pytest.approx(0.25)
    edge = error_around_arrivals(err, [0, 1], window=3)  # frames before 0 do not exist
    assert np.isnan(edge.mean_at_offset[0]) and np.isfinite(edge.after_mean)
    with pytest.raises(ValueError, match=r"arrival_frames must lie in \[0, 59\]"):
        error_around_arrivals(err, [60])


def test_recovery_frames_hand_case():
    err = np.array([1, 1, 9, 9, 9, 5, 1, 2, 1, 1, 9, 9, 9, 9], dtype=float)
    # Bursts end at frames 5 and 13; with band 2 the first is back at frame 6, the second never.
    np.testing.assert_allclose(recovery_frames(err, [5, 13], band=2.0), [1, np.inf])
    np.testing.assert_allclose(recovery_frames(err, [5], band=2.0, hold=2), [1])  # 6, 7 in band
    np.testing.assert_allclose(recovery_frames(err, [5], band=1.5, hold=2), [3])  # 8, 9
    np.testing.assert_allclose(recovery_frames(err, [0], band=2.0), [0])
    assert error_band(err, quantile=0.5, mask=err < 9) == pytest.approx(1.0)


def test_outlier_rejection_stats_counts_and_intervals():
    accepted = [(1, 2), (), (3, 4, 5), (6,)]
    rejected = [(), (7,), (8, 2), (9,)]  # 2 rejected once but accepted earlier: ambiguous
    injected = [7, 8, 10, 6]  # 10 never seen; 6 accepted (missed)
    s = outlier_rejection_stats(accepted, rejected, injected)
    assert s.poses_seen == 9 and s.poses_rejected == 3 and s.ambiguous == 1
    assert s.injected_seen == 3 and s.injected_caught == 2 and s.injected_unseen == 1
    assert s.false_rejections == 1  # id 9
    assert s.catch_rate == pytest.approx(2 / 3)
    assert s.false_rejection_rate == pytest.approx(1 / 6)
    assert s.rejected_fraction == pytest.approx(3 / 9)
    lo, hi = s.catch_rate_ci
    assert 0 <= lo < 2 / 3 < hi <= 1
    ests = [
        Estimate(
            k=k,
            T_cam_obj=np.eye(4),
            v_obj_mps=np.zeros(3),
            w_radps=np.zeros(3),
            accepted_pose_ids=a,
            rejected_pose_ids=r,
        )
        for k, (a, r) in enumerate(zip(accepted, rejected, strict=True))
    ]
    assert outlier_rejection_stats_from_estimates(ests, injected) == s


def test_step_time_stats_against_numpy():
    rng = np.random.default_rng(0)
    t = rng.gamma(4.0, 0.005, 501)
    s = step_time_stats(t)
    assert s.median_ms == pytest.approx(1e3 * np.median(t))
    assert s.p95_ms == pytest.approx(1e3 * np.percentile(t, 95))
    assert s.over_budget == int(np.sum(t > 1 / 30))
    assert s.steps == 501
    with pytest.raises(ValueError, match="finite and >= 0"):
        step_time_stats([0.01, -1.0])
    assert np.isnan(step_time_stats([]).median_ms)
