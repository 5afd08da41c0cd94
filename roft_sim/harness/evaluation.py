"""Scoring a :class:`~roft_sim.harness.runner.SequenceRun` with :mod:`roft_sim.metrics`.

:func:`evaluate_run` gives the pose and velocity metrics of one sequence (docs/metrics.md) plus
the figures that need the fault ledger:

- ``sync``: mean position [cm], rotation [deg] and angular-velocity [deg/s] error norm in the 3
  frames before and from each pose arrival (:func:`~roft_sim.metrics.error_around_arrivals`);
- ``outliers``: how many poses the tracker rejected and how many injected outliers it caught
  (only when outliers were injected or anything was rejected);
- ``recovery``: frames from the end of each burst of dropped poses until the position error is
  back within the band of the frames outside bursts (95th percentile), when poses were dropped;
- ``consistency``: NEES of the 12-D state (pose, ``v_obj``, ``w``) against the single-run 95 %
  chi-square interval, when the tracker reports covariances.

With ``--clock wall`` the metrics score the estimate held at each frame's deadline
(``SequenceRun.estimates``) and the entry adds the clock and its timing figures
(:class:`~roft_sim.metrics.deadlines.DeadlineStats`); the outlier and consistency figures, which
describe the tracker rather than its timing, use the tracker's own estimates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.harness.runner import SequenceRun
from roft_sim.harness.wall_clock import clock_record
from roft_sim.metrics import (
    InvalidPolicy,
    SequenceMetrics,
    chi2_bounds,
    error_around_arrivals,
    error_band,
    evaluate_estimates,
    nees,
    outlier_rejection_stats_from_estimates,
    recovery_frames,
    state_error,
)
from roft_sim.metrics.deadlines import DeadlineStats
from roft_sim.records import Estimate, PoseTrack

F64 = NDArray[np.float64]

__all__ = [
    "SequenceEvaluation",
    "evaluate_run",
    "estimate_errors",
    "ARRIVAL_WINDOW_FRAMES",
    "NEES_DOF",
]

ARRIVAL_WINDOW_FRAMES = 3
"""Frames on each side of a pose arrival averaged by the ``arrivals`` figure."""
NEES_DOF = 12
"""Dimension of the state whose NEES is reported (pose 6 + velocity 6)."""


def _num(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


@dataclass(frozen=True, slots=True, kw_only=True)
class SequenceEvaluation:
    """The metrics of one run of one sequence."""

    metrics: SequenceMetrics | None
    """Pose and velocity metrics; None when the sequence has no ground truth."""
    figures: dict[str, Any]
    """JSON-ready synchronisation and consistency figures (see the module docstring)."""
    deadlines: DeadlineStats | None = None
    """The timing of a ``--clock wall`` run (its summary is in ``figures``); None otherwise."""

    def entry(self) -> dict[str, Any]:
        """The sequence's entry of ``metrics.json``: the metric scalars and the figures."""
        out: dict[str, Any] = {} if self.metrics is None else self.metrics.summary()
        if self.metrics is not None and self.metrics.step_time is not None:
            out["time_max_ms"] = _num(self.metrics.step_time.max_ms)
        return out | self.figures


def _per_frame(m: SequenceMetrics, values: F64, n: int) -> F64:
    """A per-evaluated-frame array spread back onto all ``n`` frames (NaN where not scored)."""
    out = np.full(n, np.nan)
    out[m.frame_index] = values
    return out


def _arrival_figures(run: SequenceRun, m: SequenceMetrics) -> dict[str, Any]:
    n = len(run)
    arrivals = run.pose_arrival_frames()
    if arrivals.size == 0:
        return {"arrivals": 0}
    out: dict[str, Any] = {"arrivals": int(arrivals.size), "window_frames": ARRIVAL_WINDOW_FRAMES}
    w_err_norm_dps = np.linalg.norm(m.w_err_dps, axis=1)  # (F,) NaN where no twist was scored
    for key, values in (
        ("t_err_cm", m.t_err_norm_cm),
        ("a_err_deg", m.a_err_deg),
        ("w_err_dps", w_err_norm_dps),
    ):
        effect = error_around_arrivals(
            _per_frame(m, values, n), arrivals, window=ARRIVAL_WINDOW_FRAMES
        )
        out[key] = {
            "before": _num(effect.before_mean),
            "after": _num(effect.after_mean),
            "ratio": _num(effect.ratio),
        }
    return out


def _outlier_figures(run: SequenceRun) -> dict[str, Any] | None:
    injected = run.ledger.outlier_ids()
    estimates = run.tracker_estimates
    rejected_any = any(e.rejected_pose_ids for e in estimates)
    if not injected and not rejected_any:
        return None
    s = outlier_rejection_stats_from_estimates(estimates, injected)
    return {
        "poses_seen": s.poses_seen,
        "poses_rejected": s.poses_rejected,
        "rejected_fraction": _num(s.rejected_fraction),
        "injected": len(injected),
        "injected_seen": s.injected_seen,
        "injected_caught": s.injected_caught,
        "catch_rate": _num(s.catch_rate),
        "catch_rate_ci95": [_num(x) for x in s.catch_rate_ci],
        "false_rejections": s.false_rejections,
        "false_rejection_rate": _num(s.false_rejection_rate),
    }


def dropout_bursts(run: SequenceRun) -> list[tuple[int, int]]:
    """``(first_frame, end_frame)`` of every burst of consecutive dropped pose results: from the
    capture frame of the first lost result to the arrival of the next delivered one."""
    records = run.ledger.pose
    bursts: list[tuple[int, int]] = []
    i = 0
    while i < len(records):
        if records[i].fate != "dropped":
            i += 1
            continue
        j = i
        while j < len(records) and records[j].fate == "dropped":
            j += 1
        following = [r for r in records[j:] if r.arrivals]
        if following:
            bursts.append((records[i].true_capture_k, min(following[0].arrivals)))
        i = j
    return bursts


def _recovery_figures(run: SequenceRun, m: SequenceMetrics) -> dict[str, Any] | None:
    bursts = dropout_bursts(run)
    if not bursts:
        return None
    n = len(run)
    err = _per_frame(m, m.t_err_norm_cm, n)
    outside = np.ones(n, dtype=bool)
    for first, end in bursts:
        outside[first : min(end, n)] = False
    if not (outside & np.isfinite(err)).any():
        return {"bursts": len(bursts), "band_t_cm": None}
    band = error_band(err, quantile=0.95, mask=outside)
    ends = np.array([min(end, n - 1) for _, end in bursts], dtype=np.int64)
    frames = recovery_frames(err, ends, band=band)
    finite = frames[np.isfinite(frames)]
    return {
        "bursts": len(bursts),
        "band_t_cm": _num(band),
        "recovery_frames_mean": _num(float(finite.mean())) if finite.size else None,
        "recovery_frames_max": _num(float(frames.max())),
        "not_recovered": int(np.count_nonzero(~np.isfinite(frames))),
    }


def estimate_errors(
    estimates: Sequence[Estimate], ground_truth: PoseTrack, frames: NDArray[np.int64]
) -> tuple[F64, F64]:
    """The 12-D errors of estimates that all carry a covariance, with those covariances.

    Args:
        estimates: N estimates, each with a ``covariance``.
        ground_truth: the sequence's ground truth.
        frames: (N,) frame of each estimate in ``ground_truth``.

    Returns:
        ``(errors, covariances)``: (N, 12) ``x_true - x_est`` (:func:`state_error`) and
        (N, 12, 12), both in ``ESTIMATE_COVARIANCE_ORDER``.
    """
    errors = state_error(
        np.stack([e.T_cam_obj for e in estimates]),
        np.stack([e.v_obj_mps for e in estimates]),
        np.stack([e.w_radps for e in estimates]),
        ground_truth.T_cam_obj[frames],
        ground_truth.v_obj_mps[frames],
        ground_truth.w_radps[frames],
    )
    covariances = np.stack([e.covariance for e in estimates])  # type: ignore[misc]
    return errors, covariances


def _consistency_figures(run: SequenceRun) -> dict[str, Any] | None:
    gt = run.ground_truth
    estimates = run.tracker_estimates
    rows = [
        k
        for k, e in enumerate(estimates)
        if e.valid and e.covariance is not None and np.isfinite(e.T_cam_obj).all()
    ]
    if gt is None or not rows:
        return None
    errors, covs = estimate_errors([estimates[k] for k in rows], gt, np.array(rows))
    try:
        values = nees(errors, covs)
    except ValueError as e:
        return {"nees_error": str(e)}
    lo, hi = chi2_bounds(NEES_DOF, 1)
    return {
        "nees_dof": NEES_DOF,
        "nees_mean": _num(float(values.mean())),
        "nees_median": _num(float(np.median(values))),
        "nees_fraction_inside_95": _num(float(np.mean((values >= lo) & (values <= hi)))),
        "nees_bounds_95": [lo, hi],
        "nees_frames": int(values.size),
    }


def evaluate_run(
    run: SequenceRun, *, invalid: InvalidPolicy = "failure", with_adds: bool = False
) -> SequenceEvaluation:
    """Scores one run (see the module docstring); metrics are None without ground truth."""
    figures: dict[str, Any] = {"faults": run.ledger.summary()}
    deadlines = None
    if run.wall_clock is not None:
        deadlines = run.wall_clock.stats()
        figures |= {"clock": clock_record(run.wall_clock.clock)} | deadlines.summary()
    if run.ground_truth is None:
        return SequenceEvaluation(metrics=None, figures=figures, deadlines=deadlines)
    m = evaluate_estimates(
        run.estimates,
        run.ground_truth,
        run.object_model.model_points_m,
        velocity="auto",
        invalid=invalid,
        step_times_s=run.step_times_s,
        with_adds=with_adds,
    )
    figures["sync"] = _arrival_figures(run, m)
    for key, value in (
        ("outliers", _outlier_figures(run)),
        ("recovery", _recovery_figures(run, m)),
        ("consistency", _consistency_figures(run)),
    ):
        if value is not None:
            figures[key] = value
    return SequenceEvaluation(metrics=m, figures=figures, deadlines=deadlines)
