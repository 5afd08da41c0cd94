"""Area under the ADD accuracy-threshold curve, exactly as the YCB-Video toolbox computes it.

The YCB-Video toolbox (yuxng/YCB_Video_toolbox, ``VOCap`` in ``plot_accuracy_keyframe.m``) and the
ROFT reference evaluation (``evaluation/metrics.py`` calling bop_pose_error's ``VOCap``) do:

1. set every distance above the maximum threshold (0.1 m) to ``inf``;
2. sort all N distances (failures at the end) and give the i-th its accuracy ``i / N``;
3. keep the finite ones, ``d_1 <= ... <= d_n``, with their accuracies ``prec_i = i / N``;
4. ``mrec = [0, d_1, ..., d_n, 0.1]``, ``mpre = [0, prec_1, ..., prec_n, prec_n]``, made
   non-decreasing by a running maximum;
5. ``AUC = (1 / 0.1) sum_{i : mrec_i != mrec_(i-1)} (mrec_i - mrec_(i-1)) mpre_i``, x100 for %.

This is a right-endpoint step integral of the accuracy curve over continuous thresholds in
[0, 0.1] m (not 1 cm steps). With ties, the interval ending at a repeated value takes the
accuracy of the FIRST of the tied entries, as the MATLAB code does. With no finite distance it
is 0. The accuracies ``i / N`` are float32, as the reference computes them
(``cumsum(ones(N, float32)) / N``), and the sum float64, so the two AUCs agree to rounding
(float64 accuracies would differ from the reference's by up to ~1e-6 percentage points).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

__all__ = ["add_auc", "add_auc_rows", "accuracy_curve", "DEFAULT_MAX_THRESHOLD_M"]

DEFAULT_MAX_THRESHOLD_M = 0.1
"""Largest ADD threshold of the YCB-Video AUC [m]."""


def _distances(distances_m: ArrayLike) -> F64:
    d = np.asarray(distances_m, dtype=np.float64)
    if d.ndim != 1:
        raise ValueError(f"distances_m must have shape (N,), got {d.shape}")
    if (d < 0).any():
        raise ValueError(f"distances must be >= 0, got min {np.nanmin(d)}")
    return np.where(np.isnan(d), np.inf, d)


def add_auc(distances_m: ArrayLike, *, max_threshold_m: float = DEFAULT_MAX_THRESHOLD_M) -> float:
    """ADD (or ADD-S) AUC in percent, the YCB-Video ``VOCap`` (see the module docstring).

    Args:
        distances_m: (N,) per-frame distances [m]; NaN and inf count as failures (they stay in
            N, so they lower the accuracy of every threshold).
        max_threshold_m: the largest threshold [m]; 0.1 in the YCB-Video protocol.

    Returns:
        AUC in [0, 100] %; NaN when N = 0 (no frame to evaluate).
    """
    if not max_threshold_m > 0:
        raise ValueError(f"max_threshold_m must be > 0, got {max_threshold_m}")
    d = _distances(distances_m)
    n_total = d.size
    if n_total == 0:
        return float("nan")
    d = np.sort(np.where(d > max_threshold_m, np.inf, d))
    # float32 accuracy steps, the reference's (module docstring)
    prec = (np.arange(1, n_total + 1, dtype=np.float32) / np.float32(n_total)).astype(np.float64)
    finite = np.isfinite(d)
    rec, prec = d[finite], prec[finite]
    if rec.size == 0:
        return 0.0
    mrec = np.concatenate([[0.0], rec, [max_threshold_m]])
    mpre = np.maximum.accumulate(np.concatenate([[0.0], prec, [prec[-1]]]))
    step = np.flatnonzero(mrec[1:] != mrec[:-1]) + 1
    area = np.sum((mrec[step] - mrec[step - 1]) * mpre[step])
    return float(area * (1.0 / max_threshold_m) * 100.0)


def add_auc_rows(
    distances_m: ArrayLike, *, max_threshold_m: float = DEFAULT_MAX_THRESHOLD_M
) -> F64:
    """:func:`add_auc` of every row of (R, N) distances at once (bootstrap resamples), with
    float64 accuracy steps (within 1e-5 points of :func:`add_auc`'s float32 ones).

    The step integral of the module docstring sums to a closed form: with ``d_i`` the finite
    distances up to the maximum threshold ``M`` (ties change nothing: their intervals have no
    width), ``AUC = (sum_i (M - d_i) + max_i d_i) / (N M)``; 0 with no such distance.

    Returns:
        (R,) AUC [%]; NaN for rows when N = 0.
    """
    d = np.asarray(distances_m, dtype=np.float64)
    if d.ndim != 2:
        raise ValueError(f"distances_m must have shape (R, N), got {d.shape}")
    n = d.shape[1]
    if n == 0:
        return np.full(d.shape[0], np.nan)
    ok = np.isfinite(d) & (d <= max_threshold_m)
    area = np.where(ok, max_threshold_m - d, 0.0).sum(axis=1)
    area += np.where(ok, d, 0.0).max(axis=1)
    auc: F64 = area / (n * max_threshold_m) * 100.0
    return auc


def accuracy_curve(distances_m: ArrayLike, thresholds_m: ArrayLike) -> F64:
    """Fraction of frames with distance ``<= tau`` for each threshold (T,), failures included.

    Args:
        distances_m: (N,) distances [m]; NaN/inf never pass.
        thresholds_m: (T,) thresholds [m].

    Returns:
        (T,) accuracies in [0, 1] (NaN when N = 0); for plots and the "ADD-S < 2 cm" number.
    """
    d = np.sort(_distances(distances_m))
    tau = np.asarray(thresholds_m, dtype=np.float64)
    if d.size == 0:
        return np.full(tau.shape, np.nan)
    return np.searchsorted(d, tau, side="right") / d.size
