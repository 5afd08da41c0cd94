"""A trajectory moved by constant rigid transforms on both sides, with exact derivatives.

``T_cam_obj(t) = T_cam_world @ T_world_hand(t) @ T_hand_obj`` for constant ``T_cam_world`` (the
anchoring of a capture in front of the camera) and ``T_hand_obj`` (the grasp offset). With
``A = T_cam_world``, ``B = T_hand_obj``, inner velocities ``v, w`` and accelerations
``a, alpha`` (world frame), and ``d = R_world_hand t_B`` (hand origin to object origin, world):

- ``w_cam = R_A w``, ``alpha_cam = R_A alpha``;
- ``v_cam = R_A (v + w x d)``;
- ``a_cam = R_A (a + alpha x d + w x (w x d))``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry.se3 import as_transform
from roft_sim.trajectories.base import Trajectory, TrajectorySample

F64 = NDArray[np.float64]

__all__ = ["RigidlyMappedTrajectory"]


class RigidlyMappedTrajectory:
    """``T_left @ inner(t) @ T_right`` with velocities mapped exactly; satisfies ``Trajectory``."""

    __slots__ = ("_inner", "_T_left", "_T_right")

    def __init__(
        self,
        inner: Trajectory,
        *,
        T_left: ArrayLike | None = None,
        T_right: ArrayLike | None = None,
    ) -> None:
        """Wraps ``inner``.

        Args:
            inner: trajectory of ``T_world_hand``.
            T_left: (4, 4) constant ``T_cam_world`` [m] (default identity).
            T_right: (4, 4) constant ``T_hand_obj`` [m] (default identity).

        Raises:
            ValueError: a transform is not rigid.
        """
        self._inner = inner
        self._T_left = np.eye(4) if T_left is None else as_transform(T_left)
        self._T_right = np.eye(4) if T_right is None else as_transform(T_right)

    @property
    def inner(self) -> Trajectory:
        """The wrapped trajectory."""
        return self._inner

    @property
    def T_left(self) -> F64:
        """(4, 4) left transform (``T_cam_world``), a copy."""
        return self._T_left.copy()

    @property
    def T_right(self) -> F64:
        """(4, 4) right transform (``T_hand_obj``), a copy."""
        return self._T_right.copy()

    @property
    def start_s(self) -> float:
        return self._inner.start_s

    @property
    def end_s(self) -> float:
        return self._inner.end_s

    def sample(self, t_s: ArrayLike) -> TrajectorySample:
        """Samples ``inner`` and maps it; see ``Trajectory.sample``."""
        s = self._inner.sample(t_s)
        R_A = self._T_left[:3, :3]
        d = np.einsum("nij,j->ni", s.T_ref_obj[:, :3, :3], self._T_right[:3, 3])
        v = s.v_mps + np.cross(s.w_radps, d)
        a = s.a_mps2 + np.cross(s.alpha_radps2, d) + np.cross(s.w_radps, np.cross(s.w_radps, d))
        return TrajectorySample(
            t_s=s.t_s,
            T_ref_obj=self._T_left @ s.T_ref_obj @ self._T_right,
            v_mps=v @ R_A.T,
            w_radps=s.w_radps @ R_A.T,
            a_mps2=a @ R_A.T,
            alpha_radps2=s.alpha_radps2 @ R_A.T,
        )
