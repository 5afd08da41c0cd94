"""Rigid transforms and velocities on batched numpy arrays.

Conventions (see docs/conventions.md):
- ``T_a_b`` is the pose of frame b in frame a, shape ``(..., 4, 4)``: ``p_a = T_a_b @ p_b`` and
  ``T_a_c = T_a_b @ T_b_c``. Translations in metres.
- Velocities of an object seen from a camera, all expressed in the camera frame:
  ``v_obj`` [m/s] is the time derivative of the object origin ``t_cam_obj``; ``w`` [rad/s] is
  the angular velocity, ``dR/dt = [w]x R``. ROFT's spatial twist uses instead
  ``v_o = v_obj - w x t_cam_obj`` [m/s], the velocity of the body point at the camera origin,
  so that any body point P (camera frame) moves as ``dP/dt = v_o + w x P``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry.so3 import (
    as_rotation_matrix,
    matrix_from_quat,
    quat_angle,
    quat_from_matrix,
    skew,
)

F64 = NDArray[np.float64]

__all__ = [
    "as_transform",
    "transform_from_rt",
    "transform_from_pq",
    "pq_from_transform",
    "invert_transform",
    "transform_points",
    "v_o_from_v_obj",
    "v_obj_from_v_o",
    "twist_at_point_matrix",
    "relative_motion",
    "transform_distance",
]


def as_transform(T: ArrayLike, *, atol: float = 1e-6) -> F64:
    """Validates homogeneous transforms ``(..., 4, 4)`` -> float64 copy.

    Raises:
        ValueError: wrong shape, non-finite values, last row not ``(0, 0, 0, 1)``, or a rotation
            block that is not a proper rotation within ``atol``.
    """
    T = np.array(T, dtype=np.float64)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"expected transforms of shape (..., 4, 4), got {T.shape}")
    if not np.isfinite(T).all():
        raise ValueError("transform contains NaN or inf")
    if np.abs(T[..., 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(initial=0.0) > atol:
        raise ValueError("last row of a transform must be (0, 0, 0, 1)")
    as_rotation_matrix(T[..., :3, :3], atol=atol)
    return T


def transform_from_rt(R: ArrayLike, t: ArrayLike) -> F64:
    """Transforms ``(..., 4, 4)`` from rotations ``(..., 3, 3)`` and translations ``(..., 3)``."""
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    batch = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros(batch + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def transform_from_pq(p: ArrayLike, q: ArrayLike) -> F64:
    """Transforms from positions ``(..., 3)`` [m] and quaternions ``(..., 4)`` (w, x, y, z)."""
    return transform_from_rt(matrix_from_quat(q), p)


def pq_from_transform(T: ArrayLike) -> tuple[F64, F64]:
    """Positions ``(..., 3)`` [m] and quaternions ``(..., 4)`` (w, x, y, z; w >= 0)."""
    T = np.asarray(T, dtype=np.float64)
    return T[..., :3, 3].copy(), quat_from_matrix(T[..., :3, :3])


def invert_transform(T: ArrayLike) -> F64:
    """Inverse of rigid transforms: ``T_b_a`` from ``T_a_b``, ``(..., 4, 4)``; exact (no inv())."""
    T = np.asarray(T, dtype=np.float64)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    return transform_from_rt(Rt, -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3]))


def transform_points(T_a_b: ArrayLike, p_b: ArrayLike) -> F64:
    """Maps points ``p_b`` ``(..., 3)`` [m] of frame b into frame a: ``p_a = R p_b + t``.

    ``T_a_b`` ``(..., 4, 4)`` broadcasts against the leading shape of ``p_b``; for one transform
    and N points pass ``T`` of shape (4, 4) and ``p_b`` of shape (N, 3).
    """
    T = np.asarray(T_a_b, dtype=np.float64)
    p = np.asarray(p_b, dtype=np.float64)
    if T.ndim == 2:
        return p @ T[:3, :3].T + T[:3, 3]
    p_a: F64 = np.einsum("...ij,...j->...i", T[..., :3, :3], p) + T[..., :3, 3]
    return p_a


def v_o_from_v_obj(v_obj: ArrayLike, w: ArrayLike, t_cam_obj: ArrayLike) -> F64:
    """ROFT's spatial linear velocity ``v_o = v_obj - w x t`` [m/s], shapes ``(..., 3)``.

    Args:
        v_obj: velocity of the object origin, camera frame [m/s].
        w: angular velocity, camera frame [rad/s].
        t_cam_obj: position of the object origin, camera frame [m].
    """
    v_obj, w, t = (np.asarray(a, dtype=np.float64) for a in (v_obj, w, t_cam_obj))
    return v_obj - np.cross(w, t)


def v_obj_from_v_o(v_o: ArrayLike, w: ArrayLike, t_cam_obj: ArrayLike) -> F64:
    """Object-origin velocity ``v_obj = v_o + w x t`` [m/s] from ROFT's spatial twist."""
    v_o, w, t = (np.asarray(a, dtype=np.float64) for a in (v_o, w, t_cam_obj))
    return v_o + np.cross(w, t)


def twist_at_point_matrix(point_m: ArrayLike) -> F64:
    """(6, 6) ``T`` with ``T (v_o, w) = (v_o + w x c, w)``: :func:`v_obj_from_v_o` at the
    point ``c = point_m`` (3,) [m, camera frame] as a linear map of ROFT's spatial twist, for
    moving twists and their covariances (``T P T^T``) to a body point."""
    T = np.eye(6)
    T[:3, 3:] = -skew(np.asarray(point_m, dtype=np.float64))  # w x c = -[c]_x w
    return T


def relative_motion(
    T_world_cam: ArrayLike,
    v_cam_world: ArrayLike,
    w_cam_world: ArrayLike,
    T_world_obj: ArrayLike,
    v_obj_world: ArrayLike,
    w_obj_world: ArrayLike,
) -> tuple[F64, F64, F64]:
    """Pose and velocity of an object relative to a moving camera, in the camera frame.

    Args:
        T_world_cam: ``(..., 4, 4)`` camera pose in the world [m].
        v_cam_world: ``(..., 3)`` velocity of the camera origin, world frame [m/s].
        w_cam_world: ``(..., 3)`` camera angular velocity, world frame [rad/s].
        T_world_obj: ``(..., 4, 4)`` object pose in the world [m].
        v_obj_world: ``(..., 3)`` velocity of the object origin, world frame [m/s].
        w_obj_world: ``(..., 3)`` object angular velocity, world frame [rad/s].

    Returns:
        ``T_cam_obj`` (..., 4, 4); ``v_obj`` (..., 3) [m/s] = d/dt of ``t_cam_obj``, camera frame;
        ``w`` (..., 3) [rad/s] with ``dR_cam_obj/dt = [w]x R_cam_obj``, camera frame.
    """
    T_wc = np.asarray(T_world_cam, dtype=np.float64)
    T_wo = np.asarray(T_world_obj, dtype=np.float64)
    R_cw = np.swapaxes(T_wc[..., :3, :3], -1, -2)
    T_cam_obj = invert_transform(T_wc) @ T_wo
    w_rel_world = np.asarray(w_obj_world, dtype=np.float64) - np.asarray(
        w_cam_world, dtype=np.float64
    )
    d_world = T_wo[..., :3, 3] - T_wc[..., :3, 3]
    # t_cam_obj = R_cw (p_o - p_c)  =>  d/dt = R_cw (v_o - v_c) - R_cw [w_c]x (p_o - p_c)
    ddot = np.asarray(v_obj_world, dtype=np.float64) - np.asarray(v_cam_world, dtype=np.float64)
    ddot = ddot - np.cross(np.asarray(w_cam_world, dtype=np.float64), d_world)
    v_cam = np.einsum("...ij,...j->...i", R_cw, ddot)
    w_cam = np.einsum("...ij,...j->...i", R_cw, w_rel_world)
    return T_cam_obj, v_cam, w_cam


def transform_distance(T1: ArrayLike, T2: ArrayLike) -> tuple[F64, F64]:
    """Translation distance [m] and geodesic angle [rad] between transforms, ``(...,)`` each."""
    T1 = np.asarray(T1, dtype=np.float64)
    T2 = np.asarray(T2, dtype=np.float64)
    dt = np.linalg.norm(T1[..., :3, 3] - T2[..., :3, 3], axis=-1)
    return dt, quat_angle(quat_from_matrix(T1[..., :3, :3]), quat_from_matrix(T2[..., :3, :3]))
