"""NEES/NIS chi-square tests, SO(3) tangent errors, whiteness and bias (section 4.3 numbers)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from roft_sim.geometry import matrix_from_rotvec, transform_from_rt
from roft_sim.metrics import (
    chi2_bounds,
    innovation_whiteness,
    mahalanobis_squared,
    nees,
    nees_test,
    nis_test,
    normalized_bias,
    pose_error_tangent,
    state_error,
)


@pytest.mark.parametrize(
    ("dof", "samples", "lo", "hi"),
    [
        (6, 50, 5.08, 7.00),
        (12, 50, 10.68, 13.40),
        (6, 100, 5.34, 6.70),
        (3, 50, 2.36, 3.72),
        (6, 1, 1.24, 14.45),
        (6, 300, 5.61, 6.40),
        (6, 1000, 5.79, 6.22),
        (2, 300, 1.78, 2.23),
    ],
)
def test_chi2_bounds_match_reference_table(dof, samples, lo, hi):
    got = chi2_bounds(dof, samples)
    assert got == pytest.approx((lo, hi), abs=0.006)


def test_chi2_bounds_rejects_bad_arguments():
    with pytest.raises(ValueError, match="dof >= 1"):
        chi2_bounds(0, 10)


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n) * 0.1


def test_mahalanobis_matches_explicit_inverse_and_rejects_bad_covariances():
    rng = np.random.default_rng(0)
    P = np.stack([_spd(rng, 6) for _ in range(5)])
    e = rng.normal(size=(5, 6))
    expected = np.einsum("ni,nij,nj->n", e, np.linalg.inv(P), e)
    np.testing.assert_allclose(mahalanobis_squared(e, P), expected, rtol=1e-10)
    bad = P.copy()
    bad[3] = -np.eye(6)
    with pytest.raises(ValueError, match=r"index \(3,\) is not positive definite"):
        nees(e, bad)
    asym = P.copy()
    asym[2, 0, 1] += 1.0
    with pytest.raises(ValueError, match=r"index \(2,\) is not symmetric"):
        nees(e, asym)
    with pytest.raises(ValueError, match="shape"):
        nees(e, P[:, :5, :5])


def test_tangent_error_is_left_perturbation():
    rng = np.random.default_rng(1)
    R_est = Rotation.random(20, random_state=rng).as_matrix()
    t_est = rng.normal(size=(20, 3))
    r = rng.normal(0, 0.2, (20, 3))
    dt = rng.normal(0, 0.01, (20, 3))
    T_est = transform_from_rt(R_est, t_est)
    T_left = transform_from_rt(matrix_from_rotvec(r) @ R_est, t_est + dt)  # exp(r) R_est
    np.testing.assert_allclose(
        pose_error_tangent(T_est, T_left), np.concatenate([dt, r], 1), atol=1e-12
    )
    # A right (body) perturbation R_est exp(s) appears as r = R_est s: a different vector.
    T_right = transform_from_rt(R_est @ matrix_from_rotvec(r), t_est)
    np.testing.assert_allclose(
        pose_error_tangent(T_est, T_right)[:, 3:], np.einsum("nij,nj->ni", R_est, r), atol=1e-12
    )
    assert not np.allclose(pose_error_tangent(T_est, T_right)[:, 3:], r, atol=1e-3)
    full = state_error(T_est, np.zeros((20, 3)), np.zeros((20, 3)), T_left, dt, r)
    np.testing.assert_allclose(full[:, 6:], np.concatenate([dt, r], 1))


def _monte_carlo_pose_nees(rng, runs, steps, scale_reported):
    P = _spd(rng, 6) * 1e-3
    L = np.linalg.cholesky(P)
    values = np.empty((runs, steps))
    R_est = Rotation.random(steps, random_state=rng).as_matrix()
    T_est = transform_from_rt(R_est, np.tile([0, 0, 0.7], (steps, 1)))
    for i in range(runs):
        x = rng.normal(size=(steps, 6)) @ L.T  # true error ~ N(0, P)
        T_true = transform_from_rt(
            np.einsum("nij,njk->nik", matrix_from_rotvec(x[:, 3:]), R_est),
            T_est[:, :3, 3] + x[:, :3],
        )
        err = pose_error_tangent(T_est, T_true)
        values[i] = nees(err, np.broadcast_to(P * scale_reported, (steps, 6, 6)))
    return values


def test_nees_of_consistent_se3_filter_passes_and_overconfident_fails():
    rng = np.random.default_rng(2)
    ok = nees_test(_monte_carlo_pose_nees(rng, 50, 200, 1.0), 6)
    assert (ok.step_lower, ok.step_upper) == pytest.approx((5.08, 7.00), abs=0.006)
    assert 0.90 <= ok.fraction_inside <= 0.99
    assert ok.overall.passed and ok.overall.value == pytest.approx(6.0, abs=0.1)
    over = nees_test(_monte_carlo_pose_nees(rng, 50, 200, 0.5), 6)  # reports half the truth
    assert over.fraction_inside < 0.01 and not over.overall.passed
    under = nees_test(_monte_carlo_pose_nees(rng, 50, 200, 2.0), 6)  # conservative
    assert under.fraction_inside < 0.01 and under.overall.value < under.overall.lower


def test_nis_time_average():
    rng = np.random.default_rng(3)
    S = _spd(rng, 6)
    L = np.linalg.cholesky(S)
    nu = rng.normal(size=(1000, 6)) @ L.T
    good = nis_test(nees(nu, np.broadcast_to(S, (1000, 6, 6))), 6)
    assert (good.lower, good.upper) == pytest.approx((5.79, 6.22), abs=0.006)
    assert good.passed
    bad = nis_test(nees(1.3 * nu, np.broadcast_to(S, (1000, 6, 6))), 6)
    assert not bad.passed
    with pytest.raises(ValueError, match="finite and >= 0"):
        nis_test([1.0, -1.0], 2)


def test_whiteness_accepts_white_and_rejects_correlated_innovations():
    rng = np.random.default_rng(4)
    white = rng.normal(size=(1000, 3))
    rep = innovation_whiteness(white, max_lag=20)
    assert rep.bound == pytest.approx(1.96 / np.sqrt(1000), abs=1e-4)
    assert rep.passed
    ar = np.zeros_like(white)
    for k in range(1, 1000):  # AR(1), coefficient 0.5: rho(1) ~ 0.5
        ar[k] = 0.5 * ar[k - 1] + white[k]
    rep_ar = innovation_whiteness(ar, max_lag=20)
    assert rep_ar.rho[0] == pytest.approx(0.5, abs=0.08)
    assert not rep_ar.passed
    with pytest.raises(ValueError, match="max_lag"):
        innovation_whiteness(white[:5], max_lag=5)


def test_bias_detects_a_half_sigma_offset():
    rng = np.random.default_rng(5)
    P = np.broadcast_to(np.diag([1.0, 4.0, 9.0]), (2000, 3, 3))
    e = rng.normal(size=(2000, 3)) * [1, 2, 3]
    assert normalized_bias(e, P).passed.all()
    rep = normalized_bias(e + [0, 1.0, 0], P)  # 0.5 sigma on y
    assert rep.passed.tolist() == [True, False, True]
    assert rep.mu[1] == pytest.approx(0.5, abs=0.06)
