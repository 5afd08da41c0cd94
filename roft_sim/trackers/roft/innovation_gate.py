"""The adaptive pose gate: a chi-square test of a pose's innovation against the spread of the
innovations the gate accepted before (``gate.adaptive``; docs/roft.md).

The innovation of a pose captured at frame c is its difference from the filter's prediction at
c: ``nu_p = p_pose - p_pred`` [m] and ``nu_r = 2 log(q_pose ⊗ q_pred^*)`` [rad] (left rotation
vector, camera frame). Each is tested as a 3-D isotropic Gaussian::

    |nu|^2 > chi2_3^-1(probability) * (s^2 + tr(P_pred block) / 3)

where ``s^2`` is an exponentially weighted mean of the per-axis squared innovations ``|nu|^2 / 3``
of the poses the test accepted (starting from the prior ``prior_*`` with weight
``prior_weight``), and ``P_pred`` the predicted covariance of the filter (its position or
rotation block), so the gate widens while the filter only predicts. ``s^2`` estimates the
innovation variance from the data (covariance matching): on a sequence where the detector is
off by 15 degrees and the flow-integrated orientation drifts, the gate follows, and a
180-degree flip or a 30 cm jump still stands out. Poses accepted only because the rejection
streak ran out (``max_consecutive_rejections``) do not enter ``s^2``.

The spread is per typical prediction horizon: a pose captured
``d`` frames after the last pose that passed is tested against ``s^2 max(1, d / g)``, ``g`` the
running mean of the frames between passing poses, and enters ``s^2`` divided by that factor. The
filter's drift between poses grows with the time it only predicts (a random walk's variance in
proportion to it), so after a long stretch without poses (a blackout, a detector that lost the
object) the gate does not lock out the detections that would correct a filter that drifted.

Until one pose has passed the test the track is not confirmed: a pose that fails then
re-initialises the pose instead of being gated, because the pose that initialised the filter
may itself be the outlier (a flipped first detection would otherwise lock out the correct poses
that follow until the rejection streak runs out).

The spread is a value stored per frame with the beliefs, so a replay from a delayed pose's
capture frame restores it exactly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.so3 import quat_angle
from roft_sim.trackers.roft.config import PoseGateConfig
from roft_sim.trackers.roft.medians import chi2_quantile

F64 = NDArray[np.float64]

__all__ = [
    "InnovationSpread",
    "initial_spread",
    "squared_innovations",
    "horizon_factor",
    "adaptive_gate_test",
]


@dataclass(frozen=True, slots=True)
class InnovationSpread:
    """Running per-axis variance of the accepted pose innovations."""

    translation_m2: float
    """Mean of ``|nu_p|^2 / 3`` [m^2]."""
    rotation_rad2: float
    """Mean of ``|nu_r|^2 / 3`` [rad^2]."""
    weight: float
    """Accumulated weight (prior plus decayed accepted poses)."""
    passed: int = 0
    """Poses that passed the test so far (0: the track is not confirmed yet)."""
    last_frame: int = -1
    """Capture frame of the last pose that passed (-1: none yet)."""
    gap_frames: float = 0.0
    """Running mean of the frames between the capture frames of consecutive passing poses (time
    constant ``memory_poses``; 0 until two poses have passed)."""


def initial_spread(gate: PoseGateConfig) -> InnovationSpread:
    """The prior: ``prior_translation_m``, ``prior_rotation_deg`` with ``prior_weight``."""
    return InnovationSpread(
        translation_m2=gate.prior_translation_m**2,
        rotation_rad2=math.radians(gate.prior_rotation_deg) ** 2,
        weight=gate.prior_weight,
    )


@lru_cache(maxsize=8)
def _chi2_3(probability: float) -> float:
    return chi2_quantile(probability, 3)


def squared_innovations(
    p_pred_m: F64, q_pred_wxyz: F64, p_m: F64, q_wxyz: F64
) -> tuple[float, float]:
    """``(|nu_p|^2 [m^2], |nu_r|^2 [rad^2])`` of a pose ``(p_m (3,), q_wxyz (4,))`` against the
    prediction ``(p_pred_m (3,), q_pred_wxyz (4,))``, camera frame."""
    d_t = float(np.sum((np.asarray(p_m) - np.asarray(p_pred_m)) ** 2))
    d_r = float(quat_angle(q_wxyz, q_pred_wxyz)) ** 2
    return d_t, d_r


def horizon_factor(gate: PoseGateConfig, spread: InnovationSpread, capture_k: int | None) -> float:
    """``max(1, d / g)`` for a pose captured at ``capture_k``, ``d`` frames after the last
    passing pose and ``g`` the mean gap between passing poses; 1 before two poses have passed
    or without a capture frame."""
    if capture_k is None or spread.last_frame < 0 or spread.gap_frames <= 0.0:
        return 1.0
    return max(1.0, (capture_k - spread.last_frame) / spread.gap_frames)


def adaptive_gate_test(
    gate: PoseGateConfig,
    spread: InnovationSpread,
    squared: tuple[float, float],
    predicted_variance: tuple[float, float],
    capture_k: int | None = None,
) -> tuple[bool, InnovationSpread]:
    """Whether the innovation passes the test, and the spread after it.

    Args:
        gate: the gate's settings (``probability``, ``memory_poses``).
        spread: the spread before this pose.
        squared: ``(|nu_p|^2 [m^2], |nu_r|^2 [rad^2])`` (:func:`squared_innovations`).
        predicted_variance: mean diagonal of the filter's predicted position [m^2] and rotation
            [rad^2] covariance blocks.
        capture_k: the pose's capture frame (for the horizon scaling; None: no scaling).

    Returns:
        ``(passes, spread)``: the spread is updated with the innovation (divided by the
        horizon factor) when it passes and unchanged otherwise.
    """
    limit = _chi2_3(gate.probability)
    factor = horizon_factor(gate, spread, capture_k)
    d_t, d_r = squared
    passes = d_t <= limit * (factor * spread.translation_m2 + predicted_variance[0]) and (
        d_r <= limit * (factor * spread.rotation_rad2 + predicted_variance[1])
    )
    if not passes:
        return False, spread
    weight = (1.0 - 1.0 / gate.memory_poses) * spread.weight + 1.0
    last_frame, gap = spread.last_frame, spread.gap_frames
    if capture_k is not None:
        if last_frame >= 0 and capture_k > last_frame:
            gaps = min(float(spread.passed), gate.memory_poses)  # gaps seen, this one included
            gap += (capture_k - last_frame - gap) / max(gaps, 1.0)
        last_frame = max(last_frame, capture_k)
    d_t, d_r = d_t / factor, d_r / factor
    return True, InnovationSpread(
        translation_m2=spread.translation_m2 + (d_t / 3.0 - spread.translation_m2) / weight,
        rotation_rad2=spread.rotation_rad2 + (d_r / 3.0 - spread.rotation_rad2) / weight,
        weight=weight,
        passed=spread.passed + 1,
        last_frame=last_frame,
        gap_frames=gap,
    )
