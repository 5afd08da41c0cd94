"""Properties a tracker under delays and faults should have, as checks that return a result.

Each ``check_*`` runs a tracker (built fresh by ``make_tracker()``) over observations and returns a
:class:`PropertyResult`: ``passed``, the number of frames compared, the largest differences and
readable violations (frame, quantity, value, tolerance). ``result.raise_if_failed()`` turns it
into an ``AssertionError``; inside a hypothesis test the failing stream's ``repr``
(:class:`~roft_sim.testing.streams.FaultedStream`) prints the timeline beside it.

- :func:`check_delay_invariance`: once every pose captured up to frame k has arrived, the
  estimate at k equals that of a run in which each pose arrived at its capture frame
  (rollback-and-replay is exact; ``metrics_faults_flow.md`` 4.4, properties 1-3).
- :func:`check_same_estimates`: two observation lists give the same estimates on given frames
  (order invariance: the same poses in another arrival order).
- :func:`check_horizon_rule`: a pose older than the buffer horizon is dropped, reported, and
  changes nothing (property 4).
- :func:`check_determinism`: the same observations give bit-identical estimates (property 10).
- :func:`check_error_bounded` and :func:`check_recovery`: pose error against ground truth stays
  within a bound, or returns inside it within a number of frames after a burst (property 9).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.so3 import quat_angle, quat_from_matrix
from roft_sim.records import Estimate, Observation, PoseDetection, PoseTrack
from roft_sim.testing.streams import poses_at_capture, settled_frames
from roft_sim.trackers import Tracker, run_tracker

F64 = NDArray[np.float64]

__all__ = [
    "Tolerance",
    "EXACT",
    "REPLAY_EXACT",
    "PropertyResult",
    "estimate_differences",
    "check_same_estimates",
    "check_delay_invariance",
    "check_horizon_rule",
    "check_determinism",
    "pose_errors",
    "check_error_bounded",
    "check_recovery",
]

_MAX_LISTED = 5
"""Violations spelled out in a message (the rest are counted)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Tolerance:
    """How close two estimates must be (absolute, per quantity)."""

    atol_m: float = 1e-9
    """Position [m]."""
    atol_rad: float = 1e-9
    """Rotation, geodesic angle [rad]."""
    atol_mps: float = 1e-9
    """Object-origin velocity and the linear part of ``spatial_twist`` [m/s]."""
    atol_radps: float = 1e-9
    """Angular velocity (also in ``spatial_twist``) [rad/s]."""
    atol_cov: float = 1e-9
    """Covariance entries [SI units squared]; compared when both estimates carry one."""

    def limits(self) -> dict[str, float]:
        """Quantity name -> tolerance, in the keys of :func:`estimate_differences`."""
        return {
            "position_m": self.atol_m,
            "rotation_rad": self.atol_rad,
            "v_obj_mps": self.atol_mps,
            "w_radps": self.atol_radps,
            "spatial_v_mps": self.atol_mps,
            "spatial_w_radps": self.atol_radps,
            "covariance": self.atol_cov,
        }


REPLAY_EXACT = Tolerance()
"""The default: 1e-9 in every quantity (rollback-and-replay in double precision)."""

EXACT = Tolerance(atol_m=0.0, atol_rad=0.0, atol_mps=0.0, atol_radps=0.0, atol_cov=0.0)
"""Bit-identical (every difference must be exactly 0)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class PropertyResult:
    """The outcome of one property check."""

    name: str
    """The property, e.g. ``delay invariance``."""
    passed: bool
    """True when no violation was found."""
    frames_checked: int
    """Frames on which the property was evaluated (0: nothing to compare, vacuously passed)."""
    violations: tuple[str, ...] = ()
    """One readable line per violation (frame, quantity, value, limit)."""
    worst: Mapping[str, float] = field(default_factory=dict)
    """Largest value of each compared quantity over the checked frames."""

    def message(self) -> str:
        """A multi-line summary: the verdict, the worst values and the first violations."""
        verdict = "holds" if self.passed else "FAILS"
        lines = [f"{self.name} {verdict} on {self.frames_checked} checked frames"]
        if self.worst:
            lines.append(
                "  largest: " + ", ".join(f"{k} {v:.3g}" for k, v in sorted(self.worst.items()))
            )
        lines += [f"  {v}" for v in self.violations[:_MAX_LISTED]]
        if len(self.violations) > _MAX_LISTED:
            lines.append(f"  ... and {len(self.violations) - _MAX_LISTED} more violations")
        return "\n".join(lines)

    def raise_if_failed(self) -> PropertyResult:
        """Raises ``AssertionError(self.message())`` unless passed; returns self otherwise."""
        if not self.passed:
            raise AssertionError(self.message())
        return self

    def __str__(self) -> str:
        return self.message()


def estimate_differences(a: Estimate, b: Estimate) -> dict[str, float]:
    """Absolute differences between two estimates of the same frame.

    Returns:
        ``position_m`` [m], ``rotation_rad`` (geodesic) [rad], ``v_obj_mps`` [m/s], ``w_radps``
        [rad/s] (Euclidean norms of the differences), ``spatial_v_mps`` [m/s] and
        ``spatial_w_radps`` [rad/s] (the two halves of ``spatial_twist``, ROFT's own velocity
        output), ``covariance`` (largest absolute entry difference) and ``valid`` (1.0 when the
        validity flags differ, else 0.0). An optional quantity (covariance, spatial twist) that
        only one estimate carries differs by ``inf``; one that neither carries by 0.
    """
    Ta = np.asarray(a.T_cam_obj, dtype=np.float64)
    Tb = np.asarray(b.T_cam_obj, dtype=np.float64)
    if not (np.isfinite(Ta).all() and np.isfinite(Tb).all()):
        rotation = 0.0 if np.array_equal(Ta, Tb, equal_nan=True) else np.inf
    else:
        rotation = float(quat_angle(quat_from_matrix(Ta[:3, :3]), quat_from_matrix(Tb[:3, :3])))
    if a.covariance is None and b.covariance is None:
        cov = 0.0
    elif a.covariance is None or b.covariance is None:
        cov = np.inf
    else:
        cov = float(np.max(np.abs(np.asarray(a.covariance) - np.asarray(b.covariance))))

    def norm(x: object, y: object) -> float:
        d = np.asarray(x, dtype=np.float64) - np.asarray(y, dtype=np.float64)
        return float(np.linalg.norm(d)) if np.isfinite(d).all() else np.inf

    def optional_norm(x: NDArray[np.float64] | None, y: NDArray[np.float64] | None) -> float:
        if x is None and y is None:
            return 0.0
        return np.inf if x is None or y is None else norm(x, y)

    ta, tb = a.spatial_twist, b.spatial_twist
    return {
        "position_m": norm(Ta[:3, 3], Tb[:3, 3]),
        "rotation_rad": rotation,
        "v_obj_mps": norm(a.v_obj_mps, b.v_obj_mps),
        "w_radps": norm(a.w_radps, b.w_radps),
        "spatial_v_mps": optional_norm(
            None if ta is None else np.asarray(ta)[:3], None if tb is None else np.asarray(tb)[:3]
        ),
        "spatial_w_radps": optional_norm(
            None if ta is None else np.asarray(ta)[3:], None if tb is None else np.asarray(tb)[3:]
        ),
        "covariance": cov,
        "valid": float(a.valid != b.valid),
    }


def _compare(
    name: str,
    first: Sequence[Estimate],
    second: Sequence[Estimate],
    frames: NDArray[np.bool_],
    tol: Tolerance,
    labels: tuple[str, str],
) -> PropertyResult:
    limits = tol.limits()
    worst: dict[str, float] = dict.fromkeys(limits, 0.0)
    violations: list[str] = []
    checked = 0
    for k in np.flatnonzero(frames):
        a, b = first[int(k)], second[int(k)]
        checked += 1
        diff = estimate_differences(a, b)
        if diff["valid"]:
            violations.append(
                f"frame {k}: valid={a.valid} in the {labels[0]} run, {b.valid} in the "
                f"{labels[1]} run"
            )
            continue
        if not a.valid:  # neither has a pose: nothing more to compare
            continue
        for quantity, limit in limits.items():
            value = diff[quantity]
            worst[quantity] = max(worst[quantity], value)
            if not value <= limit:
                violations.append(
                    f"frame {k}: {quantity} differs by {value:.3e} (> {limit:.1e}) between the "
                    f"{labels[0]} and the {labels[1]} run"
                )
    return PropertyResult(
        name=name,
        passed=not violations,
        frames_checked=checked,
        violations=tuple(violations),
        worst=worst,
    )


def _frames_mask(
    frames: Sequence[int] | NDArray[np.integer | np.bool_] | None, n: int
) -> NDArray[np.bool_]:
    if frames is None:
        return np.ones(n, dtype=bool)
    arr = np.asarray(frames)
    if arr.dtype == np.bool_:
        if arr.shape != (n,):
            raise ValueError(f"a bool frame mask must have shape ({n},), got {arr.shape}")
        return arr
    mask = np.zeros(n, dtype=bool)
    mask[arr.astype(np.int64)] = True
    return mask


def check_same_estimates(
    make_tracker: Callable[[], Tracker],
    first: Sequence[Observation],
    second: Sequence[Observation],
    *,
    frames: Sequence[int] | NDArray[np.integer | np.bool_] | None = None,
    initial: Estimate | None = None,
    tol: Tolerance = REPLAY_EXACT,
    name: str = "same estimates",
) -> PropertyResult:
    """Runs a fresh tracker over each observation list and compares the estimates.

    Args:
        make_tracker: builds a fresh tracker (e.g. ``lambda: tracker_for("roft", seq)``).
        first, second: observation lists of equal length (frames 0..N-1).
        frames: frames to compare (indices or an ``(N,)`` bool mask); None = all.
        initial: passed to ``reset`` in both runs.
        tol: per-quantity tolerances.
        name: the property's name in the result.
    """
    if len(first) != len(second):
        raise ValueError(f"observation lists differ in length: {len(first)} vs {len(second)}")
    a = run_tracker(make_tracker(), first, initial)
    b = run_tracker(make_tracker(), second, initial)
    return _compare(name, a, b, _frames_mask(frames, len(first)), tol, ("first", "second"))


def check_delay_invariance(
    make_tracker: Callable[[], Tracker],
    observations: Sequence[Observation],
    *,
    max_delay_frames: int | None = None,
    initial: Estimate | None = None,
    tol: Tolerance = REPLAY_EXACT,
) -> PropertyResult:
    """Delay invariance: at every frame k by which all poses captured up to k have arrived, the
    estimate equals the one of a run in which each pose arrived at its capture frame.

    Args:
        make_tracker: builds a fresh tracker.
        observations: the delayed observations (frames 0..N-1), e.g.
            ``FaultedStream(...).observations()``.
        max_delay_frames: the tracker's buffer horizon: poses delayed by more are expected to be
            dropped, so the zero-delay run does not get them either; None = no horizon.
        initial: passed to ``reset`` in both runs.
        tol: per-quantity tolerances (replay is exact: ~1e-9 for a double-precision filter).
    """
    prompt = poses_at_capture(observations, max_delay_frames=max_delay_frames)
    a = run_tracker(make_tracker(), observations, initial)
    b = run_tracker(make_tracker(), prompt, initial)
    settled = settled_frames(observations, max_delay_frames=max_delay_frames)
    return _compare("delay invariance", a, b, settled, tol, ("delayed", "zero-delay"))


def check_horizon_rule(
    make_tracker: Callable[[], Tracker],
    observations: Sequence[Observation],
    late: PoseDetection,
    *,
    horizon_frames: int,
    counter: str | None = None,
    initial: Estimate | None = None,
) -> PropertyResult:
    """Horizon rule: a pose that arrives more than ``horizon_frames`` after its capture is
    dropped, reported in ``dropped_pose_ids`` at its arrival frame, and changes no estimate.

    Args:
        make_tracker: builds a fresh tracker.
        observations: the observations without the late pose.
        late: the too-old pose (``late.arrival_k - late.capture_k > horizon_frames``, a
            ``detection_id`` not used in ``observations``); it is appended to the poses of frame
            ``late.arrival_k``.
        horizon_frames: the tracker's buffer horizon [frames].
        counter: a diagnostics key that must grow by one at the last frame (e.g. ROFT's
            ``total_poses_dropped_too_old``); None = not checked.
        initial: passed to ``reset`` in both runs.

    Raises:
        ValueError: the pose is not older than the horizon, arrives outside the observed
            frames, or its ``detection_id`` is already used.
    """
    if late.arrival_k - late.capture_k <= horizon_frames:
        raise ValueError(
            f"the late pose arrives {late.arrival_k - late.capture_k} frames after its capture; "
            f"it must be more than horizon_frames = {horizon_frames}"
        )
    if not 0 <= late.arrival_k < len(observations):
        raise ValueError(
            f"the late pose arrives at frame {late.arrival_k}, outside the {len(observations)} "
            "observed frames"
        )
    used = {d.detection_id for o in observations for d in o.poses}
    if late.detection_id in used:
        raise ValueError(f"detection_id {late.detection_id} is already used in the observations")
    with_late = list(observations)
    o = with_late[late.arrival_k]
    with_late[late.arrival_k] = dataclasses.replace(o, poses=(*o.poses, late))
    base = run_tracker(make_tracker(), observations, initial)
    test = run_tracker(make_tracker(), with_late, initial)
    result = _compare(
        "horizon rule", base, test, np.ones(len(base), dtype=bool), EXACT, ("base", "late-pose")
    )
    violations: list[str] = []
    arrival = test[late.arrival_k]
    if late.detection_id not in arrival.dropped_pose_ids:
        violations.append(
            f"frame {late.arrival_k}: the pose {late.detection_id} captured at {late.capture_k} "
            f"is not in dropped_pose_ids {arrival.dropped_pose_ids}"
        )
    if late.detection_id in arrival.accepted_pose_ids:
        violations.append(f"frame {late.arrival_k}: the too-old pose was accepted")
    if counter is not None:
        before = int(base[-1].diagnostics.get(counter, 0))
        after = int(test[-1].diagnostics.get(counter, 0))
        if after != before + 1:
            violations.append(f"diagnostics[{counter!r}] went from {before} to {after}, not +1")
    violations += result.violations  # the reporting problems first: they name the cause
    return PropertyResult(
        name="horizon rule",
        passed=not violations,
        frames_checked=result.frames_checked,
        violations=tuple(violations),
        worst=result.worst,
    )


def check_determinism(
    make_tracker: Callable[[], Tracker],
    observations: Sequence[Observation],
    *,
    runs: int = 2,
    initial: Estimate | None = None,
    compare_diagnostics: bool = True,
) -> PropertyResult:
    """Determinism: ``runs`` fresh trackers over the same observations give bit-identical
    estimates (poses, velocities, covariances, spatial twists, detection ids and, unless
    ``compare_diagnostics`` is False, diagnostics)."""
    if runs < 2:
        raise ValueError(f"need runs >= 2 to compare, got {runs}")
    reference = run_tracker(make_tracker(), observations, initial)
    violations: list[str] = []
    for r in range(1, runs):
        again = run_tracker(make_tracker(), observations, initial)
        for a, b in zip(reference, again, strict=True):
            problems = _bitwise_differences(a, b, compare_diagnostics)
            violations += [f"run {r}, frame {a.k}: {p}" for p in problems]
    return PropertyResult(
        name="determinism",
        passed=not violations,
        frames_checked=len(reference) * (runs - 1),
        violations=tuple(violations),
    )


def _bitwise_differences(a: Estimate, b: Estimate, diagnostics: bool) -> list[str]:
    out = []
    for name in ("T_cam_obj", "v_obj_mps", "w_radps", "covariance", "spatial_twist"):
        x, y = getattr(a, name), getattr(b, name)
        if (x is None) != (y is None) or (
            x is not None and not np.array_equal(x, y, equal_nan=True)
        ):
            out.append(f"{name} differs")
    for name in ("valid", "accepted_pose_ids", "rejected_pose_ids", "dropped_pose_ids"):
        if getattr(a, name) != getattr(b, name):
            out.append(f"{name} differs: {getattr(a, name)} vs {getattr(b, name)}")
    if diagnostics and dict(a.diagnostics) != dict(b.diagnostics):
        keys = sorted(k for k in {*a.diagnostics, *b.diagnostics}
                      if a.diagnostics.get(k) != b.diagnostics.get(k))  # fmt: skip
        out.append(f"diagnostics differ in {keys}")
    return out


def pose_errors(estimates: Sequence[Estimate], truth: PoseTrack) -> tuple[F64, F64]:
    """Position [m] and geodesic rotation [rad] errors ``(N,)`` of each estimate against
    ``truth.T_cam_obj[estimate.k]``; NaN where the estimate is invalid."""
    pos = np.full(len(estimates), np.nan)
    rot = np.full(len(estimates), np.nan)
    for i, e in enumerate(estimates):
        if not e.valid:
            continue
        T, G = np.asarray(e.T_cam_obj, dtype=np.float64), truth.T_cam_obj[e.k]
        if not np.isfinite(T).all():
            pos[i] = rot[i] = np.inf
            continue
        pos[i] = np.linalg.norm(T[:3, 3] - G[:3, 3])
        rot[i] = quat_angle(quat_from_matrix(T[:3, :3]), quat_from_matrix(G[:3, :3]))
    return pos, rot


def check_error_bounded(
    estimates: Sequence[Estimate],
    truth: PoseTrack,
    *,
    bound_m: float,
    bound_rad: float,
    frames: Sequence[int] | NDArray[np.integer | np.bool_] | None = None,
    allow_invalid: bool = False,
) -> PropertyResult:
    """Bounded error: position and rotation errors stay within ``bound_m`` [m] and
    ``bound_rad`` [rad] on ``frames`` (indices or an ``(N,)`` bool mask; None = all). An invalid
    estimate on a checked frame is a violation unless ``allow_invalid``."""
    pos, rot = pose_errors(estimates, truth)
    mask = _frames_mask(frames, len(estimates))
    violations = []
    for k in np.flatnonzero(mask):
        if np.isnan(pos[k]):
            if not allow_invalid:
                violations.append(f"frame {k}: no valid estimate")
            continue
        if not pos[k] <= bound_m:
            violations.append(f"frame {k}: position error {pos[k]:.4f} m > {bound_m:.4f} m")
        if not rot[k] <= bound_rad:
            violations.append(
                f"frame {k}: rotation error {np.degrees(rot[k]):.2f} deg > "
                f"{np.degrees(bound_rad):.2f} deg"
            )
    checked = pos[mask]
    finite = checked[np.isfinite(checked)] if checked.size else checked
    worst = {}
    if finite.size:
        worst = {
            "position_m": float(np.nanmax(checked)),
            "rotation_rad": float(np.nanmax(rot[mask])),
        }
    return PropertyResult(
        name="bounded error",
        passed=not violations,
        frames_checked=int(mask.sum()),
        violations=tuple(violations),
        worst=worst,
    )


def check_recovery(
    estimates: Sequence[Estimate],
    truth: PoseTrack,
    *,
    burst_end_k: int,
    within_frames: int,
    bound_m: float,
    bound_rad: float,
) -> PropertyResult:
    """Recovery: from ``burst_end_k + within_frames`` to the last frame the pose error stays
    within the bounds (the error returns inside its bound within ``within_frames`` frames of the
    end of a fault burst, and stays there).

    The result's ``worst`` holds ``recovery_frames``: frames after ``burst_end_k`` from which the
    error stayed within bounds to the end (``inf`` if it never did).

    Raises:
        ValueError: ``burst_end_k`` outside the frames, ``within_frames < 0``, or no frame left
            to check (``burst_end_k + within_frames`` at or past the last estimate).
    """
    n = len(estimates)
    if not 0 <= burst_end_k < n:
        raise ValueError(f"burst_end_k = {burst_end_k} is outside the {n} frames")
    if within_frames < 0:
        raise ValueError(f"within_frames must be >= 0, got {within_frames}")
    if burst_end_k + within_frames >= n:
        raise ValueError(
            f"recovery is checked from frame {burst_end_k + within_frames} on: no frame left of "
            f"the {n} frames; use a longer run or a smaller within_frames"
        )
    pos, rot = pose_errors(estimates, truth)
    inside = (pos <= bound_m) & (rot <= bound_rad)  # NaN (invalid) compares False
    tail = inside[burst_end_k:]
    outside_idx = np.flatnonzero(~tail)
    recovery = 0 if outside_idx.size == 0 else int(outside_idx[-1]) + 1
    recovered = recovery < tail.size
    start = burst_end_k + within_frames
    bounded = check_error_bounded(
        estimates, truth, bound_m=bound_m, bound_rad=bound_rad, frames=np.arange(start, n)
    )
    return PropertyResult(
        name=f"recovery within {within_frames} frames of the burst ending at frame {burst_end_k}",
        passed=bounded.passed,
        frames_checked=bounded.frames_checked,
        violations=bounded.violations,
        worst={**bounded.worst, "recovery_frames": float(recovery) if recovered else np.inf},
    )
