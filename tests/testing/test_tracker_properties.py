"""roft_sim.testing.tracker_properties: each check passes a tracker that has the property and
catches toy trackers built to break it (the checks have teeth)."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from roft_sim.geometry import matrix_from_rotvec
from roft_sim.records import Estimate, Observation, PoseDetection, PoseTrack
from roft_sim.testing import (
    REPLAY_EXACT,
    PropertyResult,
    check_delay_invariance,
    check_determinism,
    check_error_bounded,
    check_horizon_rule,
    check_recovery,
    check_same_estimates,
    estimate_differences,
    pose_errors,
)


class NewestCapture:
    """Reports the pose with the newest capture frame (delay- and order-invariant)."""

    def reset(self, initial):
        self.best = None

    def step(self, obs: Observation) -> Estimate:
        for d in obs.poses:
            if self.best is None or d.capture_k > self.best.capture_k:
                self.best = d
        if self.best is None:
            return Estimate.invalid(obs.k)
        return Estimate(k=obs.k, T_cam_obj=self.best.T_cam_obj, v_obj_mps=np.zeros(3),
                        w_radps=np.zeros(3), covariance=np.eye(12))  # fmt: skip


class LastArrival(NewestCapture):
    """Reports the last pose to arrive: breaks delay and order invariance."""

    def step(self, obs):
        if obs.poses:
            self.best = obs.poses[-1]
        return NewestCapture.step(self, Observation(k=obs.k, t_s=obs.t_s, rgb=None,
                                                    depth_m=None, flow=None))  # fmt: skip


class Horizon(NewestCapture):
    """NewestCapture that drops poses older than 5 frames (and counts them), or, with
    ``broken``, accepts them."""

    def __init__(self, broken=False):
        self.broken = broken

    def reset(self, initial):
        super().reset(initial)
        self.too_old = 0

    def step(self, obs):
        fresh, old = [], []
        for d in obs.poses:
            (old if obs.k - d.capture_k > 5 and not self.broken else fresh).append(d)
        self.too_old += len(old)
        e = NewestCapture.step(self, Observation(k=obs.k, t_s=obs.t_s, rgb=None, depth_m=None,
                                                  flow=None, poses=tuple(fresh)))  # fmt: skip
        return Estimate(k=e.k, T_cam_obj=e.T_cam_obj, v_obj_mps=e.v_obj_mps, w_radps=e.w_radps,
                        valid=e.valid, dropped_pose_ids=tuple(d.detection_id for d in old),
                        diagnostics={"too_old": self.too_old})  # fmt: skip


_counter = itertools.count()


class Jittery(NewestCapture):
    """Adds a different tiny offset in every instance: not deterministic."""

    def reset(self, initial):
        super().reset(initial)
        self.offset = 1e-12 * next(_counter)

    def step(self, obs):
        e = super().step(obs)
        if e.valid:
            T = e.T_cam_obj.copy()
            T[0, 3] += self.offset
            e = Estimate(k=e.k, T_cam_obj=T, v_obj_mps=e.v_obj_mps, w_radps=e.w_radps)
        return e


def _pose(c: int) -> np.ndarray:
    T = np.eye(4)
    T[:3, 3] = [0.01 * c, 0.0, 0.5]
    T[:3, :3] = matrix_from_rotvec([0.0, 0.02 * c, 0.0])
    return T


def _observations(n, deliveries):
    poses: dict[int, list[PoseDetection]] = {}
    for c, a, i in deliveries:
        det = PoseDetection(capture_k=c, arrival_k=a, T_cam_obj=_pose(c), detection_id=i)
        poses.setdefault(a, []).append(det)
    empty = {"rgb": None, "depth_m": None, "flow": None}
    return [Observation(k=k, t_s=k / 30, poses=tuple(poses.get(k, ())), **empty) for k in range(n)]


DELAYED = _observations(12, [(0, 0, 0), (3, 7, 1), (5, 6, 2), (8, 9, 3)])


def test_estimate_differences_by_hand():
    a = Estimate(k=0, T_cam_obj=_pose(0), v_obj_mps=np.zeros(3), w_radps=np.zeros(3))
    b = Estimate(k=0, T_cam_obj=_pose(5), v_obj_mps=np.ones(3), w_radps=np.zeros(3),
                 covariance=np.eye(12))  # fmt: skip
    d = estimate_differences(a, b)
    assert d["position_m"] == pytest.approx(0.05) and d["rotation_rad"] == pytest.approx(0.1)
    assert d["v_obj_mps"] == pytest.approx(np.sqrt(3)) and d["covariance"] == np.inf
    assert d["valid"] == 0.0 and estimate_differences(a, Estimate.invalid(0))["valid"] == 1.0
    assert d["spatial_v_mps"] == 0.0 == d["spatial_w_radps"]  # neither carries one


def test_invariance_compares_the_spatial_twist_too():
    """Review regression: a tracker whose spatial twist (ROFT's velocity output, what the
    reference evaluation scores) depends on delays passed delay invariance unnoticed."""
    twist = np.array([0.1, 0.0, 0.0, 0.0, 0.2, 0.0])
    a = Estimate(k=0, T_cam_obj=_pose(0), v_obj_mps=np.zeros(3), w_radps=np.zeros(3),
                 spatial_twist=twist)  # fmt: skip
    b = dataclasses.replace(a, spatial_twist=twist + [0.0, 0.03, 0.0, 0.0, 0.0, 0.04])
    d = estimate_differences(a, b)
    assert d["spatial_v_mps"] == pytest.approx(0.03) and d["spatial_w_radps"] == pytest.approx(0.04)
    assert estimate_differences(a, dataclasses.replace(a, spatial_twist=None))["spatial_v_mps"] == (
        np.inf
    )
    assert {"spatial_v_mps", "spatial_w_radps"} <= set(REPLAY_EXACT.limits())


def test_delay_invariance_holds_for_newest_capture_and_fails_for_last_arrival():
    good = check_delay_invariance(NewestCapture, DELAYED)
    assert good.passed and good.frames_checked == 7  # settled: frames 0-2, 7, 9-11
    bad = check_delay_invariance(LastArrival, DELAYED)
    assert not bad.passed
    assert bad.violations[0].startswith("frame 7: position_m differs by 2.000e-02")
    with pytest.raises(AssertionError, match="delay invariance FAILS on 7 checked frames"):
        bad.raise_if_failed()


def test_same_estimates_compares_only_the_given_frames():
    reordered = _observations(12, [(0, 0, 0), (8, 9, 3), (3, 9, 1), (5, 9, 2)])
    assert check_same_estimates(LastArrival, DELAYED, reordered, frames=[0, 1, 2]).passed
    result = check_same_estimates(LastArrival, DELAYED, reordered, frames=[11])
    assert not result.passed and result.frames_checked == 1
    with pytest.raises(ValueError, match="differ in length"):
        check_same_estimates(LastArrival, DELAYED, DELAYED[:5])


def test_horizon_rule_passes_a_dropping_tracker_and_catches_one_that_keeps_old_poses():
    late = PoseDetection(capture_k=2, arrival_k=10, T_cam_obj=_pose(20), detection_id=99)
    base = _observations(12, [(0, 0, 0), (1, 1, 1)])  # the late pose would become the newest
    ok = check_horizon_rule(Horizon, base, late, horizon_frames=5, counter="too_old")
    assert ok.passed, ok.message()
    bad = check_horizon_rule(lambda: Horizon(broken=True), base, late, horizon_frames=5,
                             counter="too_old")  # fmt: skip
    assert not bad.passed
    assert bad.violations[0].startswith("frame 10: the pose 99 captured at 2 is not in")
    assert "went from 0 to 0" in bad.violations[1]
    with pytest.raises(ValueError, match="must be more than horizon_frames = 8"):
        check_horizon_rule(Horizon, base, late, horizon_frames=8)
    with pytest.raises(ValueError, match="detection_id 0 is already used"):
        used = PoseDetection(capture_k=0, arrival_k=9, T_cam_obj=_pose(0), detection_id=0)
        check_horizon_rule(Horizon, base, used, horizon_frames=5)
    for arrival in (12, -1):  # regression: an IndexError, or the last frame silently used
        outside = PoseDetection(capture_k=-9, arrival_k=arrival, T_cam_obj=_pose(0),
                                detection_id=98)  # fmt: skip
        with pytest.raises(ValueError, match=f"arrives at frame {arrival}, outside the 12"):
            check_horizon_rule(Horizon, base, outside, horizon_frames=5)


def test_determinism_is_bitwise():
    assert check_determinism(NewestCapture, DELAYED, runs=3).passed
    result = check_determinism(Jittery, DELAYED)
    assert not result.passed and "T_cam_obj differs" in result.violations[0]
    with pytest.raises(ValueError, match="runs >= 2"):
        check_determinism(NewestCapture, DELAYED, runs=1)


def _truth(n: int) -> PoseTrack:
    T = np.stack([_pose(0)] * n)
    return PoseTrack(t_s=np.arange(n) / 30, T_cam_obj=T, v_obj_mps=np.zeros((n, 3)),
                     w_radps=np.zeros((n, 3)))  # fmt: skip


def _with_errors(errors_m):
    out = []
    for k, e in enumerate(errors_m):
        if np.isnan(e):
            out.append(Estimate.invalid(k))
            continue
        T = _pose(0)
        T[1, 3] += e
        out.append(Estimate(k=k, T_cam_obj=T, v_obj_mps=np.zeros(3), w_radps=np.zeros(3)))
    return out


def test_error_bounded_and_recovery_by_hand():
    errors = [0.0, 0.01, 0.2, 0.3, 0.2, 0.05, 0.01, 0.01, 0.2, 0.01, 0.0, 0.0]
    #                       burst ends at 4 ^        a relapse at 8 ^
    estimates, truth = _with_errors(errors), _truth(12)
    pos, rot = pose_errors(estimates, truth)
    np.testing.assert_allclose(pos, errors, atol=1e-12)
    np.testing.assert_allclose(rot, 0.0, atol=1e-12)
    bounded = check_error_bounded(estimates, truth, bound_m=0.1, bound_rad=0.1)
    assert not bounded.passed and len(bounded.violations) == 4
    assert bounded.worst["position_m"] == pytest.approx(0.3)
    rec = check_recovery(estimates, truth, burst_end_k=4, within_frames=5, bound_m=0.1,
                         bound_rad=0.1)  # fmt: skip
    assert rec.passed and rec.worst["recovery_frames"] == 5  # inside from frame 9 on
    late = check_recovery(estimates, truth, burst_end_k=4, within_frames=4, bound_m=0.1,
                          bound_rad=0.1)  # fmt: skip
    assert not late.passed and "frame 8: position error 0.2000 m > 0.1000 m" in late.violations
    # regression: a window past the last frame checked nothing and passed, even a run that never
    # recovers (recovery_frames inf)
    never = _with_errors([0.0, 0.3, 0.3, 0.3, 0.3, 0.3])
    for within in (5, 9):
        with pytest.raises(ValueError, match=f"from frame {1 + within} on: no frame left"):
            check_recovery(never, _truth(6), burst_end_k=1, within_frames=within, bound_m=0.1,
                           bound_rad=0.1)  # fmt: skip
    with pytest.raises(ValueError, match="within_frames must be >= 0, got -1"):
        check_recovery(estimates, truth, burst_end_k=4, within_frames=-1, bound_m=0.1,
                       bound_rad=0.1)  # fmt: skip
    invalid = _with_errors([0.0, np.nan, 0.0])
    loose = {"bound_m": 1.0, "bound_rad": 1.0}
    assert not check_error_bounded(invalid, _truth(3), **loose).passed
    assert check_error_bounded(invalid, _truth(3), allow_invalid=True, **loose).passed


def test_property_result_message_lists_the_first_violations():
    result = PropertyResult(name="p", passed=False, frames_checked=9,
                            violations=tuple(f"v{i}" for i in range(8)))  # fmt: skip
    text = result.message()
    assert text.startswith("p FAILS on 9 checked frames")
    assert "v4" in text and "v5" not in text and "and 3 more violations" in text
    ok = PropertyResult(name="p", passed=True, frames_checked=1)
    assert ok.raise_if_failed() is ok and str(ok) == "p holds on 1 checked frames"
