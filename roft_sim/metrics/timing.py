"""Statistics of a tracker's per-frame step time."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["StepTimeStats", "step_time_stats", "REAL_TIME_BUDGET_S"]

REAL_TIME_BUDGET_S = 1.0 / 30.0
"""Frame period of a 30 fps camera [s]; the reference counts steps over 33 ms."""


@dataclass(frozen=True, slots=True, kw_only=True)
class StepTimeStats:
    """Summary of step times (reported in milliseconds)."""

    median_ms: float
    """Median step time [ms]."""
    p95_ms: float
    """95th percentile [ms] (linear interpolation between order statistics, numpy's default)."""
    mean_ms: float
    """Mean [ms] (the reference's ``time`` column)."""
    max_ms: float
    """Largest step time [ms]."""
    over_budget: int
    """Number of steps longer than ``budget_ms`` (the reference's ``excess_33_ms`` count)."""
    budget_ms: float
    """The budget used for ``over_budget`` [ms]."""
    steps: int
    """Number of steps measured."""


def step_time_stats(
    step_times_s: ArrayLike, *, budget_s: float = REAL_TIME_BUDGET_S
) -> StepTimeStats:
    """Median, p95, mean, max and over-budget count of step times.

    Args:
        step_times_s: (N,) wall-clock time of each tracker step [s], finite and >= 0.
        budget_s: real-time budget per step [s] (one 30 fps frame period by default).

    Returns:
        The statistics in milliseconds; NaN statistics and zero counts for N = 0.
    """
    t = np.asarray(step_times_s, dtype=np.float64)
    if t.ndim != 1:
        raise ValueError(f"step_times_s must have shape (N,), got {t.shape}")
    if not np.isfinite(t).all() or (t < 0).any():
        raise ValueError("step_times_s must be finite and >= 0")
    budget_ms = 1e3 * budget_s
    if t.size == 0:
        nan = float("nan")
        return StepTimeStats(
            median_ms=nan,
            p95_ms=nan,
            mean_ms=nan,
            max_ms=nan,
            over_budget=0,
            budget_ms=budget_ms,
            steps=0,
        )
    ms = 1e3 * t
    return StepTimeStats(
        median_ms=float(np.median(ms)),
        p95_ms=float(np.percentile(ms, 95)),
        mean_ms=float(ms.mean()),
        max_ms=float(ms.max()),
        over_budget=int(np.count_nonzero(ms > budget_ms)),
        budget_ms=budget_ms,
        steps=int(t.size),
    )
