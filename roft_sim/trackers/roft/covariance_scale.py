"""Online variance-scale estimation for ROFT's reported covariance (issue 14, consistency).

A Kalman filter's gains do not change when its initial covariance P0, process noise Q and
measurement noise R are all multiplied by one factor ``s``: the means are the same and every
covariance is ``s`` times larger. The factor a filter's noise model is off by can therefore be
estimated from the data WITHOUT touching its estimates: the normalised innovation squared
``NIS = nu^T S^-1 nu`` of an m-dimensional measurement has mean ``s * m`` when the true noise
is ``s`` times the modelled one, so

    s_hat = (sum_i lambda^(n-i) NIS_i + m0) / (sum_i lambda^(n-i) m_i + m0)

(a forgetting-factor mean of NIS per measurement dimension, ``lambda = 1 - 1 / memory``,
starting from ``s = 1`` with the weight ``m0`` of one measurement) is an unbiased estimate of
``s`` that follows slow changes of the input quality, and ``s_hat * P`` is the covariance the
filter would report with a correctly scaled noise model.

ROFT's state has blocks measured by different sensors, each with its own mis-specification:
the pose (t, r), corrected by the detector's poses, and the velocity (v, w), corrected by the
flow-based twist. What is used, per block (each factor a :class:`ScaleEstimate`):

- velocity (v, w): the NIS of the twist itself does not work (the UKF's large process noise
  makes every twist look consistent), so the factor comes from the change of the twist
  measurement between consecutive frames normalised by the two measurements' noise
  (:func:`twist_difference`), floored at 1 (it cannot see errors that persist from frame to
  frame, so it may only inflate);
- velocity (v, w), persistent error: the twist's error that stays the same from frame to
  frame shifts the pose prediction by its integral since the last fused pose, so the part of
  a fused pose's innovation that the prediction's covariance, the excess and the configured pose
  noise leave unexplained, divided by the squared time since that pose, samples its variance
  (:func:`persistent_twist_samples`); a forgetting mean of the samples is added to the
  velocity blocks;
- pose (t, r): the poses' true noise is estimated by covariance matching (the NIS of the fused
  poses), the filter's own correction is replayed in Joseph form with that noise
  (:func:`pose_excess_after`), and the covariance it misses is added. The noise estimate
  starts from the adaptive gate's prior spread (:func:`detector_noise_prior`), and a pose
  (re)initialised from one detection carries that noise as its excess
  (:func:`restart_pose_excess`) until fused poses replace it.

The reported covariance is ``D C D + E`` (:func:`scaled_estimate_covariance`: ``D`` the
square roots of the factors per 3-D block, ``E`` the pose excess and the persistent twist
variances): a congruence plus a PSD term, so it stays symmetric positive semi-definite.

The innovations are those of the linearised measurement models at the predicted belief (the
UKF's own statistics to first order): position ``p``; orientation ``2 log(q_meas q^*)`` (left
tangent, as the UKF's covariance); twist ``(v - w x p, w)`` with the Jacobian
``[[I, [p]x, -[w]x, 0], [0, I, 0, 0]]`` over ``(v, w, p, dtheta)``. Only measurements the filter
fused count (a pose the outlier test or the gate rejected does not).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.so3 import quat_conjugate, quat_multiply, rotvec_from_quat
from roft_sim.trackers.roft.config import CovarianceScaleConfig, PoseUKFConfig
from roft_sim.trackers.roft.innovation_gate import InnovationSpread
from roft_sim.trackers.roft.pose_ukf import PoseBelief

F64 = NDArray[np.float64]

__all__ = [
    "ScaleEstimate",
    "twist_difference",
    "BlockScales",
    "normalised_innovation_squared",
    "pose_innovation",
    "scaled_estimate_covariance",
    "pose_excess_after",
    "twist_noise",
    "detector_noise_prior",
    "restart_pose_excess",
    "persistent_twist_samples",
]


@dataclass(frozen=True, slots=True)
class ScaleEstimate:
    """A forgetting-factor mean of NIS per measurement dimension (immutable, so it can be
    stored per frame and replayed with the filter); the persistent twist variances use it as a
    forgetting mean of variance samples (one per fused pose, ``dof = 1``)."""

    nis_sum: float
    """Forgetting-weighted sum of NIS values (plus the prior's weight)."""
    dof_sum: float
    """Forgetting-weighted sum of the measurement dimensions (plus the prior's weight)."""

    @staticmethod
    def prior(dof: float) -> ScaleEstimate:
        """Factor 1 with the weight of one ``dof``-dimensional measurement."""
        return ScaleEstimate(float(dof), float(dof))

    @property
    def factor(self) -> float:
        """The variance scale: actual / modelled innovation variance (1 = consistent)."""
        return self.nis_sum / self.dof_sum

    def updated(self, nis: float, dof: int, memory: float) -> ScaleEstimate:
        """With one more measurement's NIS; ``memory`` [measurements] sets the forgetting
        factor ``1 - 1 / memory`` (the prior is forgotten at the same rate). A non-finite NIS
        is ignored."""
        if not np.isfinite(nis):
            return self
        keep = 1.0 - 1.0 / memory
        return ScaleEstimate(keep * self.nis_sum + float(nis), keep * self.dof_sum + float(dof))


@dataclass(frozen=True, slots=True)
class BlockScales:
    """The variance scales of the four 3-D blocks of the estimate (position, rotation, linear
    and angular velocity), the pose excess, and the persistent twist error."""

    t: ScaleEstimate
    r: ScaleEstimate
    v: ScaleEstimate
    w: ScaleEstimate
    pose_excess: F64
    """(6, 6) the covariance of the pose (t, r) the filter's
    own misses (its true error covariance minus its covariance), from the last fused pose, or
    from the detector-noise prior when the pose was (re)initialised from one detection."""
    v_persistent: ScaleEstimate = ScaleEstimate(0.0, 1.0)
    """Forgetting mean of the per-axis variance [(m/s)^2] of the linear velocity's error that
    persists between poses (:func:`persistent_twist_samples`; starts at 0)."""
    w_persistent: ScaleEstimate = ScaleEstimate(0.0, 1.0)
    """The same for the angular velocity [(rad/s)^2]."""
    since_pose_s: float = 0.0
    """Time from the capture of the last fused (or initialising) pose to this frame [s]."""

    @staticmethod
    def initial(t: ScaleEstimate | None = None, r: ScaleEstimate | None = None) -> BlockScales:
        """Every factor 1 with the weight of one measurement (unless the pose-noise factors
        ``t`` and ``r`` are given, e.g. :func:`detector_noise_prior`), no excess, no persistent
        twist error."""
        one = ScaleEstimate.prior(3)
        return BlockScales(
            t if t is not None else one, r if r is not None else one, one, one, np.zeros((6, 6))
        )

    def factors(self) -> F64:
        """(4,) the factors of (t, r, v, w)."""
        return np.array([self.t.factor, self.r.factor, self.v.factor, self.w.factor])

    def pose_noise_factors(self, config: CovarianceScaleConfig) -> tuple[float, float]:
        """The pose noise's (t, r) factors as used: clipped to ``[1, max_factor]`` (the
        configured pose noise is a floor)."""
        f = np.clip([self.t.factor, self.r.factor], 1.0, config.max_factor)
        return float(f[0]), float(f[1])


def detector_noise_prior(
    spread: InnovationSpread, config: PoseUKFConfig
) -> tuple[ScaleEstimate, ScaleEstimate]:
    """The pose-noise factors (t, r) before any pose innovation was seen: the adaptive gate's
    prior innovation spread (``gate.prior_translation_m``, ``gate.prior_rotation_deg``, per
    axis) in units of the configured pose noise (mean of ``meas_cov_x``, ``meas_cov_q``), with
    the gate's prior weight (``gate.prior_weight`` poses of 3 dimensions each). Conservative:
    the spread of an innovation bounds the noise of the pose in it. Covariance matching on the
    fused poses' innovations replaces it as they accumulate (forgotten at the rate of
    ``covariance_scale.memory_measurements``)."""
    weight = 3.0 * spread.weight
    f_t = spread.translation_m2 / float(np.mean(config.meas_cov_x))
    f_r = spread.rotation_rad2 / float(np.mean(config.meas_cov_q))
    return ScaleEstimate(f_t * weight, weight), ScaleEstimate(f_r * weight, weight)


def _psd_part(A: F64) -> F64:
    """The positive semi-definite part of a symmetric matrix (negative eigenvalues set to 0)."""
    A = 0.5 * (A + A.T)
    values, vectors = np.linalg.eigh(A)
    out: F64 = (vectors * np.maximum(values, 0.0)) @ vectors.T
    return 0.5 * (out + out.T)


def restart_pose_excess(pose_cov: F64, noise: F64, noise_scale: tuple[float, float]) -> F64:
    """The excess (6, 6) of a pose (re)initialised from one detection: the filter believes
    ``pose_cov`` (its (t, r) block, e.g. the configured initial covariance) while the pose's
    error is the detection's, ``noise`` (the configured pose noise (6, 6)) with its t and r
    blocks multiplied by ``noise_scale``; the excess is the positive semi-definite part of the
    difference (the reported pose block ``P + excess`` covers both)."""
    r_hat = noise * np.repeat(np.asarray(noise_scale, dtype=np.float64), 3)[:, None]
    return _psd_part(r_hat - np.asarray(pose_cov, dtype=np.float64))


def persistent_twist_samples(
    nu: F64, predicted: F64, excess: F64, noise: F64, gap_s: float
) -> tuple[float, float]:
    """Per-axis variance samples of the twist's error that persists between two poses, from a
    fused pose's innovation: linear [(m/s)^2] and angular [(rad/s)^2].

    The pose prediction at the capture frame integrates the twist over the time ``gap_s`` [s]
    since the last fused pose, so an error ``e`` of the twist that stays the same over that
    time moves the prediction by ``e * gap_s``, on top of what the filter's predicted
    covariance, the excess and the pose noise explain:
    ``E[|nu_b|^2] = tr(P_b + E_b + R_b) + gap_s^2 tr(Cov e_b)``. Each block's sample is
    ``max(0, |nu_b|^2 - tr(P_b + E_b + R_b)) / (3 gap_s^2)`` (never negative: a lucky
    innovation says nothing about the twist). An error of the twist that changes from frame to
    frame averages out in the integral; the twist-change factor covers that part.

    Args:
        nu: (6,) innovation (position [m], rotation vector [rad]).
        predicted: (6, 6) the filter's predicted (t, r) covariance.
        excess: (6, 6) the pose excess before this pose.
        noise: (6, 6) the pose noise to attribute to the detection.
        gap_s: time since the previous fused pose [s]; NaN samples when not positive.
    """
    if not gap_s > 0:
        return float("nan"), float("nan")
    explained = np.asarray(predicted) + np.asarray(excess) + np.asarray(noise)
    out = []
    for block in (slice(0, 3), slice(3, 6)):
        spare = float(nu[block] @ nu[block]) - float(np.trace(explained[block, block]))
        out.append(max(spare, 0.0) / (3.0 * gap_s**2))
    return out[0], out[1]


def normalised_innovation_squared(nu: F64, S: F64) -> float:
    """``nu^T S^-1 nu`` of an innovation ``(m,)`` with covariance ``(m, m)`` (NaN if singular)."""
    try:
        return float(nu @ np.linalg.solve(S, nu))
    except np.linalg.LinAlgError:
        return float("nan")


def _rotvec_between(q_a: F64, q_b: F64) -> F64:
    """``2 log(q_a ⊗ q_b^*)`` [rad] (3,): the left rotation taking q_b to q_a."""
    return rotvec_from_quat(quat_multiply(q_a, quat_conjugate(q_b)))


def twist_difference(
    twist: F64, noise: F64, previous_twist: F64, previous_noise: F64
) -> tuple[F64, F64]:
    """The change (6,) between two consecutive twist measurements and the covariance (6, 6) it
    would have if the twist did not change: the sum of their noises.

    ``E[d d^T] = R_k + R_(k-1) + Cov(x_k - x_(k-1))``: the statistic over-estimates the noise
    scale by the motion's change over one frame (conservative), and sees every error of the
    twist that is not the same in consecutive frames."""
    d = np.asarray(twist, dtype=np.float64) - np.asarray(previous_twist, dtype=np.float64)
    S = np.asarray(noise, dtype=np.float64) + np.asarray(previous_noise, dtype=np.float64)
    return d, 0.5 * (S + S.T)


def twist_noise(config: PoseUKFConfig, twist_cov: F64 | None) -> F64:
    """(6, 6) the UKF's noise of a twist measurement: ``diag(meas_cov_v, meas_cov_w)`` plus
    ``twist_cov`` (the velocity KF's covariance) when given."""
    R = np.diag(np.concatenate([config.meas_cov_v, config.meas_cov_w]))
    if twist_cov is not None:
        R = R + np.asarray(twist_cov, dtype=np.float64)
    return R


def pose_innovation(
    belief: PoseBelief, p_m: F64, q_wxyz: F64, config: PoseUKFConfig
) -> tuple[F64, F64]:
    """Innovation (6,) (position [m], left rotation vector [rad]) and its covariance (6, 6) of
    a pose measurement at ``belief``, with the UKF's pose noise ``diag(meas_cov_x, meas_cov_q)``."""
    nu = np.concatenate([p_m - belief.x[6:9], _rotvec_between(q_wxyz, belief.q)])
    S = belief.P[6:12, 6:12] + np.diag(np.concatenate([config.meas_cov_x, config.meas_cov_q]))
    return nu, 0.5 * (S + S.T)


def pose_excess_after(
    excess: F64, predicted: F64, noise: F64, noise_scale: tuple[float, float]
) -> F64:
    """The excess covariance (6, 6) after a pose correction with the filter's gain.

    The filter fuses a pose with ``K = P (P + R)^-1`` (``P`` = ``predicted``, its (t, r)
    block; ``R`` = ``noise``, the configured pose noise) and believes ``P+ = (I - K) P``. When
    its prediction's true error covariance is ``P + excess`` and the pose's is ``R_hat`` (the
    configured R with its t and r blocks multiplied by ``noise_scale``), the true covariance
    after the same correction is ``(I - K)(P + excess)(I - K)^T + K R_hat K^T`` (the Joseph
    form, valid for any gain); the new excess is the difference.
    """
    K = predicted @ np.linalg.inv(predicted + noise)
    I_K = np.eye(6) - K
    r_hat = noise * np.repeat(np.asarray(noise_scale, dtype=np.float64), 3)[:, None]
    true = I_K @ (predicted + excess) @ I_K.T + K @ r_hat @ K.T
    believed = I_K @ predicted
    out: F64 = true - 0.5 * (believed + believed.T)
    return 0.5 * (out + out.T)


def scaled_estimate_covariance(
    covariance: F64, scales: BlockScales, config: CovarianceScaleConfig
) -> F64:
    """``D C D`` of a covariance (12, 12) in ``ESTIMATE_COVARIANCE_ORDER`` (t, r, v, w), with
    ``D = diag(sqrt(s_t) I3, sqrt(s_r) I3, sqrt(s_v) I3, sqrt(s_w) I3)``, the pose factors
    clipped to ``[min_factor, max_factor]``, the velocity factors to ``[1, max_factor]``: the
    twist-change statistic is blind to errors that persist from frame to frame, so it may only
    inflate the filter's own velocity covariance, never shrink it. The pose block is not
    scaled: its excess is added to it; the persistent twist error's variance (per axis) is
    added to the diagonal of the (v, w) blocks."""
    lower = np.array([config.min_factor, config.min_factor, 1.0, 1.0])
    s = np.clip(scales.factors(), lower, config.max_factor)
    s[:2] = 1.0
    d = np.repeat(np.sqrt(s), 3)
    out: F64 = covariance * d[:, None] * d[None, :]
    out[:6, :6] += scales.pose_excess
    persistent = [scales.v_persistent.factor, scales.w_persistent.factor]
    out[6:, 6:] += np.diag(np.repeat(persistent, 3))
    return 0.5 * (out + out.T)  # exactly symmetric (the products round differently)
