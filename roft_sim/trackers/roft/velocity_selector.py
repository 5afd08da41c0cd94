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
   (the constant model's robust weights and flow noise). Each prediction error
   ``e_i = m_ls - p_i`` is whitened by that same covariance, the linear and the angular part
   each by its marginal block: ``s_i = e_v^T P_ls[v, v]^-1 e_v + e_w^T P_ls[w, w]^-1 e_w``, so
   both models are judged by one metric that neither model's own covariance can flatter.
3. ``L_i`` is the exponentially forgetting mean of ``s_i`` over ``selection_memory`` updates;
   the weight of the constant-acceleration model is ``e / (1 + (L_a / (m L_c))^g)`` with
   ``m = selection_margin``, ``g = selection_sharpness`` and the evidence factor
   ``e = 1 - (1 - 1 / selection_memory)^n`` after ``n`` scores (the first score is taken at the
   second update, when both models have predicted): the ratio of a few scores is noise.

Only the REPORTED twist (``x_frame``, the twist at k) is mixed: the weighted mean of the two
models' twists at k, one weight for all six components. The pose UKF keeps the constant
model's interval mean and covariance (``x``, ``P``): with ground-truth inputs the
constant-acceleration model's interval mean did not improve the poses (TUM room1 ADD-AUC 92.6 %
either way), and with the default inputs mixing it in cost ADD-AUC (72.0 -> 70.6 % on TUM room1
with an earlier weight; docs/roft.md).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray

from roft_sim.trackers.roft.config import VelocityKFConfig
from roft_sim.trackers.roft.velocity_kf import FlowMeasurement, VelocityKF

F64 = NDArray[np.float64]

__all__ = ["SelectingVelocityKF", "VelocityFilter", "make_velocity_filter"]


class SelectingVelocityKF:
    """The constant and the constant-acceleration :class:`VelocityKF`, mixed by a prequential
    weight; the same attributes the tracker reads from a :class:`VelocityKF`."""

    def __init__(self, config: VelocityKFConfig, width_px: int | None = None):
        """Args:
        config: the settings (``motion_model = "auto"``); each model gets them with its own
            ``motion_model``.
        width_px: image width [px] for the resolution scaling of the flow noise.
        """
        self._config = config
        self.constant = VelocityKF(dataclasses.replace(config, motion_model="constant"), width_px)
        """The constant-twist model (the reference's filter)."""
        self.accel = VelocityKF(
            dataclasses.replace(config, motion_model="constant_acceleration"), width_px
        )
        """The constant-acceleration model."""
        self.reset()

    def reset(self) -> None:
        self.constant.reset()
        self.accel.reset()
        self._score_sum = np.zeros(2)
        self._score_weight = 0.0
        self.score: F64 = np.zeros(2)
        """(2,) running mean whitened prediction errors ``(L_c, L_a)`` of the constant and the
        constant-acceleration model [dimensionless]."""
        self.weight_accel = 0.0
        """The constant-acceleration model's weight in [0, 1] (0 until both models have been
        scored)."""
        self._combine()

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
        scored = self.constant.updates > 0
        predictions = (
            self.constant.predicted_interval_mean(t_s, dt_s),
            self.accel.predicted_interval_mean(t_s, dt_s),
        )
        if not self.constant.step(measurement, frames=frames, t_s=t_s, dt_s=dt_s):
            return False
        self.accel.step(measurement, frames=frames, t_s=t_s, dt_s=dt_s)
        fit = self.constant.fit
        if scored and fit is not None:
            m_ls, info_ls = fit
            s = np.array([_whitened_error(m_ls - p, info_ls) for p in predictions])  # (2,)
            keep = 1.0 - 1.0 / self._config.selection_memory
            self._score_sum = keep * self._score_sum + s
            self._score_weight = keep * self._score_weight + 1.0
            self.score = self._score_sum / self._score_weight
            # the ratio of a few scores is noise: shrink the weight by the evidence so far,
            # 1 - (1 - 1/memory)^n after n scores (the reference's model until then)
            evidence = self._score_weight / self._config.selection_memory
            self.weight_accel = evidence * _accel_weight(
                self.score, self._config.selection_sharpness, self._config.selection_margin
            )
        self._combine()
        return True

    def _combine(self) -> None:
        """Sets ``x`` and ``P`` to the constant model's, ``x_frame`` to the weighted mixture."""
        w = self.weight_accel
        self.x: F64 = self.constant.x.copy()
        """(6,) the interval-mean twist (v_o [m/s], w [rad/s]) for the pose UKF: the constant
        model's."""
        self.P: F64 = self.constant.P.copy()
        """(6, 6) its covariance."""
        self.x_frame: F64 = (1.0 - w) * self.constant.x_frame + w * self.accel.x_frame
        """(6,) the twist reported for the last frame: the weighted mean of the two models'
        twists at the frame (one weight for all six components: ``v_o`` is the velocity of
        the body point at the camera origin, so a linear part from one model and an angular
        part from the other would not describe one motion)."""


def _whitened_error(error: F64, info: F64) -> float:
    """``e_v^T C_vv^-1 e_v + e_w^T C_ww^-1 e_w`` [dimensionless] for ``error`` (6,) = (e_v
    [m/s], e_w [rad/s]), ``C`` the inverse of the information ``info`` (6, 6): each part
    whitened by its marginal covariance. Each part counts on its own, at the scale the pixels
    determine it, also where a linear and an angular error compensate each other in the image
    (the full form ``e^T info e`` would not see those; on TUNING it lowered e_v but raised
    e_w by 0.3-0.5 deg/s, docs/roft.md)."""
    cov = np.linalg.inv(info)
    e_v, e_w = error[:3], error[3:]
    return float(e_v @ np.linalg.solve(cov[:3, :3], e_v) + e_w @ np.linalg.solve(cov[3:, 3:], e_w))


def _accel_weight(score: F64, sharpness: float, margin: float) -> float:
    """``1 / (1 + (L_a / (margin L_c))^g)`` from ``score = (L_c, L_a)``, computed in logs."""
    L_c, L_a = np.log(np.maximum(score, 1e-300))
    z = sharpness * (L_a - L_c - np.log(margin))
    return float(0.5 * (1.0 - np.tanh(0.5 * z)))


VelocityFilter = VelocityKF | SelectingVelocityKF
"""The velocity filters: the tracker reads ``x``, ``P``, ``x_frame``, ``updates``, ``step``."""


def make_velocity_filter(config: VelocityKFConfig, width_px: int | None = None) -> VelocityFilter:
    """The velocity filter ``config.motion_model`` asks for."""
    if config.motion_model == "auto":
        return SelectingVelocityKF(config, width_px)
    return VelocityKF(config, width_px)
