"""``naive-delay``: a constant-velocity pose UKF that fuses every pose at the frame it ARRIVES, as
if it had been captured then (the classic mistake with delayed detections).

An independent tracker class (it used to be ROFT's class with replay switched off, an ablation):
it keeps one running belief, no buffers and no replay. It shares only the quaternion UKF's
predict/correct functions (:class:`roft_sim.trackers.roft.pose_ukf.PoseUKF`), ROFT's pose gate
test (:func:`~roft_sim.trackers.roft.pose_ukf.gate_rejects`) and the settings of
``pose-only-ukf`` (:class:`PoseOnlyUkfConfig`: noise, the pose gate), so that the two baselines
differ in the delay handling alone. Per frame k: predict over the frame's time step, then correct
with each pose arriving at k (in ``detection_id`` order) unless the gate rejects it. The first
valid pose initialises the filter (zero velocity, the initial covariance) at its arrival frame;
a given initial ``Estimate`` initialises it with its own covariance where it has one.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.so3 import quat_from_matrix
from roft_sim.records import Estimate, Observation
from roft_sim.trackers.base import Tracker, TrackerContext
from roft_sim.trackers.baselines.pose_only import PoseOnlyUkfConfig
from roft_sim.trackers.roft.pose_ukf import (
    PoseBelief,
    PoseUKF,
    belief_from_estimate,
    estimate_from_belief,
    gate_rejects,
)

__all__ = ["NaiveDelayTracker", "create_naive_delay"]

F64 = NDArray[np.float64]


class NaiveDelayTracker:
    """Pose-only UKF that treats every delivered pose as current (no delay handling)."""

    def __init__(self, config: PoseOnlyUkfConfig, context: TrackerContext):
        self._config = config
        self._fps = context.fps
        self._ukf = PoseUKF(config.pose)
        self.reset(None)

    @property
    def config(self) -> PoseOnlyUkfConfig:
        return self._config

    def reset(self, initial: Estimate | None) -> None:
        """Starts a new sequence; ``initial`` (pose and velocity at frame ``initial.k``) or, when
        None, the first pose that arrives initialises the filter."""
        self._belief: PoseBelief | None = None
        self._initial = initial
        self._last_k: int | None = None
        self._last_t: float | None = None
        self._streak = 0
        self._seen: set[int] = set()

    def step(self, observation: Observation) -> Estimate:
        """Consumes camera frame ``observation.k``; poses are fused as if captured now."""
        k = observation.k
        if self._last_k is not None and k <= self._last_k:
            raise ValueError(
                f"observations must come in increasing k; got k={k} after {self._last_k}"
            )
        dt = (
            observation.t_s - self._last_t
            if self._last_t is not None and observation.t_s > self._last_t
            else 1.0 / self._fps
        )
        self._last_k, self._last_t = k, observation.t_s
        if self._belief is None and self._initial is not None:
            self._belief = belief_from_estimate(self._ukf, self._initial)
            if self._initial.k == k:
                dt = 0.0
        accepted: list[int] = []
        rejected: list[int] = []
        dropped: list[int] = []
        belief = self._belief
        if belief is not None and dt > 0:
            belief = self._ukf.predict(belief, dt)
        for det in sorted(observation.poses, key=lambda d: d.detection_id):
            T = np.asarray(det.T_cam_obj, dtype=np.float64)
            if not np.isfinite(T).all() or det.detection_id in self._seen:
                dropped.append(det.detection_id)
                continue
            self._seen.add(det.detection_id)
            p, q = T[:3, 3].copy(), quat_from_matrix(T[:3, :3])
            if belief is None:  # the first pose initialises at its arrival frame
                belief = self._ukf.predict(self._ukf.initial_belief(p, q), dt)
                belief = self._ukf.correct(belief, p_meas_m=p, q_meas_wxyz=q)
                accepted.append(det.detection_id)
                continue
            if gate_rejects(self._config.gate, belief, p, q, self._streak):
                self._streak += 1
                rejected.append(det.detection_id)
                continue
            self._streak = 0
            belief = self._ukf.correct(belief, p_meas_m=p, q_meas_wxyz=q)
            accepted.append(det.detection_id)
        self._belief = belief
        diagnostics: dict[str, float | int | str] = {"poses_gated": len(rejected)}
        if belief is None:
            return Estimate.invalid(k, dropped_pose_ids=tuple(dropped), diagnostics=diagnostics)
        return estimate_from_belief(
            k,
            belief,
            accepted_pose_ids=tuple(accepted),
            rejected_pose_ids=tuple(rejected),
            dropped_pose_ids=tuple(dropped),
            diagnostics=diagnostics,
        )


def create_naive_delay(config: PoseOnlyUkfConfig, context: TrackerContext) -> Tracker:
    """The pose-only UKF that fuses every delayed pose at its arrival frame (its own class,
    :class:`NaiveDelayTracker`)."""
    return NaiveDelayTracker(config, context)
