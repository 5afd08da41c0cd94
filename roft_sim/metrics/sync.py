"""Synchronisation-specific figures: error around delayed arrivals, recovery after dropout
bursts, and how many injected outlier poses a tracker rejected.

These take plain arrays and id sets (no dependency on the fault injectors): the per-frame error
of a run (e.g. :attr:`SequenceMetrics.t_err_norm_cm` or ``a_err_deg``), the frames at which
detections arrived, the frames at which dropout bursts ended, the ``detection_id`` values a
tracker accepted and rejected, and the ids of the detections a fault injector corrupted.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from roft_sim.records import Estimate

F64 = NDArray[np.float64]

__all__ = [
    "ArrivalEffect",
    "error_around_arrivals",
    "error_band",
    "recovery_frames",
    "OutlierRejectionStats",
    "outlier_rejection_stats",
    "outlier_rejection_stats_from_estimates",
]


def _errors(errors: ArrayLike) -> F64:
    e = np.asarray(errors, dtype=np.float64)
    if e.ndim != 1:
        raise ValueError(f"errors must have shape (N,), got {e.shape}")
    return e


def _frames(frames: ArrayLike, n: int, what: str) -> NDArray[np.int64]:
    f = np.asarray(frames)
    if f.ndim != 1 or (f.size and not np.issubdtype(f.dtype, np.integer)):
        raise ValueError(f"{what} must be a 1-D array of integer frame indices, got {f!r}")
    f = f.astype(np.int64)
    if f.size and (f.min() < 0 or f.max() >= n):
        raise ValueError(f"{what} must lie in [0, {n - 1}], got {f.min()}..{f.max()}")
    return f


@dataclass(frozen=True, slots=True, kw_only=True)
class ArrivalEffect:
    """Error just before versus just after detections arrive (event-triggered average)."""

    offsets: NDArray[np.int64]
    """(2W,) frame offsets ``-W .. W-1`` relative to the arrival frame."""
    mean_at_offset: F64
    """(2W,) mean error at each offset over the arrivals (NaN where no frame exists)."""
    before_mean: float
    """Mean error over frames ``[a - W, a)`` of every arrival ``a``."""
    after_mean: float
    """Mean error over frames ``[a, a + W)`` (the estimate at ``a`` already uses the arrival)."""
    arrivals: int
    """Arrivals averaged."""

    @property
    def ratio(self) -> float:
        """``after_mean / before_mean`` (< 1: arrivals reduce the error)."""
        return self.after_mean / self.before_mean if self.before_mean > 0 else float("nan")


def error_around_arrivals(
    errors: ArrayLike, arrival_frames: ArrayLike, *, window: int = 3
) -> ArrivalEffect:
    """Event-triggered average of a per-frame error around detection arrivals.

    Args:
        errors: (N,) per-frame error (any unit; NaN frames are ignored).
        arrival_frames: (A,) frames at which a detection reached the tracker.
        window: W, frames on each side.
    """
    e = _errors(errors)
    a = np.unique(_frames(arrival_frames, e.size, "arrival_frames"))
    if window < 1:
        raise ValueError(f"window must be >= 1, got {window}")
    offsets = np.arange(-window, window, dtype=np.int64)
    idx = a[:, None] + offsets[None, :]
    inside = (idx >= 0) & (idx < e.size)
    vals = np.where(inside, e[np.clip(idx, 0, max(e.size - 1, 0))], np.nan)
    with warnings.catch_warnings():  # all-NaN columns (arrivals at the edges) give NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        per_offset = np.nanmean(vals, axis=0) if a.size else np.full(offsets.shape, np.nan)
        before = float(np.nanmean(vals[:, :window])) if a.size else float("nan")
        after = float(np.nanmean(vals[:, window:])) if a.size else float("nan")
    return ArrivalEffect(
        offsets=offsets,
        mean_at_offset=per_offset,
        before_mean=before,
        after_mean=after,
        arrivals=int(a.size),
    )


def error_band(
    errors: ArrayLike, *, quantile: float = 0.95, mask: ArrayLike | None = None
) -> float:
    """A tolerance band for :func:`recovery_frames`: the ``quantile`` of the error on the frames
    selected by ``mask`` (e.g. a fault-free run, or the frames outside any burst).

    Args:
        errors: (N,) per-frame error.
        quantile: in (0, 1].
        mask: (N,) bool frames to use; None = all finite frames.
    """
    e = _errors(errors)
    sel = np.isfinite(e) if mask is None else np.asarray(mask, dtype=bool) & np.isfinite(e)
    if not 0 < quantile <= 1 or not sel.any():
        raise ValueError(
            f"need 0 < quantile <= 1 (got {quantile}) and at least one finite selected frame"
        )
    return float(np.quantile(e[sel], quantile))


def recovery_frames(
    errors: ArrayLike, burst_end_frames: ArrayLike, *, band: float, hold: int = 1
) -> F64:
    """Frames from the end of each dropout burst until the error is back within ``band``.

    Args:
        errors: (N,) per-frame error.
        burst_end_frames: (B,) first frame after each burst (when detections resume).
        band: tolerance; "recovered" means ``error <= band`` for ``hold`` consecutive frames.
        hold: consecutive frames required inside the band.

    Returns:
        (B,) float: ``r >= 0`` such that frames ``[end + r, end + r + hold)`` are within the band
        (0 if the error never left it); ``inf`` when it does not recover before the sequence
        ends.
    """
    e = _errors(errors)
    ends = _frames(burst_end_frames, e.size, "burst_end_frames")
    if hold < 1:
        raise ValueError(f"hold must be >= 1, got {hold}")
    within = np.nan_to_num(e, nan=np.inf) <= band
    # run[k] = number of consecutive within-band frames starting at k
    run = np.zeros(e.size + 1, dtype=np.int64)
    for k in range(e.size - 1, -1, -1):
        run[k] = run[k + 1] + 1 if within[k] else 0
    ok = run[:-1] >= hold
    out = np.full(ends.size, np.inf)
    for i, end in enumerate(ends):
        hit = np.flatnonzero(ok[end:])
        if hit.size:
            out[i] = float(hit[0])
    return out


def _binomial_ci(k: int, n: int, confidence: float) -> tuple[float, float]:
    if n == 0:
        return (float("nan"), float("nan"))
    ci = stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="exact")
    return (float(ci.low), float(ci.high))


@dataclass(frozen=True, slots=True, kw_only=True)
class OutlierRejectionStats:
    """How a tracker's outlier rejection treated the poses it saw."""

    poses_seen: int
    """Distinct pose ids the tracker accepted or rejected."""
    poses_rejected: int
    """Distinct ids rejected (and never accepted)."""
    injected_seen: int
    """Injected outliers among the poses seen."""
    injected_caught: int
    """Injected outliers rejected."""
    injected_unseen: int
    """Injected outliers never seen (dropped by other faults, or arrived too late)."""
    false_rejections: int
    """Clean poses rejected."""
    ambiguous: int
    """Ids both accepted and rejected at some step (counted as accepted)."""
    catch_rate_ci: tuple[float, float]
    """Clopper-Pearson interval of ``catch_rate``."""
    false_rejection_rate_ci: tuple[float, float]
    """Clopper-Pearson interval of ``false_rejection_rate``."""

    @property
    def rejected_fraction(self) -> float:
        """Rejected / seen."""
        return self.poses_rejected / self.poses_seen if self.poses_seen else float("nan")

    @property
    def catch_rate(self) -> float:
        """Injected outliers rejected / injected outliers seen."""
        return self.injected_caught / self.injected_seen if self.injected_seen else float("nan")

    @property
    def false_rejection_rate(self) -> float:
        """Clean poses rejected / clean poses seen."""
        clean = self.poses_seen - self.injected_seen
        return self.false_rejections / clean if clean else float("nan")


def _flatten(ids: Iterable[Iterable[int]] | Iterable[int]) -> set[int]:
    out: set[int] = set()
    for item in ids:
        if isinstance(item, int | np.integer):
            out.add(int(item))
        else:
            out.update(int(i) for i in item)
    return out


def outlier_rejection_stats(
    accepted_ids: Iterable[Iterable[int]] | Iterable[int],
    rejected_ids: Iterable[Iterable[int]] | Iterable[int],
    injected_outlier_ids: Iterable[int],
    *,
    confidence: float = 0.95,
) -> OutlierRejectionStats:
    """Counts rejections against the ledger of injected outliers.

    Args:
        accepted_ids: pose ids the tracker fused (per frame, or flat).
        rejected_ids: pose ids the tracker rejected as outliers (per frame, or flat).
        injected_outlier_ids: ids of the detections a fault injector corrupted.
        confidence: level of the binomial intervals.
    """
    acc = _flatten(accepted_ids)
    rej_any = _flatten(rejected_ids)
    inj = {int(i) for i in injected_outlier_ids}
    ambiguous = acc & rej_any
    rej = rej_any - acc
    seen = acc | rej
    inj_seen = inj & seen
    caught = inj & rej
    false = rej - inj
    clean_seen = len(seen) - len(inj_seen)
    return OutlierRejectionStats(
        poses_seen=len(seen),
        poses_rejected=len(rej),
        injected_seen=len(inj_seen),
        injected_caught=len(caught),
        injected_unseen=len(inj - seen),
        false_rejections=len(false),
        ambiguous=len(ambiguous),
        catch_rate_ci=_binomial_ci(len(caught), len(inj_seen), confidence),
        false_rejection_rate_ci=_binomial_ci(len(false), clean_seen, confidence),
    )


def outlier_rejection_stats_from_estimates(
    estimates: SequenceABC[Estimate],
    injected_outlier_ids: Iterable[int],
    *,
    confidence: float = 0.95,
) -> OutlierRejectionStats:
    """:func:`outlier_rejection_stats` from the ids recorded in a run's estimates."""
    return outlier_rejection_stats(
        [e.accepted_pose_ids for e in estimates],
        [e.rejected_pose_ids for e in estimates],
        injected_outlier_ids,
        confidence=confidence,
    )
