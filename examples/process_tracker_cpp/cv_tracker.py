"""A constant-velocity pose tracker: the Python twin of cv_tracker.cpp (docs/process.md).

In process it is a plain :class:`~roft_sim.trackers.Tracker`; run as a script it is served over
the tracker process protocol::

    roft-sim run DATASET --tracker "process:python examples/process_tracker_cpp/cv_tracker.py"

It keeps the newest detection by capture frame, takes the velocity from the last two (by capture
time ``capture_k / fps``) and extrapolates to the current frame. Detections that are not newer
than the one held are dropped. The arithmetic is scalar, in the same order as the C++ program,
with ``math`` functions (the C library's, as ``std::`` calls them), so both give the same bits.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np

from roft_sim.geometry.se3 import pq_from_transform, transform_from_pq
from roft_sim.records import Estimate, Observation
from roft_sim.trackers import TrackerContext

Vec = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def quat_multiply(a: Quat, b: Quat) -> Quat:
    """Hamilton product ``a * b`` of (w, x, y, z) quaternions."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return (
        w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
        w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
        w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
    )


def rotvec_from_quat(q: Quat) -> Vec:
    """Rotation vector [rad] of a unit quaternion (the short way round)."""
    w, x, y, z = q
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    n = math.sqrt(x * x + y * y + z * z)
    if n == 0.0:
        return (0.0, 0.0, 0.0)
    s = 2.0 * math.atan2(n, w) / n
    return (s * x, s * y, s * z)


def quat_from_rotvec(r: Vec) -> Quat:
    """Unit quaternion of a rotation vector [rad]."""
    angle = math.sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2])
    if angle == 0.0:
        return (1.0, 0.0, 0.0, 0.0)
    s = math.sin(0.5 * angle) / angle
    return (math.cos(0.5 * angle), s * r[0], s * r[1], s * r[2])


def normalized(q: Quat) -> Quat:
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


@dataclass(frozen=True, slots=True, kw_only=True)
class ConstantVelocityConfig:
    """The constant-velocity tracker has no settings."""


class ConstantVelocityTracker:
    """Holds the newest detection and extrapolates it at constant velocity (camera frame)."""

    def __init__(self, context: TrackerContext) -> None:
        self.fps = int(context.fps)
        self.reset(None)

    def reset(self, initial: Estimate | None) -> None:
        self.has_pose = initial is not None
        self.k_last = 0
        self.t_last: Vec = (0.0, 0.0, 0.0)
        self.q_last: Quat = (1.0, 0.0, 0.0, 0.0)
        self.v: Vec = (0.0, 0.0, 0.0)
        self.w: Vec = (0.0, 0.0, 0.0)
        if initial is not None:
            t, q = pq_from_transform(initial.T_cam_obj)
            self.k_last = int(initial.k)
            self.t_last = (float(t[0]), float(t[1]), float(t[2]))
            self.q_last = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
            self.v = tuple(float(c) for c in initial.v_obj_mps)  # type: ignore[assignment]
            self.w = tuple(float(c) for c in initial.w_radps)  # type: ignore[assignment]

    def _take(self, capture_k: int, t: Vec, q: Quat) -> None:
        if self.has_pose:
            dt = (capture_k - self.k_last) / self.fps
            tl = self.t_last
            self.v = ((t[0] - tl[0]) / dt, (t[1] - tl[1]) / dt, (t[2] - tl[2]) / dt)
            ql = self.q_last
            r = rotvec_from_quat(quat_multiply(q, (ql[0], -ql[1], -ql[2], -ql[3])))
            self.w = (r[0] / dt, r[1] / dt, r[2] / dt)
        self.has_pose = True
        self.k_last, self.t_last, self.q_last = capture_k, t, q

    def step(self, observation: Observation) -> Estimate:
        accepted, dropped = [], []
        for pose in observation.poses:
            if self.has_pose and pose.capture_k <= self.k_last:
                dropped.append(pose.detection_id)
                continue
            t, q = pq_from_transform(pose.T_cam_obj)
            self._take(
                int(pose.capture_k),
                (float(t[0]), float(t[1]), float(t[2])),
                (float(q[0]), float(q[1]), float(q[2]), float(q[3])),
            )
            accepted.append(pose.detection_id)
        ids = {"accepted_pose_ids": tuple(accepted), "dropped_pose_ids": tuple(dropped)}
        if not self.has_pose:
            return Estimate.invalid(observation.k, **ids)
        tau = (observation.k - self.k_last) / self.fps
        t, v, w = self.t_last, self.v, self.w
        t_now = (t[0] + v[0] * tau, t[1] + v[1] * tau, t[2] + v[2] * tau)
        q_now = normalized(
            quat_multiply(quat_from_rotvec((w[0] * tau, w[1] * tau, w[2] * tau)), self.q_last)
        )
        return Estimate(
            k=observation.k,
            T_cam_obj=transform_from_pq(np.array(t_now), np.array(q_now)),
            v_obj_mps=np.array(v),
            w_radps=np.array(w),
            **ids,  # type: ignore[arg-type]
        )


if __name__ == "__main__":
    from roft_sim.trackers.process import serve

    sys.exit(serve(ConstantVelocityTracker))
