"""Synthetic human-like fast manipulation: chained minimum-jerk submovements.

The motion is a sequence of segments; in each, the object moves along a straight line and
turns about a fixed axis (camera frame), both with the minimum-jerk profile
``s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5`` (Flash and Hogan 1985), which starts and ends with
zero velocity and acceleration. So the motion is C2 and its derivatives are exact:
``p = p0 + s dp``, ``v = s' dp / T``, ``a = s'' dp / T^2``, ``R = Exp(s theta k) R0``,
``w = s' theta k / T``, ``alpha = s'' theta k / T^2``. A segment's peak speed is
``1.875 |dp| / T`` at its middle.

Primitives (each one or more segments): *reach* (point-to-point move with some turning),
*twist* (turn, moving a little), *shake* (fast back-and-forth in position and orientation), *hold*.
The first reach and the first twist run exactly at the configured peak speeds, every other
primitive at a random fraction of them, so the trajectory's peaks equal the targets. Every
segment runs between two points of the convex view region, so the object centre never leaves
it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry.so3 import matrix_from_quat, quat_from_rotvec, quat_multiply
from roft_sim.trajectories.base import TrajectorySample, as_sample_times
from roft_sim.trajectories.placement import ViewRegion

F64 = NDArray[np.float64]

__all__ = [
    "SyntheticMotionConfig",
    "MinimumJerkTrajectory",
    "generate_synthetic_motion",
    "MINIMUM_JERK_PEAK_FACTOR",
    "MINIMUM_JERK_ACCELERATION_FACTOR",
]

MINIMUM_JERK_PEAK_FACTOR = 1.875
"""Peak of ``ds/dtau`` of the minimum-jerk profile: peak speed = 1.875 distance / duration."""

MINIMUM_JERK_ACCELERATION_FACTOR: float = 10.0 / np.sqrt(3.0) / MINIMUM_JERK_PEAK_FACTOR
"""Peak acceleration = 3.079 peak speed / duration for a minimum-jerk segment (``max d2s/dtau2``
is ``10 / sqrt(3)`` at ``tau = (3 - sqrt(3)) / 6``)."""


def _check_range(name: str, value: tuple[float, float], *, low: float = 0.0) -> None:
    a, b = value
    if not (np.isfinite([a, b]).all() and low < a <= b):
        raise ConfigError(f"{name} must be (min, max) with {low:g} < min <= max, got {value!r}")


@dataclass(frozen=True, slots=True, kw_only=True)
class SyntheticMotionConfig:
    """Seeded synthetic hand-like motion of the object in front of a static camera."""

    kind: Literal["synthetic"] = "synthetic"
    """Tells trajectory configs apart in scenario files."""
    seed: int = 0
    """Seed of the generator (>= 0); the same seed gives the same motion."""
    duration_s: float = 10.0
    """Length of the motion [s]."""
    peak_linear_speed_mps: float = 0.6
    """Peak speed of the object origin [m/s] (Fast-YCB: up to about 0.6)."""
    peak_angular_speed_dps: float = 266.0
    """Peak angular speed [deg/s] (Fast-YCB: up to about 266)."""
    peak_linear_acceleration_mps2: float = 4.0
    """Largest acceleration of the object origin in any primitive [m/s^2]. Primitives are
    lengthened (reaches, twists) or made smaller (shakes) to respect it. Captured hand motion
    (TUM VI rooms, 10 Hz low-pass) has a p95 of 2.3-4.5 m/s^2; with 4.0 the default motion has
    a p95 of about 3.8-3.9."""
    peak_angular_acceleration_dps2: float = 1000.0
    """Largest angular acceleration in any primitive [deg/s^2], enforced like the linear one.
    The TUM VI captures have a p95 of 830-990 deg/s^2 (and a change of angular velocity per
    30 fps frame of 26-29 deg/s at p95); with 1000 the default motion has 980-990 deg/s^2 and
    31 deg/s. Without a bound, peak speeds reached in short submovements and fast shakes gave
    3-5 times the captured accelerations."""
    min_speed_fraction: float = 0.3
    """Every primitive after the first reach and twist peaks at a fraction of the targets drawn
    uniformly from [min_speed_fraction, 1]."""
    working_distance_m: tuple[float, float] = (0.4, 0.9)
    """Range of the object centre's depth in the camera frame [m]."""
    in_view_margin: float = 0.5
    """The object centre keeps at least this fraction of the object radius inside each side
    plane of the frustum."""
    reach_weight: float = 0.35
    """Relative frequency of reaches (point-to-point moves)."""
    twist_weight: float = 0.25
    """Relative frequency of twists (turns with a little motion)."""
    shake_weight: float = 0.25
    """Relative frequency of shakes (fast back-and-forth)."""
    hold_weight: float = 0.15
    """Relative frequency of holds (still)."""
    submovement_duration_s: tuple[float, float] = (0.35, 0.9)
    """Duration range of one reach or twist [s]."""
    reach_rotation_fraction: float = 0.5
    """A reach also turns, at up to this fraction of the peak angular speed."""
    twist_translation_fraction: float = 0.25
    """A twist also moves, at up to this fraction of the peak linear speed."""
    shake_frequency_hz: tuple[float, float] = (2.0, 4.0)
    """Frequency range of shakes [Hz] (one back-and-forth per period)."""
    shake_half_cycles: tuple[int, int] = (4, 8)
    """Range of the number of half-cycles of a shake (rounded up to an even number)."""
    hold_duration_s: tuple[float, float] = (0.1, 0.5)
    """Duration range of a hold [s]."""

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int | np.integer):
            raise ConfigError(f"seed must be an integer >= 0, got {self.seed!r}")
        if self.seed < 0:
            raise ConfigError(f"seed must be an integer >= 0, got {self.seed}")
        for name in (
            "duration_s",
            "peak_linear_speed_mps",
            "peak_angular_speed_dps",
            "peak_linear_acceleration_mps2",
            "peak_angular_acceleration_dps2",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a positive number, got {value}")
        if not (0.0 < self.min_speed_fraction <= 1.0):
            raise ConfigError(
                f"min_speed_fraction must lie in (0, 1], got {self.min_speed_fraction}"
            )
        near, far = self.working_distance_m
        if not (np.isfinite([near, far]).all() and 0.0 < near < far):
            raise ConfigError(
                f"working_distance_m must be (near, far) with 0 < near < far, got "
                f"{self.working_distance_m!r}"
            )
        if not (np.isfinite(self.in_view_margin) and self.in_view_margin >= 0):
            raise ConfigError(f"in_view_margin must be >= 0, got {self.in_view_margin}")
        weights = (self.reach_weight, self.twist_weight, self.shake_weight, self.hold_weight)
        if not (np.isfinite(weights).all() and min(weights) >= 0 and sum(weights) > 0):
            raise ConfigError(
                f"primitive weights (reach, twist, shake, hold) must be >= 0 with a positive "
                f"sum, got {weights}"
            )
        _check_range("submovement_duration_s", self.submovement_duration_s)
        _check_range("shake_frequency_hz", self.shake_frequency_hz)
        _check_range("hold_duration_s", self.hold_duration_s)
        lo, hi = self.shake_half_cycles
        if not (1 <= lo <= hi):
            raise ConfigError(
                f"shake_half_cycles must be (min, max) with 1 <= min <= max, got "
                f"{self.shake_half_cycles!r}"
            )
        for name in ("reach_rotation_fraction", "twist_translation_fraction"):
            value = getattr(self, name)
            if not (0.0 <= value <= 1.0):
                raise ConfigError(f"{name} must lie in [0, 1], got {value}")
        shortest = 2.0 * max(
            self.submovement_duration_s[1],
            self.shortest_segment_s(self.peak_linear_speed_mps, self.peak_angular_speed_radps),
        )
        if self.duration_s < shortest:
            raise ConfigError(
                f"duration_s = {self.duration_s} s is too short for the first reach and twist "
                f"that hit the speed targets; use at least {shortest:.2f} s (each lasts the "
                "longest submovement_duration_s, or longer where the acceleration bounds need "
                "it), or lower the speed targets / raise the acceleration bounds"
            )

    @property
    def peak_angular_speed_radps(self) -> float:
        """Peak angular speed [rad/s]."""
        return float(np.radians(self.peak_angular_speed_dps))

    def shortest_segment_s(self, linear_speed_mps: float, angular_speed_radps: float) -> float:
        """Shortest minimum-jerk segment [s] that reaches these peak speeds within the
        acceleration bounds."""
        c = MINIMUM_JERK_ACCELERATION_FACTOR
        return c * max(
            linear_speed_mps / self.peak_linear_acceleration_mps2,
            angular_speed_radps / float(np.radians(self.peak_angular_acceleration_dps2)),
        )


def _profile(tau: F64) -> tuple[F64, F64, F64]:
    """Minimum-jerk ``s``, ``ds/dtau``, ``d2s/dtau2`` at ``tau`` in [0, 1]."""
    t2 = tau * tau
    s = t2 * tau * (10.0 - 15.0 * tau + 6.0 * t2)
    ds = 30.0 * t2 * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - 3.0 * tau + 2.0 * t2)
    return s, ds, dds


class MinimumJerkTrajectory:
    """Chained minimum-jerk segments on ``[0, sum of durations]``; satisfies ``Trajectory``."""

    __slots__ = ("_t0", "_T", "_p0", "_dp", "_q0", "_axis", "_angle", "_end_s", "kinds")

    def __init__(
        self,
        *,
        durations_s: ArrayLike,
        p_start_m: ArrayLike,
        q_start_wxyz: ArrayLike,
        dp_m: ArrayLike,
        rotvec_rad: ArrayLike,
        kinds: tuple[str, ...] | None = None,
        end_s: float | None = None,
    ) -> None:
        """Builds the chain.

        Args:
            durations_s: (M,) positive segment durations [s].
            p_start_m: (3,) start position [m], reference frame.
            q_start_wxyz: (4,) start orientation (w, x, y, z).
            dp_m: (M, 3) displacement of each segment [m], reference frame.
            rotvec_rad: (M, 3) rotation of each segment as a rotation vector in the reference
                frame [rad]: ``R_end = Exp(rotvec) R_start``.
            kinds: optional (M,) primitive name per segment (for inspection).
            end_s: optional exact end time [s]: the last segment then lasts until it (its
                duration is replaced by ``end_s`` minus its start), so that sums of float
                durations do not shift the end by an ulp.
        """
        T = np.asarray(durations_s, dtype=np.float64)
        dp = np.asarray(dp_m, dtype=np.float64)
        rv = np.asarray(rotvec_rad, dtype=np.float64)
        m = T.shape[0]
        if T.ndim != 1 or m == 0 or dp.shape != (m, 3) or rv.shape != (m, 3):
            raise ValueError(
                f"need durations (M,), dp (M, 3), rotvec (M, 3); got {T.shape}, {dp.shape}, "
                f"{rv.shape}"
            )
        if not (np.isfinite(T).all() and (T > 0).all()):
            raise ValueError("segment durations must be positive and finite")
        t0 = np.concatenate([[0.0], np.cumsum(T)[:-1]])
        if end_s is not None:
            if not end_s > t0[-1]:
                raise ValueError(f"end_s = {end_s} is not after the last segment's start {t0[-1]}")
            T = T.copy()
            T[-1] = end_s - t0[-1]
        self._T = T
        self._t0 = t0
        self._end_s = float(t0[-1] + T[-1]) if end_s is None else float(end_s)
        self._dp = dp
        self._p0 = np.asarray(p_start_m, dtype=np.float64) + np.concatenate(
            [np.zeros((1, 3)), np.cumsum(dp, axis=0)[:-1]]
        )
        angle = np.linalg.norm(rv, axis=-1)
        self._angle = angle
        self._axis = np.where(
            angle[:, None] > 0, rv / np.where(angle > 0, angle, 1.0)[:, None], [1.0, 0.0, 0.0]
        )
        q = np.empty((m, 4))
        q[0] = np.asarray(q_start_wxyz, dtype=np.float64) / np.linalg.norm(q_start_wxyz)
        for i in range(1, m):
            qi = quat_multiply(quat_from_rotvec(rv[i - 1]), q[i - 1])
            q[i] = qi / np.linalg.norm(qi)
        self._q0 = q
        self.kinds = kinds if kinds is not None else ("segment",) * m

    @property
    def start_s(self) -> float:
        return 0.0

    @property
    def end_s(self) -> float:
        return self._end_s

    @property
    def segment_start_times_s(self) -> F64:
        """(M,) start time of each segment [s]."""
        return self._t0.copy()

    @property
    def segment_durations_s(self) -> F64:
        """(M,) duration of each segment [s]."""
        return self._T.copy()

    def segment_peak_speeds(self) -> tuple[F64, F64]:
        """(M,) exact peak linear [m/s] and angular [rad/s] speed of each segment."""
        return (
            MINIMUM_JERK_PEAK_FACTOR * np.linalg.norm(self._dp, axis=-1) / self._T,
            MINIMUM_JERK_PEAK_FACTOR * self._angle / self._T,
        )

    def sample(self, t_s: ArrayLike) -> TrajectorySample:
        """Exact pose, velocity and acceleration; see ``Trajectory.sample``."""
        t = as_sample_times(t_s, self.start_s, self.end_s)
        i = np.clip(np.searchsorted(self._t0, t, side="right") - 1, 0, self._T.size - 1)
        T = self._T[i]
        tau = np.clip((t - self._t0[i]) / T, 0.0, 1.0)
        s, ds, dds = _profile(tau)
        rate, accel = ds / T, dds / (T * T)
        dp, axis, angle = self._dp[i], self._axis[i], self._angle[i]
        pose = np.zeros((t.size, 4, 4))
        pose[:, :3, :3] = matrix_from_quat(
            quat_multiply(quat_from_rotvec((s * angle)[:, None] * axis), self._q0[i])
        )
        pose[:, :3, 3] = self._p0[i] + s[:, None] * dp
        pose[:, 3, 3] = 1.0
        return TrajectorySample(
            t_s=t,
            T_ref_obj=pose,
            v_mps=rate[:, None] * dp,
            w_radps=(rate * angle)[:, None] * axis,
            a_mps2=accel[:, None] * dp,
            alpha_radps2=(accel * angle)[:, None] * axis,
        )


def _random_unit(rng: np.random.Generator) -> F64:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def _move_inside(
    region: ViewRegion, p: F64, distance_m: float, rng: np.random.Generator, tries: int = 48
) -> F64 | None:
    """A displacement of ``distance_m`` (or shorter) from ``p`` that stays in the region."""
    d = distance_m
    while d > 1e-4:
        dirs = rng.normal(size=(tries, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        ok = region.contains(p + d * dirs)
        if ok.any():
            step: F64 = d * dirs[int(np.argmax(ok))]
            return step
        d *= 0.7
    return None


_Segment = tuple[float, F64, F64]
"""One minimum-jerk submovement: duration [s], displacement (3,) [m], rotation vector (3,) [rad]."""


@dataclass(frozen=True, slots=True, kw_only=True)
class _PrimitiveLimits:
    """The speed and acceleration bounds every primitive of :func:`generate_synthetic_motion`
    respects (SI units)."""

    v_peak: float
    w_peak: float
    a_max: float
    alpha_max: float

    @classmethod
    def of(cls, config: SyntheticMotionConfig) -> _PrimitiveLimits:
        return cls(
            v_peak=config.peak_linear_speed_mps,
            w_peak=config.peak_angular_speed_radps,
            a_max=config.peak_linear_acceleration_mps2,
            alpha_max=float(np.radians(config.peak_angular_acceleration_dps2)),
        )


def _speed_fraction(config: SyntheticMotionConfig, forced: bool, rng: np.random.Generator) -> float:
    """1 for the forced first reach and twist (they run at the targets), else a random fraction."""
    return 1.0 if forced else float(rng.uniform(config.min_speed_fraction, 1.0))


def _submovement_duration_s(
    config: SyntheticMotionConfig, speed_mps: float, rate_radps: float, rng: np.random.Generator
) -> float:
    """A random reach or twist duration [s], lengthened to respect the acceleration bounds."""
    return max(
        float(rng.uniform(*config.submovement_duration_s)),
        config.shortest_segment_s(speed_mps, rate_radps),
    )


def _reach(
    config: SyntheticMotionConfig,
    lim: _PrimitiveLimits,
    region: ViewRegion,
    p: F64,
    forced: bool,
    rng: np.random.Generator,
) -> list[_Segment]:
    """A reach from ``p`` (with a little rotation), or nothing when no move fits the region."""
    k, c_acc = MINIMUM_JERK_PEAK_FACTOR, MINIMUM_JERK_ACCELERATION_FACTOR
    speed = _speed_fraction(config, forced, rng) * lim.v_peak
    T = _submovement_duration_s(config, speed, 0.0, rng)
    move = _move_inside(region, p, speed * T / k, rng)
    if move is None:
        return []
    T = k * float(np.linalg.norm(move)) / speed
    turn_rate = rng.uniform(0.0, config.reach_rotation_fraction) * lim.w_peak
    turn_rate = min(turn_rate, lim.alpha_max * T / c_acc)
    return [(T, move, _random_unit(rng) * turn_rate * T / k)]


def _twist(
    config: SyntheticMotionConfig,
    lim: _PrimitiveLimits,
    region: ViewRegion,
    p: F64,
    forced: bool,
    rng: np.random.Generator,
) -> list[_Segment]:
    """A rotation about a random axis, with a little drift of the position."""
    k, c_acc = MINIMUM_JERK_PEAK_FACTOR, MINIMUM_JERK_ACCELERATION_FACTOR
    turn_rate = _speed_fraction(config, forced, rng) * lim.w_peak
    T = _submovement_duration_s(config, 0.0, turn_rate, rng)
    turn = _random_unit(rng) * turn_rate * T / k
    drift_speed = rng.uniform(0.0, config.twist_translation_fraction) * lim.v_peak
    drift_speed = min(drift_speed, lim.a_max * T / c_acc)
    move = _move_inside(region, p, drift_speed * T / k, rng)
    return [(T, np.zeros(3) if move is None else move, turn)]


def _shake(
    config: SyntheticMotionConfig,
    lim: _PrimitiveLimits,
    region: ViewRegion,
    p: F64,
    rng: np.random.Generator,
) -> list[_Segment]:
    """An even number of back-and-forth half-cycles (it returns to where it started)."""
    k, c_acc = MINIMUM_JERK_PEAK_FACTOR, MINIMUM_JERK_ACCELERATION_FACTOR
    half = 0.5 / float(rng.uniform(*config.shake_frequency_hz))
    count = int(rng.integers(config.shake_half_cycles[0], config.shake_half_cycles[1] + 1))
    count += count % 2
    # a shake's half-cycles are short: its amplitude, not its duration, gives way
    shake_speed = min(_speed_fraction(config, False, rng) * lim.v_peak, lim.a_max * half / c_acc)
    shake_rate = min(_speed_fraction(config, False, rng) * lim.w_peak, lim.alpha_max * half / c_acc)
    move = _move_inside(region, p, shake_speed * half / k, rng)
    move = np.zeros(3) if move is None else move
    turn = _random_unit(rng) * shake_rate * half / k
    return [(half, sign * move, sign * turn) for sign in [1.0, -1.0] * (count // 2)]


def generate_synthetic_motion(
    config: SyntheticMotionConfig, region: ViewRegion, rng: np.random.Generator
) -> MinimumJerkTrajectory:
    """Draws a synthetic motion (camera frame) that stays in ``region``.

    Args:
        config: targets and primitive mix.
        region: where the object centre must stay (built from the camera and object radius).
        rng: the only source of randomness.

    Returns:
        A trajectory on ``[0, config.duration_s]`` whose peak linear and angular speeds equal
        the targets (the first reach and the first twist run at them).
    """
    lim = _PrimitiveLimits.of(config)
    z_mid = 0.5 * (region.near_m + region.far_m)
    p = region.centre_at(z_mid)
    if not region.contains(p[None])[0]:
        raise ConfigError("the view region is empty; lower in_view_margin")
    p_start = p.copy()
    q_start = rng.normal(size=4)
    q_start /= np.linalg.norm(q_start)
    segments_done: list[_Segment] = []
    kinds: list[str] = []
    names = ("reach", "twist", "shake", "hold")
    weights = np.array(
        [config.reach_weight, config.twist_weight, config.shake_weight, config.hold_weight]
    )
    plan = [str(kind) for kind in rng.permutation(["reach", "twist"])]
    t = 0.0
    while True:
        forced = bool(plan)
        kind = plan.pop(0) if plan else str(rng.choice(names, p=weights / weights.sum()))
        if kind == "reach":
            segments = _reach(config, lim, region, p, forced, rng)
        elif kind == "twist":
            segments = _twist(config, lim, region, p, forced, rng)
        elif kind == "shake":
            segments = _shake(config, lim, region, p, rng)
        else:
            segments = [(float(rng.uniform(*config.hold_duration_s)), np.zeros(3), np.zeros(3))]
        total = sum(s[0] for s in segments)
        if t + total > config.duration_s - 1e-9:
            if forced:
                raise ConfigError(
                    f"duration_s = {config.duration_s} s is too short for the first reach and "
                    "twist at the speed targets; make it longer"
                )
            break
        for segment in segments:
            segments_done.append(segment)
            kinds.append(kind)
            p = p + segment[1]
        t += total
    segments_done.append((config.duration_s - t, np.zeros(3), np.zeros(3)))
    kinds.append("hold")
    return MinimumJerkTrajectory(
        durations_s=[s[0] for s in segments_done],
        p_start_m=p_start,
        q_start_wxyz=q_start,
        dp_m=np.array([s[1] for s in segments_done]),
        rotvec_rad=np.array([s[2] for s in segments_done]),
        kinds=tuple(kinds),
        end_s=config.duration_s,
    )
