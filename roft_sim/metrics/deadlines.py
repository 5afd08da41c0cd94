"""Scoring a tracker that ran against a real clock (``roft-sim run --clock wall``).

Times are on the run's clock [s] (wall seconds divided by the run's time scale), from the
release of frame 0. Camera frame k is released at ``k / fps``; its **deadline** is the release of
the next frame, ``(k + 1) / fps``. A consumer of the tracker holds, at any time, the most
recently delivered estimate, whatever frame it was computed for; so the estimate scored for frame
k is the one with the latest delivery time at or before frame k's deadline
(:func:`held_at_deadlines`), and frames before the first delivery have none (scored as invalid
estimates).

:class:`DeadlineStats` keeps the per-frame timing and summarises it: latency percentiles (from a
frame's release to the delivery of its own estimate, over the frames whose images the tracker
got), deadline misses (frames whose own estimate came after their deadline, or never), frames
the tracker never saw (dropped while it was busy) and the longest queue of frames waiting for it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
Bool = NDArray[np.bool_]

__all__ = [
    "DeadlineStats",
    "deadline_stats",
    "frame_deadlines_s",
    "held_at_deadlines",
    "pool_deadline_stats",
]


def frame_deadlines_s(n_frames: int, fps: int) -> F64:
    """(N,) deadline of each frame [s]: the release of the next one, ``(k + 1) / fps``."""
    if n_frames < 0 or fps <= 0:
        raise ValueError(f"need n_frames >= 0 and fps > 0, got {n_frames} and {fps}")
    deadlines: F64 = (np.arange(n_frames, dtype=np.float64) + 1.0) / float(fps)
    return deadlines


def held_at_deadlines(delivered_s: ArrayLike, deadlines_s: ArrayLike) -> I64:
    """For each deadline, the estimate a consumer holds then: the latest delivered by it.

    Args:
        delivered_s: (E,) delivery time of each estimate [s]; NaN = never delivered. Ties go to
            the estimate with the larger index (delivered last).
        deadlines_s: (N,) deadlines [s]; an estimate delivered exactly at a deadline counts.

    Returns:
        (N,) int64 index into ``delivered_s`` of the estimate held at each deadline; -1 where
        none had been delivered yet.
    """
    t = np.asarray(delivered_s, dtype=np.float64)
    d = np.asarray(deadlines_s, dtype=np.float64)
    if t.ndim != 1 or d.ndim != 1:
        raise ValueError(f"need 1-D arrays, got shapes {t.shape} and {d.shape}")
    if np.isinf(t).any() or not np.isfinite(d).all():
        raise ValueError("delivery times must be finite or NaN, deadlines finite")
    index = np.flatnonzero(np.isfinite(t))
    order = index[np.lexsort((index, t[index]))]  # by time, then by index
    # the number of deliveries at or before each deadline; the last of them is the one held
    count = np.searchsorted(t[order], d, side="right")
    held: I64 = np.where(count > 0, order[np.maximum(count - 1, 0)], -1).astype(np.int64)
    return held


@dataclass(frozen=True, slots=True, kw_only=True)
class DeadlineStats:
    """Per-frame timing of a wall-clock run and its summary (all times on the run's clock)."""

    latency_s: F64
    """(N,) delivery of frame k's own estimate minus the release of frame k [s]; NaN where the
    tracker never saw the frame's images (the summary's percentiles skip those)."""
    missed: Bool
    """(N,) True where frame k's own estimate was not delivered by its deadline."""
    dropped_busy: Bool
    """(N,) True where the tracker was busy and the frame's images were dropped (``drop``)."""
    estimate_age_frames: I64
    """(N,) ``k - j`` for the estimate of frame j held at frame k's deadline; -1 where none."""
    release_lag_s: F64
    """(N,) how late the harness released each frame against ``k / fps`` [s] (its own load)."""
    queue_max: int | None
    """Under ``queue``, the most frames still waiting for the tracker when the next one was
    released (0: it always kept up); None under ``drop``."""

    @property
    def frames(self) -> int:
        """Frames timed."""
        return int(self.missed.size)

    def summary(self) -> dict[str, Any]:
        """Flat, JSON-ready figures: ``latency_p50_ms``, ``latency_p95_ms``, ``latency_max_ms``,
        ``deadline_misses``, ``frames_dropped_busy``, ``frames_without_estimate``,
        ``estimate_age_max_frames``, ``queue_max`` and ``release_lag_max_ms`` (None when there
        is nothing to summarise)."""

        def ms(x: float) -> float | None:
            return round(1e3 * x, 3) if np.isfinite(x) else None

        seen = self.latency_s[np.isfinite(self.latency_s)]
        p50, p95, top = (
            (np.percentile(seen, 50), np.percentile(seen, 95), seen.max())
            if seen.size
            else (np.nan, np.nan, np.nan)
        )
        held = self.estimate_age_frames[self.estimate_age_frames >= 0]
        lag = self.release_lag_s[np.isfinite(self.release_lag_s)]
        return {
            "latency_p50_ms": ms(float(p50)),
            "latency_p95_ms": ms(float(p95)),
            "latency_max_ms": ms(float(top)),
            "deadline_misses": int(np.count_nonzero(self.missed)),
            "frames_dropped_busy": int(np.count_nonzero(self.dropped_busy)),
            "frames_without_estimate": int(np.count_nonzero(self.estimate_age_frames < 0)),
            "estimate_age_max_frames": int(held.max()) if held.size else None,
            "queue_max": self.queue_max,
            "release_lag_max_ms": ms(float(lag.max())) if lag.size else None,
        }


def deadline_stats(
    *,
    release_s: ArrayLike,
    delivered_s: ArrayLike,
    seen: ArrayLike,
    dropped_busy: ArrayLike,
    fps: int,
    queue_max: int | None,
) -> DeadlineStats:
    """The timing figures of one sequence run against a real clock.

    Args:
        release_s: (N,) when the harness released frame k [s] (ideally ``k / fps``).
        delivered_s: (N,) when the estimate computed for frame k was delivered [s]; NaN = never.
        seen: (N,) True where the tracker got frame k's images (False: dropped by a camera
            fault or while the tracker was busy).
        dropped_busy: (N,) True where frame k was dropped because the tracker was busy.
        fps: camera rate [Hz].
        queue_max: the longest backlog under ``queue`` (see :class:`DeadlineStats`), None under
            ``drop``.

    Returns:
        The :class:`DeadlineStats`.
    """
    release = np.asarray(release_s, dtype=np.float64)
    delivered = np.asarray(delivered_s, dtype=np.float64)
    seen_ = np.asarray(seen, dtype=bool)
    dropped = np.asarray(dropped_busy, dtype=bool)
    n = release.shape[0] if release.ndim == 1 else -1
    for name, a in (("delivered_s", delivered), ("seen", seen_), ("dropped_busy", dropped)):
        if a.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},) like release_s, got {a.shape}")
    deadlines = frame_deadlines_s(n, fps)
    held = held_at_deadlines(delivered, deadlines)
    late = ~(delivered <= deadlines)  # NaN (never delivered) is late too
    return DeadlineStats(
        latency_s=np.where(seen_, delivered - release, np.nan),
        missed=late,
        dropped_busy=dropped,
        estimate_age_frames=np.where(held >= 0, np.arange(n) - held, -1).astype(np.int64),
        release_lag_s=release - (deadlines - 1.0 / fps),
        queue_max=queue_max,
    )


def pool_deadline_stats(parts: Sequence[DeadlineStats]) -> DeadlineStats:
    """Frames of several runs pooled into one (percentiles over all frames; the largest queue)."""
    if not parts:
        raise ValueError("need at least one DeadlineStats to pool")
    queues = [p.queue_max for p in parts if p.queue_max is not None]
    return DeadlineStats(
        latency_s=np.concatenate([p.latency_s for p in parts]),
        missed=np.concatenate([p.missed for p in parts]),
        dropped_busy=np.concatenate([p.dropped_busy for p in parts]),
        estimate_age_frames=np.concatenate([p.estimate_age_frames for p in parts]),
        release_lag_s=np.concatenate([p.release_lag_s for p in parts]),
        queue_max=max(queues) if queues else None,
    )
