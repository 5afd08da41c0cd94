"""Filter consistency over Monte-Carlo runs: NEES (or NIS) within chi-square bounds.

A consistent filter's errors match its covariance: ``e^T P^-1 e ~ chi2(n)``. Averaged over R
independent runs at each step k, ``R * eps_bar_k ~ chi2(R n)`` (Bar-Shalom, Li & Kirubarajan
2001, section 5.4; ``metrics_faults_flow.md`` 4.3). :func:`check_consistency` computes the NEES
of a tracker's estimates against ground truth on the chosen components of
:data:`~roft_sim.records.ESTIMATE_COVARIANCE_ORDER` (rotation error as the LEFT perturbation
``R_true = exp([r]x) R_est``, as the covariance is defined), and
:func:`check_error_consistency` does the same for any errors (or innovations, for NIS) with
their covariances.

Acceptance (``sided="two-sided"``, the default):

1. the average over all runs and steps lies inside the per-step interval
   ``[chi2_{Rn}((1-c)/2), chi2_{Rn}((1+c)/2)] / R`` for NEES. The per-step interval is used, not
   the much narrower one for ``R K`` independent samples, because a filter's errors are
   correlated in time: the mean of K correlated per-step averages varies at most as much as one
   of them. For NIS (``independent_steps``, the default for ``statistic="NIS"``) the narrower
   interval ``[chi2_{RKn}((1-c)/2), chi2_{RKn}((1+c)/2)] / (R K)`` is used: a consistent filter's
   innovations are white, so the time average is a mean of ``R K`` independent values
   (``metrics_faults_flow.md`` 4.3);
2. at least ``min_fraction_inside`` of the per-step averages lie inside the interval (about
   ``c`` of them for a consistent filter; default ``c - 0.1``).

``sided="upper"`` accepts a conservative filter (NEES low is fine: "neglect" of delayed
measurements) and rejects only an optimistic one (NEES above the upper bound), as
``metrics_faults_flow.md`` 4.4 asks of the neglect strategy. Apply-as-current (``naive-delay``)
fails both under motion.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.metrics.consistency import chi2_bounds, mahalanobis_squared, state_error
from roft_sim.records import ESTIMATE_COVARIANCE_ORDER, Estimate, PoseTrack

F64 = NDArray[np.float64]

__all__ = [
    "COMPONENT_GROUPS",
    "ConsistencyResult",
    "check_consistency",
    "check_error_consistency",
    "assert_consistent",
    "component_indices",
]

COMPONENT_GROUPS: dict[str, tuple[str, ...]] = {
    "all": ESTIMATE_COVARIANCE_ORDER,
    "pose": ESTIMATE_COVARIANCE_ORDER[0:6],
    "position": ESTIMATE_COVARIANCE_ORDER[0:3],
    "rotation": ESTIMATE_COVARIANCE_ORDER[3:6],
    "velocity": ESTIMATE_COVARIANCE_ORDER[6:12],
    "linear_velocity": ESTIMATE_COVARIANCE_ORDER[6:9],
    "angular_velocity": ESTIMATE_COVARIANCE_ORDER[9:12],
}
"""Named groups of :data:`~roft_sim.records.ESTIMATE_COVARIANCE_ORDER` components."""

Sided = Literal["two-sided", "upper"]


@dataclass(frozen=True, slots=True, kw_only=True)
class ConsistencyResult:
    """A Monte-Carlo NEES or NIS test, with the numbers behind the verdict."""

    statistic: str
    """``NEES`` or ``NIS``."""
    components: tuple[str, ...]
    """Names of the tested components (``dof`` of them)."""
    dof: int
    """Degrees of freedom of one sample (the tested dimension)."""
    runs: int
    """Monte-Carlo runs R."""
    frames: NDArray[np.int64]
    """(K,) the frames (steps) tested."""
    per_step: F64
    """(K,) average of the statistic over the runs at each step."""
    lower: float
    """Lower bound of the per-step average (R samples, two-sided ``confidence``)."""
    upper: float
    """Upper bound of the per-step average."""
    average: float
    """Average over every run and step (ANEES / ANIS)."""
    average_lower: float
    """Lower bound applied to ``average``: ``lower`` (NEES), or the bound for ``R K``
    independent values with ``independent_steps`` (NIS)."""
    average_upper: float
    """Upper bound applied to ``average``."""
    fraction_inside: float
    """Fraction of steps whose average lies in ``[lower, upper]``."""
    fraction_above: float
    """Fraction of steps above ``upper`` (the filter claims too much certainty)."""
    fraction_below: float
    """Fraction of steps below ``lower`` (the filter is conservative)."""
    confidence: float
    """Two-sided confidence of the bounds."""
    sided: Sided
    """``two-sided`` or ``upper`` acceptance (see the module docstring)."""
    min_fraction_inside: float
    """Required fraction of steps inside the bounds (not above them, for ``upper``)."""

    @property
    def passed(self) -> bool:
        """The verdict of the acceptance rule of the module docstring."""
        if self.sided == "upper":
            return self.average <= self.average_upper and 1.0 - self.fraction_above >= (
                self.min_fraction_inside
            )
        return self.average_lower <= self.average <= self.average_upper and (
            self.fraction_inside >= self.min_fraction_inside
        )

    @property
    def worst_frame(self) -> int:
        """The frame whose per-step average is farthest from the bounds' geometric centre (in
        log ratio): the most optimistic or most conservative step."""
        centre = np.sqrt(self.lower * self.upper)
        distance = np.abs(np.log(np.maximum(self.per_step, 1e-300) / centre))
        return int(self.frames[int(np.argmax(distance))])

    def summary(self) -> str:
        """A readable multi-line account: verdict, average vs bounds, fractions, worst step."""
        verdict = "consistent" if self.passed else "NOT consistent"
        kind = "two-sided" if self.sided == "two-sided" else "upper bound only"
        worst = self.worst_frame
        value = float(self.per_step[np.flatnonzero(self.frames == worst)[0]])
        return "\n".join(
            [
                f"{self.statistic} test ({kind}, {self.confidence:.0%}): {verdict}",
                f"  components {', '.join(self.components)} (dof {self.dof}), {self.runs} runs x "
                f"{len(self.frames)} steps",
                f"  average {self.statistic} {self.average:.3f} (bounds "
                f"[{self.average_lower:.3f}, {self.average_upper:.3f}]); per-step bounds "
                f"[{self.lower:.3f}, {self.upper:.3f}] (expected value {self.dof})",
                f"  steps inside {self.fraction_inside:.1%}, above {self.fraction_above:.1%}, "
                f"below {self.fraction_below:.1%} (need {self.min_fraction_inside:.0%} "
                f"{'inside' if self.sided == 'two-sided' else 'not above'})",
                f"  worst step: frame {worst}, average {value:.3f}",
            ]
        )

    def __str__(self) -> str:
        return self.summary()


def component_indices(components: str | Sequence[str]) -> tuple[NDArray[np.int64], tuple[str, ...]]:
    """Indices into :data:`~roft_sim.records.ESTIMATE_COVARIANCE_ORDER` and the names, for a
    group name of :data:`COMPONENT_GROUPS` or a list of component names.

    Raises:
        ValueError: an unknown group or component name (the message lists the valid ones).
    """
    if isinstance(components, str):
        if components not in COMPONENT_GROUPS:
            raise ValueError(
                f"unknown component group {components!r}; expected one of "
                f"{', '.join(COMPONENT_GROUPS)} or a list of {ESTIMATE_COVARIANCE_ORDER}"
            )
        names = COMPONENT_GROUPS[components]
    else:
        names = tuple(components)
        unknown = [c for c in names if c not in ESTIMATE_COVARIANCE_ORDER]
        if unknown or not names or len(set(names)) != len(names):
            raise ValueError(
                f"components must be distinct names from {ESTIMATE_COVARIANCE_ORDER}, got "
                f"{list(names)}"
            )
    index = {c: i for i, c in enumerate(ESTIMATE_COVARIANCE_ORDER)}
    return np.array([index[c] for c in names], dtype=np.int64), names


def _report_labels(
    frames: ArrayLike | None, components: tuple[str, ...] | None, steps: int, n: int
) -> tuple[NDArray[np.int64], tuple[str, ...]]:
    """The (steps,) frame index of each step (default ``0..steps-1``) and the n component names
    (default ``x0, x1, ...``) of a consistency report."""
    frame_index = (
        np.arange(steps, dtype=np.int64)
        if frames is None
        else np.asarray(frames, dtype=np.int64).reshape(-1)
    )
    if frame_index.shape != (steps,):
        raise ValueError(f"frames must have {steps} entries, got {frame_index.shape}")
    names = components if components is not None else tuple(f"x{i}" for i in range(n))
    if len(names) != n:
        raise ValueError(f"{len(names)} component names for dimension {n}")
    return frame_index, tuple(names)


def check_error_consistency(
    errors: ArrayLike,
    covariances: ArrayLike,
    *,
    frames: ArrayLike | None = None,
    statistic: str = "NEES",
    components: tuple[str, ...] | None = None,
    confidence: float = 0.95,
    sided: Sided = "two-sided",
    min_fraction_inside: float | None = None,
    independent_steps: bool | None = None,
) -> ConsistencyResult:
    """Monte-Carlo chi-square test of errors (NEES) or innovations (NIS) and their covariances.

    Args:
        errors: (R, K, n) errors ``x_true - x_est`` (or innovations) of R runs at K steps.
        covariances: (R, K, n, n) the filter's covariances (or innovation covariances S).
        frames: (K,) frame index of each step, for the report; default ``0..K-1``.
        statistic: the label, ``NEES`` or ``NIS``.
        components: names of the n components, for the report; default ``x0, x1, ...``.
        confidence: two-sided confidence of the bounds (0.95: the 2.5 % and 97.5 % quantiles).
        sided: ``two-sided`` or ``upper`` (accept conservative filters).
        min_fraction_inside: required fraction of steps inside the bounds (``upper``: not above);
            default ``confidence - 0.1``.
        independent_steps: test the overall average against the interval for ``R K``
            independent values (right for white innovations) instead of the per-step one;
            default: True for ``NIS``, False otherwise (see the module docstring).

    Raises:
        ValueError: shapes disagree, values are not finite, a covariance is not symmetric
            positive definite (naming the run and step), or bad options.
    """
    e = np.asarray(errors, dtype=np.float64)
    P = np.asarray(covariances, dtype=np.float64)
    if e.ndim != 3 or e.shape[0] < 1 or e.shape[1] < 1:
        raise ValueError(f"errors must have shape (runs, steps, n), got {e.shape}")
    runs, steps, n = e.shape
    if P.shape != (runs, steps, n, n):
        raise ValueError(f"covariances must have shape {(runs, steps, n, n)}, got {P.shape}")
    if sided not in ("two-sided", "upper"):
        raise ValueError(f"sided must be 'two-sided' or 'upper', got {sided!r}")
    if min_fraction_inside is None:
        min_fraction_inside = max(0.0, confidence - 0.1)
    if not 0.0 <= min_fraction_inside <= 1.0:
        raise ValueError(f"min_fraction_inside must be in [0, 1], got {min_fraction_inside}")
    try:
        values = mahalanobis_squared(e, P)
    except ValueError as err:
        raise ValueError(f"{statistic}: {err} (index = (run, step))") from None
    frame_index, names = _report_labels(frames, components, steps, n)
    per_step = values.mean(axis=0)
    lower, upper = chi2_bounds(n, runs, confidence=confidence)
    if independent_steps is None:
        independent_steps = statistic == "NIS"
    average_bounds = (
        chi2_bounds(n, runs * steps, confidence=confidence) if independent_steps else (lower, upper)
    )
    return ConsistencyResult(
        statistic=statistic,
        components=tuple(names),
        dof=n,
        runs=runs,
        frames=frame_index,
        per_step=per_step,
        lower=lower,
        upper=upper,
        average=float(values.mean()),
        average_lower=average_bounds[0],
        average_upper=average_bounds[1],
        fraction_inside=float(np.mean((per_step >= lower) & (per_step <= upper))),
        fraction_above=float(np.mean(per_step > upper)),
        fraction_below=float(np.mean(per_step < lower)),
        confidence=confidence,
        sided=sided,
        min_fraction_inside=float(min_fraction_inside),
    )


def _selected_frames(frames: ArrayLike | slice | None, n_frames: int) -> NDArray[np.int64]:
    """The frame indices chosen by ``frames`` (indices, a slice, a bool mask, or None = all),
    checked to lie in ``[0, n_frames)``."""
    if frames is None:
        selected = np.arange(n_frames)
    elif isinstance(frames, slice):
        selected = np.arange(n_frames)[frames]
    else:
        f = np.asarray(frames)
        selected = np.flatnonzero(f) if f.dtype == np.bool_ else f.astype(np.int64)
    if selected.size == 0:
        raise ValueError("no frames selected")
    if selected.min() < 0 or selected.max() >= n_frames:
        raise ValueError(f"frames must lie in [0, {n_frames}), got {selected.tolist()}")
    return selected


def check_consistency(
    runs: Sequence[Sequence[Estimate]],
    truths: PoseTrack | Sequence[PoseTrack],
    *,
    components: str | Sequence[str] = "pose",
    frames: ArrayLike | slice | None = None,
    confidence: float = 0.95,
    sided: Sided = "two-sided",
    min_fraction_inside: float | None = None,
) -> ConsistencyResult:
    """NEES of a tracker's estimates over Monte-Carlo runs, against chi-square bounds.

    Args:
        runs: R runs, each the list of estimates of frames 0..K-1 (every run the same length).
            Every estimate on a tested frame must be valid and carry a covariance.
        truths: the ground truth of each run (one :class:`~roft_sim.records.PoseTrack` per run,
            or one shared by all), indexed by ``estimate.k``.
        components: a group of :data:`COMPONENT_GROUPS` (``pose``, ``position``, ``rotation``,
            ``velocity``, ``all``, ...) or a list of names from
            :data:`~roft_sim.records.ESTIMATE_COVARIANCE_ORDER`; NEES uses the marginal
            covariance of these components.
        frames: frames to test (indices, a slice or an ``(K,)`` bool mask); None = all. Leave
            out the first frames while the filter forgets a deliberately wrong initial state.
        confidence, sided, min_fraction_inside: as in :func:`check_error_consistency`.

    Returns:
        The :class:`ConsistencyResult` (``result.passed``, ``result.summary()``).

    Raises:
        ValueError: runs of different lengths, frames outside the runs, a tested estimate
            invalid or without covariance (naming the run and frame), or a covariance that is not
            positive definite.
    """
    if len(runs) == 0:
        raise ValueError("need at least one run")
    n_frames = len(runs[0])
    if any(len(r) != n_frames for r in runs):
        raise ValueError(f"every run must have {n_frames} estimates, got {[len(r) for r in runs]}")
    truth_list = [truths] * len(runs) if isinstance(truths, PoseTrack) else list(truths)
    if len(truth_list) != len(runs):
        raise ValueError(f"{len(truth_list)} ground truths for {len(runs)} runs")
    selected = _selected_frames(frames, n_frames)
    idx, names = component_indices(components)
    errors = np.empty((len(runs), selected.size, idx.size))
    covs = np.empty((len(runs), selected.size, idx.size, idx.size))
    for r, (run, truth) in enumerate(zip(runs, truth_list, strict=True)):
        for j, k in enumerate(selected):
            est = run[int(k)]
            if not est.valid or est.covariance is None:
                why = "invalid" if not est.valid else "without a covariance"
                raise ValueError(
                    f"run {r}, frame {est.k}: the estimate is {why}; test only frames where the "
                    "tracker has a pose with a covariance (frames=...)"
                )
            e = state_error(
                est.T_cam_obj,
                est.v_obj_mps,
                est.w_radps,
                truth.T_cam_obj[est.k],
                truth.v_obj_mps[est.k],
                truth.w_radps[est.k],
            )
            errors[r, j] = e[idx]
            covs[r, j] = np.asarray(est.covariance, dtype=np.float64)[np.ix_(idx, idx)]
    return check_error_consistency(
        errors,
        covs,
        frames=selected,
        statistic="NEES",
        components=names,
        confidence=confidence,
        sided=sided,
        min_fraction_inside=min_fraction_inside,
    )


def assert_consistent(
    runs: Sequence[Sequence[Estimate]],
    truths: PoseTrack | Sequence[PoseTrack],
    **options: object,
) -> ConsistencyResult:
    """:func:`check_consistency`, raising ``AssertionError(result.summary())`` when it fails;
    returns the result when it passes."""
    result = check_consistency(runs, truths, **options)  # type: ignore[arg-type]
    if not result.passed:
        raise AssertionError(result.summary())
    return result
