"""Well-formedness of a tracker's output: the checks every estimate must pass after every step.

:func:`check_well_formed` looks at a run's estimates (and, optionally, the observations they
answer) and returns a :class:`WellFormedReport` listing every problem; :func:`assert_well_formed`
raises with that list. Checked (``metrics_faults_flow.md`` 4.4, property 6):

- frame indices strictly increasing (and equal to the observations' ``k``, when given), the
  observations' time stamps strictly increasing;
- no NaN or infinity in the pose, velocities, spatial twist or covariance;
- the rotation orthonormal with determinant +1 (the pose's quaternion has unit norm), the last
  row of ``T_cam_obj`` ``(0, 0, 0, 1)``;
- the covariance ``(12, 12)`` symmetric and positive definite (smallest eigenvalue > 0), and not
  absurdly ill-conditioned;
- detection ids: no id both accepted and rejected in one step.

Invalid estimates (``valid=False``) are only checked for finiteness and frame order: their pose
means "none yet".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from roft_sim.records import Estimate, Observation

__all__ = ["WellFormedReport", "check_well_formed", "assert_well_formed"]

_MAX_LISTED = 8


@dataclass(frozen=True, slots=True, kw_only=True)
class WellFormedReport:
    """Every problem found in a run's estimates."""

    estimates: int
    """Number of estimates checked."""
    problems: tuple[str, ...]
    """One line per problem: ``frame k: what is wrong (the value)``."""
    min_eigenvalue: float
    """Smallest covariance eigenvalue over all valid estimates (``inf`` if none had one)."""
    max_orthonormality_error: float
    """Largest ``max |R^T R - I|`` over all valid estimates."""

    @property
    def passed(self) -> bool:
        """True when nothing is wrong."""
        return not self.problems

    def message(self) -> str:
        """The verdict and the first problems."""
        head = (
            f"{self.estimates} estimates well formed"
            if self.passed
            else f"{len(self.problems)} problems in {self.estimates} estimates:"
        )
        lines = [head] + [f"  {p}" for p in self.problems[:_MAX_LISTED]]
        if len(self.problems) > _MAX_LISTED:
            lines.append(f"  ... and {len(self.problems) - _MAX_LISTED} more")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.message()


def _finite(name: str, value: object, where: str, problems: list[str]) -> bool:
    if value is None:
        return True
    arr = np.asarray(value, dtype=np.float64)
    if not np.isfinite(arr).all():
        problems.append(f"{where}: {name} has {int((~np.isfinite(arr)).sum())} non-finite values")
        return False
    return True


def _observation_problems(
    estimates: Sequence[Estimate], observations: Sequence[Observation]
) -> list[str]:
    """One estimate per observation, increasing time stamps, and matching frame indices."""
    problems = []
    if len(observations) != len(estimates):
        problems.append(
            f"{len(estimates)} estimates for {len(observations)} observations (one each)"
        )
    previous_t = -np.inf
    for obs in observations:
        if not (np.isfinite(obs.t_s) and obs.t_s > previous_t):
            problems.append(
                f"frame {obs.k}: time stamp {obs.t_s} s does not increase (previous {previous_t} s)"
            )
        previous_t = obs.t_s
    for obs, est in zip(observations, estimates, strict=False):
        if est.k != obs.k:
            problems.append(f"frame {obs.k}: the estimate is for frame {est.k}")
    return problems


def _covariance_problems(
    covariance: ArrayLike, where: str, max_condition: float, problems: list[str]
) -> float:
    """Appends to ``problems`` what is wrong with one (12, 12) covariance (asymmetric, not
    positive definite, numerically singular); returns its smallest eigenvalue."""
    P = np.asarray(covariance, dtype=np.float64)
    asym = float(np.abs(P - P.T).max())
    scale = float(np.abs(P).max())
    if asym > 1e-12 * max(scale, 1e-300):
        problems.append(f"{where}: covariance not symmetric, max |P - P^T| = {asym:.2e}")
    eig = np.linalg.eigvalsh(0.5 * (P + P.T))
    if eig[0] <= 0:
        problems.append(
            f"{where}: covariance not positive definite, smallest eigenvalue {eig[0]:.3e}"
        )
    elif eig[-1] / eig[0] > max_condition:
        problems.append(
            f"{where}: covariance condition number {eig[-1] / eig[0]:.2e} > "
            f"{max_condition:.0e} (numerically singular)"
        )
    return float(eig[0])


def check_well_formed(
    estimates: Sequence[Estimate],
    observations: Sequence[Observation] | None = None,
    *,
    atol_orthonormal: float = 1e-9,
    max_condition: float = 1e14,
    require_covariance: bool = False,
) -> WellFormedReport:
    """Checks a run's estimates (see the module docstring for the list).

    Args:
        estimates: the tracker's estimates in step order.
        observations: the observations they answer, in the same order (checks ``k`` pairs and
            that time stamps increase); None skips those checks.
        atol_orthonormal: tolerance on ``|R^T R - I|`` entries (a unit quaternion to about
            ``atol_orthonormal / 2``).
        max_condition: largest accepted covariance condition number (``lambda_max /
            lambda_min``); beyond it the matrix is numerically singular.
        require_covariance: a valid estimate without a covariance is a problem.

    Returns:
        The :class:`WellFormedReport`.
    """
    problems: list[str] = []
    min_eig = np.inf
    max_orth = 0.0
    if observations is not None:
        problems += _observation_problems(estimates, observations)
    previous_k: int | None = None
    for est in estimates:
        where = f"frame {est.k}"
        if previous_k is not None and est.k <= previous_k:
            problems.append(f"{where}: frame index does not increase (previous {previous_k})")
        previous_k = est.k
        ok = True
        for name in ("T_cam_obj", "v_obj_mps", "w_radps", "spatial_twist", "covariance"):
            ok &= _finite(name, getattr(est, name), where, problems)
        ids = set(est.accepted_pose_ids) & set(est.rejected_pose_ids)
        if ids:
            problems.append(f"{where}: pose ids {sorted(ids)} both accepted and rejected")
        if not est.valid or not ok:
            continue
        T = np.asarray(est.T_cam_obj, dtype=np.float64)
        if not np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]):
            problems.append(f"{where}: last row of T_cam_obj is {T[3].tolist()}, not [0, 0, 0, 1]")
        R = T[:3, :3]
        orth = float(np.abs(R.T @ R - np.eye(3)).max())
        max_orth = max(max_orth, orth)
        if orth > atol_orthonormal:
            problems.append(
                f"{where}: rotation not orthonormal, max |R^T R - I| = {orth:.2e} "
                f"(> {atol_orthonormal:.0e})"
            )
        det = float(np.linalg.det(R))
        if det <= 0:
            problems.append(f"{where}: rotation has determinant {det:.3f} (a reflection)")
        if est.covariance is None:
            if require_covariance:
                problems.append(f"{where}: no covariance")
            continue
        smallest = _covariance_problems(est.covariance, where, max_condition, problems)
        min_eig = min(min_eig, smallest)
    return WellFormedReport(
        estimates=len(estimates),
        problems=tuple(problems),
        min_eigenvalue=float(min_eig),
        max_orthonormality_error=max_orth,
    )


def assert_well_formed(
    estimates: Sequence[Estimate],
    observations: Sequence[Observation] | None = None,
    **options: float | bool,
) -> WellFormedReport:
    """:func:`check_well_formed`, raising ``AssertionError`` with the problems; returns the
    report when everything is well formed."""
    report = check_well_formed(estimates, observations, **options)  # type: ignore[arg-type]
    if not report.passed:
        raise AssertionError(report.message())
    return report
