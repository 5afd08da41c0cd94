"""``velocity.motion_model = "auto"``: the constant and the constant-acceleration velocity KF
side by side, weighted by how well each predicted the flow (issue 14, upper bound).

The flow F_k measures the mean twist over (k-1, k]. The constant model reports it as the twist
at k (half a frame late: ``|a| dt / 2``); the constant-acceleration model estimates the twist at
k and its rate, which with exact flow removes the lag and with noisy flow reads the flow's
coloured errors as acceleration (docs/roft.md). Which of the two is better depends on the flow,
so both run, unchanged and independent, on the same pixels, and a prequential score decides:

1. Before frame k's flow is used, each model predicts the interval mean of (k-1, k]: the
   constant model its last twist ``x``, the constant-acceleration model ``M F X`` (its twist
   carried to k less half an interval of its rate).
2. The flow's pixels on their own give the interval mean ``m_ls`` with covariance ``P_ls``
   (the constant model's robust weights and flow noise). Both are moved to the fit's
   DECOUPLING POINT ``c`` (3,) [m, camera frame]: the body point whose velocity
   ``v_c = v_o + w x c`` the pixels determine independently of ``w`` (the skew-symmetric
   least-squares solution of ``[c]_x P_ww = P_vw``; about the visible surface's centre). Each
   prediction error ``e_i = m_ls - p_i``, moved there, is whitened by that same covariance,
   the linear and the angular part each by its marginal block:
   ``s_i = (s_iv, s_iw) = (e_v^T P_ls[v, v]^-1 e_v, e_w^T P_ls[w, w]^-1 e_w)``, so both
   models are judged by one metric that neither model's own covariance can flatter, and an
   angular error is not counted again as the linear error it causes at the camera origin.
3. ``L_i`` (2,) is the exponentially forgetting mean of ``s_i`` over ``selection_memory``
   updates; the ratio weight of each part is ``r = 1 / (1 + (L_a / (m L_c))^g)``
   (``m = selection_margin``, ``g = selection_sharpness``). The ratio of a few scores is noise,
   so both parts' ``r`` are multiplied by the CONFIDENCE that the constant-acceleration model
   predicts better by the margin: the per-update log ratios ``d = log(sum s_a / sum s_c)``
   (clipped to ``+-selection_log_ratio_clip``) have a forgetting mean and variance over the
   same memory, shrunk towards "no difference" by ``selection_prior_updates`` pseudo-updates
   of ``d = 0`` with variance ``(clip / 2)^2``; the confidence is
   ``Phi(-(mean_d - log m) / se_d)``. A consistent advantage (exact flow on smooth motion) is
   trusted after a few updates, a noisy one (coloured flow errors, bursts) not at all; the
   first score is taken at the second update, when both models have predicted. Each part's
   weight is also multiplied by the same function of THIS update's scores with the ratio
   ``selection_instant_ratio`` (4) in place of the margin: a model whose current prediction is
   several times worse than the other's loses its weight at once, as a likelihood update of
   an interacting-multiple-model filter would (the means react over ~30 updates; at the start
   of an occlusion the constant-acceleration model extrapolates the disturbance).

Only the REPORTED twist (``x_frame``, the twist at k) is mixed, at the decoupling point: its
linear velocity there is ``(1 - a_v) v_c + a_v v_a``, its angular velocity ``(1 - a_w) w_c +
a_w w_a``, ``a = confidence * r`` per part (one weight for all six components at the camera
origin let an acceleration model that predicts the linear part better carry its angular
errors into the report: TUNING TUM room1, default inputs, e_w 29.1 -> 32.2 deg/s, per part
29.2; EVALUATION TUM room2 28.1 -> 40.7, per part 28.3; docs/roft.md). The pose UKF keeps the
constant model's interval mean and covariance (``x``, ``P``): with ground-truth inputs the
constant-acceleration model's interval mean did not improve the poses (TUM room1 ADD-AUC
92.6 % either way), and with the default inputs mixing it in cost ADD-AUC (72.0 -> 70.6 % on
TUM room1 with an earlier weight; docs/roft.md).
"""

from __future__ import annotations

import copy

import numpy as np
from numpy.typing import NDArray
from scipy.special import ndtr

from roft_sim.geometry.se3 import twist_at_point_matrix
from roft_sim.trackers.roft.config import VelocityKFConfig
from roft_sim.trackers.roft.velocity_kf import FlowMeasurement, VelocityKF

F64 = NDArray[np.float64]

__all__ = ["SelectingVelocityKF", "VelocityFilter", "make_velocity_filter"]


class SelectingVelocityKF:
    """The constant and the constant-acceleration :class:`VelocityKF`, mixed by a prequential
    weight; the same attributes the tracker reads from a :class:`VelocityKF`."""

    def __init__(self, config: VelocityKFConfig, width_px: int | None = None):
        """Args:
        config: the settings (``motion_model = "auto"``).
        width_px: image width [px] for the resolution scaling of the flow noise.
        """
        self._config = config
        self.constant = VelocityKF(config, width_px, "constant")
        """The constant-twist model (the reference's filter)."""
        self.accel = VelocityKF(config, width_px, "constant_acceleration")
        """The constant-acceleration model."""
        self.reset()

    def reset(self) -> None:
        self.constant.reset()
        self.accel.reset()
        self._score_sum = np.zeros((2, 2))
        self._score_weight = 0.0
        self._log_ratio_sums = np.zeros(2)  # forgetting sums of d and d^2
        self.score: F64 = np.zeros((2, 2))
        """(2, 2) running mean whitened prediction errors ``L`` [dimensionless]: rows the
        constant and the constant-acceleration model, columns the linear part (at the
        decoupling point) and the angular part."""
        self.confidence = 0.0
        """Confidence in [0, 1] that the constant-acceleration model predicts the flow better by
        ``selection_margin`` (module docstring, step 3)."""
        self.weights_accel: F64 = np.zeros(2)
        """(2,) the constant-acceleration model's weights in [0, 1] for the linear velocity at
        the decoupling point and for the angular velocity (0 until both models have been
        scored)."""
        self.decoupling_point_m: F64 = np.zeros(3)
        """(3,) the last fit's decoupling point ``c`` [m], camera frame: where the twists are
        scored and mixed (module docstring, step 2)."""
        self._combine()

    def copy(self) -> SelectingVelocityKF:
        """An independent copy of this filter and of its two models."""
        out = copy.copy(self)
        out.constant = self.constant.copy()
        out.accel = self.accel.copy()
        return out

    @property
    def updates(self) -> int:
        """Number of corrections so far (0: the twist is the prior)."""
        return self.constant.updates

    def step(
        self,
        measurement: FlowMeasurement | None,
        *,
        frames: float = 1.0,
        t_s: float | None = None,
        dt_s: float | None = None,
    ) -> bool:
        """Scores both models' predictions of this interval, corrects both with
        ``measurement``, and mixes them (arguments and return as :meth:`VelocityKF.step`;
        ``t_s`` and ``dt_s`` are required)."""
        if t_s is None or dt_s is None:
            raise ValueError(
                "motion_model = 'auto' needs the frame time t_s and the interval dt_s the flow "
                "spans"
            )
        if (
            measurement is not None
            and measurement.relinearize is not None
            and len(measurement) >= self._config.min_pixels
        ):
            # once, at the constant model's estimate, for both models (the pose UKF reads the
            # constant model: its twist is the same as on its own; half the cost)
            measurement = self.constant.relinearized(measurement, frames, t_s, dt_s)
        scored = self.constant.updates > 0
        predictions = (
            self.constant.predicted_interval_mean(t_s, dt_s),
            self.accel.predicted_interval_mean(t_s, dt_s),
        )
        if not self.constant.step(measurement, frames=frames, t_s=t_s, dt_s=dt_s):
            return False
        # each model weighs the flow about its own prediction: weighed about the constant
        # model's, the reported twist of DIS flow was worse (640x480 benchmark: e_w 29.7 ->
        # 33.3 deg/s)
        self.accel.step(measurement, frames=frames, t_s=t_s, dt_s=dt_s)
        fit = self.constant.fit
        if fit is not None:
            m_ls, info_ls = fit
            cov_ls = np.asarray(np.linalg.inv(info_ls), dtype=np.float64)
            self.decoupling_point_m = _decoupling_point(cov_ls)
            if scored:
                shift = twist_at_point_matrix(self.decoupling_point_m)  # (6, 6)
                cov_c = shift @ cov_ls @ shift.T
                errors = np.stack([shift @ (m_ls - p) for p in predictions])  # (2, 6)
                self._score(_whitened_parts(errors, cov_c))
        self._combine()
        return True

    def _score(self, s: F64) -> None:
        """Adds one update's whitened prediction errors ``s`` (2, 2) (rows constant,
        acceleration; columns linear, angular) and sets ``score``, ``confidence`` and
        ``weights_accel`` (module docstring, step 3)."""
        cfg = self._config
        keep = 1.0 - 1.0 / cfg.selection_memory
        self._score_sum = keep * self._score_sum + s
        self._score_weight = keep * self._score_weight + 1.0
        self.score = self._score_sum / self._score_weight
        clip = cfg.selection_log_ratio_clip
        total = s.sum(axis=1)
        d = float(np.clip(np.log(max(total[1], _TINY)) - np.log(max(total[0], _TINY)), -clip, clip))
        self._log_ratio_sums = keep * self._log_ratio_sums + np.array([d, d * d])
        n = self._score_weight
        n0 = cfg.selection_prior_updates
        mean_seen = self._log_ratio_sums[0] / n
        spread = max(self._log_ratio_sums[1] - n * mean_seen**2, 0.0)
        variance = (spread + n0 * (clip / 2.0) ** 2) / (n + n0)
        mean = self._log_ratio_sums[0] / (n + n0)  # shrunk towards "no difference"
        z = (mean - np.log(cfg.selection_margin)) / np.sqrt(variance / (n + n0))
        self.confidence = float(ndtr(-z))
        self.weights_accel = self.confidence * np.array(
            [
                _accel_weight(self.score[:, part], cfg.selection_sharpness, cfg.selection_margin)
                * _accel_weight(s[:, part], cfg.selection_sharpness, cfg.selection_instant_ratio)
                for part in range(2)
            ]
        )

    def _combine(self) -> None:
        """Sets ``x`` and ``P`` to the constant model's, ``x_frame`` to the mixture."""
        a_v, a_w = self.weights_accel
        shift = twist_at_point_matrix(self.decoupling_point_m)
        at_c = (shift @ self.constant.x_frame, shift @ self.accel.x_frame)
        mixed = np.concatenate(
            [
                (1.0 - a_v) * at_c[0][:3] + a_v * at_c[1][:3],
                (1.0 - a_w) * at_c[0][3:] + a_w * at_c[1][3:],
            ]
        )
        self.x: F64 = self.constant.x.copy()
        """(6,) the interval-mean twist (v_o [m/s], w [rad/s]) for the pose UKF: the constant
        model's."""
        self.P: F64 = self.constant.P.copy()
        """(6, 6) its covariance."""
        self.x_frame: F64 = _twist_from_point(mixed, self.decoupling_point_m)
        """(6,) the twist (v_o [m/s], w [rad/s]) reported for the last frame: the two models'
        twists at the frame, mixed per part at the decoupling point (module docstring)."""


def _twist_from_point(twist_at_c: F64, point_m: F64) -> F64:
    """The spatial twist (6,) whose velocity at the body point ``point_m`` (3,) [m] is
    ``twist_at_c`` (6,) = (v_c [m/s], w [rad/s]): the inverse of
    :func:`~roft_sim.geometry.se3.twist_at_point_matrix`, ``v_o = v_c - w x c``."""
    out = twist_at_c.copy()
    out[:3] -= np.cross(twist_at_c[3:], point_m)
    return out


def _decoupling_point(cov: F64) -> F64:
    """The point ``c`` (3,) [m] whose velocity ``v_c = v_o + w x c`` has the least covariance
    with ``w`` under the twist covariance ``cov`` (6, 6) of (v_o, w): ``cov(v_c, w) = P_vw -
    [c]_x P_ww``, zero where ``[c]_x = P_vw P_ww^-1``; ``c`` is read from the skew-symmetric
    part of that matrix (its least-squares skew fit)."""
    M = cov[:3, 3:] @ np.linalg.inv(cov[3:, 3:])
    A = 0.5 * (M - M.T)
    return np.array([A[2, 1], A[0, 2], A[1, 0]])


def _whitened_parts(errors: F64, cov: F64) -> F64:
    """``(e_v^T C_vv^-1 e_v, e_w^T C_ww^-1 e_w)`` (P, 2) [dimensionless] of ``errors`` (P, 6) =
    (e_v [m/s], e_w [rad/s]) with the covariance ``cov`` (6, 6): each part whitened by its
    marginal covariance, at the scale the pixels determine it, also where a linear and an
    angular error compensate each other in the image (the full form ``e^T C^-1 e`` would not
    see those; on the tuning split it lowered e_v but raised e_w by 0.3-0.5 deg/s)."""
    e_v, e_w = errors[:, :3], errors[:, 3:]
    s_v = np.einsum("pi,pi->p", e_v, np.linalg.solve(cov[:3, :3], e_v.T).T)
    s_w = np.einsum("pi,pi->p", e_w, np.linalg.solve(cov[3:, 3:], e_w.T).T)
    return np.stack([s_v, s_w], axis=1)


_TINY = 1e-12
"""Floor of a whitened error before its logarithm [dimensionless]."""


def _accel_weight(score: F64, sharpness: float, margin: float) -> float:
    """``1 / (1 + (L_a / (margin L_c))^g)`` from ``score = (L_c, L_a)`` (2,), in logs (also
    for one update's scores ``(s_c, s_a)``)."""
    L_c, L_a = np.log(np.maximum(score, 1e-300))
    z = sharpness * (L_a - L_c - np.log(margin))
    return float(0.5 * (1.0 - np.tanh(0.5 * z)))


VelocityFilter = VelocityKF | SelectingVelocityKF
"""The velocity filters: the tracker reads ``x``, ``P``, ``x_frame``, ``updates``, ``step``."""


def make_velocity_filter(config: VelocityKFConfig, width_px: int | None = None) -> VelocityFilter:
    """The velocity filter ``config.motion_model`` asks for."""
    if config.motion_model == "auto":
        return SelectingVelocityKF(config, width_px)
    return VelocityKF(config, width_px, "constant")
