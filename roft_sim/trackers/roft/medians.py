"""Medians of the small arrays of a ROFT step without ``np.median``'s overhead, and the
chi-square quantiles of its tests without importing scipy.stats.

``np.median`` spends most of its time on a few thousand values in argument handling and NaN
checks; these take one ``np.partition`` and give the same values (the middle element, or the
mean of the two middle ones, ``(a + b) / 2``) for finite inputs.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray
from scipy.special import gammaincinv

F64 = NDArray[np.float64]

__all__ = ["MAD_TO_SIGMA", "chi2_quantile", "column_medians", "median"]

MAD_TO_SIGMA = 1.4826
"""Median absolute deviation to standard deviation for Gaussian data."""


def median(x: NDArray[np.floating]) -> float:
    """``np.median(x)`` of a 1-D array of N > 0 finite values."""
    n = x.shape[0]
    h = n // 2
    if n % 2:
        return float(np.partition(x, h)[h])
    part = np.partition(x, (h - 1, h))
    return float((part[h - 1] + part[h]) / 2.0)


def column_medians(x: F64) -> F64:
    """``np.median(x, axis=0)`` (C,) of an (N, C) array of N > 0 finite values."""
    n = x.shape[0]
    h = n // 2
    if n % 2:
        out: F64 = np.partition(x, h, axis=0)[h]
        return out
    part = np.partition(x, (h - 1, h), axis=0)
    mid: F64 = (part[h - 1] + part[h]) / 2.0
    return mid


@functools.lru_cache(maxsize=32)
def chi2_quantile(probability: float, dof: int) -> float:
    """The chi-square quantile ``chi2.ppf(probability, dof)`` as scipy.stats computes it,
    ``2 gammaincinv(dof / 2, probability)``, without importing scipy.stats (a second of a fresh
    process's start-up)."""
    return float(2.0 * gammaincinv(dof / 2.0, probability))
