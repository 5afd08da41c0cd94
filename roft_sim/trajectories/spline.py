"""Replay of sampled poses with exact analytic derivatives.

Position is a C2 cubic spline (scipy ``CubicSpline``, not-a-knot ends); rotation is scipy's
``RotationSpline`` (continuous angular rate and acceleration). scipy returns the angular rate in
the BODY frame (``dR/dt = R [w_body]x``, checked by finite differences in the tests); this module
returns it in the reference frame, ``w = R w_body``, and likewise ``alpha = R d(w_body)/dt``
(the term ``R [w_body]x w_body`` vanishes). So velocities and accelerations are the analytic
derivatives of exactly the poses returned.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

from roft_sim.geometry.so3 import quat_xyzw_from_wxyz
from roft_sim.trajectories.base import TrajectorySample, as_sample_times

F64 = NDArray[np.float64]

__all__ = ["SplinePoseTrajectory", "MIN_SPLINE_SAMPLES"]

MIN_SPLINE_SAMPLES = 4
"""Fewest samples a spline replay accepts (a not-a-knot cubic needs four)."""


class SplinePoseTrajectory:
    """Interpolates poses sampled at strictly increasing times; satisfies ``Trajectory``.

    The trajectory passes exactly through every sample (up to rounding) and is defined on
    ``[t_s[0], t_s[-1]]``.
    """

    __slots__ = ("_knots_s", "_position", "_velocity", "_acceleration", "_rotation")

    def __init__(self, t_s: ArrayLike, T_ref_obj: ArrayLike) -> None:
        """Fits the splines.

        Args:
            t_s: (N,) strictly increasing sample times [s], N >= 4.
            T_ref_obj: (N, 4, 4) sampled poses in the reference frame [m].

        Raises:
            ValueError: shapes, too few samples, times not strictly increasing, non-finite values.
        """
        t = np.array(t_s, dtype=np.float64)
        T = np.asarray(T_ref_obj, dtype=np.float64)
        if t.ndim != 1 or T.shape != (t.shape[0], 4, 4):
            raise ValueError(f"need t_s (N,) and T_ref_obj (N, 4, 4), got {t.shape}, {T.shape}")
        if t.shape[0] < MIN_SPLINE_SAMPLES:
            raise ValueError(
                f"a spline replay needs at least {MIN_SPLINE_SAMPLES} samples, got {t.shape[0]}"
            )
        if not (np.isfinite(t).all() and np.isfinite(T).all()):
            raise ValueError("sample times or poses contain NaN or inf")
        if not (np.diff(t) > 0).all():
            k = int(np.argmin(np.diff(t)))
            raise ValueError(
                f"sample times must increase strictly; t[{k}] = {t[k]!r}, t[{k + 1}] = {t[k + 1]!r}"
            )
        self._knots_s = t
        self._position = CubicSpline(t, T[:, :3, 3], axis=0, bc_type="not-a-knot")
        self._velocity = self._position.derivative(1)
        self._acceleration = self._position.derivative(2)
        self._rotation = RotationSpline(t, Rotation.from_matrix(T[:, :3, :3]))

    @classmethod
    def from_pq(cls, t_s: ArrayLike, p_m: ArrayLike, q_wxyz: ArrayLike) -> SplinePoseTrajectory:
        """From positions ``(N, 3)`` [m] and quaternions ``(N, 4)`` (w, x, y, z)."""
        p = np.asarray(p_m, dtype=np.float64)
        R = Rotation.from_quat(quat_xyzw_from_wxyz(q_wxyz)).as_matrix()
        T = np.zeros((p.shape[0], 4, 4))
        T[:, :3, :3] = R
        T[:, :3, 3] = p
        T[:, 3, 3] = 1.0
        return cls(t_s, T)

    @property
    def start_s(self) -> float:
        return float(self._knots_s[0])

    @property
    def end_s(self) -> float:
        return float(self._knots_s[-1])

    @property
    def knot_times_s(self) -> F64:
        """(N,) the sample times the spline interpolates [s] (a copy)."""
        return self._knots_s.copy()

    def sample(self, t_s: ArrayLike) -> TrajectorySample:
        """Pose, velocity and acceleration at ``t_s`` ``(N,)`` [s]; see ``Trajectory.sample``."""
        t = as_sample_times(t_s, self.start_s, self.end_s)
        R = self._rotation(t).as_matrix().reshape(-1, 3, 3)
        w_body = np.asarray(self._rotation(t, 1)).reshape(-1, 3)
        alpha_body = np.asarray(self._rotation(t, 2)).reshape(-1, 3)
        T = np.zeros((t.shape[0], 4, 4))
        T[:, :3, :3] = R
        T[:, :3, 3] = self._position(t)
        T[:, 3, 3] = 1.0
        return TrajectorySample(
            t_s=t,
            T_ref_obj=T,
            v_mps=np.asarray(self._velocity(t), dtype=np.float64).reshape(-1, 3),
            w_radps=np.einsum("nij,nj->ni", R, w_body),
            a_mps2=np.asarray(self._acceleration(t), dtype=np.float64).reshape(-1, 3),
            alpha_radps2=np.einsum("nij,nj->ni", R, alpha_body),
        )
