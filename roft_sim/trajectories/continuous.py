"""Continuous hand-held motion: the object keeps moving and turning, with no rest between bursts.

The bursty generator (:mod:`roft_sim.trajectories.synthetic`) chains minimum-jerk submovements
that start and end at rest, and holds in between: its median angular speed is about 30 deg/s.
Captured hand-held motion (TUM VI rooms, CMU hands, 10 Hz low-pass) keeps turning: medians of
40-115 deg/s. This profile draws band-limited random signals instead:

- orientation ``R(t) = Exp(phi_1 a_1) Exp(phi_2 a_2) Exp(phi_3 a_3) R_0`` with three orthonormal
  camera-frame axes ``a_i`` and angles ``phi_i(t)``, each a sum of sinusoids with random
  frequencies in a band, phases and signs, scaled so the root-mean-square angular speed is the
  target; the angular velocity and acceleration are closed-form
  (``w = phi_1' u_1 + phi_2' u_2 + phi_3' u_3`` with ``u_1 = a_1``, ``u_2 = E_1 a_2``,
  ``u_3 = E_1 E_2 a_3``, and ``alpha`` its exact derivative);
- position ``p(t) = c + L tanh(q(t) / L)`` per axis, ``q`` the same kind of signal, ``c`` and
  ``L`` the largest axis-aligned box of the view region: the object centre can never leave the
  view, and the derivatives stay exact through the chain rule;
- both play on a warped clock ``tau(t)`` whose rate ``e(t) = dtau/dt`` swings slowly around 1
  (``e = 1 + sum_j b_j cos(nu_j t + chi_j)``, ``sum |b_j| = tempo_variation < 1``): the hand
  speeds up and slows down over seconds but never stops, which gives captured motion's heavy
  tails (bursts) without rests. ``x(tau(t))`` has ``x' e`` and ``x'' e^2 + x' e'`` as
  derivatives.

Every random number comes from ``np.random.default_rng(seed)``; the same seed gives the same
motion. The default targets are fitted to captured hand-object motion of the TUNING split
(:func:`roft_sim.trajectories.statistics.fit_continuous_motion`, docs/trajectories.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry.so3 import matrix_from_rotvec
from roft_sim.trajectories.base import TrajectorySample, as_sample_times
from roft_sim.trajectories.placement import ViewRegion

F64 = NDArray[np.float64]

__all__ = ["ContinuousMotionConfig", "ContinuousHandMotion", "generate_continuous_motion"]


@dataclass(frozen=True, slots=True, kw_only=True)
class ContinuousMotionConfig:
    """Seeded continuous hand-held motion in front of a static camera (``kind = "continuous"``).

    Defaults: fitted to the TUNING captures (TUM VI room1 and CMU 02_05 hands, 10 Hz low-pass,
    room drift removed over 2 s) with the median angular speed held at 80 deg/s or more; see
    docs/trajectories.md for the fit and the EVALUATION comparison.
    """

    kind: Literal["continuous"] = "continuous"
    """Tells trajectory configs apart in scenario files."""
    seed: int = 0
    """Seed of the generator (>= 0); the same seed gives the same motion."""
    duration_s: float = 10.0
    """Length of the motion [s]."""
    angular_speed_rms_dps: float = 101.1
    """Root-mean-square angular speed [deg/s] (sets the angular speed percentiles)."""
    angular_frequency_hz: tuple[float, float] = (0.753, 2.279)
    """Band of the rotation signals' frequencies [Hz] (sets the angular acceleration)."""
    linear_speed_rms_mps: float = 1.019
    """Root-mean-square speed of the unbounded position signal [m/s] (the view box's soft
    bound lowers it a little near its faces)."""
    linear_frequency_hz: tuple[float, float] = (0.221, 0.659)
    """Band of the position signals' frequencies [Hz] (sets the linear acceleration)."""
    tempo_variation: float = 0.7
    """Amplitude of the clock rate's swing around 1 (0 = steady; must stay below 1 so the
    motion never stops)."""
    tempo_frequency_hz: tuple[float, float] = (0.05, 0.25)
    """Band of the clock rate's frequencies [Hz] (how fast bursts come and go)."""
    components: int = 6
    """Sinusoids per signal (per rotation angle and per position axis)."""
    working_distance_m: tuple[float, float] = (0.4, 0.9)
    """Range of the object centre's depth in the camera frame [m]."""
    in_view_margin: float = 0.5
    """The object centre keeps at least this fraction of the object radius inside each side
    plane of the frustum."""

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int | np.integer):
            raise ConfigError(f"seed must be an integer >= 0, got {self.seed!r}")
        if self.seed < 0:
            raise ConfigError(f"seed must be an integer >= 0, got {self.seed}")
        for name in ("duration_s", "angular_speed_rms_dps", "linear_speed_rms_mps"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ConfigError(f"{name} must be a positive number, got {value}")
        if not (np.isfinite(self.tempo_variation) and 0.0 <= self.tempo_variation < 1.0):
            raise ConfigError(
                f"tempo_variation must lie in [0, 1), got {self.tempo_variation}; at 1 or more "
                "the clock would stop or run backwards"
            )
        for name in ("angular_frequency_hz", "linear_frequency_hz", "tempo_frequency_hz"):
            lo, hi = getattr(self, name)
            if not (np.isfinite([lo, hi]).all() and 0 < lo <= hi):
                raise ConfigError(
                    f"{name} must be (low, high) with 0 < low <= high [Hz], got "
                    f"{getattr(self, name)!r}; e.g. (0.4, 1.2)"
                )
        if isinstance(self.components, bool) or not 1 <= self.components <= 64:
            raise ConfigError(f"components must be an integer in [1, 64], got {self.components}")
        near, far = self.working_distance_m
        if not (np.isfinite([near, far]).all() and 0.0 < near < far):
            raise ConfigError(
                f"working_distance_m must be (near, far) with 0 < near < far, got "
                f"{self.working_distance_m!r}"
            )
        if not (np.isfinite(self.in_view_margin) and self.in_view_margin >= 0):
            raise ConfigError(f"in_view_margin must be >= 0, got {self.in_view_margin}")


@dataclass(frozen=True, slots=True, kw_only=True)
class _Signals:
    """Sums of sinusoids ``x_i(t) = sum_j A_ij sin(2 pi f_ij t + psi_ij)``, one per row."""

    amplitude: F64
    """(S, K) amplitudes (in the signal's unit)."""
    omega_radps: F64
    """(S, K) angular frequencies ``2 pi f`` [rad/s]."""
    phase_rad: F64
    """(S, K) phases [rad]."""

    def evaluate(self, t_s: F64) -> tuple[F64, F64, F64]:
        """``x, x', x''`` at times ``t_s`` (N,), each (N, S)."""
        arg = t_s[:, None, None] * self.omega_radps[None] + self.phase_rad[None]
        s, c = np.sin(arg), np.cos(arg)
        a, om = self.amplitude[None], self.omega_radps[None]
        return (
            np.sum(a * s, axis=-1),
            np.sum(a * om * c, axis=-1),
            -np.sum(a * om * om * s, axis=-1),
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class _Clock:
    """A warped clock ``tau(t) = t + sum_j (b_j / nu_j) (sin(nu_j t + chi_j) - sin(chi_j))``,
    rate ``e(t) = 1 + sum_j b_j cos(nu_j t + chi_j) > 0``."""

    amplitude: F64
    """(J,) rate amplitudes ``b_j`` (sum of magnitudes below 1)."""
    omega_radps: F64
    """(J,) angular frequencies ``nu_j`` [rad/s]."""
    phase_rad: F64
    """(J,) phases ``chi_j`` [rad]."""

    def evaluate(self, t_s: F64) -> tuple[F64, F64, F64]:
        """``tau, e = dtau/dt, de/dt`` at times ``t_s`` (N,), each (N,)."""
        arg = t_s[:, None] * self.omega_radps + self.phase_rad
        b, nu = self.amplitude, self.omega_radps
        tau = t_s + np.sum(b / nu * (np.sin(arg) - np.sin(self.phase_rad)), axis=-1)
        rate = 1.0 + np.sum(b * np.cos(arg), axis=-1)
        rate_dot = -np.sum(b * nu * np.sin(arg), axis=-1)
        return tau, rate, rate_dot


def _warped(signals: _Signals, tau: F64, rate: F64, rate_dot: F64) -> tuple[F64, F64, F64]:
    """``x(tau(t))`` and its first two time derivatives, each (N, S)."""
    x, dx, ddx = signals.evaluate(tau)
    e, de = rate[:, None], rate_dot[:, None]
    return x, dx * e, ddx * e * e + dx * de


def _draw_signals(
    rng: np.random.Generator,
    count: int,
    components: int,
    band_hz: tuple[float, float],
    rate_rms: float,
) -> _Signals:
    """``count`` signals whose derivatives have a root-mean-square of ``rate_rms`` each
    (in expectation over the phases): every sinusoid gets the derivative amplitude
    ``rate_rms * sqrt(2 / K)``."""
    freq = rng.uniform(band_hz[0], band_hz[1], size=(count, components))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(count, components))
    omega = 2.0 * np.pi * freq
    rate_amplitude = rate_rms * np.sqrt(2.0 / components)
    return _Signals(amplitude=rate_amplitude / omega, omega_radps=omega, phase_rad=phase)


def _view_box(region: ViewRegion) -> tuple[F64, F64]:
    """Centre (3,) and half-sizes (3,) [m] of the largest axis-aligned box of the convex view
    region centred on its middle depth (found by halving until its corners are inside)."""
    z_mid = 0.5 * (region.near_m + region.far_m)
    centre = region.centre_at(z_mid)
    x_lo, x_hi = region.x_bounds(np.array([region.near_m]))
    y_lo, y_hi = region.y_bounds(np.array([region.near_m]))
    half = np.array(
        [
            min(centre[0] - x_lo[0], x_hi[0] - centre[0]),
            min(centre[1] - y_lo[0], y_hi[0] - centre[1]),
            0.5 * (region.far_m - region.near_m),
        ]
    )
    signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    for _ in range(60):
        if region.contains(centre + signs * half).all():
            return centre, half
        half = 0.97 * half
    raise ConfigError("the view region is empty; lower in_view_margin or widen working_distance_m")


class ContinuousHandMotion:
    """Continuous hand-held motion on ``[0, duration_s]``; satisfies ``Trajectory``."""

    __slots__ = ("_angles", "_position", "_clock", "_axes", "_R0", "_centre", "_half", "_end_s")

    def __init__(
        self,
        *,
        angles: _Signals,
        position: _Signals,
        clock: _Clock,
        axes: F64,
        R_start: F64,
        centre_m: F64,
        half_size_m: F64,
        end_s: float,
    ) -> None:
        self._angles = angles
        self._position = position
        self._clock = clock
        self._axes = axes
        self._R0 = R_start
        self._centre = centre_m
        self._half = half_size_m
        self._end_s = float(end_s)

    @property
    def start_s(self) -> float:
        return 0.0

    @property
    def end_s(self) -> float:
        return self._end_s

    @property
    def view_box_m(self) -> tuple[F64, F64]:
        """Centre (3,) and half-sizes (3,) [m] of the box the object centre stays in (camera
        frame)."""
        return self._centre.copy(), self._half.copy()

    def sample(self, t_s: ArrayLike) -> TrajectorySample:
        """Exact pose, velocity and acceleration; see ``Trajectory.sample``."""
        t = as_sample_times(t_s, self.start_s, self.end_s)
        tau, rate, rate_dot = self._clock.evaluate(t)
        phi, dphi, ddphi = _warped(self._angles, tau, rate, rate_dot)  # (N, 3) each
        a1, a2, a3 = self._axes
        E1 = matrix_from_rotvec(phi[:, :1] * a1)
        E2 = matrix_from_rotvec(phi[:, 1:2] * a2)
        E3 = matrix_from_rotvec(phi[:, 2:3] * a3)
        E12 = E1 @ E2
        u1 = np.broadcast_to(a1, t.shape + (3,))
        u2 = E1 @ a2
        u3 = E12 @ a3
        w12 = dphi[:, :1] * u1 + dphi[:, 1:2] * u2
        w = w12 + dphi[:, 2:3] * u3
        alpha = (
            ddphi[:, :1] * u1
            + ddphi[:, 1:2] * u2
            + dphi[:, 1:2] * np.cross(dphi[:, :1] * u1, u2)
            + ddphi[:, 2:3] * u3
            + dphi[:, 2:3] * np.cross(w12, u3)
        )
        q, dq, ddq = _warped(self._position, tau, rate, rate_dot)
        L = self._half[None]
        th = np.tanh(q / L)
        sech2 = 1.0 - th * th
        pose = np.zeros((t.size, 4, 4))
        pose[:, :3, :3] = E12 @ E3 @ self._R0
        pose[:, :3, 3] = self._centre + L * th
        pose[:, 3, 3] = 1.0
        return TrajectorySample(
            t_s=t,
            T_ref_obj=pose,
            v_mps=sech2 * dq,
            w_radps=w,
            a_mps2=sech2 * ddq - 2.0 * sech2 * th * dq * dq / L,
            alpha_radps2=alpha,
        )


def generate_continuous_motion(
    config: ContinuousMotionConfig, region: ViewRegion, rng: np.random.Generator
) -> ContinuousHandMotion:
    """Draws a continuous motion (camera frame) whose object centre stays in ``region``.

    Args:
        config: speed targets, frequency bands, duration.
        region: where the object centre must stay (built from the camera and object radius).
        rng: the only source of randomness.
    """
    k = config.components
    angular_rms_radps = float(np.radians(config.angular_speed_rms_dps))
    angles = _draw_signals(rng, 3, k, config.angular_frequency_hz, angular_rms_radps / np.sqrt(3))
    position = _draw_signals(
        rng, 3, k, config.linear_frequency_hz, config.linear_speed_rms_mps / np.sqrt(3)
    )
    tempo = rng.uniform(config.tempo_frequency_hz[0], config.tempo_frequency_hz[1], size=3)
    weights = rng.uniform(0.5, 1.0, size=3)
    clock = _Clock(
        amplitude=config.tempo_variation * weights / weights.sum(),
        omega_radps=2.0 * np.pi * tempo,
        phase_rad=rng.uniform(0.0, 2.0 * np.pi, size=3),
    )
    axes, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    q0 = rng.normal(size=3)
    R0 = matrix_from_rotvec(np.pi * rng.uniform() * q0 / np.linalg.norm(q0))
    centre, half = _view_box(region)
    return ContinuousHandMotion(
        angles=angles,
        position=position,
        clock=clock,
        axes=axes.T.copy(),
        R_start=R0,
        centre_m=centre,
        half_size_m=half,
        end_s=config.duration_s,
    )
