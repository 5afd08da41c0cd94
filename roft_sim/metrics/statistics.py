"""Confidence intervals over replicates, paired verdicts, block bootstrap over time.

Definitions and the reasons for each choice: docs/statistics.md.

- :func:`mean_interval` / :func:`mean_intervals`: the mean of replicate values (one per
  sequence x seed cell) with a 95 % interval: scipy's BCa bootstrap (:data:`INTERVAL_METHOD`),
  widened on each side to at least Student's t interval. BCa follows a skewed metric (a tail of
  failures lengthens one side); at the few replicates of a seed sweep every bootstrap interval is
  too narrow (measured coverage 0.91-0.94 at n = 6-20 on heavy-tailed symmetric laws), while the
  t interval holds 95 % on symmetric laws, which a paired difference under "no difference" is.
- :func:`paired_comparison`: tracker A minus tracker B on the same cells, the interval of the
  mean difference and a verdict word (:data:`BETTER`, :data:`WORSE`, :data:`NO_DIFFERENCE`) that
  knows each metric's direction (:data:`METRIC_DIRECTIONS`).
- :func:`replicates_needed`: how many replicates detect a difference with 80 % power, from the
  paired standard deviation (of a pilot: its upper 80 % confidence bound).
- :func:`politis_white_block_length`, :func:`moving_block_indices`,
  :func:`block_bootstrap_interval`: a moving-block bootstrap for per-frame series, whose
  frames are correlated; the block length is the Politis-White automatic choice.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

F64 = NDArray[np.float64]

__all__ = [
    "CONFIDENCE",
    "INTERVAL_METHOD",
    "BLOCK_METHOD",
    "Direction",
    "METRIC_DIRECTIONS",
    "METRIC_RANGES",
    "BETTER",
    "WORSE",
    "NO_DIFFERENCE",
    "Interval",
    "mean_interval",
    "mean_intervals",
    "PairedComparison",
    "paired_comparison",
    "verdict_word",
    "replicates_needed",
    "PILOT_SD_CONFIDENCE",
    "bootstrap_percentile_interval",
    "politis_white_block_length",
    "moving_block_indices",
    "block_bootstrap_interval",
]

CONFIDENCE = 0.95
"""Confidence level of every interval."""
INTERVAL_METHOD = "BCa bootstrap, at least as wide as Student's t"
"""How :func:`mean_interval` forms its interval (named in every table)."""
BLOCK_METHOD = "moving-block bootstrap (Politis-White block length), percentile"
"""How :func:`block_bootstrap_interval` forms its interval."""
DEFAULT_RESAMPLES = 2000
"""Bootstrap resamples (Monte Carlo error of a 95 % bound: about 1 % of the interval width)."""

Direction = Literal["higher", "lower"]
METRIC_DIRECTIONS: dict[str, Direction] = {
    "add_auc_pct": "higher",
    "adds_auc_pct": "higher",
    "rmse_t_cm": "lower",
    "rmse_a_deg": "lower",
    "rmse_v_cmps": "lower",
    "rmse_w_dps": "lower",
}
"""Which way each metric is better: ADD-AUC higher, the RMSEs (e_t, e_a, e_v, e_w) lower."""

METRIC_RANGES: dict[str, tuple[float, float]] = {
    "add_auc_pct": (0.0, 100.0),
    "adds_auc_pct": (0.0, 100.0),
    "rmse_t_cm": (0.0, math.inf),
    "rmse_a_deg": (0.0, math.inf),
    "rmse_v_cmps": (0.0, math.inf),
    "rmse_w_dps": (0.0, math.inf),
}
"""The values each metric can take: an interval of its mean is cut to them."""

BETTER = "better"
WORSE = "worse"
NO_DIFFERENCE = "no detectable difference"


@dataclass(frozen=True, slots=True, kw_only=True)
class Interval:
    """A mean (or another estimate) with its confidence interval."""

    estimate: float
    """The point estimate (the mean of the replicates, or the statistic on all frames)."""
    low: float
    """Lower bound; NaN when there is no interval (fewer than 2 replicates)."""
    high: float
    """Upper bound; NaN when there is no interval."""
    n: int
    """Replicates (or frames) the interval rests on."""
    confidence: float = CONFIDENCE
    """Confidence level."""
    method: str = INTERVAL_METHOD
    """How it was formed."""

    @property
    def has_interval(self) -> bool:
        """True when both bounds are finite."""
        return math.isfinite(self.low) and math.isfinite(self.high)

    def excludes(self, value: float = 0.0) -> bool:
        """True when the interval exists and ``value`` lies outside it."""
        return self.has_interval and not (self.low <= value <= self.high)

    def text(self, fmt: str = ".2f") -> str:
        """``"12.30 [11.02, 13.51]"``; ``"12.30 (n=1)"`` without an interval; ``-`` for NaN."""
        if not math.isfinite(self.estimate):
            return "-"
        if not self.has_interval:
            return f"{self.estimate:{fmt}} (n={self.n})"
        return f"{self.estimate:{fmt}} [{self.low:{fmt}}, {self.high:{fmt}}]"

    def json_fields(self) -> dict[str, float | None]:
        """``{"estimate", "low", "high"}`` for JSON, a missing (non-finite) value as None."""
        return {
            k: (v if math.isfinite(v) else None)
            for k, v in (("estimate", self.estimate), ("low", self.low), ("high", self.high))
        }


def _t_half_width(values: F64, confidence: float) -> F64:
    """(R,) Student-t half width of the mean of each row of (R, n) ``values``."""
    n = values.shape[-1]
    sd = values.std(axis=-1, ddof=1)
    q = float(stats.t.ppf(0.5 + confidence / 2.0, n - 1))
    half: F64 = q * sd / math.sqrt(n)
    return half


def mean_intervals(
    values: ArrayLike,
    *,
    rng: np.random.Generator,
    confidence: float = CONFIDENCE,
    n_resamples: int = DEFAULT_RESAMPLES,
) -> tuple[F64, F64, F64]:
    """Means and intervals of many replicate sets at once (see the module docstring).

    Args:
        values: (R, n) R sets of n replicate values each (finite).
        rng: generator of the bootstrap resamples.
        confidence: confidence level.
        n_resamples: bootstrap resamples.

    Returns:
        (R,) means, lower and upper bounds; the bounds are NaN when n < 2.
    """
    x = np.asarray(values, dtype=np.float64)
    if x.ndim != 2 or not np.isfinite(x).all():
        raise ValueError(f"values must be a finite (R, n) array, got shape {x.shape}")
    mean = x.mean(axis=-1)
    if x.shape[1] < 2:
        nan = np.full(x.shape[0], np.nan)
        return mean, nan, nan.copy()
    half = _t_half_width(x, confidence)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # degenerate rows (all equal): BCa gives NaN, t decides
        result = stats.bootstrap(
            (x,),
            np.mean,
            axis=-1,
            vectorized=True,
            confidence_level=confidence,
            n_resamples=n_resamples,
            method="BCa",
            rng=rng,
        )
    lo_b, hi_b = (np.asarray(b, dtype=np.float64) for b in result.confidence_interval)
    low = np.fmin(np.where(np.isfinite(lo_b), lo_b, np.nan), mean - half)
    high = np.fmax(np.where(np.isfinite(hi_b), hi_b, np.nan), mean + half)
    return mean, low, high


def mean_interval(
    values: ArrayLike,
    *,
    rng: np.random.Generator,
    confidence: float = CONFIDENCE,
    n_resamples: int = DEFAULT_RESAMPLES,
    bounds: tuple[float, float] = (-math.inf, math.inf),
) -> Interval:
    """The mean of replicate ``values`` (n,) with its interval (:func:`mean_intervals`), cut to
    ``bounds`` (the values the quantity can take, e.g. :data:`METRIC_RANGES`: with few
    replicates the t floor may reach past them).

    Non-finite values are left out (a metric a replicate could not compute); none left gives a
    NaN estimate.
    """
    x = np.asarray(values, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    if x.size == 0:
        return Interval(estimate=math.nan, low=math.nan, high=math.nan, n=0)
    mean, low, high = mean_intervals(
        x[None, :], rng=rng, confidence=confidence, n_resamples=n_resamples
    )
    low0, high0 = float(low[0]), float(high[0])
    if math.isfinite(low0):
        low0, high0 = max(low0, bounds[0]), min(high0, bounds[1])
    return Interval(
        estimate=float(mean[0]),
        low=low0,
        high=high0,
        n=int(x.size),
        confidence=confidence,
    )


def verdict_word(difference: Interval, direction: Direction) -> str:
    """:data:`BETTER` / :data:`WORSE` when the interval of ``A - B`` excludes 0 (A better when
    the difference points the metric's good way), else :data:`NO_DIFFERENCE`."""
    if not difference.excludes(0.0):
        return NO_DIFFERENCE
    up = difference.low > 0.0
    return BETTER if up == (direction == "higher") else WORSE


@dataclass(frozen=True, slots=True, kw_only=True)
class PairedComparison:
    """Tracker A against tracker B on the same cells, one metric."""

    metric: str
    """Metric key (``add_auc_pct``, ``rmse_t_cm``, ...)."""
    direction: Direction
    """Which way the metric is better."""
    difference: Interval
    """Mean of ``A - B`` over the pairs, with its interval."""
    sd: float
    """Standard deviation of the paired differences (NaN with fewer than 2 pairs)."""
    verdict: str
    """:data:`BETTER`, :data:`WORSE` or :data:`NO_DIFFERENCE` (A relative to B)."""


def paired_comparison(
    a: ArrayLike,
    b: ArrayLike,
    metric: str,
    *,
    rng: np.random.Generator,
    confidence: float = CONFIDENCE,
    n_resamples: int = DEFAULT_RESAMPLES,
) -> PairedComparison:
    """Paired comparison of ``a`` (n,) and ``b`` (n,), the metric of A and B on the same n
    cells (same sequence, same fault draw), in the same order. Pairs where either is not
    finite are left out; the interval is cut to the differences the metric allows (ADD-AUC:
    [-100, 100]).

    Raises:
        ValueError: different lengths, or a metric without a known direction.
    """
    if metric not in METRIC_DIRECTIONS:
        raise ValueError(
            f"no direction known for metric {metric!r}; have {list(METRIC_DIRECTIONS)}"
        )
    x, y = np.asarray(a, dtype=np.float64).ravel(), np.asarray(b, dtype=np.float64).ravel()
    if x.shape != y.shape:
        raise ValueError(f"paired values need equal lengths, got {x.size} and {y.size}")
    d = (x - y)[np.isfinite(x) & np.isfinite(y)]
    lo, hi = METRIC_RANGES.get(metric, (-math.inf, math.inf))
    difference = mean_interval(
        d, rng=rng, confidence=confidence, n_resamples=n_resamples, bounds=(lo - hi, hi - lo)
    )
    direction = METRIC_DIRECTIONS[metric]
    return PairedComparison(
        metric=metric,
        direction=direction,
        difference=difference,
        sd=float(d.std(ddof=1)) if d.size > 1 else math.nan,
        verdict=verdict_word(difference, direction),
    )


PILOT_SD_CONFIDENCE = 0.8
"""Upper confidence level of a pilot's standard deviation used by :func:`replicates_needed`."""


def replicates_needed(
    paired_sd: float,
    difference: float,
    *,
    pilot_pairs: int | None = None,
    confidence: float = CONFIDENCE,
    power: float = 0.8,
    max_n: int = 10_000,
) -> int | None:
    """The fewest paired replicates whose interval excludes 0 with probability ``power`` when
    the true mean difference is ``difference`` and the paired standard deviation ``paired_sd``:
    the smallest n >= 2 with ``sqrt(n) |difference| / sd >= t_(1+c)/2,n-1 + t_power,n-1`` (the
    paired t test's power, noncentral t approximated).

    Args:
        paired_sd: standard deviation of the paired differences.
        difference: the true difference to detect (same unit).
        pilot_pairs: the pairs ``paired_sd`` was estimated from: the sd is then raised to its
            upper :data:`PILOT_SD_CONFIDENCE` confidence bound, ``sd sqrt((m-1) /
            chi2_0.2,m-1)`` (Browne 1995), so that the recommendation reaches ``power`` in at
            least four pilots of five; None = ``paired_sd`` is known.
        confidence: confidence level of the intervals.
        power: probability of finding the difference.
        max_n: give up above this.

    Returns:
        The replicates; None when ``paired_sd`` is not finite, ``pilot_pairs`` < 2, or more
        than ``max_n`` would be needed; 2 when ``paired_sd`` is 0.
    """
    if not math.isfinite(paired_sd) or paired_sd < 0 or not difference:
        return None
    if pilot_pairs is not None:
        if pilot_pairs < 2:
            return None
        df = pilot_pairs - 1
        paired_sd *= math.sqrt(df / float(stats.chi2.ppf(1.0 - PILOT_SD_CONFIDENCE, df)))
    if paired_sd == 0:
        return 2
    effect = abs(difference) / paired_sd
    n = np.arange(2, max_n + 1)
    need = stats.t.ppf(0.5 + confidence / 2, n - 1) + stats.t.ppf(power, n - 1)
    enough = np.flatnonzero(np.sqrt(n) * effect >= need)
    return int(n[enough[0]]) if enough.size else None


def bootstrap_percentile_interval(
    statistic: Callable[[NDArray[np.int64]], float],
    n: int,
    *,
    rng: np.random.Generator,
    confidence: float = CONFIDENCE,
    n_resamples: int = 999,
) -> Interval:
    """Percentile bootstrap of any statistic of ``n`` replicates (e.g. Kendall's tau over seeds):
    ``statistic(index)`` gets the (n,) indices of a resample (with repeats) and returns a number.
    The estimate is ``statistic(arange(n))``; no interval when n < 2."""
    everything = np.arange(n, dtype=np.int64)
    estimate = float(statistic(everything))
    if n < 2:
        return Interval(estimate=estimate, low=math.nan, high=math.nan, n=n, method="percentile")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = stats.bootstrap(
            (everything,),
            lambda index: statistic(np.asarray(index, dtype=np.int64)),
            vectorized=False,
            confidence_level=confidence,
            n_resamples=n_resamples,
            method="percentile",
            rng=rng,
        )
    low, high = (float(v) for v in result.confidence_interval)
    return Interval(
        estimate=estimate,
        low=low,
        high=high,
        n=n,
        confidence=confidence,
        method="percentile bootstrap",
    )


# ----------------------------------------------------------------------- block bootstrap
def _flat_top(u: F64) -> F64:
    """The flat-top lag window of Politis and Romano: 1 up to 1/2, linear to 0 at 1."""
    u = np.abs(u)
    window: F64 = np.where(u <= 0.5, 1.0, np.where(u <= 1.0, 2.0 * (1.0 - u), 0.0))
    return window


def politis_white_block_length(series: ArrayLike) -> int:
    """The automatic block length of the moving-block bootstrap (Politis and White 2004, with
    the correction of Patton, Politis and White 2009) for the mean of ``series`` (N,):
    ``b = (2 G^2 / D)^(1/3) N^(1/3)`` with ``G = sum lambda(k/M) |k| gamma(k)``,
    ``D = 4/3 g^2``, ``g = sum lambda(k/M) gamma(k)``; ``M = 2 m``, m the first lag after which
    ``K_N = max(5, log10 N)`` autocorrelations in a row are insignificant
    (``|rho| < 2 sqrt(log10 N / N)``). Rounded up and kept in ``[1, min(3 sqrt(N), N / 3)]``.
    Non-finite entries are dropped first."""
    x = np.asarray(series, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    n = x.size
    if n < 9:
        return 1
    e = x - x.mean()
    gamma0 = float(e @ e) / n
    if gamma0 == 0.0:
        return 1
    k_n = max(5, int(math.log10(n)))
    m_max = min(int(math.ceil(math.sqrt(n))) + k_n, n - 1)
    gamma = np.array([float(e[k:] @ e[: n - k]) / n for k in range(m_max + 1)])
    rho = np.abs(gamma[1:] / gamma0)
    bound = 2.0 * math.sqrt(math.log10(n) / n)
    m_hat = m_max
    for m in range(0, m_max - k_n + 1):
        if (rho[m : m + k_n] < bound).all():
            m_hat = m
            break
    big_m = min(2 * max(m_hat, 1), m_max)
    k = np.arange(-big_m, big_m + 1)
    lam = _flat_top(k / big_m)
    gam = gamma[np.abs(k)]
    g_sum = float(np.sum(lam * np.abs(k) * gam))
    g0 = float(np.sum(lam * gam))
    if g0 <= 0.0 or g_sum == 0.0:
        return 1
    b = (2.0 * g_sum**2 / (4.0 / 3.0 * g0**2)) ** (1.0 / 3.0) * n ** (1.0 / 3.0)
    b_max = min(3.0 * math.sqrt(n), n / 3.0)
    return int(min(max(math.ceil(b), 1), math.floor(b_max)))


def moving_block_indices(
    lengths: Sequence[int], block: int, n_resamples: int, rng: np.random.Generator
) -> NDArray[np.int64]:
    """(B, N) frame indices of ``n_resamples`` moving-block resamples of segments of the given
    lengths laid end to end (N = their sum): each segment (a sequence) is rebuilt from blocks
    of ``block`` consecutive frames of that segment only, starting anywhere in it, cut to its
    length; no block crosses from one segment into the next."""
    if block < 1:
        raise ValueError(f"block must be >= 1, got {block}")
    parts = []
    offset = 0
    for n in lengths:
        if n <= 0:
            raise ValueError(f"segment lengths must be > 0, got {list(lengths)}")
        b = min(block, n)
        count = -(-n // b)
        starts = rng.integers(0, n - b + 1, size=(n_resamples, count))
        index = (starts[:, :, None] + np.arange(b)[None, None, :]).reshape(n_resamples, -1)
        parts.append(index[:, :n] + offset)
        offset += n
    return np.concatenate(parts, axis=1).astype(np.int64)


def block_bootstrap_interval(
    statistic: Callable[[NDArray[np.int64]], F64],
    lengths: Sequence[int],
    block: int,
    *,
    rng: np.random.Generator,
    confidence: float = CONFIDENCE,
    n_resamples: int = DEFAULT_RESAMPLES,
) -> Interval:
    """Percentile interval of a statistic of correlated frames by the moving-block bootstrap.

    Args:
        statistic: maps (B, N) frame indices to (B,) values (vectorised over resamples); the
            estimate is its value on the frames as they are.
        lengths: frames of each segment (sequence); blocks stay inside a segment.
        block: block length [frames] (e.g. :func:`politis_white_block_length`).
        rng: generator of the resamples.
        confidence: confidence level.
        n_resamples: resamples.
    """
    n = int(sum(lengths))
    estimate = float(statistic(np.arange(n, dtype=np.int64)[None, :])[0])
    index = moving_block_indices(lengths, block, n_resamples, rng)
    values = np.asarray(statistic(index), dtype=np.float64)
    values = values[np.isfinite(values)]
    if values.size < 2 or not math.isfinite(estimate):
        return Interval(estimate=estimate, low=math.nan, high=math.nan, n=n, method=BLOCK_METHOD)
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(values, [alpha, 1.0 - alpha])
    return Interval(
        estimate=estimate,
        low=float(low),
        high=float(high),
        n=n,
        confidence=confidence,
        method=BLOCK_METHOD,
    )
