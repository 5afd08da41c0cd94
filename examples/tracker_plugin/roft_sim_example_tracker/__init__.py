"""An example tracker plugin for roft_sim: the newest detector pose, extrapolated to now.

It keeps the two detector poses with the newest capture frames, estimates the object's velocity
from them by finite differences, and reports the newest pose moved forward by that velocity from
its capture time to the current frame (so a pose delivered 6 frames late is not shown where the
object was 6 frames ago). The whole plugin interface is used: a frozen config dataclass (loadable
from TOML), a factory ``(config, context) -> tracker``, ``reset``/``step`` returning
:class:`~roft_sim.records.Estimate`, and a :class:`~roft_sim.trackers.TrackerSpec` registered in
``pyproject.toml`` under the entry-point group ``roft_sim.trackers``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roft_sim.errors import ConfigError
from roft_sim.geometry import matrix_from_rotvec, rotvec_from_matrix
from roft_sim.records import Estimate, Observation
from roft_sim.trackers import TrackerContext, TrackerSpec

__all__ = ["ExtrapolateConfig", "ExtrapolatingTracker", "SPEC"]


@dataclass(frozen=True, slots=True, kw_only=True)
class ExtrapolateConfig:
    """Settings of the extrapolating tracker."""

    max_extrapolation_frames: int = 12
    """Extrapolate at most this many frames past the newest capture; hold the pose after that."""

    def __post_init__(self) -> None:
        if self.max_extrapolation_frames < 0:
            raise ConfigError(
                f"max_extrapolation_frames must be >= 0, got {self.max_extrapolation_frames}"
            )


class ExtrapolatingTracker:
    """Newest pose moved forward with the finite-difference velocity of the two newest poses."""

    def __init__(self, config: ExtrapolateConfig, context: TrackerContext):
        self._config = config
        self._fps = context.fps
        self.reset(None)

    def reset(self, initial: Estimate | None) -> None:
        self._poses: list[tuple[int, np.ndarray]] = []  # (capture_k, T_cam_obj), newest last
        if initial is not None:
            self._poses.append((initial.k, np.asarray(initial.T_cam_obj, dtype=np.float64)))

    def step(self, observation: Observation) -> Estimate:
        k = observation.k
        accepted, dropped = [], []
        for det in observation.poses:
            T = np.asarray(det.T_cam_obj, dtype=np.float64)
            newest = self._poses[-1][0] if self._poses else -(10**9)
            if det.capture_k <= newest or det.capture_k > k or not np.isfinite(T).all():
                dropped.append(det.detection_id)
                continue
            self._poses = [*self._poses[-1:], (det.capture_k, T)]
            accepted.append(det.detection_id)
        ids = {"accepted_pose_ids": tuple(accepted), "dropped_pose_ids": tuple(dropped)}
        if not self._poses:
            return Estimate.invalid(k, **ids)
        c1, T1 = self._poses[-1]
        v, w = np.zeros(3), np.zeros(3)
        if len(self._poses) == 2:
            c0, T0 = self._poses[0]
            dt = (c1 - c0) / self._fps
            v = (T1[:3, 3] - T0[:3, 3]) / dt
            w = rotvec_from_matrix(T1[:3, :3] @ T0[:3, :3].T) / dt
        ahead = min(k - c1, self._config.max_extrapolation_frames) / self._fps
        T = np.eye(4)
        T[:3, :3] = matrix_from_rotvec(w * ahead) @ T1[:3, :3]
        T[:3, 3] = T1[:3, 3] + v * ahead
        return Estimate(k=k, T_cam_obj=T, v_obj_mps=v, w_radps=w, **ids)


SPEC = TrackerSpec(
    name="extrapolate-latest",
    description="example plugin: newest detector pose extrapolated to the current frame",
    config_type=ExtrapolateConfig,
    factory=ExtrapolatingTracker,
)
