"""check_well_formed: a good run passes; every defect is named with its frame."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from roft_sim.geometry import matrix_from_rotvec
from roft_sim.records import Estimate, Observation
from roft_sim.testing import assert_well_formed, check_well_formed


def _estimate(frame: int, **changes) -> Estimate:
    k = frame
    T = np.eye(4)
    T[:3, :3] = matrix_from_rotvec([0.1 * k, -0.2, 0.3])
    T[:3, 3] = [0.0, 0.01 * k, 0.5]
    A = np.random.default_rng(k).normal(size=(12, 12))
    base = Estimate(k=k, T_cam_obj=T, v_obj_mps=np.zeros(3), w_radps=np.ones(3),
                    covariance=A @ A.T + 0.1 * np.eye(12), spatial_twist=np.zeros(6))  # fmt: skip
    return dataclasses.replace(base, **changes)


GOOD = [_estimate(k) for k in range(4)]


def _with(index: int, **changes) -> list[Estimate]:
    out = list(GOOD)
    out[index] = _estimate(index, **changes)
    return out


def _observations(times):
    return [Observation(k=k, t_s=t, rgb=None, depth_m=None, flow=None) for k, t in enumerate(times)]


def test_a_good_run_is_well_formed():
    report = assert_well_formed(GOOD, _observations([0.0, 0.1, 0.2, 0.3]))
    assert report.passed and report.min_eigenvalue > 0.09
    assert report.max_orthonormality_error < 1e-14
    assert str(report) == "4 estimates well formed"


def _bad_T(kind: str) -> np.ndarray:
    T = _estimate(2).T_cam_obj.copy()
    if kind == "nan":
        T[0, 3] = np.nan
    elif kind == "scaled":
        T[:3, :3] *= 1.001
    elif kind == "reflection":
        T[:3, 0] *= -1
    elif kind == "last row":
        T[3, 0] = 1e-3
    return T


def _bad_P(kind: str) -> np.ndarray:
    P = _estimate(2).covariance.copy()
    if kind == "asymmetric":
        P[0, 1] += 1e-6
    elif kind == "indefinite":
        P[5, 5] = -1.0
    elif kind == "singular":
        P = np.diag([1.0] * 11 + [1e-16])
    return P


@pytest.mark.parametrize(
    "changes, problem",
    [
        ({"T_cam_obj": _bad_T("nan")}, "frame 2: T_cam_obj has 1 non-finite values"),
        ({"T_cam_obj": _bad_T("scaled")}, r"frame 2: rotation not orthonormal, max \|R\^T R - I\|"),
        ({"T_cam_obj": _bad_T("reflection")}, "frame 2: rotation has determinant -1.000"),
        ({"T_cam_obj": _bad_T("last row")}, r"frame 2: last row of T_cam_obj is \[0.001, 0.0"),
        ({"covariance": _bad_P("asymmetric")}, "frame 2: covariance not symmetric"),
        ({"covariance": _bad_P("indefinite")}, "frame 2: covariance not positive definite"),
        ({"covariance": _bad_P("singular")}, "condition number 1.00e\\+16 > 1e\\+14"),
        ({"w_radps": np.array([0.0, np.inf, 0.0])}, "frame 2: w_radps has 1 non-finite values"),
        ({"spatial_twist": np.full(6, np.nan)}, "frame 2: spatial_twist has 6 non-finite"),
        ({"accepted_pose_ids": (3,), "rejected_pose_ids": (3,)}, r"pose ids \[3\] both accepted"),
        ({"k": 1}, "frame 1: frame index does not increase \\(previous 1\\)"),
    ],
)
def test_each_defect_is_named(changes, problem):
    report = check_well_formed(_with(2, **changes))
    assert not report.passed
    assert len(report.problems) >= 1
    assert any(re.search(problem, p) for p in report.problems), report.problems
    with pytest.raises(AssertionError, match="problems in 4 estimates"):
        assert_well_formed(_with(2, **changes))


def test_observation_time_stamps_and_pairing():
    report = check_well_formed(GOOD, _observations([0.0, 0.2, 0.2, 0.3]))
    assert report.problems == ("frame 2: time stamp 0.2 s does not increase (previous 0.2 s)",)
    report = check_well_formed(GOOD[:3], _observations([0.0, 0.1, 0.2, 0.3]))
    assert "3 estimates for 4 observations" in report.problems[0]


def test_invalid_estimates_are_only_checked_for_finiteness_and_order():
    garbage = np.diag([2.0, 2.0, 2.0, 1.0])  # not a rotation: fine while invalid
    run = _with(1, valid=False, T_cam_obj=garbage, covariance=None)
    assert check_well_formed(run).passed
    assert not check_well_formed(_with(1, valid=False, T_cam_obj=_bad_T("nan"))).passed


def test_a_missing_covariance_is_a_problem_only_when_required():
    run = _with(0, covariance=None)
    assert check_well_formed(run).passed
    report = check_well_formed(run, require_covariance=True)
    assert report.problems == ("frame 0: no covariance",)
