"""The ``Trajectory`` protocol, its samples, and speed statistics.

A trajectory gives, for any array of times, the pose of an object in the trajectory's reference
frame (the camera frame once placed) together with velocities and accelerations that are the
exact analytic time derivatives of the poses returned. See docs/conventions.md for the frames
and the velocity conventions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.records import PoseTrack

F64 = NDArray[np.float64]

__all__ = [
    "Trajectory",
    "TrajectorySample",
    "SpeedSummary",
    "SpeedStatistics",
    "speed_statistics",
    "sample_at_rate",
    "as_sample_times",
    "TIME_TOLERANCE_S",
]

TIME_TOLERANCE_S = 1e-9
"""Times up to this far outside ``[start_s, end_s]`` are accepted and clamped onto the interval
(so ``k / rate`` rounding never fails); anything further raises ``ValueError``."""


@runtime_checkable
class Trajectory(Protocol):
    """A rigid-body motion defined on ``[start_s, end_s]``."""

    @property
    def start_s(self) -> float:
        """First time [s] at which the trajectory is defined."""
        ...

    @property
    def end_s(self) -> float:
        """Last time [s] at which the trajectory is defined."""
        ...

    def sample(self, t_s: ArrayLike) -> TrajectorySample:
        """Pose, velocity and acceleration at times ``t_s`` ``(N,)`` [s] in ``[start_s, end_s]``.

        Raises:
            ValueError: a time lies outside ``[start_s, end_s]`` or is not finite.
        """
        ...


@dataclass(frozen=True, slots=True, kw_only=True)
class TrajectorySample:
    """A trajectory evaluated at N times; every quantity in the trajectory's reference frame."""

    t_s: F64
    """(N,) times [s]."""
    T_ref_obj: F64
    """(N, 4, 4) pose of the object in the reference frame (the camera frame once placed) [m]."""
    v_mps: F64
    """(N, 3) velocity of the object origin, d/dt of ``T_ref_obj[:, :3, 3]`` [m/s]."""
    w_radps: F64
    """(N, 3) angular velocity in the reference frame [rad/s]: ``dR/dt = [w]x R``."""
    a_mps2: F64
    """(N, 3) acceleration of the object origin, d/dt of ``v_mps`` [m/s^2]."""
    alpha_radps2: F64
    """(N, 3) angular acceleration, d/dt of ``w_radps`` [rad/s^2], reference frame."""

    def __post_init__(self) -> None:
        n = self.t_s.shape[0] if self.t_s.ndim == 1 else -1
        expected = {
            "T_ref_obj": (n, 4, 4),
            "v_mps": (n, 3),
            "w_radps": (n, 3),
            "a_mps2": (n, 3),
            "alpha_radps2": (n, 3),
        }
        if n < 0:
            raise ValueError(f"t_s must have shape (N,), got {self.t_s.shape}")
        for name, shape in expected.items():
            if getattr(self, name).shape != shape:
                raise ValueError(
                    f"{name} must have shape {shape} for {n} times, got {getattr(self, name).shape}"
                )

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def linear_speed_mps(self) -> F64:
        """(N,) speed of the object origin [m/s]."""
        speed: F64 = np.linalg.norm(self.v_mps, axis=-1)
        return speed

    @property
    def angular_speed_radps(self) -> F64:
        """(N,) magnitude of the angular velocity [rad/s]."""
        speed: F64 = np.linalg.norm(self.w_radps, axis=-1)
        return speed

    def as_pose_track(self) -> PoseTrack:
        """The poses and velocities as a :class:`roft_sim.records.PoseTrack`.

        The reference frame becomes the camera frame: ``T_cam_obj = T_ref_obj``,
        ``v_obj_mps = v_mps``, ``w_radps = w_radps``.
        """
        return PoseTrack(
            t_s=self.t_s, T_cam_obj=self.T_ref_obj, v_obj_mps=self.v_mps, w_radps=self.w_radps
        )


def as_sample_times(t_s: ArrayLike, start_s: float, end_s: float) -> F64:
    """Validates sample times for :meth:`Trajectory.sample` -> float64 ``(N,)`` copy.

    Times within :data:`TIME_TOLERANCE_S` outside the interval are clamped onto it.

    Raises:
        ValueError: not 1-D, not finite, or outside ``[start_s, end_s]``.
    """
    t = np.array(t_s, dtype=np.float64)
    if t.ndim == 0:
        t = t[None]
    if t.ndim != 1:
        raise ValueError(f"sample times must have shape (N,), got {t.shape}")
    if not np.isfinite(t).all():
        raise ValueError("sample times contain NaN or inf")
    if t.size and (t.min() < start_s - TIME_TOLERANCE_S or t.max() > end_s + TIME_TOLERANCE_S):
        raise ValueError(
            f"sample times span [{t.min():.9g}, {t.max():.9g}] s, outside the trajectory's "
            f"[{start_s:.9g}, {end_s:.9g}] s; sample only inside it"
        )
    return np.clip(t, start_s, end_s)


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedSummary:
    """Peak, 95th percentile and median of a speed over the samples."""

    peak: float
    p95: float
    median: float

    @classmethod
    def of(cls, speeds: ArrayLike) -> SpeedSummary:
        """Summary of ``(N,)`` speeds (N >= 1)."""
        s = np.asarray(speeds, dtype=np.float64)
        return cls(
            peak=float(s.max()),
            p95=float(np.percentile(s, 95.0)),
            median=float(np.median(s)),
        )

    def scaled(self, factor: float) -> SpeedSummary:
        """The same summary with every value times ``factor`` (unit conversion)."""
        return SpeedSummary(
            peak=self.peak * factor, p95=self.p95 * factor, median=self.median * factor
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class SpeedStatistics:
    """How fast a trajectory moves, from its samples."""

    duration_s: float
    """Last minus first sample time [s]."""
    rate_hz: float
    """Sample rate [Hz]: 1 / median time step (0 for a single sample)."""
    num_samples: int
    """Number of samples the statistics are computed from."""
    linear_speed_mps: SpeedSummary
    """Speed of the object origin [m/s]."""
    angular_speed_radps: SpeedSummary
    """Angular speed [rad/s]."""
    excluded_samples: int = 0
    """Samples left out because they fell in an excluded interval (e.g. a tracking gap)."""

    @property
    def angular_speed_dps(self) -> SpeedSummary:
        """Angular speed in degrees per second (for reports)."""
        return self.angular_speed_radps.scaled(180.0 / np.pi)

    def report(self) -> dict[str, object]:
        """JSON-ready report: ``duration_s``, ``rate_hz``, ``num_samples``,
        ``excluded_samples``, ``linear_speed_mps`` and ``angular_speed_dps`` (each
        ``{peak, p95, median}``)."""
        lin, ang = self.linear_speed_mps, self.angular_speed_dps
        return {
            "duration_s": self.duration_s,
            "rate_hz": self.rate_hz,
            "num_samples": self.num_samples,
            "excluded_samples": self.excluded_samples,
            "linear_speed_mps": {"peak": lin.peak, "p95": lin.p95, "median": lin.median},
            "angular_speed_dps": {"peak": ang.peak, "p95": ang.p95, "median": ang.median},
        }


def speed_statistics(
    sample: TrajectorySample,
    *,
    exclude_intervals_s: Sequence[tuple[float, float]] = (),
) -> SpeedStatistics:
    """Peak / p95 / median linear [m/s] and angular [rad/s] speed over the samples.

    Statistics are over the given samples, so sample uniformly in time (:func:`sample_at_rate`)
    for time-weighted percentiles.

    Args:
        sample: the samples; ``duration_s`` and ``rate_hz`` describe all of them.
        exclude_intervals_s: closed intervals ``(start_s, end_s)`` whose samples are left out
            of the speed summaries (e.g. tracking gaps a spline bridged, see
            ``CapturedTrajectory.bridged_intervals_s``).

    Raises:
        ValueError: the sample is empty, or every sample is excluded.
    """
    if len(sample) == 0:
        raise ValueError("speed statistics need at least one sample")
    t = sample.t_s
    dt = np.diff(t)
    keep = np.ones(t.shape, dtype=bool)
    for lo, hi in exclude_intervals_s:
        keep &= ~((t >= lo) & (t <= hi))
    if not keep.any():
        raise ValueError("every sample lies in an excluded interval")
    return SpeedStatistics(
        duration_s=float(t[-1] - t[0]),
        rate_hz=float(1.0 / np.median(dt)) if dt.size and np.median(dt) > 0 else 0.0,
        num_samples=len(sample),
        linear_speed_mps=SpeedSummary.of(sample.linear_speed_mps[keep]),
        angular_speed_radps=SpeedSummary.of(sample.angular_speed_radps[keep]),
        excluded_samples=int((~keep).sum()),
    )


def sample_at_rate(
    trajectory: Trajectory,
    rate_hz: float,
    *,
    start_s: float | None = None,
    end_s: float | None = None,
) -> TrajectorySample:
    """Samples at ``t_k = start_s + k / rate_hz`` for every ``t_k <= end_s``.

    Args:
        trajectory: any trajectory.
        rate_hz: samples per second (> 0).
        start_s: first time [s] (default ``trajectory.start_s``).
        end_s: last admissible time [s] (default ``trajectory.end_s``).

    Raises:
        ValueError: non-positive rate or an interval outside the trajectory.
    """
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive number, got {rate_hz}")
    t0 = trajectory.start_s if start_s is None else float(start_s)
    t1 = trajectory.end_s if end_s is None else float(end_s)
    if t1 < t0:
        raise ValueError(f"end_s ({t1}) is before start_s ({t0})")
    count = int(np.floor((t1 - t0) * rate_hz + 1e-9)) + 1
    return trajectory.sample(t0 + np.arange(count) / rate_hz)
