"""What a camera's frame rate lets a causal tracker know of the instantaneous velocity.

Optical flow between frames k-1 and k tells the motion over that interval, not the velocity at
frame k, which is what ``e_v`` and ``e_w`` score. Even a tracker that measured every interval
exactly must guess the velocity at the interval's end; on fast, jerky motion (hands) that guess
alone costs more than a goal such as ``e_w <= 15 deg/s`` allows. These figures put a tracker's
``e_v``/``e_w`` beside what the exact interval motion gives (docs/metrics.md, "Interval
velocity"):

- ``held``: the exact interval-mean twist taken as the velocity at the interval's end (what a
  constant-velocity filter that trusts its flow converges to);
- ``extrapolated``: carried half an interval forward with the difference of the last two interval
  means (a constant-acceleration guess);
- ``fitted``: the least-squares linear combination of the last three interval means, fitted per
  axis to the truth it is scored on: a predictor no tracker can build without knowing the answer,
  so an optimistic figure for any linear motion model fed with exact flow.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.so3 import rotvec_from_matrix
from roft_sim.records import PoseTrack

__all__ = [
    "FITTED_HISTORY",
    "IntervalVelocityErrors",
    "interval_mean_twists",
    "interval_velocity_errors",
]

F64 = NDArray[np.float64]

FITTED_HISTORY = 3
"""Number of past interval means the ``fitted`` predictor combines."""


def interval_mean_twists(track: PoseTrack) -> tuple[F64, F64]:
    """The motion over each interval ``(t_{k-1}, t_k]`` of ``track``, camera frame.

    Returns:
        ``v`` (N-1, 3) [m/s]: the mean velocity of the object origin, ``(t_k - t_{k-1}) / dt``
        (exact: ``v_obj`` is the derivative of the translation); ``w`` (N-1, 3) [rad/s]: the
        constant angular velocity that turns ``R_{k-1}`` into ``R_k``, ``log(R_k R_{k-1}^T) /
        dt`` (the interval mean when the axis stays put).

    Raises:
        ValueError: time stamps that do not increase.
    """
    dt = np.diff(track.t_s)
    if (dt <= 0.0).any():
        raise ValueError(f"ground-truth time stamps must increase; got steps {dt[dt <= 0][:3]} s")
    R = track.T_cam_obj[:, :3, :3]
    v = np.diff(track.T_cam_obj[:, :3, 3], axis=0) / dt[:, None]
    w = rotvec_from_matrix(R[1:] @ np.swapaxes(R[:-1], 1, 2)) / dt[:, None]
    return v, w


@dataclass(frozen=True, slots=True, kw_only=True)
class IntervalVelocityErrors:
    """RMS errors [cm/s, deg/s] against the instantaneous ground truth at frames
    ``FITTED_HISTORY..N-1`` (the same frames for every predictor; module docstring)."""

    held_v_cmps: float
    held_w_dps: float
    extrapolated_v_cmps: float
    extrapolated_w_dps: float
    fitted_v_cmps: float
    fitted_w_dps: float
    frames: int
    """Number of frames scored (0: too short a track; every figure is then NaN)."""

    def summary(self) -> dict[str, float | int | None]:
        """The figures as a JSON-ready dict (NaN as None)."""
        out: dict[str, float | int | None] = {}
        for field in fields(self):
            value = getattr(self, field.name)
            out[field.name] = None if isinstance(value, float) and not np.isfinite(value) else value
        return out


def _rms_norm(error: F64) -> float:
    return float(np.sqrt(np.mean(np.sum(error * error, axis=1))))


def _fitted(means: F64, truth: F64) -> F64:
    """Per axis, the least-squares prediction of ``truth`` (M, 3) from the last
    ``FITTED_HISTORY`` rows of ``means`` (M + FITTED_HISTORY - 1, 3)."""
    m = truth.shape[0]
    starts = [FITTED_HISTORY - 1 - lag for lag in range(FITTED_HISTORY)]  # newest mean first
    out = np.empty_like(truth)
    for axis in range(3):
        X = np.stack([means[start : start + m, axis] for start in starts], axis=1)
        coef, *_ = np.linalg.lstsq(X, truth[:, axis], rcond=None)
        out[:, axis] = X @ coef
    return out


def interval_velocity_errors(track: PoseTrack) -> IntervalVelocityErrors:
    """The ``held``, ``extrapolated`` and ``fitted`` errors of ``track`` (module docstring),
    scored like the trackers' ``e_v`` (``v_obj``, cm/s) and ``e_w`` (deg/s)."""
    n = len(track)
    if n <= FITTED_HISTORY:
        nan = float("nan")
        return IntervalVelocityErrors(
            held_v_cmps=nan,
            held_w_dps=nan,
            extrapolated_v_cmps=nan,
            extrapolated_w_dps=nan,
            fitted_v_cmps=nan,
            fitted_w_dps=nan,
            frames=0,
        )
    v_mean, w_mean = interval_mean_twists(track)
    dt = np.diff(track.t_s)
    first = FITTED_HISTORY  # frame index of the first scored frame
    figures = {}
    for name, means, truth, scale in (
        ("v_cmps", v_mean, track.v_obj_mps, 100.0),
        ("w_dps", w_mean, track.w_radps, 180.0 / np.pi),
    ):
        # means[k - 1] is the interval ending at frame k
        now = means[first - 1 :]
        before = means[first - 2 : -1]
        gap = 0.5 * (dt[first - 1 :] + dt[first - 2 : -1])  # between the two intervals' middles
        extrapolated = now + (now - before) * (0.5 * dt[first - 1 :] / gap)[:, None]
        target = truth[first:]
        figures[f"held_{name}"] = scale * _rms_norm(now - target)
        figures[f"extrapolated_{name}"] = scale * _rms_norm(extrapolated - target)
        figures[f"fitted_{name}"] = scale * _rms_norm(_fitted(means, target) - target)
    return IntervalVelocityErrors(**figures, frames=n - first)
