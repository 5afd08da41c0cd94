"""Sampled poses read from a file, and the clean-up applied before spline replay.

Every importer returns :class:`PoseSamples`. The clean-up steps are pure functions on them:
:func:`resample_uniform` (filters need a uniform rate; captured data has gaps),
:func:`remove_position_drift` (walking), :func:`lowpass_poses` (zero-phase Butterworth on the
position and the sign-aligned quaternions), :func:`window_samples` and :func:`scale_speed`;
:func:`clean_samples` applies them in that order.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry.so3 import matrix_from_quat, quat_from_matrix
from roft_sim.trajectories.spline import MIN_SPLINE_SAMPLES, SplinePoseTrajectory

F64 = NDArray[np.float64]

__all__ = [
    "PoseSamples",
    "find_gaps",
    "resample_uniform",
    "remove_position_drift",
    "lowpass_poses",
    "window_samples",
    "scale_speed",
    "is_uniform",
    "clean_samples",
    "LOWPASS_ORDER",
]

_log = logging.getLogger(__name__)

LOWPASS_ORDER = 4
"""Butterworth order of :func:`lowpass_poses` (applied forward and backward: zero phase,
effective order 8, -6 dB at the cut-off)."""

_UNIFORM_RTOL = 1e-3


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseSamples:
    """Poses of a rigid body at increasing times, as read from a file."""

    t_s: F64
    """(N,) strictly increasing times [s], the first at 0 (file time minus its first stamp)."""
    T_ref_obj: F64
    """(N, 4, 4) poses in the file's reference frame [m]."""
    source: str
    """Where the samples come from, for messages (file name and selection)."""
    up_ref: F64 | None = None
    """(3,) unit vector pointing up (against gravity) in the reference frame, when the format
    defines one (TUM: +z, BVH: +y); None for camera-frame formats."""
    camera_frame: bool = False
    """True when the reference frame already is a camera frame (Fast-YCB, BOP, CSV)."""

    def __post_init__(self) -> None:
        n = self.t_s.shape[0] if self.t_s.ndim == 1 else -1
        if n < 0 or self.T_ref_obj.shape != (n, 4, 4):
            raise ValueError(
                f"PoseSamples needs t_s (N,) and T_ref_obj (N, 4, 4), got {self.t_s.shape} "
                f"and {self.T_ref_obj.shape}"
            )

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @property
    def nominal_rate_hz(self) -> float:
        """1 / median time step [Hz]."""
        return float(1.0 / np.median(np.diff(self.t_s)))


def is_uniform(samples: PoseSamples) -> bool:
    """True when every time step equals the median step within 0.1 %."""
    dt = np.diff(samples.t_s)
    return bool(np.all(np.abs(dt - np.median(dt)) <= _UNIFORM_RTOL * np.median(dt)))


def find_gaps(t_s: F64, *, factor: float = 1.5) -> list[tuple[float, float]]:
    """Gaps in a time series: ``(start_s, length_s)`` of every step longer than ``factor`` times
    the median step."""
    dt = np.diff(t_s)
    idx = np.flatnonzero(dt > factor * np.median(dt))
    return [(float(t_s[i]), float(dt[i])) for i in idx]


def resample_uniform(samples: PoseSamples, rate_hz: float | None = None) -> PoseSamples:
    """The same motion sampled at ``t_k = k / rate_hz`` over the samples' time span.

    The poses between samples come from the C2 spline replay (:class:`SplinePoseTrajectory`),
    which also bridges gaps; gaps longer than 1.5 sample steps are logged.

    Args:
        samples: any increasing sample times.
        rate_hz: target rate [Hz] (default: the nominal rate, 1 / median step).
    """
    rate = samples.nominal_rate_hz if rate_hz is None else float(rate_hz)
    gaps = find_gaps(samples.t_s)
    if gaps:
        worst = max(gaps, key=lambda g: g[1])
        _log.info(
            "%s: %d gaps in the time stamps bridged by the spline (longest %.3f s at t = %.2f s)",
            samples.source,
            len(gaps),
            worst[1],
            worst[0],
        )
    spline = SplinePoseTrajectory(samples.t_s, samples.T_ref_obj)
    t = np.arange(int(np.floor(samples.t_s[-1] * rate + 1e-9)) + 1) / rate
    return replace(samples, t_s=t, T_ref_obj=spline.sample(t).T_ref_obj)


def _require_uniform(samples: PoseSamples, what: str) -> float:
    if not is_uniform(samples):
        raise ValueError(f"{what} needs uniformly sampled poses; call resample_uniform first")
    return samples.nominal_rate_hz


def remove_position_drift(samples: PoseSamples, window_s: float) -> PoseSamples:
    """Subtracts a centred moving average of the position over ``window_s`` [s].

    Removes slow motion (an operator walking with the object) and keeps hand motion; rotations
    are unchanged. The average window has an odd number of samples, ``window_s * rate`` rounded;
    at the ends the first and last positions are repeated.

    Raises:
        ConfigError: the window is shorter than three samples.
        ValueError: the samples are not uniform.
    """
    rate = _require_uniform(samples, "drift removal")
    n = int(round(window_s * rate)) // 2 * 2 + 1
    if n < 3:
        raise ConfigError(
            f"remove_drift_window_s = {window_s} s covers fewer than 3 samples at {rate:.4g} Hz; "
            "use a longer window (about 2 s for walking)"
        )
    from scipy import ndimage  # here: generation workers never need it (1-2 s to import)

    p = samples.T_ref_obj[:, :3, 3]
    mean = ndimage.uniform_filter1d(p, size=n, axis=0, mode="nearest")
    T = samples.T_ref_obj.copy()
    T[:, :3, 3] = p - mean
    return replace(samples, T_ref_obj=T)


def _continuous_quats(q: F64) -> F64:
    """Flips signs so that consecutive quaternions ``(N, 4)`` have a non-negative dot product."""
    dots = np.sum(q[1:] * q[:-1], axis=-1)
    flips: F64 = np.concatenate([[1.0], np.cumprod(np.where(dots < 0.0, -1.0, 1.0))])
    return q * flips[:, None]


def lowpass_poses(samples: PoseSamples, cutoff_hz: float) -> PoseSamples:
    """Zero-phase low-pass filter (Butterworth, :data:`LOWPASS_ORDER`, forward-backward).

    Position: filtered per component. Rotation: the unit quaternions are made sign-continuous
    first (``q`` and ``-q`` are the same rotation, and a sign flip would look like a jump),
    filtered per component and renormalised. Along a rotation about a fixed axis this equals
    filtering the angle (the tangent-space filter) up to terms of second order in the motion
    within the filter's time scale (tested: 5e-5 rad for 1 rad swings at 1 Hz with a 10 Hz
    cut-off). The result does not depend on the quaternion signs in the input.

    Raises:
        ConfigError: the cut-off is not below the Nyquist frequency, or the samples are too few
            for the filter's edge padding.
        ValueError: the samples are not uniform.
    """
    rate = _require_uniform(samples, "low-pass filtering")
    if not (0.0 < cutoff_hz < 0.5 * rate):
        raise ConfigError(
            f"lowpass_hz = {cutoff_hz} must lie between 0 and the Nyquist frequency "
            f"{0.5 * rate:.4g} Hz of these {rate:.4g} Hz samples"
        )
    from scipy import signal  # here: generation workers never need it (1-2 s to import)

    sos = signal.butter(LOWPASS_ORDER, cutoff_hz, btype="low", fs=rate, output="sos")
    padlen = 3 * (2 * len(sos) + 1)
    if len(samples) <= padlen:
        raise ConfigError(
            f"lowpass_hz needs more than {padlen} samples to filter, but {samples.source} has "
            f"{len(samples)}; remove lowpass_hz or use a longer recording"
        )
    p = signal.sosfiltfilt(sos, samples.T_ref_obj[:, :3, 3], axis=0)
    q = _continuous_quats(quat_from_matrix(samples.T_ref_obj[:, :3, :3]))
    q_out = signal.sosfiltfilt(sos, q, axis=0)
    q_out /= np.linalg.norm(q_out, axis=-1, keepdims=True)
    T = samples.T_ref_obj.copy()
    T[:, :3, :3] = matrix_from_quat(q_out)
    T[:, :3, 3] = p
    return replace(samples, T_ref_obj=T)


def window_samples(samples: PoseSamples, start_s: float, end_s: float) -> PoseSamples:
    """The samples with ``start_s <= t <= end_s``, times shifted so the first is 0.

    Raises:
        ConfigError: the window is empty, reversed, or keeps fewer than four samples.
    """
    if not (end_s > start_s):
        raise ConfigError(f"window_s = [{start_s}, {end_s}] must have end > start")
    keep = (samples.t_s >= start_s - 1e-9) & (samples.t_s <= end_s + 1e-9)
    if keep.sum() < MIN_SPLINE_SAMPLES:
        raise ConfigError(
            f"window_s = [{start_s}, {end_s}] s keeps {int(keep.sum())} samples of "
            f"{samples.source}, which spans [0, {samples.t_s[-1]:.6g}] s; choose a window "
            f"inside it with at least {MIN_SPLINE_SAMPLES} samples"
        )
    t = samples.t_s[keep]
    return replace(samples, t_s=t - t[0], T_ref_obj=samples.T_ref_obj[keep])


def scale_speed(samples: PoseSamples, speed_scale: float) -> PoseSamples:
    """Plays the motion ``speed_scale`` times faster: times divided by it (x0.5 = half speed,
    twice as long); velocities scale by ``speed_scale`` and accelerations by its square.

    Raises:
        ConfigError: a non-positive or non-finite scale.
    """
    if not (np.isfinite(speed_scale) and speed_scale > 0):
        raise ConfigError(f"speed_scale must be a positive number, got {speed_scale}")
    if speed_scale == 1.0:
        return samples
    return replace(samples, t_s=samples.t_s / speed_scale)


def clean_samples(
    samples: PoseSamples,
    *,
    lowpass_hz: float | None,
    remove_drift_window_s: float | None,
    window_s: tuple[float, float] | None,
    speed_scale: float,
) -> tuple[PoseSamples, float]:
    """Resampling (when filtering needs uniform samples), drift removal, low-pass, the time
    window and the speed scale, in that order (each step skipped when its setting is None).

    Returns:
        The cleaned samples and the window's start shift [s]: the time of the first kept sample
        before windowing (0 without a window).

    Raises:
        ConfigError: a setting that does not suit the samples (see each step).
    """
    if (lowpass_hz or remove_drift_window_s) and not is_uniform(samples):
        samples = resample_uniform(samples)
    if remove_drift_window_s:
        samples = remove_position_drift(samples, remove_drift_window_s)
    if lowpass_hz:
        samples = lowpass_poses(samples, lowpass_hz)
    shift = 0.0
    if window_s is not None:
        start, end = window_s
        kept = samples.t_s[samples.t_s >= start - 1e-9]
        shift = float(kept[0]) if kept.size else 0.0
        samples = window_samples(samples, start, end)
    return scale_speed(samples, speed_scale), shift
