"""Filter consistency: NEES and NIS with chi-square bounds, innovation whiteness, bias.

Bar-Shalom, Li & Kirubarajan (2001), section 5.4; formulas and numbers in
``metrics_faults_flow.md`` section 4.3 and docs/metrics.md.

- NEES ``eps_k = e_k^T P_k^-1 e_k ~ chi2(n)`` with the error ``e = x_true - x_est``. Over R
  Monte-Carlo runs the average ``eps_bar_k`` satisfies ``R eps_bar_k ~ chi2(R n)``; accept when
  ``eps_bar_k`` lies in ``[chi2_{Rn}(a/2) / R, chi2_{Rn}(1 - a/2) / R]``.
- NIS ``nu_k^T S_k^-1 nu_k ~ chi2(n_z)``; its average over K steps (and R runs) is tested the same
  way with ``K R`` samples (innovations of a consistent filter are white, so the samples are
  independent).
- Whiteness ``rho(j) = sum_k nu_k^T nu_(k+j) / sqrt(sum_k |nu_k|^2 sum_k |nu_(k+j)|^2)``,
  approximately ``N(0, 1/K)``; per lag accept ``|rho(j)| <= z_(1-a/2) / sqrt(K)``, and jointly
  over lags 1..L the Box-Pierce statistic ``K sum_j rho(j)^2 <= chi2_L(confidence)``.
- Bias per component ``mu_j = (1/N) sum_i e_ij / sqrt(P_i,jj)``, approximately ``N(0, 1/N)``;
  accept ``|mu_j| <= z_(1-a/2) / sqrt(N)``.

On SO(3) the error is the tangent vector that matches the covariance convention of
:data:`roft_sim.records.ESTIMATE_COVARIANCE_ORDER`: the GLOBAL (left) perturbation
``R_true = exp([r]x) R_est``, so ``r = Log(R_true R_est^T)``, in the camera frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from roft_sim.geometry.so3 import rotvec_from_matrix

F64 = NDArray[np.float64]

__all__ = [
    "pose_error_tangent",
    "state_error",
    "mahalanobis_squared",
    "nees",
    "nis",
    "chi2_bounds",
    "ChiSquareTest",
    "NeesReport",
    "nees_test",
    "nis_test",
    "WhitenessReport",
    "innovation_whiteness",
    "BiasReport",
    "normalized_bias",
]


def pose_error_tangent(T_est: ArrayLike, T_true: ArrayLike) -> F64:
    """Pose error ``x_true - x_est`` in the estimate covariance's tangent space, ``(..., 6)``.

    Args:
        T_est: (..., 4, 4) estimated ``T_cam_obj`` [m].
        T_true: (..., 4, 4) true ``T_cam_obj`` [m].

    Returns:
        ``(t_true - t_est [m], Log(R_true R_est^T) [rad])``, camera frame; the rotation part is
        the ``r`` of ``R_true = exp([r]x) R_est`` (left / global perturbation).
    """
    T_est = np.asarray(T_est, dtype=np.float64)
    T_true = np.asarray(T_true, dtype=np.float64)
    if T_est.shape != T_true.shape or T_est.shape[-2:] != (4, 4):
        raise ValueError(f"expected matching (..., 4, 4) poses, got {T_est.shape}, {T_true.shape}")
    dR = T_true[..., :3, :3] @ np.swapaxes(T_est[..., :3, :3], -1, -2)
    return np.concatenate([T_true[..., :3, 3] - T_est[..., :3, 3], rotvec_from_matrix(dR)], axis=-1)


def state_error(
    T_est: ArrayLike,
    v_obj_est: ArrayLike,
    w_est: ArrayLike,
    T_true: ArrayLike,
    v_obj_true: ArrayLike,
    w_true: ArrayLike,
) -> F64:
    """Full 12-D error ``x_true - x_est`` in ``ESTIMATE_COVARIANCE_ORDER``, shape ``(..., 12)``.

    Args:
        T_est, T_true: (..., 4, 4) poses [m].
        v_obj_est, v_obj_true: (..., 3) object-origin velocities, camera frame [m/s].
        w_est, w_true: (..., 3) angular velocities, camera frame [rad/s].
    """
    pose = pose_error_tangent(T_est, T_true)
    dv = np.asarray(v_obj_true, dtype=np.float64) - np.asarray(v_obj_est, dtype=np.float64)
    dw = np.asarray(w_true, dtype=np.float64) - np.asarray(w_est, dtype=np.float64)
    return np.concatenate([pose, dv, dw], axis=-1)


def mahalanobis_squared(errors: ArrayLike, covariances: ArrayLike) -> F64:
    """``e^T P^-1 e`` for each of a batch, ``(...,)``; via a Cholesky factor of P.

    Args:
        errors: (..., n) error (or innovation) vectors.
        covariances: (..., n, n) symmetric positive-definite covariances.

    Raises:
        ValueError: shapes disagree, values are not finite, or a covariance is not symmetric
            positive definite (the message gives the first bad index).
    """
    e = np.asarray(errors, dtype=np.float64)
    P = np.asarray(covariances, dtype=np.float64)
    n = e.shape[-1]
    if P.shape != e.shape + (n,):
        raise ValueError(f"covariances must have shape {e.shape + (n,)}, got {P.shape}")
    if not (np.isfinite(e).all() and np.isfinite(P).all()):
        raise ValueError("errors and covariances must be finite")
    asym = np.abs(P - np.swapaxes(P, -1, -2)).max(axis=(-1, -2), initial=0.0)
    scale = np.abs(P).max(axis=(-1, -2), initial=0.0)
    bad = asym > 1e-9 * np.maximum(scale, 1e-300)
    if bad.any():
        i = tuple(int(x) for x in np.argwhere(bad)[0])
        raise ValueError(f"covariance at index {i} is not symmetric (max |P - P^T| {asym[i]:.2e})")
    try:
        L = np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(P).min(axis=-1)
        i = tuple(int(x) for x in np.argwhere(eig <= 0)[0]) if (eig <= 0).any() else ()
        raise ValueError(
            f"covariance at index {i} is not positive definite (min eigenvalue {eig.min():.3e})"
        ) from None
    y = np.linalg.solve(L, e[..., None])[..., 0]
    d2: F64 = np.sum(y * y, axis=-1)
    return d2


def nees(errors: ArrayLike, covariances: ArrayLike) -> F64:
    """Normalised estimation error squared ``e^T P^-1 e``, ``(...,)`` (see the module doc)."""
    return mahalanobis_squared(errors, covariances)


def nis(innovations: ArrayLike, innovation_covariances: ArrayLike) -> F64:
    """Normalised innovation squared ``nu^T S^-1 nu``, ``(...,)``."""
    return mahalanobis_squared(innovations, innovation_covariances)


def chi2_bounds(dof: int, samples: int = 1, *, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided acceptance interval of the mean of ``samples`` independent ``chi2(dof)`` values.

    ``[chi2_{samples dof}((1 - c) / 2), chi2_{samples dof}((1 + c) / 2)] / samples``; e.g.
    ``dof=6, samples=50`` gives ``[5.08, 7.00]`` at 95 %.
    """
    if dof < 1 or samples < 1 or not 0 < confidence < 1:
        raise ValueError(
            f"need dof >= 1, samples >= 1 and 0 < confidence < 1, got {dof}, {samples}, "
            f"{confidence}"
        )
    k = samples * dof
    lo = stats.chi2.ppf((1.0 - confidence) / 2.0, k) / samples
    hi = stats.chi2.ppf((1.0 + confidence) / 2.0, k) / samples
    return float(lo), float(hi)


@dataclass(frozen=True, slots=True, kw_only=True)
class ChiSquareTest:
    """An averaged chi-square statistic and its acceptance interval."""

    value: float
    """The averaged statistic."""
    lower: float
    upper: float
    dof: int
    """Degrees of freedom of one sample."""
    samples: int
    """Number of samples averaged."""
    confidence: float

    @property
    def passed(self) -> bool:
        """True when ``lower <= value <= upper``."""
        return self.lower <= self.value <= self.upper


def _as_runs(values: ArrayLike, what: str) -> F64:
    v = np.asarray(values, dtype=np.float64)
    if v.ndim == 1:
        v = v[None]
    if v.ndim != 2 or v.size == 0:
        raise ValueError(f"{what} must have shape (K,) or (runs, K) with K >= 1, got {v.shape}")
    if not np.isfinite(v).all() or (v < 0).any():
        raise ValueError(f"{what} must be finite and >= 0")
    return v


@dataclass(frozen=True, slots=True, kw_only=True)
class NeesReport:
    """Monte-Carlo NEES test: per step over runs, and overall."""

    per_step: F64
    """(K,) average NEES over the runs at each step."""
    step_lower: float
    """Acceptance interval of ``per_step`` (``runs`` samples each)."""
    step_upper: float
    fraction_inside: float
    """Fraction of steps whose average lies in the interval (about ``confidence`` when
    consistent)."""
    overall: ChiSquareTest
    """Average over every run and step, with the interval for ``runs * K`` independent samples
    (too narrow when the errors are correlated in time, as filter errors are: read it as a
    summary, the per-step test is the proper one)."""
    runs: int


def nees_test(nees_values: ArrayLike, dof: int, *, confidence: float = 0.95) -> NeesReport:
    """Monte-Carlo averaged NEES test.

    Args:
        nees_values: (runs, K) NEES of each run at each step, or (K,) for one run.
        dof: state dimension n (6 for a pose, 12 for pose and velocity).
        confidence: two-sided confidence of the intervals.
    """
    v = _as_runs(nees_values, "nees_values")
    runs = v.shape[0]
    per_step = v.mean(axis=0)
    lo, hi = chi2_bounds(dof, runs, confidence=confidence)
    olo, ohi = chi2_bounds(dof, v.size, confidence=confidence)
    inside = (per_step >= lo) & (per_step <= hi)
    return NeesReport(
        per_step=per_step,
        step_lower=lo,
        step_upper=hi,
        fraction_inside=float(inside.mean()),
        overall=ChiSquareTest(
            value=float(v.mean()),
            lower=olo,
            upper=ohi,
            dof=dof,
            samples=v.size,
            confidence=confidence,
        ),
        runs=runs,
    )


def nis_test(nis_values: ArrayLike, dof: int, *, confidence: float = 0.95) -> ChiSquareTest:
    """Time- (and run-) averaged NIS test: the mean of all values against ``chi2_bounds``.

    Args:
        nis_values: (K,) NIS of one run, or (runs, K).
        dof: measurement dimension n_z.
    """
    v = _as_runs(nis_values, "nis_values")
    lo, hi = chi2_bounds(dof, v.size, confidence=confidence)
    return ChiSquareTest(
        value=float(v.mean()), lower=lo, upper=hi, dof=dof, samples=v.size, confidence=confidence
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class WhitenessReport:
    """Sample autocorrelation of the innovations at lags 1..L."""

    rho: F64
    """(L,) normalised autocorrelation at lags 1..L."""
    bound: float
    """``z_(1-a/2) / sqrt(K)``: the per-lag acceptance bound."""
    outside: int
    """Lags with ``|rho| > bound`` (about 5 % of the lags by chance when white)."""
    portmanteau: float
    """Box-Pierce statistic ``Q = K sum_j rho(j)^2``, approximately ``chi2(L)`` when white."""
    portmanteau_limit: float
    """``chi2_L(confidence)``: the acceptance limit of ``Q``."""

    @property
    def passed(self) -> bool:
        """True when ``Q <= portmanteau_limit`` (one joint test over all lags, so a single large
        lag fails it while the ~5 % chance exceedances of single lags do not)."""
        return self.portmanteau <= self.portmanteau_limit


def innovation_whiteness(
    innovations: ArrayLike, *, max_lag: int = 10, confidence: float = 0.95
) -> WhitenessReport:
    """Whiteness test of one run's innovation sequence.

    Args:
        innovations: (K, n_z) innovations in time order (or (K,) scalars). Pass whitened
            innovations ``S^-1/2 nu`` to weigh the components equally; with raw innovations the
            ``1/K`` variance is an upper bound, so the test stays conservative.
        max_lag: largest lag L (< K).
        confidence: two-sided confidence of the bound.
    """
    nu = np.asarray(innovations, dtype=np.float64)
    if nu.ndim == 1:
        nu = nu[:, None]
    if nu.ndim != 2 or not np.isfinite(nu).all():
        raise ValueError(f"innovations must be a finite (K, n_z) array, got shape {nu.shape}")
    K = nu.shape[0]
    if not 1 <= max_lag < K:
        raise ValueError(f"max_lag must be in [1, K - 1] = [1, {K - 1}], got {max_lag}")
    rho = np.empty(max_lag)
    for j in range(1, max_lag + 1):
        a, b = nu[:-j], nu[j:]
        den = np.sqrt(np.sum(a * a) * np.sum(b * b))
        rho[j - 1] = np.sum(a * b) / den if den > 0 else 0.0
    z = stats.norm.ppf(0.5 + confidence / 2.0)
    bound = float(z / np.sqrt(K))
    return WhitenessReport(
        rho=rho,
        bound=bound,
        outside=int(np.count_nonzero(np.abs(rho) > bound)),
        portmanteau=float(K * np.sum(rho**2)),
        portmanteau_limit=float(stats.chi2.ppf(confidence, max_lag)),
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class BiasReport:
    """Normalised mean error per component."""

    mu: F64
    """(n,) ``mean_i e_ij / sqrt(P_i,jj)``."""
    bound: float
    """``z_(1-a/2) / sqrt(N)``."""
    passed: NDArray[np.bool_]
    """(n,) ``|mu_j| <= bound``."""


def normalized_bias(
    errors: ArrayLike, covariances: ArrayLike, *, confidence: float = 0.95
) -> BiasReport:
    """Bias test: normalised mean error per component over N samples (runs or steps).

    Args:
        errors: (N, n) errors ``x_true - x_est``.
        covariances: (N, n, n) covariances (only the diagonals are used).
    """
    e = np.asarray(errors, dtype=np.float64)
    P = np.asarray(covariances, dtype=np.float64)
    if e.ndim != 2 or P.shape != e.shape + (e.shape[1],) or e.shape[0] == 0:
        raise ValueError(f"need errors (N, n) and covariances (N, n, n), got {e.shape}, {P.shape}")
    var = np.diagonal(P, axis1=1, axis2=2)
    if not (np.isfinite(e).all() and np.isfinite(var).all()) or (var <= 0).any():
        raise ValueError("errors must be finite and covariance diagonals finite and > 0")
    mu = np.mean(e / np.sqrt(var), axis=0)
    bound = float(stats.norm.ppf(0.5 + confidence / 2.0) / np.sqrt(e.shape[0]))
    return BiasReport(mu=mu, bound=bound, passed=np.abs(mu) <= bound)
