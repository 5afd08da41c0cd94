"""Per-sequence pose and velocity metrics, and pooling over sequences ("ALL" and "MEAN").

The reference evaluation (ROFT ``evaluation/``; docs/metrics.md) scores every frame, aligned by
index with the ground truth:

- ADD-AUC [%]: :func:`roft_sim.metrics.auc.add_auc` of the per-frame ADD (all model points,
  plain ADD for every object, distances above 0.1 m are failures).
- RMSE of the position error [cm]: ``sqrt(mean |t_est - t_gt|^2)``; per axis as well.
- RMSE of the geodesic rotation error [deg]: ``sqrt(mean angle(R_gt R_est^T)^2)``.
- Velocity RMSE [cm/s] and [deg/s] of the object-origin velocity ``v_obj`` and the angular
  velocity ``w``, camera frame. A spatial twist estimate ``(v_o, w)`` (ROFT's velocity KF) is
  converted with the GROUND-TRUTH position, ``v = v_o + w x t_gt``, as the reference does;
  otherwise ``v_obj`` and ``w`` are compared directly. A frame without a twist (ROFT's frame 0,
  before its velocity filter has seen flow) is scored with its ``v_obj`` and ``w``: the row of
  ``velocity_estimate.txt`` the reference scores for it. The angular error is the norm of the
  component-wise rad->deg difference.
- "ALL" pools the frames of every sequence into one curve and one RMSE; "MEAN" averages the
  per-sequence numbers (the "Average" of other papers).

Invalid estimates (``Estimate.valid`` False: the tracker has no pose yet) enter by policy:

- ``"failure"`` (default): ADD = inf (a failure in the AUC, counted in N), and the frame is
  left out of the RMSEs (which the identity pose of an invalid estimate would otherwise
  dominate arbitrarily); ``frames_invalid`` reports how many.
- ``"exclude"``: the frame is dropped from every metric, as the reference does for missing
  detections when it scores "DOPE (ideal)".
- ``"as_given"``: the pose and velocity are scored as they are (the reference scores whatever
  a tracker wrote on each frame).
- ``"hold"``: the reference's treatment of its DOPE row (``data_loader.load_dope`` with
  ``simulate_inference``): frames before the first valid estimate are dropped, and an invalid
  frame after it is scored with the last valid estimate (pose and velocity held). The default of
  the ``paper`` fault preset (``roft-sim run``, ``roft-sim paper``).

Every table that prints these metrics says which policy produced it (:func:`policy_note`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry.se3 import v_obj_from_v_o
from roft_sim.metrics.auc import DEFAULT_MAX_THRESHOLD_M, add_auc
from roft_sim.metrics.pose_errors import (
    add_distances,
    adds_distances,
    rotation_errors_rad,
    translation_errors_m,
)
from roft_sim.metrics.timing import StepTimeStats, step_time_stats
from roft_sim.records import Estimate, PoseTrack

F64 = NDArray[np.float64]

__all__ = [
    "InvalidPolicy",
    "SequenceMetrics",
    "evaluate_sequence",
    "evaluate_estimates",
    "concatenate_metrics",
    "pool_metrics",
    "POOLED_ALL",
    "POOLED_MEAN",
    "INVALID_POLICIES",
    "held_estimate_index",
    "policy_note",
]

InvalidPolicy = Literal["failure", "exclude", "as_given", "hold"]
INVALID_POLICIES: tuple[str, ...] = get_args(InvalidPolicy)
"""Every :data:`InvalidPolicy`, in the order the CLI lists them."""
_POLICY_NOTES = {
    "failure": "frames without a tracker pose are failures (ADD = inf, left out of the RMSEs)",
    "exclude": "frames without a tracker pose are left out",
    "as_given": "frames without a tracker pose are scored as given",
    "hold": "frames before the first tracker pose are left out, later frames without one hold "
    "the last (the reference's DOPE policy)",
}
POOLED_ALL = "ALL"
"""Key of the frame-pooled entry of :func:`pool_metrics`."""
POOLED_MEAN = "MEAN"
"""Key of the mean-over-entries entry of :func:`pool_metrics`."""

_CM = 100.0
_DEG = 180.0 / np.pi


def policy_note(invalid: str) -> str:
    """One line for a table: which invalid-estimate policy produced it, in words."""
    if invalid not in _POLICY_NOTES:
        raise ValueError(f"invalid must be one of {INVALID_POLICIES}, got {invalid!r}")
    return f"invalid estimates: {invalid} ({_POLICY_NOTES[invalid]})"


def held_estimate_index(valid: ArrayLike) -> NDArray[np.int64]:
    """(N,) index of the last valid frame at or before each frame; -1 before the first.

    Args:
        valid: (N,) bool, True where the tracker reported a pose.
    """
    ok = np.asarray(valid, dtype=bool)
    if ok.ndim != 1:
        raise ValueError(f"valid must have shape (N,), got {ok.shape}")
    marks = np.where(ok, np.arange(ok.size, dtype=np.int64), np.int64(-1))
    held: NDArray[np.int64] = np.maximum.accumulate(marks)
    return held


def _rmse(norms: F64) -> float:
    """sqrt(mean(x^2)) over the finite entries of ``norms``; NaN when there is none."""
    x = norms[np.isfinite(norms)]
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


@dataclass(frozen=True, slots=True, kw_only=True)
class SequenceMetrics:
    """Metrics of one sequence (or of pooled sequences) and the per-frame errors behind them.

    Per-frame arrays have one row per EVALUATED frame (``frames`` rows; frames dropped by the
    ``"exclude"`` policy are absent, see ``frame_index``). Rows left out of an RMSE are NaN.
    """

    add_auc_pct: float
    """ADD-AUC [%] (YCB-Video VOCap, thresholds up to ``max_threshold_m``)."""
    adds_auc_pct: float
    """ADD-S-AUC [%]; NaN unless requested (``with_adds=True``)."""
    rmse_t_cm: float
    """RMSE of the position error [cm]."""
    rmse_t_axes_cm: tuple[float, float, float]
    """RMSE of the x, y, z position error [cm], camera frame."""
    rmse_a_deg: float
    """RMSE of the geodesic rotation error [deg]."""
    rmse_v_cmps: float
    """RMSE of the object-origin velocity error [cm/s]; NaN without velocities."""
    rmse_w_dps: float
    """RMSE of the angular velocity error [deg/s]; NaN without velocities."""
    frames: int
    """Frames evaluated (the N of the ADD-AUC, failures included)."""
    frames_invalid: int
    """Frames whose estimate was invalid (whatever the policy did with them)."""
    frames_rmse: int
    """Frames in the pose RMSEs."""
    frames_velocity: int
    """Frames in the velocity RMSEs."""
    step_time: StepTimeStats | None
    """Step-time statistics when step times were given."""
    frame_index: NDArray[np.int64]
    """(F,) index of each evaluated frame in its sequence."""
    add_m: F64
    """(F,) ADD [m]; inf for failures."""
    adds_m: F64 | None
    """(F,) ADD-S [m], or None."""
    t_err_cm: F64
    """(F, 3) position error ``t_est - t_gt`` [cm], camera frame."""
    a_err_deg: F64
    """(F,) geodesic rotation error [deg]."""
    v_err_cmps: F64
    """(F, 3) velocity error ``v_est - v_gt`` [cm/s], camera frame."""
    w_err_dps: F64
    """(F, 3) angular velocity error ``w_est - w_gt`` [deg/s], camera frame."""
    step_times_s: F64 | None
    """(S,) the step times [s] given, or None."""

    @property
    def t_err_norm_cm(self) -> F64:
        """(F,) position error norm [cm]."""
        norm: F64 = np.linalg.norm(self.t_err_cm, axis=1)
        return norm

    def summary(self) -> dict[str, Any]:
        """Scalars for ``metrics.json``: NaN becomes None; step times as ``time_*_ms``."""

        def num(x: float) -> float | None:
            return None if not np.isfinite(x) else float(x)

        out: dict[str, Any] = {
            "add_auc_pct": num(self.add_auc_pct),
            "adds_auc_pct": num(self.adds_auc_pct),
            "rmse_t_cm": num(self.rmse_t_cm),
            "rmse_t_axes_cm": [num(x) for x in self.rmse_t_axes_cm],
            "rmse_a_deg": num(self.rmse_a_deg),
            "rmse_v_cmps": num(self.rmse_v_cmps),
            "rmse_w_dps": num(self.rmse_w_dps),
            "frames": self.frames,
            "frames_invalid": self.frames_invalid,
            "frames_rmse": self.frames_rmse,
            "frames_velocity": self.frames_velocity,
        }
        if self.step_time is not None:
            out |= {
                "time_median_ms": num(self.step_time.median_ms),
                "time_p95_ms": num(self.step_time.p95_ms),
                "time_mean_ms": num(self.step_time.mean_ms),
                "time_over_budget": self.step_time.over_budget,
            }
        return out


def _as_rows(name: str, a: ArrayLike | None, n: int, width: int) -> F64 | None:
    if a is None:
        return None
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape != (n, width):
        raise ValueError(f"{name} must have shape ({n}, {width}), got {arr.shape}")
    return arr


def _checked_poses(
    T_est: ArrayLike, T_gt: ArrayLike, valid: ArrayLike | None, invalid: str
) -> tuple[F64, F64, NDArray[np.bool_]]:
    """``T_est``, ``T_gt`` as (N, 4, 4) float64 and ``valid`` as (N,) bool (None = all), checked
    with ``invalid`` (see :func:`evaluate_sequence`)."""
    T_est = np.asarray(T_est, dtype=np.float64)
    T_gt = np.asarray(T_gt, dtype=np.float64)
    n = T_gt.shape[0] if T_gt.ndim == 3 else -1
    if T_est.shape != (n, 4, 4) or T_gt.shape != (n, 4, 4):
        raise ValueError(
            f"T_est and T_gt must both have shape (N, 4, 4), got {T_est.shape} and {T_gt.shape}"
        )
    if invalid not in INVALID_POLICIES:
        raise ValueError(
            f"invalid must be 'failure', 'exclude', 'as_given' or 'hold', got {invalid!r}"
        )
    ok = np.ones(n, bool) if valid is None else np.asarray(valid, dtype=bool)
    if ok.shape != (n,):
        raise ValueError(f"valid must have shape ({n},), got {ok.shape}")
    return T_est, T_gt, ok


def _velocity_errors(
    index: NDArray[np.intp],
    from_k: NDArray[np.intp],
    Tg: F64,
    scored: NDArray[np.bool_],
    v_obj_gt: F64 | None,
    w_gt: F64 | None,
    v_obj_est: F64 | None,
    w_est: F64 | None,
    twist: F64 | None,
) -> tuple[F64, F64]:
    """Per scored frame ``index`` (F = index.size), scored with the estimate of frame ``from_k``
    (the held one under ``invalid="hold"``, else the same frame), the linear (F, 3) [cm/s] and
    angular (F, 3) [deg/s] velocity errors, estimate minus ground truth, camera frame; NaN rows
    where a frame is not scored or either side is missing. A spatial twist is scored at the
    ground-truth origin ``t_gt`` (rows of ``Tg``, the ground truth of the kept frames); where its
    row is NaN (no twist), ``v_obj_est`` and ``w_est`` are scored when given."""
    f = index.size
    v_err = np.full((f, 3), np.nan)
    w_err = np.full((f, 3), np.nan)
    if v_obj_gt is None or w_gt is None:
        if any(x is not None for x in (v_obj_est, w_est, twist)):
            raise ValueError("velocity estimates were given without v_obj_gt and w_gt")
        return v_err, w_err
    if twist is not None:
        w_hat = twist[from_k, 3:]
        v_hat = v_obj_from_v_o(twist[from_k, :3], w_hat, Tg[:, :3, 3])
        if v_obj_est is not None and w_est is not None:
            no_twist = ~np.isfinite(twist[from_k]).all(axis=1)
            v_hat[no_twist] = v_obj_est[from_k][no_twist]
            w_hat[no_twist] = w_est[from_k][no_twist]
    elif v_obj_est is not None and w_est is not None:
        v_hat, w_hat = v_obj_est[from_k], w_est[from_k]
    else:
        return v_err, w_err
    v_err = (v_hat - v_obj_gt[index]) * _CM
    w_err = (w_hat - w_gt[index]) * _DEG
    rows = np.isfinite(v_err).all(1) & np.isfinite(w_err).all(1) & scored
    v_err[~rows] = np.nan
    w_err[~rows] = np.nan
    return v_err, w_err


def evaluate_sequence(
    T_est: ArrayLike,
    T_gt: ArrayLike,
    model_points_m: ArrayLike,
    *,
    v_obj_gt: ArrayLike | None = None,
    w_gt: ArrayLike | None = None,
    v_obj_est: ArrayLike | None = None,
    w_est: ArrayLike | None = None,
    spatial_twist_est: ArrayLike | None = None,
    valid: ArrayLike | None = None,
    invalid: InvalidPolicy = "failure",
    step_times_s: ArrayLike | None = None,
    with_adds: bool = False,
    max_threshold_m: float = DEFAULT_MAX_THRESHOLD_M,
) -> SequenceMetrics:
    """Scores one sequence, frame by frame aligned by index (see the module docstring).

    Args:
        T_est: (N, 4, 4) estimated ``T_cam_obj`` [m]; non-finite rows are failures.
        T_gt: (N, 4, 4) ground-truth ``T_cam_obj`` [m].
        model_points_m: (M, 3) model points in the object frame [m].
        v_obj_gt: (N, 3) ground-truth object-origin velocity, camera frame [m/s].
        w_gt: (N, 3) ground-truth angular velocity, camera frame [rad/s].
        v_obj_est: (N, 3) estimated object-origin velocity [m/s] (used without a spatial twist,
            and on the NaN rows of ``spatial_twist_est``).
        w_est: (N, 3) estimated angular velocity [rad/s] (likewise).
        spatial_twist_est: (N, 6) estimated ``(v_o [m/s], w [rad/s])``, camera frame; when
            given it is scored instead of ``v_obj_est``/``w_est``, with ``v = v_o + w x t_gt``.
            A NaN row (a frame without a twist) is scored with ``v_obj_est``/``w_est`` when they
            are given, else left out of the velocity RMSE.
        valid: (N,) bool, False where the tracker had no pose; None = all valid.
        invalid: what invalid frames do: ``"failure"``, ``"exclude"``, ``"as_given"`` or
            ``"hold"`` (module docstring).
        step_times_s: (S,) tracker step times [s] for the timing statistics.
        with_adds: also compute ADD-S and its AUC (KD-tree; slower).
        max_threshold_m: AUC threshold cap [m].

    Returns:
        The :class:`SequenceMetrics`.
    """
    T_est, T_gt, ok = _checked_poses(T_est, T_gt, valid, invalid)
    n = T_gt.shape[0]
    v_obj_gt = _as_rows("v_obj_gt", v_obj_gt, n, 3)
    w_gt = _as_rows("w_gt", w_gt, n, 3)
    v_obj_est = _as_rows("v_obj_est", v_obj_est, n, 3)
    w_est = _as_rows("w_est", w_est, n, 3)
    twist = _as_rows("spatial_twist_est", spatial_twist_est, n, 6)

    source = np.arange(n)  # the estimate scored on each frame
    if invalid == "hold":
        source = held_estimate_index(ok)
        keep = source >= 0
    else:
        keep = ok if invalid == "exclude" else np.ones(n, bool)
    index = np.flatnonzero(keep)
    from_k = source[index]
    Te, Tg, ok_k = T_est[from_k], T_gt[index], ok[from_k]
    f = index.size

    add = add_distances(Te, Tg, model_points_m)
    adds = adds_distances(Te, Tg, model_points_m) if with_adds else None
    scored = np.ones(f, bool) if invalid == "as_given" else ok_k
    if invalid == "failure":
        add[~ok_k] = np.inf
        if adds is not None:
            adds[~ok_k] = np.inf

    t_err = translation_errors_m(Te, Tg) * _CM
    a_err = rotation_errors_rad(Te, Tg) * _DEG
    t_err[~scored] = np.nan
    a_err[~scored] = np.nan

    v_err, w_err = _velocity_errors(
        index, from_k, Tg, scored, v_obj_gt, w_gt, v_obj_est, w_est, twist
    )

    times = None if step_times_s is None else np.asarray(step_times_s, dtype=np.float64)
    return _metrics_from_frames(
        frame_index=index.astype(np.int64),
        add_m=add,
        adds_m=adds,
        t_err_cm=t_err,
        a_err_deg=a_err,
        v_err_cmps=v_err,
        w_err_dps=w_err,
        frames_invalid=int(np.count_nonzero(~ok)),
        step_times_s=times,
        max_threshold_m=max_threshold_m,
    )


def _metrics_from_frames(
    *,
    frame_index: NDArray[np.int64],
    add_m: F64,
    adds_m: F64 | None,
    t_err_cm: F64,
    a_err_deg: F64,
    v_err_cmps: F64,
    w_err_dps: F64,
    frames_invalid: int,
    step_times_s: F64 | None,
    max_threshold_m: float,
) -> SequenceMetrics:
    t_rows = np.isfinite(t_err_cm).all(axis=1)
    vel_rows = np.isfinite(v_err_cmps).all(axis=1)
    return SequenceMetrics(
        add_auc_pct=add_auc(add_m, max_threshold_m=max_threshold_m),
        adds_auc_pct=(
            add_auc(adds_m, max_threshold_m=max_threshold_m) if adds_m is not None else np.nan
        ),
        rmse_t_cm=_rmse(np.linalg.norm(t_err_cm, axis=1)),
        rmse_t_axes_cm=tuple(_rmse(t_err_cm[:, i]) for i in range(3)),  # type: ignore[arg-type]
        rmse_a_deg=_rmse(a_err_deg),
        rmse_v_cmps=_rmse(np.linalg.norm(v_err_cmps, axis=1)),
        rmse_w_dps=_rmse(np.linalg.norm(w_err_dps, axis=1)),
        frames=int(add_m.size),
        frames_invalid=frames_invalid,
        frames_rmse=int(np.count_nonzero(t_rows)),
        frames_velocity=int(np.count_nonzero(vel_rows)),
        step_time=None if step_times_s is None else step_time_stats(step_times_s),
        frame_index=frame_index,
        add_m=add_m,
        adds_m=adds_m,
        t_err_cm=t_err_cm,
        a_err_deg=a_err_deg,
        v_err_cmps=v_err_cmps,
        w_err_dps=w_err_dps,
        step_times_s=step_times_s,
    )


def evaluate_estimates(
    estimates: SequenceABC[Estimate],
    ground_truth: PoseTrack,
    model_points_m: ArrayLike,
    *,
    velocity: Literal["auto", "spatial_twist", "v_obj"] = "auto",
    invalid: InvalidPolicy = "failure",
    step_times_s: ArrayLike | None = None,
    with_adds: bool = False,
) -> SequenceMetrics:
    """Scores a tracker's per-frame :class:`Estimate` records against the ground truth.

    Args:
        estimates: one estimate per frame, ``estimates[i].k == i``.
        ground_truth: the sequence's ground truth, same length.
        model_points_m: (M, 3) model points [m].
        velocity: which velocity to score: the spatial twist (ROFT's velocity KF, converted
            with the ground-truth position), ``v_obj``/``w``, or ``"auto"``: each frame's spatial
            twist when it carries one, else its ``v_obj``/``w``, what ``velocity_estimate.txt``
            holds for the frame and the reference evaluation scores (it scores every row).
        invalid: policy for ``valid=False`` estimates (module docstring).
        step_times_s: (N,) step times [s], optional.
        with_adds: also compute ADD-S.
    """
    n = len(ground_truth)
    ks = np.array([e.k for e in estimates], dtype=np.int64)
    if ks.shape != (n,) or not np.array_equal(ks, np.arange(n)):
        raise ValueError(
            f"need one estimate per ground-truth frame with k = 0..{n - 1} in order; got "
            f"{len(ks)} estimates" + (f" starting k = {ks[:3].tolist()}..." if len(ks) else "")
        )
    has_twist = np.array([e.spatial_twist is not None for e in estimates], dtype=bool)
    if velocity == "spatial_twist" and not has_twist.all():
        raise ValueError(
            f"velocity='spatial_twist' but {int((~has_twist).sum())} estimates carry no "
            "spatial_twist; use velocity='v_obj' or 'auto'"
        )
    use_twist = velocity == "spatial_twist" or (velocity == "auto" and has_twist.any())
    twist = None
    if use_twist:
        twist = np.full((n, 6), np.nan)
        for i, e in enumerate(estimates):
            if e.spatial_twist is not None:
                twist[i] = e.spatial_twist

    def rows(name: str, width: int) -> F64:
        return np.stack([getattr(e, name) for e in estimates]) if n else np.zeros((0, width))

    return evaluate_sequence(
        np.stack([e.T_cam_obj for e in estimates]) if n else np.zeros((0, 4, 4)),
        ground_truth.T_cam_obj,
        model_points_m,
        v_obj_gt=ground_truth.v_obj_mps,
        w_gt=ground_truth.w_radps,
        v_obj_est=rows("v_obj_mps", 3),
        w_est=rows("w_radps", 3),
        spatial_twist_est=twist,
        valid=np.array([e.valid for e in estimates], dtype=bool),
        invalid=invalid,
        step_times_s=step_times_s,
        with_adds=with_adds,
    )


def concatenate_metrics(
    parts: SequenceABC[SequenceMetrics], *, max_threshold_m: float = DEFAULT_MAX_THRESHOLD_M
) -> SequenceMetrics:
    """Pools frames: one AUC over all distances and one RMSE over all frames ("ALL").

    Also how the reference forms a per-object entry from several sequences of one object.
    ``frame_index`` keeps each frame's index within its own sequence.
    """
    if not parts:
        raise ValueError("need at least one SequenceMetrics to pool")
    adds = [p.adds_m for p in parts]
    times = [p.step_times_s for p in parts if p.step_times_s is not None]
    return _metrics_from_frames(
        frame_index=np.concatenate([p.frame_index for p in parts]),
        add_m=np.concatenate([p.add_m for p in parts]),
        adds_m=None if any(a is None for a in adds) else np.concatenate(adds),  # type: ignore[arg-type]
        t_err_cm=np.concatenate([p.t_err_cm for p in parts]),
        a_err_deg=np.concatenate([p.a_err_deg for p in parts]),
        v_err_cmps=np.concatenate([p.v_err_cmps for p in parts]),
        w_err_dps=np.concatenate([p.w_err_dps for p in parts]),
        frames_invalid=sum(p.frames_invalid for p in parts),
        step_times_s=np.concatenate(times) if times else None,
        max_threshold_m=max_threshold_m,
    )


def pool_metrics(
    by_name: Mapping[str, SequenceMetrics], *, max_threshold_m: float = DEFAULT_MAX_THRESHOLD_M
) -> dict[str, SequenceMetrics]:
    """Adds ``"ALL"`` (frames pooled) and ``"MEAN"`` (mean of each number over the entries).

    Args:
        by_name: metrics per sequence or per object (the reference's table rows).

    Returns:
        ``{"ALL": ..., "MEAN": ..., **by_name}``. ``MEAN``'s scalar metrics are plain means over
        the entries (NaN if any entry's is NaN); its counts are sums and its per-frame arrays
        and step-time statistics are those of ``ALL``.
    """
    if not by_name:
        raise ValueError("need at least one entry to pool")
    clash = {POOLED_ALL, POOLED_MEAN} & set(by_name)
    if clash:
        raise ValueError(f"entry names {sorted(clash)} are reserved for the pooled results")
    parts = list(by_name.values())
    pooled = concatenate_metrics(parts, max_threshold_m=max_threshold_m)

    def mean(name: str) -> float:
        return float(np.mean([getattr(p, name) for p in parts]))

    mean_entry = dataclasses.replace(
        pooled,
        add_auc_pct=mean("add_auc_pct"),
        adds_auc_pct=mean("adds_auc_pct"),
        rmse_t_cm=mean("rmse_t_cm"),
        rmse_t_axes_cm=tuple(np.mean([p.rmse_t_axes_cm for p in parts], axis=0).tolist()),
        rmse_a_deg=mean("rmse_a_deg"),
        rmse_v_cmps=mean("rmse_v_cmps"),
        rmse_w_dps=mean("rmse_w_dps"),
    )
    return {POOLED_ALL: pooled, POOLED_MEAN: mean_entry, **by_name}
