"""Per-frame pose errors: ADD, ADD-S, position error and geodesic rotation error.

Definitions (docs/metrics.md; Hinterstoisser et al. 2012; bop_toolkit ``add``/``adi``; the ROFT
reference evaluation, ``evaluation/metrics.py``):

- ADD: ``(1/M) sum_j |(R_est x_j + t_est) - (R_gt x_j + t_gt)|`` over the M model points.
- ADD-S (ADI): ``(1/M) sum_j min_k |(R_gt x_j + t_gt) - (R_est x_k + t_est)|``: for every
  ground-truth-placed point, the nearest estimate-placed point (KD-tree).
- Position error ``|t_est - t_gt|``; rotation error ``|Log(R_gt R_est^T)|`` in ``[0, pi]`` (the
  reference uses the angle of ``R_gt R_est^T``; the same number as ``|Log(R_est^T R_gt)|``).

A non-finite estimate (NaN or inf anywhere in its pose) is a failure: its ADD and ADD-S are
``inf``, and its position and rotation errors are NaN. Ground truth must be finite.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from roft_sim.geometry.so3 import quat_angle, quat_from_matrix

F64 = NDArray[np.float64]

__all__ = [
    "add_distances",
    "adds_distances",
    "translation_errors_m",
    "rotation_errors_rad",
]

_POINTS_PER_CHUNK = 2_000_000
"""Frames x points processed at once by :func:`add_distances` (bounds memory to ~50 MB)."""


def _pose_pair(T_est: ArrayLike, T_gt: ArrayLike) -> tuple[F64, F64, NDArray[np.bool_]]:
    """Validated ``(N, 4, 4)`` estimate and ground-truth poses, and the finite-estimate mask."""
    T_est = np.asarray(T_est, dtype=np.float64)
    T_gt = np.asarray(T_gt, dtype=np.float64)
    if T_est.ndim == 2 and T_gt.ndim == 2:  # one pose each
        T_est, T_gt = T_est[None], T_gt[None]
    if T_est.ndim != 3 or T_est.shape[1:] != (4, 4) or T_gt.shape != T_est.shape:
        raise ValueError(
            f"T_est and T_gt must both have shape (N, 4, 4), got {T_est.shape} and {T_gt.shape}"
        )
    if not np.isfinite(T_gt).all():
        bad = int(np.flatnonzero(~np.isfinite(T_gt).all(axis=(1, 2)))[0])
        raise ValueError(f"ground-truth pose {bad} is not finite; ground truth must be complete")
    finite = np.isfinite(T_est).all(axis=(1, 2))
    return T_est, T_gt, finite


def _model_points(model_points_m: ArrayLike) -> F64:
    pts = np.asarray(model_points_m, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
        raise ValueError(f"model_points_m must have shape (M, 3) with M >= 1, got {pts.shape}")
    if not np.isfinite(pts).all():
        raise ValueError("model_points_m contains NaN or inf")
    return pts


def add_distances(T_est: ArrayLike, T_gt: ArrayLike, model_points_m: ArrayLike) -> F64:
    """ADD per frame: mean distance between corresponding model points [m].

    Args:
        T_est: (N, 4, 4) estimated ``T_cam_obj`` [m]; non-finite rows are failures.
        T_gt: (N, 4, 4) ground-truth ``T_cam_obj`` [m], finite.
        model_points_m: (M, 3) model points in the object frame [m] (all points of the model's
            ``points.xyz``, as the reference evaluation uses).

    Returns:
        (N,) ADD [m]; ``inf`` where the estimate is not finite.
    """
    T_est, T_gt, finite = _pose_pair(T_est, T_gt)
    pts = _model_points(model_points_m)
    out = np.full(T_est.shape[0], np.inf)
    idx = np.flatnonzero(finite)
    chunk = max(1, _POINTS_PER_CHUNK // pts.shape[0])
    for start in range(0, idx.size, chunk):
        sel = idx[start : start + chunk]
        dR = T_est[sel, :3, :3] - T_gt[sel, :3, :3]
        dt = T_est[sel, :3, 3] - T_gt[sel, :3, 3]
        diff = np.einsum("nij,mj->nmi", dR, pts) + dt[:, None, :]
        out[sel] = np.linalg.norm(diff, axis=2).mean(axis=1)
    return out


def adds_distances(T_est: ArrayLike, T_gt: ArrayLike, model_points_m: ArrayLike) -> F64:
    """ADD-S (ADI) per frame: mean distance to the nearest estimate-placed model point [m].

    Uses one ``scipy.spatial.cKDTree`` on the model points: the nearest estimate-placed point to
    a ground-truth-placed point ``y`` is the model point nearest to ``R_est^T (y - t_est)``,
    which is the same distance because rigid motions preserve it.

    Args:
        T_est: (N, 4, 4) estimated ``T_cam_obj`` [m]; non-finite rows are failures.
        T_gt: (N, 4, 4) ground-truth ``T_cam_obj`` [m], finite.
        model_points_m: (M, 3) model points in the object frame [m].

    Returns:
        (N,) ADD-S [m]; ``inf`` where the estimate is not finite.
    """
    T_est, T_gt, finite = _pose_pair(T_est, T_gt)
    pts = _model_points(model_points_m)
    tree = cKDTree(pts)
    out = np.full(T_est.shape[0], np.inf)
    for n in np.flatnonzero(finite):
        y = pts @ T_gt[n, :3, :3].T + T_gt[n, :3, 3]
        query = (y - T_est[n, :3, 3]) @ T_est[n, :3, :3]  # R_est^T (y - t_est), row-wise
        dist, _ = tree.query(query, k=1)
        out[n] = np.mean(dist)
    return out


def translation_errors_m(T_est: ArrayLike, T_gt: ArrayLike) -> F64:
    """Position error vectors ``t_est - t_gt`` (N, 3) [m], camera frame; NaN rows for failures."""
    T_est, T_gt, finite = _pose_pair(T_est, T_gt)
    err = T_est[:, :3, 3] - T_gt[:, :3, 3]
    err[~finite] = np.nan
    return err


def rotation_errors_rad(T_est: ArrayLike, T_gt: ArrayLike) -> F64:
    """Geodesic rotation error ``|Log(R_gt R_est^T)|`` (N,) [rad] in [0, pi]; NaN for failures.

    Accepts (N, 4, 4) poses or (N, 3, 3) rotations.
    """
    A = np.asarray(T_est, dtype=np.float64)
    B = np.asarray(T_gt, dtype=np.float64)
    if A.shape != B.shape or A.shape[-2:] not in ((3, 3), (4, 4)):
        raise ValueError(
            f"expected matching (N, 4, 4) poses or (N, 3, 3) rotations, got {A.shape} and {B.shape}"
        )
    finite = np.isfinite(A).all(axis=(-1, -2))  # a NaN anywhere in the pose is a failure
    A, B = A[..., :3, :3], B[..., :3, :3]
    out = np.full(A.shape[:-2], np.nan)
    if finite.any():
        out[finite] = quat_angle(quat_from_matrix(A[finite]), quat_from_matrix(B[finite]))
    return out
