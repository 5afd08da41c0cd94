"""An example tracker to test with roft_sim's toolkit: a constant-velocity Kalman filter of the
object position that handles delayed poses by rollback and replay.

- State ``x = (p, v)`` (6,), camera frame [m, m/s]; ``p_k = p_(k-1) + v dt``; white-noise
  acceleration of power spectral density ``accel_psd_m2ps3`` [m^2/s^3]; a pose detection measures
  ``p`` with variance ``position_noise_var_m2`` [m^2].
- A delayed pose (``capture_k < k``) is fused where it belongs: the filter restarts from its
  belief before ``capture_k`` and replays every frame up to ``k``, so the result does not depend on
  delays or arrival order. Poses older than ``horizon_frames`` are dropped (and reported).
- Orientation: the rotation of the newest captured pose, held (no filtering), with the fixed
  variance ``rotation_var_rad2``; angular velocity reported as 0 with ``angular_var_rad2ps2``.
- When no pose was captured for more than ``max_prediction_frames``, the reported position stays
  where the prediction was at that age (no runaway extrapolation).

Registered for roft_sim through the entry point in pyproject.toml (``my-cv-tracker``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from roft_sim.errors import ConfigError
from roft_sim.records import Estimate, Observation
from roft_sim.trackers import TrackerContext, TrackerSpec

__all__ = ["CvTrackerConfig", "CvPositionTracker", "SPEC"]

_DIFFUSE_M2 = 1e4
"""Prior variance of position and velocity when no initial estimate is given [m^2, (m/s)^2]."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CvTrackerConfig:
    """Settings of the constant-velocity position tracker."""

    accel_psd_m2ps3: float = 1.0
    """White-noise acceleration power spectral density [m^2/s^3]."""
    position_noise_var_m2: float = 1e-3
    """Variance of a detected position, per axis [m^2]."""
    horizon_frames: int = 15
    """Poses captured more than this many frames before the current one are dropped."""
    max_prediction_frames: int = 12
    """Stop extrapolating the reported position this many frames after the newest capture."""
    rotation_var_rad2: float = 0.01
    """Variance reported for the (held) orientation [rad^2]."""
    angular_var_rad2ps2: float = 100.0
    """Variance reported for the (unknown, reported as 0) angular velocity [(rad/s)^2]."""

    def __post_init__(self) -> None:
        positive = ("accel_psd_m2ps3", "position_noise_var_m2", "rotation_var_rad2",
                    "angular_var_rad2ps2")  # fmt: skip
        for name in positive:
            if not getattr(self, name) > 0:
                raise ConfigError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.horizon_frames < 0 or self.max_prediction_frames < 0:
            raise ConfigError("horizon_frames and max_prediction_frames must be >= 0")


class CvPositionTracker:
    """See the module docstring. Satisfies :class:`roft_sim.trackers.Tracker`."""

    def __init__(self, config: CvTrackerConfig, context: TrackerContext):
        self._cfg = config
        self._fps = context.fps
        self.reset(None)

    def reset(self, initial: Estimate | None) -> None:
        self._poses: dict[int, list[tuple[int, np.ndarray]]] = {}  # capture_k -> [(id, T)]
        self._beliefs: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # k -> posterior (x, P)
        self._newest: tuple[int, int, np.ndarray] | None = None  # (capture_k, id, R_cam_obj)
        self._last_k = -1
        P = np.eye(6) * _DIFFUSE_M2
        x = np.zeros(6)
        self._rotation = np.eye(3)
        if initial is not None:
            x = np.concatenate([initial.T_cam_obj[:3, 3], initial.v_obj_mps]).astype(np.float64)
            self._rotation = np.array(initial.T_cam_obj[:3, :3], dtype=np.float64)
            if initial.covariance is not None:  # (t, r, v, w) order: take the t and v blocks
                keep = [0, 1, 2, 6, 7, 8]
                P = np.array(initial.covariance, dtype=np.float64)[np.ix_(keep, keep)]
        # beliefs[-1] is the prior; an initial estimate describes frame 0 itself (not predicted)
        self._beliefs[-1] = (x, P)
        self._initialised = initial is not None

    def _step_filter(self, j: int, belief: tuple[np.ndarray, np.ndarray]):
        """Predict from j-1 to j (not into frame 0 from an initial estimate: it describes frame
        0), then correct with every pose captured at j."""
        dt = 0.0 if (j == 0 and self._initialised) else 1.0 / self._fps
        F = np.eye(6)
        F[:3, 3:] = np.eye(3) * dt
        q = self._cfg.accel_psd_m2ps3
        Q = np.block([[np.eye(3) * q * dt**3 / 3, np.eye(3) * q * dt**2 / 2],
                      [np.eye(3) * q * dt**2 / 2, np.eye(3) * q * dt]])  # fmt: skip
        x, P = F @ belief[0], F @ belief[1] @ F.T + Q
        H = np.hstack([np.eye(3), np.zeros((3, 3))])
        R = np.eye(3) * self._cfg.position_noise_var_m2
        for _, T in sorted(self._poses.get(j, []), key=lambda p: p[0]):
            S = H @ P @ H.T + R
            K = np.linalg.solve(S, H @ P).T
            x = x + K @ (T[:3, 3] - H @ x)
            I_KH = np.eye(6) - K @ H
            P = I_KH @ P @ I_KH.T + K @ R @ K.T  # Joseph form: stays symmetric PD
        return x, 0.5 * (P + P.T)

    def step(self, observation: Observation) -> Estimate:
        k = observation.k
        accepted, dropped = [], []
        start = self._last_k + 1
        for det in observation.poses:
            c, T = det.capture_k, np.asarray(det.T_cam_obj, dtype=np.float64)
            known = any(i == det.detection_id for i, _ in self._poses.get(c, []))
            if c > k or c < k - self._cfg.horizon_frames or known or not np.isfinite(T).all():
                dropped.append(det.detection_id)
                continue
            self._poses.setdefault(c, []).append((det.detection_id, T))
            accepted.append(det.detection_id)
            start = min(start, c)
            if self._newest is None or (c, det.detection_id) > self._newest[:2]:
                self._newest = (c, det.detection_id, T[:3, :3].copy())
        for j in range(start, k + 1):  # roll back to the belief before `start`, replay to k
            self._beliefs[j] = self._step_filter(j, self._beliefs[j - 1])
        self._last_k = k
        oldest = k - self._cfg.horizon_frames  # no pose captured before this can arrive now
        for j in [j for j in self._beliefs if j < oldest - 1]:
            del self._beliefs[j]
        for c in [c for c in self._poses if c < oldest]:
            del self._poses[c]
        ids = {"accepted_pose_ids": tuple(accepted), "dropped_pose_ids": tuple(dropped)}
        if self._newest is None and not self._initialised:
            return Estimate.invalid(k, **ids)
        x, P = self._beliefs[k]
        rotation = self._newest[2] if self._newest is not None else self._rotation
        age = k - self._newest[0] if self._newest is not None else k
        beyond = max(0, age - self._cfg.max_prediction_frames) / self._fps  # [s]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = rotation, x[:3] - x[3:] * beyond
        cov = np.zeros((12, 12))
        cov[np.ix_([0, 1, 2, 6, 7, 8], [0, 1, 2, 6, 7, 8])] = P
        cov[3:6, 3:6] = np.eye(3) * self._cfg.rotation_var_rad2
        cov[9:12, 9:12] = np.eye(3) * self._cfg.angular_var_rad2ps2
        return Estimate(k=k, T_cam_obj=T, v_obj_mps=x[3:].copy(), w_radps=np.zeros(3),
                        covariance=cov, **ids)  # fmt: skip


SPEC = TrackerSpec(
    name="my-cv-tracker",
    description="constant-velocity position KF with delayed-pose replay (roft_sim testing example)",
    config_type=CvTrackerConfig,
    factory=CvPositionTracker,
)
