"""The detector alone: hold the newest pose until a newer one arrives (the paper's "DOPE" rows).

``detector-hold`` sees detections through the fault/delay stream, so at frame k it reports the
last delivered pose, which shows the object where it was when the network saw it (the paper's
"DOPE" baseline). ``detector-ideal`` is the same tracker registered with
``detection_mode = "ideal"``: the harness delivers every frame's own detection at that frame
("DOPE (ideal)"), and a frame without a detection holds the previous one.

"Newest" means the largest ``capture_k`` among the poses received; a pose captured before the
one held (out-of-order delivery, a stale or duplicated result) never replaces it and is reported
in ``dropped_pose_ids``. Velocity: by default the finite difference of the two newest held poses
over their capture times (``capture_k / fps``), held with them (``velocity = "zero"`` reports
zero). The estimate is invalid until the first pose arrives, unless ``reset`` got one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, TypedDict

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.so3 import rotvec_from_matrix
from roft_sim.records import Estimate, Observation
from roft_sim.trackers.base import TrackerContext

F64 = NDArray[np.float64]

__all__ = ["DetectorHoldConfig", "DetectorHoldTracker"]


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectorHoldConfig:
    """Settings of the hold-last-detection baselines."""

    velocity: Literal["finite_difference", "zero"] = "finite_difference"
    """Reported velocity: finite difference of the two newest held poses (by capture), or zero."""


@dataclass(frozen=True, slots=True)
class _Held:
    capture_k: int
    T_cam_obj: F64
    detection_id: int


class _PoseIds(TypedDict):
    accepted_pose_ids: tuple[int, ...]
    dropped_pose_ids: tuple[int, ...]


class DetectorHoldTracker:
    """Reports the newest received detector pose (see module docstring)."""

    def __init__(self, config: DetectorHoldConfig, context: TrackerContext):
        self._config = config
        self._fps = context.fps
        self.reset(None)

    def reset(self, initial: Estimate | None) -> None:
        self._held: _Held | None = None
        self._previous: _Held | None = None
        self._initial = initial

    def _velocity(self) -> tuple[F64, F64]:
        a, b = self._previous, self._held
        if self._config.velocity == "zero" or a is None or b is None:
            return np.zeros(3), np.zeros(3)
        dt = (b.capture_k - a.capture_k) / self._fps
        v = (b.T_cam_obj[:3, 3] - a.T_cam_obj[:3, 3]) / dt
        w = rotvec_from_matrix(b.T_cam_obj[:3, :3] @ a.T_cam_obj[:3, :3].T) / dt
        return v, w

    def step(self, observation: Observation) -> Estimate:
        accepted: list[int] = []
        dropped: list[int] = []
        for det in observation.poses:
            T = np.asarray(det.T_cam_obj, dtype=np.float64)
            newer = self._held is None or det.capture_k > self._held.capture_k
            if not np.isfinite(T).all() or not newer or det.capture_k > observation.k:
                dropped.append(det.detection_id)
                continue
            self._previous, self._held = self._held, _Held(det.capture_k, T, det.detection_id)
            accepted.append(det.detection_id)
        ids: _PoseIds = {"accepted_pose_ids": tuple(accepted), "dropped_pose_ids": tuple(dropped)}
        if self._held is None:
            if self._initial is None:
                return Estimate.invalid(observation.k, **ids)
            return Estimate(
                k=observation.k,
                T_cam_obj=np.asarray(self._initial.T_cam_obj, dtype=np.float64).copy(),
                v_obj_mps=np.zeros(3),
                w_radps=np.zeros(3),
                **ids,
            )
        v, w = self._velocity()
        return Estimate(
            k=observation.k,
            T_cam_obj=self._held.T_cam_obj.copy(),
            v_obj_mps=v,
            w_radps=w,
            diagnostics={"held_capture_k": self._held.capture_k},
            **ids,
        )
