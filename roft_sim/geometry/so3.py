"""Rotations on batched numpy arrays.

Conventions (see docs/conventions.md):
- Quaternions are unit Hamilton quaternions, scalar first ``(w, x, y, z)``, shape ``(..., 4)``.
  Functions that return quaternions return the representative with ``w >= 0``. Compare
  quaternions with :func:`quat_angle`, which is sign-invariant (q ~ -q).
- Scalar-last data (scipy's ``as_quat()``, TUM files) is converted only by the ``*_xyzw``
  boundary functions.
- Rotation vectors ``r = angle * axis`` [rad], shape ``(..., 3)``.
- Axis-angle as in Fast-YCB files: ``(ax, ay, az, angle)``, unit axis then angle [rad] LAST,
  shape ``(..., 4)``; the identity is ``(1, 0, 0, 0)``; angle in ``[0, pi]``.
- Matrices are proper rotations, shape ``(..., 3, 3)``, acting on column vectors.

All functions accept any leading batch shape and return float64 arrays.
"""

from __future__ import annotations

import math
from typing import cast

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]

__all__ = [
    "as_quat_wxyz",
    "as_rotation_matrix",
    "quat_wxyz_from_xyzw",
    "quat_xyzw_from_wxyz",
    "canonical_quat",
    "quat_multiply",
    "quat_conjugate",
    "quat_rotate",
    "matrix_from_quat",
    "quat_from_matrix",
    "quat_from_rotvec",
    "rotvec_from_quat",
    "matrix_from_rotvec",
    "rotvec_from_matrix",
    "so3_left_jacobian",
    "so3_exp_and_left_jacobian",
    "quat_from_axis_angle",
    "axis_angle_from_quat",
    "matrix_from_axis_angle",
    "axis_angle_from_matrix",
    "quat_angle",
    "rotation_angle",
    "skew",
    "QUAT_NORM_TOLERANCE",
]

QUAT_NORM_TOLERANCE = 1e-6
"""Largest accepted | |q| - 1 | for quaternions that must be unit already (file readers)."""

_SMALL_ANGLE_RAD = 1e-6


def as_quat_wxyz(q: ArrayLike, *, normalize: bool = True) -> F64:
    """Validates quaternions, shape ``(..., 4)``, order ``(w, x, y, z)`` -> float64 copy.

    Args:
        q: quaternions; need not be unit when ``normalize`` is True.
        normalize: divide by the norm. When False, the norm must already be within
            :data:`QUAT_NORM_TOLERANCE` of 1.

    Raises:
        ValueError: wrong shape, non-finite values, zero norm, or (normalize=False) non-unit.
    """
    q = np.array(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(
            f"expected quaternions of shape (..., 4) in (w, x, y, z) order, got {q.shape}"
        )
    if not np.isfinite(q).all():
        raise ValueError("quaternion contains NaN or inf")
    n: F64 = np.linalg.norm(q, axis=-1, keepdims=True)
    if (n < 1e-12).any():
        raise ValueError("quaternion has zero norm")
    if normalize:
        return q / n
    bad = np.abs(n - 1.0) > QUAT_NORM_TOLERANCE
    if bad.any():
        worst = float(np.max(np.abs(n - 1.0)))
        raise ValueError(
            f"quaternion norm differs from 1 by {worst:.2e} (> {QUAT_NORM_TOLERANCE:g})"
        )
    return q


def as_rotation_matrix(R: ArrayLike, *, atol: float = 1e-6) -> F64:
    """Validates rotation matrices, shape ``(..., 3, 3)``: orthonormal with det +1.

    Raises:
        ValueError: wrong shape, non-finite, not orthonormal within ``atol`` or a reflection.
    """
    R = np.array(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected rotation matrices of shape (..., 3, 3), got {R.shape}")
    if not np.isfinite(R).all():
        raise ValueError("rotation matrix contains NaN or inf")
    err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(initial=0.0)
    if err > atol:
        raise ValueError(f"matrix is not orthonormal (max |R^T R - I| = {err:.2e} > {atol:g})")
    if (np.linalg.det(R) < 0).any():
        raise ValueError("matrix is a reflection (det = -1), not a rotation")
    return R


def quat_wxyz_from_xyzw(q_xyzw: ArrayLike) -> F64:
    """Boundary conversion from scalar-last ``(x, y, z, w)`` (scipy, TUM) to ``(w, x, y, z)``."""
    q = np.asarray(q_xyzw, dtype=np.float64)
    return np.concatenate([q[..., 3:4], q[..., :3]], axis=-1)


def quat_xyzw_from_wxyz(q_wxyz: ArrayLike) -> F64:
    """Boundary conversion from ``(w, x, y, z)`` to scalar-last ``(x, y, z, w)``."""
    q = np.asarray(q_wxyz, dtype=np.float64)
    return np.concatenate([q[..., 1:4], q[..., 0:1]], axis=-1)


def canonical_quat(q: ArrayLike) -> F64:
    """The representative of ``q`` (and ``-q``) with ``w >= 0``; normalised."""
    q = as_quat_wxyz(q)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_multiply(q1: ArrayLike, q2: ArrayLike) -> F64:
    """Hamilton product ``q1 ⊗ q2`` (rotate by q2, then by q1), shapes broadcast, ``(..., 4)``."""
    a = np.asarray(q1, dtype=np.float64)
    b = np.asarray(q2, dtype=np.float64)
    w1, v1 = a[..., :1], a[..., 1:]
    w2, v2 = b[..., :1], b[..., 1:]
    w = w1 * w2 - np.sum(v1 * v2, axis=-1, keepdims=True)
    v = w1 * v2 + w2 * v1 + np.cross(v1, v2)
    return np.concatenate([w, v], axis=-1)


def quat_conjugate(q: ArrayLike) -> F64:
    """Conjugate (the inverse of a unit quaternion), ``(..., 4)``."""
    q = np.asarray(q, dtype=np.float64)
    conjugate: F64 = q * np.array([1.0, -1.0, -1.0, -1.0])
    return conjugate


def quat_rotate(q: ArrayLike, p: ArrayLike) -> F64:
    """Rotates vectors ``p`` ``(..., 3)`` by unit quaternions ``q`` ``(..., 4)`` (broadcast)."""
    q = np.asarray(q, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(u, p)
    return p + w * t + np.cross(u, t)


def matrix_from_quat(q: ArrayLike) -> F64:
    """Rotation matrices ``(..., 3, 3)`` from quaternions ``(..., 4)`` (normalised first)."""
    q = np.asarray(q, dtype=np.float64)
    if q.shape == (4,):  # one quaternion: scalar arithmetic, the same operations
        w, x, y, z = _unit_quat_scalars(q)
        return np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
    q = as_quat_wxyz(q)
    w, x, y, z = np.moveaxis(q, -1, 0)
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def quat_from_matrix(R: ArrayLike) -> F64:
    """Quaternions ``(..., 4)`` with ``w >= 0`` from rotation matrices ``(..., 3, 3)``.

    Shepperd's method: for each matrix, take the largest of ``(w, x, y, z)`` from the diagonal and
    the others from off-diagonal sums, so no square root of a small number is taken.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"expected rotation matrices of shape (..., 3, 3), got {R.shape}")
    if R.shape == (3, 3):
        return _quat_from_one_matrix(R)
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    trace = m00 + m11 + m22
    # 4 * squared components, one candidate per case.
    cand = np.stack([1 + trace, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    case = np.argmax(cand, axis=-1)
    s = 2.0 * np.sqrt(np.maximum(np.take_along_axis(cand, case[..., None], -1)[..., 0], 1e-300))
    d21, d02, d10 = (
        R[..., 2, 1] - R[..., 1, 2],
        R[..., 0, 2] - R[..., 2, 0],
        R[..., 1, 0] - R[..., 0, 1],
    )
    s21, s02, s10 = (
        R[..., 2, 1] + R[..., 1, 2],
        R[..., 0, 2] + R[..., 2, 0],
        R[..., 1, 0] + R[..., 0, 1],
    )
    q = np.stack(
        [
            np.choose(case, [s / 4, d21 / s, d02 / s, d10 / s]),
            np.choose(case, [d21 / s, s / 4, s10 / s, s02 / s]),
            np.choose(case, [d02 / s, s10 / s, s / 4, s21 / s]),
            np.choose(case, [d10 / s, s02 / s, s21 / s, s / 4]),
        ],
        axis=-1,
    )
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def _quat_from_one_matrix(R: F64) -> F64:
    """:func:`quat_from_matrix` of one (3, 3) matrix in scalar arithmetic (the same operations
    as the batch path: equal results, a tenth of the time)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = R.tolist()
    trace = m00 + m11 + m22
    cand = [1 + trace, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22]
    case = cand.index(max(cand))
    s = 2.0 * math.sqrt(max(cand[case], 1e-300))
    d21, d02, d10 = m21 - m12, m02 - m20, m10 - m01
    s21, s02, s10 = m21 + m12, m02 + m20, m10 + m01
    q = [
        [s / 4, d21 / s, d02 / s, d10 / s],
        [d21 / s, s / 4, s10 / s, s02 / s],
        [d02 / s, s10 / s, s / 4, s21 / s],
        [d10 / s, s02 / s, s21 / s, s / 4],
    ]
    w, x, y, z = q[0][case], q[1][case], q[2][case], q[3][case]
    n = math.sqrt(w * w + x * x + y * y + z * z)
    out = np.array([w / n, x / n, y / n, z / n])
    return -out if out[0] < 0.0 else out


def _unit_quat_scalars(q: F64) -> tuple[float, float, float, float]:
    """The components of one quaternion (4,) divided by its norm, as :func:`as_quat_wxyz`
    validates and normalises them (the same operations)."""
    w, x, y, z = q.tolist()
    if not all(math.isfinite(c) for c in (w, x, y, z)):
        raise ValueError("quaternion contains NaN or inf")
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if n < 1e-12:
        raise ValueError("quaternion has zero norm")
    return w / n, x / n, y / n, z / n


def quat_from_rotvec(r: ArrayLike) -> F64:
    """Quaternions ``(..., 4)`` (``w >= 0`` for angles <= pi) from rotation vectors [rad].

    Uses the series of sin(x)/x near 0, so tiny rotations keep full relative precision.
    """
    r = np.asarray(r, dtype=np.float64)
    if r.shape[-1:] != (3,):
        raise ValueError(f"expected rotation vectors of shape (..., 3), got {r.shape}")
    if not np.isfinite(r).all():
        raise ValueError("rotation vector contains NaN or inf")
    angle = np.linalg.norm(r, axis=-1, keepdims=True)
    half = 0.5 * angle
    small = angle < _SMALL_ANGLE_RAD
    safe = np.where(small, 1.0, angle)
    # sin(a/2)/a = 1/2 - a^2/48 + ... for small a
    k = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / safe)
    return np.concatenate([np.cos(half), k * r], axis=-1)


def rotvec_from_quat(q: ArrayLike) -> F64:
    """Rotation vectors ``(..., 3)`` [rad], angle in ``[0, pi]``, from quaternions ``(..., 4)``.

    ``angle = 2 atan2(|v|, |w|)``: the atan2 form keeps digits near 0 and near pi, where arccos
    and arcsin lose them.
    """
    q = canonical_quat(q)
    w, v = q[..., :1], q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = np.minimum(2.0 * np.arctan2(s, w), np.pi)  # rounding can give pi + 1 ulp
    small = s < _SMALL_ANGLE_RAD
    safe_s = np.where(small, 1.0, s)
    safe_w = np.where(small, w, 1.0)  # w ~ 1 wherever s is small
    # angle / s -> 2/w * (1 - s^2/(3 w^2)) for small s
    k: F64 = np.where(small, 2.0 / safe_w * (1.0 - s**2 / (3.0 * safe_w**2)), angle / safe_s)
    return k * v


def matrix_from_rotvec(r: ArrayLike) -> F64:
    """Rotation matrices ``(..., 3, 3)`` from rotation vectors ``(..., 3)`` [rad] (exp map)."""
    return matrix_from_quat(quat_from_rotvec(r))


def rotvec_from_matrix(R: ArrayLike) -> F64:
    """Rotation vectors ``(..., 3)`` [rad] from rotation matrices (log map); exact near 0 and pi."""
    return rotvec_from_quat(quat_from_matrix(R))


def so3_left_jacobian(r: ArrayLike) -> F64:
    """Left Jacobian ``(..., 3, 3)`` of SO(3) at rotation vectors ``r`` ``(..., 3)``:
    ``d/dt exp([r]x) = [J_l(r) r']x exp([r]x)``; also the translation part of the SE(3)
    exponential, ``exp((v, w) t)`` moves by ``J_l(w t) v t``."""
    r = np.asarray(r, dtype=np.float64)
    theta = np.linalg.norm(r, axis=-1)[..., None, None]
    K = skew(r)
    small = theta < 1e-6
    t = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t)) / t**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (t - np.sin(t)) / t**3)
    V: F64 = np.eye(3) + a * K + b * (K @ K)
    return V


def so3_exp_and_left_jacobian(r: F64) -> tuple[F64, F64]:
    """``exp([r]x)`` and ``J_l(r)`` (each (3, 3)) of ONE rotation vector ``r`` (3,) [rad], in
    scalar arithmetic: :func:`matrix_from_rotvec` and :func:`so3_left_jacobian` without their
    batch machinery, for hot loops that take one rotation at a time (equal to 1e-15; tested).
    No input validation: ``r`` must be finite."""
    x, y, z = float(r[0]), float(r[1]), float(r[2])
    theta = math.sqrt(x * x + y * y + z * z)
    if theta < _SMALL_ANGLE_RAD:
        s_half = 0.5 - theta * theta / 48.0  # sin(theta / 2) / theta
        a = 0.5 - theta * theta / 24.0  # (1 - cos theta) / theta^2
        b = 1.0 / 6.0 - theta * theta / 120.0  # (theta - sin theta) / theta^3
    else:
        s_half = math.sin(0.5 * theta) / theta
        a = (1.0 - math.cos(theta)) / (theta * theta)
        b = (theta - math.sin(theta)) / (theta * theta * theta)
    qw, qx, qy, qz = math.cos(0.5 * theta), s_half * x, s_half * y, s_half * z
    R = np.array(
        [
            [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy)],
            [2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx)],
            [2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy)],
        ]
    )
    # J_l = I + a K + b K^2, K = [r]x, K^2 = r r^T - theta^2 I
    t2 = theta * theta
    J = np.array(
        [
            [1.0 + b * (x * x - t2), -a * z + b * x * y, a * y + b * x * z],
            [a * z + b * x * y, 1.0 + b * (y * y - t2), -a * x + b * y * z],
            [-a * y + b * x * z, a * x + b * y * z, 1.0 + b * (z * z - t2)],
        ]
    )
    return R, J


def quat_from_axis_angle(axis_angle: ArrayLike) -> F64:
    """Quaternions from Fast-YCB axis-angle rows ``(ax, ay, az, angle)``, shape ``(..., 4)``.

    The axis is normalised; an all-zero axis is accepted only with a zero angle (identity).

    Raises:
        ValueError: wrong shape, non-finite values, or a zero axis with a non-zero angle.
    """
    a = np.asarray(axis_angle, dtype=np.float64)
    if a.shape[-1:] != (4,):
        raise ValueError(
            f"expected axis-angle rows of shape (..., 4) as (ax, ay, az, angle), got {a.shape}"
        )
    if not np.isfinite(a).all():
        raise ValueError("axis-angle contains NaN or inf")
    axis, angle = a[..., :3], a[..., 3:4]
    n = np.linalg.norm(axis, axis=-1, keepdims=True)
    if ((n < 1e-12) & (np.abs(angle) > 1e-12)).any():
        raise ValueError("axis-angle has a zero axis with a non-zero angle")
    unit = axis / np.where(n < 1e-12, 1.0, n)
    return canonical_quat(np.concatenate([np.cos(angle / 2), np.sin(angle / 2) * unit], axis=-1))


def axis_angle_from_quat(q: ArrayLike) -> F64:
    """Fast-YCB axis-angle ``(ax, ay, az, angle)``, angle in ``[0, pi]``, from quaternions.

    The identity maps to ``(1, 0, 0, 0)``.
    """
    q = canonical_quat(q)
    w, v = q[..., :1], q[..., 1:]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = np.minimum(2.0 * np.arctan2(s, w), np.pi)
    zero = s < 1e-300
    axis = np.where(zero, np.array([1.0, 0.0, 0.0]), v / np.where(zero, 1.0, s))
    return np.concatenate([axis, np.where(zero, 0.0, angle)], axis=-1)


def matrix_from_axis_angle(axis_angle: ArrayLike) -> F64:
    """Rotation matrices from Fast-YCB axis-angle rows ``(..., 4)``."""
    return matrix_from_quat(quat_from_axis_angle(axis_angle))


def axis_angle_from_matrix(R: ArrayLike) -> F64:
    """Fast-YCB axis-angle rows ``(..., 4)`` from rotation matrices ``(..., 3, 3)``."""
    return axis_angle_from_quat(quat_from_matrix(R))


def quat_angle(q1: ArrayLike, q2: ArrayLike) -> F64:
    """Geodesic angle between rotations [rad] in ``[0, pi]``, shape ``(...,)``; q ~ -q.

    Computed as ``2 atan2(|vec(q1* ⊗ q2)|, |w(q1* ⊗ q2)|)``: arccos of the dot product loses
    half the digits near 0.
    """
    a, b = np.asarray(q1, dtype=np.float64), np.asarray(q2, dtype=np.float64)
    if a.shape == (4,) and b.shape == (4,):  # two quaternions: scalar arithmetic
        w1, x1, y1, z1 = _unit_quat_scalars(a)
        x1, y1, z1 = -x1, -y1, -z1  # the conjugate
        w2, x2, y2, z2 = _unit_quat_scalars(b)
        w = w1 * w2 - (x1 * x2 + y1 * y2 + z1 * z2)
        vx = w1 * x2 + w2 * x1 + (y1 * z2 - z1 * y2)
        vy = w1 * y2 + w2 * y1 + (z1 * x2 - x1 * z2)
        vz = w1 * z2 + w2 * z1 + (x1 * y2 - y1 * x2)
        one = np.float64(2.0 * math.atan2(math.sqrt(vx * vx + vy * vy + vz * vz), abs(w)))
        return cast(F64, one)  # a numpy scalar, as the batch path gives for one pair
    d = quat_multiply(quat_conjugate(as_quat_wxyz(a)), as_quat_wxyz(b))
    angle: F64 = 2.0 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))
    return angle


def rotation_angle(R1: ArrayLike, R2: ArrayLike) -> F64:
    """Geodesic angle ``|Log(R1^T R2)|`` [rad] between rotation matrices, shape ``(...,)``."""
    R1 = np.asarray(R1, dtype=np.float64)
    R2 = np.asarray(R2, dtype=np.float64)
    return quat_angle(quat_from_matrix(R1), quat_from_matrix(R2))


def skew(v: ArrayLike) -> F64:
    """Cross-product matrices ``[v]x`` ``(..., 3, 3)`` with ``[v]x @ p = v x p``."""
    v = np.asarray(v, dtype=np.float64)
    if v.shape == (3,):  # one vector: no batch machinery
        a, b, c = float(v[0]), float(v[1]), float(v[2])
        return np.array([[0.0, -c, b], [c, 0.0, -a], [-b, a, 0.0]])
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    o = np.zeros_like(x)
    return np.stack(
        [np.stack([o, -z, y], -1), np.stack([z, o, -x], -1), np.stack([-y, x, o], -1)], -2
    )
