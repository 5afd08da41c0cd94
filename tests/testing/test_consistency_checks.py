"""check_consistency / check_error_consistency against oracles: errors drawn exactly from the
claimed covariance pass, scaled covariances fail on the right side, and the numbers match the
reference's chi-square bounds and a direct computation."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import stats

from roft_sim.geometry import matrix_from_rotvec
from roft_sim.records import Estimate, PoseTrack
from roft_sim.testing import assert_consistent, check_consistency, check_error_consistency
from roft_sim.testing.consistency_checks import component_indices


def _gaussian_runs(runs: int, steps: int, n: int, seed: int = 0):
    """Errors drawn from N(0, P_k) with a different random SPD P_k at every step."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(steps, n, n))
    P = A @ np.swapaxes(A, 1, 2) + 0.1 * np.eye(n)
    L = np.linalg.cholesky(P)
    e = np.einsum("kij,rkj->rki", L, rng.normal(size=(runs, steps, n)))
    return e, np.broadcast_to(P, (runs, steps, n, n)).copy()


def test_bounds_are_the_reference_numbers():
    """metrics_faults_flow.md 4.3: N=50, n=6 -> [5.08, 7.00]; N=50, n=12 -> [10.68, 13.40];
    N=50, n=3 -> [2.36, 3.72]."""
    for n, (lo, hi) in {6: (5.08, 7.00), 12: (10.68, 13.40), 3: (2.36, 3.72)}.items():
        e, P = _gaussian_runs(50, 5, n)
        result = check_error_consistency(e, P)
        assert (round(result.lower, 2), round(result.upper, 2)) == (lo, hi)


def test_per_step_values_are_the_mahalanobis_distances():
    e, P = _gaussian_runs(3, 4, 6)
    result = check_error_consistency(e, P, frames=[10, 11, 12, 13])
    direct = np.einsum("rki,rki->rk", e, np.linalg.solve(P, e[..., None])[..., 0])
    np.testing.assert_allclose(result.per_step, direct.mean(axis=0), rtol=1e-10)
    assert result.average == pytest.approx(direct.mean())
    assert list(result.frames) == [10, 11, 12, 13] and result.runs == 3 and result.dof == 6


def test_a_consistent_filter_passes_and_scaled_covariances_fail():
    e, P = _gaussian_runs(100, 60, 6, seed=1)
    good = check_error_consistency(e, P)
    assert good.passed, good.summary()
    optimistic = check_error_consistency(e, P / 4)  # claims twice the true precision
    assert not optimistic.passed and optimistic.fraction_above > 0.9
    assert not check_error_consistency(e, P / 4, sided="upper").passed
    conservative = check_error_consistency(e, P * 4)
    assert not conservative.passed and conservative.fraction_below > 0.9
    assert check_error_consistency(e, P * 4, sided="upper").passed


def test_nis_time_average_uses_the_bound_for_independent_steps():
    """Review regression (metrics_faults_flow.md 4.3): white innovations of one run over K = 300
    steps are K independent chi2(6) values, so an innovation covariance 1.5 times too small
    must fail; the per-step interval of one run ([1.24, 14.45]) let it pass."""
    e, S = _gaussian_runs(1, 300, 6, seed=3)
    good = check_error_consistency(e, S, statistic="NIS")
    lo, hi = stats.chi2.ppf([0.025, 0.975], 1800) / 300
    assert (good.average_lower, good.average_upper) == (pytest.approx(lo), pytest.approx(hi))
    assert good.passed, good.summary()
    optimistic = check_error_consistency(e, S / 1.5, statistic="NIS")
    assert not optimistic.passed and optimistic.average > optimistic.average_upper
    # the per-step rule alone (NEES's, for time-correlated errors) cannot see it
    assert check_error_consistency(e, S / 1.5, statistic="NIS", independent_steps=False).passed
    nees = check_error_consistency(e, S)
    assert (nees.average_lower, nees.average_upper) == (nees.lower, nees.upper)


def test_the_fraction_rule_is_binomially_sensible():
    """Over 200 independent consistent experiments, the default rule (fraction inside >= 85 %
    and average inside the per-step bounds) rejects rarely (measured: 2 of 200)."""
    rejected = sum(
        not check_error_consistency(*_gaussian_runs(20, 40, 3, seed=s)).passed for s in range(200)
    )
    assert rejected <= 20  # <= 10 %
    # the per-step rate outside matches 1 - confidence
    e, P = _gaussian_runs(20, 2000, 3, seed=7)
    outside = 1.0 - check_error_consistency(e, P).fraction_inside
    assert abs(outside - 0.05) < 3 * np.sqrt(0.05 * 0.95 / 2000)


def _truth(steps: int) -> PoseTrack:
    t = np.arange(steps) / 30
    T = np.tile(np.eye(4), (steps, 1, 1))
    T[:, :3, 3] = np.stack([0.1 * t, 0 * t, 0.6 + 0 * t], axis=1)
    T[:, :3, :3] = matrix_from_rotvec(np.stack([t, 0.5 * t, 0 * t], axis=1))
    return PoseTrack(t_s=t, T_cam_obj=T, v_obj_mps=np.tile([0.1, 0, 0], (steps, 1)),
                     w_radps=np.tile([1.0, 0.5, 0.0], (steps, 1)))  # fmt: skip


def _estimates(truth: PoseTrack, P: np.ndarray, rng, *, right_perturbation=False):
    """Estimates whose error x_true - x_est ~ N(0, P) in ESTIMATE_COVARIANCE_ORDER (the rotation
    error is a LEFT perturbation: R_true = exp(r) R_est), or the wrong (right) convention."""
    out = []
    for k in range(len(truth)):
        e = rng.multivariate_normal(np.zeros(12), P)
        T = truth.T_cam_obj[k].copy()
        T[:3, 3] -= e[0:3]
        R_err = matrix_from_rotvec(-e[3:6])
        T[:3, :3] = T[:3, :3] @ R_err if right_perturbation else R_err @ T[:3, :3]
        out.append(Estimate(k=k, T_cam_obj=T, v_obj_mps=truth.v_obj_mps[k] - e[6:9],
                            w_radps=truth.w_radps[k] - e[9:12], covariance=P))  # fmt: skip
    return out


def test_estimates_use_the_left_rotation_perturbation_of_the_covariance_order():
    rng = np.random.default_rng(3)
    truth = _truth(40)
    P = np.diag([1e-4] * 3 + [0.3, 0.3, 1e-6] + [1e-2] * 3 + [1e-1] * 3)
    runs = [_estimates(truth, P, rng) for _ in range(50)]
    for components in ("all", "pose", "rotation", "velocity", ("t_z", "w_x")):
        result = assert_consistent(runs, truth, components=components)
        assert result.dof == len(component_indices(components)[0])
    # an estimate perturbed on the right (body frame) looks inconsistent in the thin z direction
    wrong = [_estimates(truth, P, rng, right_perturbation=True) for _ in range(50)]
    with pytest.raises(AssertionError, match="NOT consistent"):
        assert_consistent(wrong, truth, components="rotation")


def test_input_errors_name_the_run_and_frame():
    truth = _truth(5)
    P = np.eye(12) * 1e-2
    run = _estimates(truth, P, np.random.default_rng(0))
    bad = list(run)
    bad[2] = Estimate.invalid(2)
    with pytest.raises(ValueError, match="run 1, frame 2: the estimate is invalid"):
        check_consistency([run, bad], truth)
    assert check_consistency([run, bad], truth, frames=[0, 1, 3, 4]).runs == 2
    no_cov = list(run)
    no_cov[3] = dataclasses.replace(run[3], covariance=None)
    with pytest.raises(ValueError, match="frame 3: the estimate is without a covariance"):
        check_consistency([no_cov], truth)
    with pytest.raises(ValueError, match="every run must have 5 estimates"):
        check_consistency([run, run[:4]], truth)
    for outside in ([5], [-1]):  # regression: an IndexError, or frame 4 tested as "frame -1"
        with pytest.raises(ValueError, match=r"frames must lie in \[0, 5\), got \["):
            check_consistency([run], truth, frames=outside)
    with pytest.raises(ValueError, match="unknown component group 'orientation'"):
        check_consistency([run], truth, components="orientation")
    e, P6 = _gaussian_runs(2, 3, 6)
    P6[1, 2, 0, 0] = -5.0
    with pytest.raises(ValueError, match=r"NEES: covariance at index \(1, 2\)"):
        check_error_consistency(e, P6)
    with pytest.raises(ValueError, match="errors must have shape"):
        check_error_consistency(e[0], P6[0])


def test_summary_reads_like_a_report():
    e, P = _gaussian_runs(50, 20, 6, seed=2)
    text = check_error_consistency(e, P / 9).summary()
    assert text.startswith("NEES test (two-sided, 95%): NOT consistent")
    assert "(bounds [5.078, 6.997]); per-step bounds [5.078, 6.997] (expected value 6)" in text
    assert "steps inside 0.0%, above 100.0%" in text
    assert stats.chi2.ppf(0.975, 300) / 50 == pytest.approx(6.997, abs=1e-3)
