"""The velocity Kalman filter: ROFT's spatial twist from optical flow (paper eqs. 4-9).

State ``x = (v_o, w)`` [m/s, rad/s], camera frame: ``v_o`` is the velocity of the body point at
the camera origin, so a body point P moves as ``dP/dt = v_o + w x P``. Motion model ``F = I``,
``Q`` per frame (not scaled by dt). Measurements: the flow F_k (frame k-1 -> k) at every n-th
mask pixel of frame k-1, predicted as ``dt * J(u, v, Z) x`` with the object-motion interaction
matrix of reference report section 3.2 (depth Z of frame k-1). With ``depth_rate`` (a
deviation) each pixel also gives its depth change over the interval where the flow carries it,
predicted as ``dt (v_z + w_x Y - w_y X)`` (range flow; :func:`depth_rate_rows`).

The reference updates sequentially, one 2x2 block per pixel; with a block-diagonal R that is
algebraically one batch update, done here in information form with a single 6x6 solve:
``P+ = (P-^-1 + J^T W J)^-1``, ``x+ = x- + P+ J^T W (y - J x-)``, ``W = R^-1`` (diagonal).
The robust reweighting of reference section 3.3 scales each pixel's R by the inverse of a
Laplacian likelihood of its innovation norm.

With ``finite_motion_correction`` (a deviation) the measured flow is first corrected by
``h(x) - J x``, ``h`` the exact flow of the constant twist ``x`` over the interval
(:func:`finite_motion_flow`), at the filter's own estimate (iterated EKF), so the linear model
above holds at fast turns too.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry.camera import CameraIntrinsics, backproject_pixels, project_points
from roft_sim.geometry.so3 import so3_exp_and_left_jacobian
from roft_sim.records import FlowField
from roft_sim.trackers.roft.config import VelocityKFConfig
from roft_sim.trackers.roft.mask_sync import PixelSet, lookup_flow, mask_window
from roft_sim.trackers.roft.medians import MAD_TO_SIGMA, chi2_quantile, column_medians, median

F64 = NDArray[np.float64]

__all__ = [
    "DepthRateRows",
    "FlowMeasurement",
    "depth_rate_rows",
    "flow_measurement",
    "flow_jacobian",
    "finite_motion_flow",
    "laplacian_likelihood",
    "VelocityKF",
]


_LIKELIHOOD_FLOOR = 1e-6
_MIN_SPREAD = 1e-4


@dataclass(frozen=True, slots=True)
class DepthRateRows:
    """The depth change of the sampled points over the interval (range flow), one linear
    measurement row each (``VelocityKFConfig.depth_rate``)."""

    u_px: NDArray[np.int64]
    """(M,) the points' pixel columns in frame k-1."""
    v_px: NDArray[np.int64]
    """(M,) the points' pixel rows in frame k-1."""
    dz_m: F64
    """(M,) measured depth change ``Z_k(u + du, v + dv) - Z_{k-1}(u, v)`` [m]."""
    J: F64
    """(M, 6) ``dt * d(dz)/d(v_o, w)`` = ``dt (0, 0, 1, Y, -X, 0)`` at the point's mean
    position over the interval [m per (m/s), m per (rad/s)], camera frame."""
    slope_m_per_px: F64
    """(M,) the depth gradient's norm of frame k where the point was read [m/px]: a flow
    error of e px moves the read depth by about ``slope * e``."""
    cell_weight: F64 | None = None
    """(M,) the weight of each row's flow grid cell (as ``FlowMeasurement.cell_weight``), or
    None (all 1)."""

    def __len__(self) -> int:
        return int(self.dz_m.shape[0])


@dataclass(frozen=True, slots=True)
class FlowMeasurement:
    """Stacked flow measurements of N pixels and their model."""

    y_px: F64
    """(N, 2) measured flow (du, dv) [px] over the frame interval."""
    J: F64
    """(N, 2, 6) ``dt * d(flow)/d(v_o, w)`` [px per (m/s), px per (rad/s)]."""
    u_px: NDArray[np.int64]
    """(N,) pixel columns in frame k-1."""
    v_px: NDArray[np.int64]
    """(N,) pixel rows in frame k-1."""
    cell_weight: F64 | None = None
    """(N,) 1 / (number of the N pixels that read the same flow grid cell), or None (all 1)."""
    relinearize: Callable[[F64], F64] | None = None
    """``twist (6,) -> (N, 2)``: the measured flow [px] corrected for the finite motion at that
    twist instead (``finite_motion_correction``); the filter calls it at its own estimates of
    the interval (:meth:`VelocityKF.relinearized`) and updates with the result. None: ``y_px``
    is final."""
    depth_rate: DepthRateRows | None = None
    """The sampled points' depth changes (``depth_rate``), or None (the flow alone)."""
    grid_px: int = 1
    """Image pixels per cell of the flow field the vectors were read from (1: dense)."""
    _distinct: list[int] = field(init=False, repr=False, compare=False)
    """Memo of :meth:`distinct_vectors` (both motion models of ``auto`` ask)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "_distinct", [])

    def __len__(self) -> int:
        return int(self.y_px.shape[0])

    def distinct_vectors(self) -> int:
        """The number of distinct flow vectors ``y_px`` (rows equal in both components)."""
        if not self._distinct:
            y = np.ascontiguousarray(self.y_px, dtype=np.float64).view(np.complex128).ravel()
            if y.size and np.isfinite(y).all():  # a sort and a count: np.unique's result, 4x faster
                s = np.sort(y)
                self._distinct.append(1 + int(np.count_nonzero(s[1:] != s[:-1])))
            else:  # np.unique counts all NaNs as one
                self._distinct.append(int(np.unique(y).size))
        return self._distinct[0]


def flow_rows_at(J: F64, twist: F64) -> F64:
    """``J @ twist`` (N, 2) [px] of flow Jacobians ``J`` (N, 2, 6) at a twist (6,), as one
    matrix-vector product of the stacked rows (five times faster than the stacked ``@``)."""
    out: F64 = (J.reshape(-1, 6) @ twist).reshape(-1, 2)
    return out


def flow_jacobian(
    intrinsics: CameraIntrinsics, u_px: ArrayLike, v_px: ArrayLike, z_m: ArrayLike, dt_s: float
) -> F64:
    """``dt * J`` ``(N, 2, 6)``: flow [px] per spatial twist (v_o [m/s], w [rad/s]).

    Object-motion form (paper eq. 9): the rows are the time derivatives of ``u = fx X/Z + cx``,
    ``v = fy Y/Z + cy`` for ``dP/dt = v_o + w x P``, at pixels ``(u, v)`` with z-depth ``Z``.
    """
    fx, fy = intrinsics.fx_px, intrinsics.fy_px
    up = np.asarray(u_px, dtype=np.float64) - intrinsics.cx_px
    vp = np.asarray(v_px, dtype=np.float64) - intrinsics.cy_px
    inv_z = 1.0 / np.asarray(z_m, dtype=np.float64)
    J = np.zeros(up.shape + (2, 6))
    J[..., 0, 0] = fx * inv_z
    J[..., 0, 2] = -up * inv_z
    J[..., 0, 3] = -up * vp / fy
    J[..., 0, 4] = fx + up * up / fx
    J[..., 0, 5] = -vp * fx / fy
    J[..., 1, 1] = fy * inv_z
    J[..., 1, 2] = -vp * inv_z
    J[..., 1, 3] = -(fy + vp * vp / fy)
    J[..., 1, 4] = up * vp / fx
    J[..., 1, 5] = up * fy / fx
    return J * dt_s


def finite_motion_flow(
    intrinsics: CameraIntrinsics,
    u_px: ArrayLike,
    v_px: ArrayLike,
    z_m: ArrayLike,
    twist: ArrayLike,
    dt_s: float,
) -> F64:
    """``(N, 2)`` flow [px] of pixels ``(u, v)`` with z-depth ``Z`` [m] when the body moves
    with the constant spatial twist ``(v_o [m/s], w [rad/s])`` for ``dt_s`` [s]: each point
    ``P`` goes to ``exp(dt (v_o, w)) P = R P + J_l(w dt) v_o dt`` (``R = exp([w dt]x)``); the
    finite counterpart of :func:`flow_jacobian` (NaN where a point ends behind the camera)."""
    return _FiniteMotion(intrinsics, u_px, v_px, z_m).flow(np.asarray(twist, np.float64), dt_s)


class _FiniteMotion:
    """:func:`finite_motion_flow` at fixed pixels, their back-projection computed once (the
    filter evaluates it at several twists per update)."""

    def __init__(
        self, intrinsics: CameraIntrinsics, u_px: ArrayLike, v_px: ArrayLike, z_m: ArrayLike
    ):
        self._intrinsics = intrinsics
        self._uv = np.stack(
            [np.asarray(u_px, dtype=np.float64), np.asarray(v_px, dtype=np.float64)], -1
        )
        self._points = backproject_pixels(intrinsics, self._uv, z_m)

    def flow(self, twist: F64, dt_s: float) -> F64:
        """(N, 2) the pixels' flow [px] under ``twist`` (6,) for ``dt_s`` [s]."""
        R, J_l = so3_exp_and_left_jacobian(twist[3:] * dt_s)
        moved = self._points @ R.T + J_l @ (twist[:3] * dt_s)
        return project_points(self._intrinsics, moved) - self._uv

    def corrected(self, y: F64, J: F64, dt_s: float, twist: F64) -> F64:
        """The flow ``y`` (N, 2) [px] less ``h(x) - J x`` at ``x = twist`` (6,)
        (``VelocityKFConfig.finite_motion_correction``); ``y`` unchanged if ``h`` is not
        finite (a point carried behind the camera)."""
        correction = self.flow(twist, dt_s) - flow_rows_at(J, twist)
        return y - correction if np.isfinite(correction).all() else y


_FINITE_MOTION_MIN_PIXELS = 6
"""Fewer pixels than this and no twist given: no finite-motion correction (their own twist is
not determined)."""
_FINITE_MOTION_FITS = 2
"""Re-fits of the pixels' least-squares twist when no twist is given (the first update)."""
_RELINEARIZATIONS = 2
"""Iterated-EKF steps of :meth:`VelocityKF.relinearized`."""


_EXACT_FLOW_NOISE_RATIO = 0.01
"""Smallest factor on the flow noise that ``exact_flow_spread_px`` applies: that of the shipped
exact-flow configuration (``scenarios/trackers/roft_exact_flow.toml``)."""
_EXACT_FLOW_MIN_VECTORS = 30
"""``exact_flow_spread_px`` needs at least this many distinct flow vectors (and 90 % of the
pixels' vectors distinct): five times the twist's six parameters, so that a small residual
spread is evidence, not a fit of too few values."""
_DEPTH_RATE_EDGE_M = 0.02
"""A point whose four depth neighbours at its flow-carried position differ by more than this
[m] sits on a depth edge there: no depth-change row (bilinear depth across an edge is neither
surface's)."""
_DEPTH_RATE_MIN_ROWS = 6
"""Fewer valid depth-change rows than this: none are used (their noise is not determined)."""


def depth_rate_rows(
    intrinsics: CameraIntrinsics,
    u_px: NDArray[np.int64],
    v_px: NDArray[np.int64],
    z_m: F64,
    flow_px: F64,
    next_depth_m: NDArray[np.floating],
    dt_s: float,
    config: VelocityKFConfig,
    cell_weight: F64 | None = None,
) -> DepthRateRows | None:
    """The depth change of each sampled point over the interval, where the flow carries it.

    Args:
        intrinsics: the camera.
        u_px, v_px: (N,) the points' pixels in frame k-1.
        z_m: (N,) their z-depth in frame k-1 [m].
        flow_px: (N, 2) their measured flow (du, dv) to frame k [px].
        next_depth_m: (H, W) z-depth of frame k [m] (0: no measurement).
        dt_s: the interval [s].
        config: the filter settings (``depth_maximum_m``, ``depth_band_m``).
        cell_weight: (N,) the points' flow grid-cell weights, or None.

    Returns:
        The rows of the points whose new position lies inside the image on a valid, edge-free
        depth (bilinear over its four neighbours, all measured and within
        ``_DEPTH_RATE_EDGE_M`` of each other; within ``depth_band_m`` of the points' median
        depth when set), or None when fewer than ``_DEPTH_RATE_MIN_ROWS`` remain.
    """
    h, w = next_depth_m.shape
    u2 = u_px + flow_px[:, 0]
    v2 = v_px + flow_px[:, 1]
    ok = np.isfinite(u2) & np.isfinite(v2) & (u2 >= 0) & (v2 >= 0) & (u2 < w - 1) & (v2 < h - 1)
    if np.count_nonzero(ok) < _DEPTH_RATE_MIN_ROWS:
        return None
    idx = np.flatnonzero(ok)
    u2, v2 = u2[idx], v2[idx]
    c0 = np.floor(u2).astype(np.int64)
    r0 = np.floor(v2).astype(np.int64)
    a = u2 - c0
    b = v2 - r0
    # the four neighbours (r0, c0), (r0, c0 + 1), (r0 + 1, c0), (r0 + 1, c0 + 1): (4, M)
    base = r0 * w + c0
    corner_offsets = np.array([0, 1, w, w + 1])[:, None]
    c = np.take(next_depth_m.reshape(-1), base + corner_offsets).astype(np.float64)
    good = (c > 0.0).all(axis=0) & (c < config.depth_maximum_m).all(axis=0)
    good &= c.max(axis=0) - c.min(axis=0) <= _DEPTH_RATE_EDGE_M
    z2 = (1 - a) * (1 - b) * c[0] + a * (1 - b) * c[1] + (1 - a) * b * c[2] + a * b * c[3]
    if config.depth_band_m is not None:
        good &= np.abs(z2 - median(z_m)) < config.depth_band_m
    if np.count_nonzero(good) < _DEPTH_RATE_MIN_ROWS:
        return None
    slope = 0.5 * np.hypot((c[1] - c[0]) + (c[3] - c[2]), (c[2] - c[0]) + (c[3] - c[1]))
    idx, z2, u2, v2, slope = idx[good], z2[good], u2[good], v2[good], slope[good]
    z1 = z_m[idx]
    # the points' mean position over the interval (camera frame) [m]
    cx, cy, fx, fy = intrinsics.cx_px, intrinsics.cy_px, intrinsics.fx_px, intrinsics.fy_px
    x_mean = 0.5 * ((u_px[idx] - cx) / fx * z1 + (u2 - cx) / fx * z2)
    y_mean = 0.5 * ((v_px[idx] - cy) / fy * z1 + (v2 - cy) / fy * z2)
    J = np.zeros((idx.size, 6))
    J[:, 2] = dt_s
    J[:, 3] = y_mean * dt_s
    J[:, 4] = -x_mean * dt_s
    return DepthRateRows(
        u_px=u_px[idx],
        v_px=v_px[idx],
        dz_m=z2 - z1,
        J=J,
        slope_m_per_px=slope,
        cell_weight=None if cell_weight is None else cell_weight[idx],
    )


def _depth_rate_weights(
    rows: DepthRateRows, x_prior: F64, flow_sigma_px: float, config: VelocityKFConfig
) -> tuple[F64, F64]:
    """Innovations (M,) [m] of the depth-change rows from ``x_prior`` (6,) and their weights
    (M,) [1/m^2].

    Each row's variance is ``sigma^2 + (slope * flow_sigma_px)^2``: the depth noise ``sigma``
    and the flow's error carried through the depth gradient where the point is read (a point
    read on a steep flank, an object's limb, measures its depth change poorly). ``sigma`` is
    the robust spread of the rows' residuals about their own weighted least-squares fit of the
    three components they observe (v_z, w_x, w_y), at least ``depth_rate_sigma_min_m``; twice,
    each time dropping the rows beyond ``depth_rate_inlier_sigmas`` of their standard
    deviation."""
    innovation = rows.dz_m - rows.J @ x_prior
    A = np.ascontiguousarray(rows.J[:, 2:5])
    spread = (rows.slope_m_per_px * flow_sigma_px) ** 2
    keep: NDArray[np.bool_] | None = None  # None: every row
    sigma = config.depth_rate_sigma_min_m
    variance = sigma**2 + spread
    for _ in range(2):
        if keep is None:
            fit = _weighted_fit(A, innovation, 1.0 / variance)
        elif np.count_nonzero(keep) < _DEPTH_RATE_MIN_ROWS:
            return innovation, np.zeros_like(innovation)
        else:
            fit = _weighted_fit(A[keep], innovation[keep], 1.0 / variance[keep])
        distance = np.abs(innovation - A @ fit)
        kept = distance if keep is None else distance[keep]
        sigma = max(config.depth_rate_sigma_min_m, MAD_TO_SIGMA * median(kept))
        variance = sigma**2 + spread
        keep = distance <= config.depth_rate_inlier_sigmas * np.sqrt(variance)
    weight = np.asarray(keep, dtype=np.float64) / variance
    if rows.cell_weight is not None:
        weight = weight * rows.cell_weight
    return innovation, weight


def _weighted_fit(A: F64, b: F64, weight: F64) -> F64:
    """The weighted least-squares solution (n,) of ``A x = b`` (A (M, n), b (M,)) with weights
    ``weight`` (M,) (inverse variances): the normal equations, or, when they are singular
    (points on a line), ``lstsq``'s minimum-norm solution."""
    AtW = A.T * weight
    try:
        x = np.asarray(np.linalg.solve(AtW @ A, AtW @ b), dtype=np.float64)
        if np.isfinite(x).all():
            return x
    except np.linalg.LinAlgError:
        pass
    w = np.sqrt(weight)
    return np.asarray(np.linalg.lstsq(A * w[:, None], b * w, rcond=None)[0], dtype=np.float64)


_OCCLUDER_MIN_PIXELS = 12
"""Fewer sampled pixels than this: no occluder test (too few to fit a motion and test parts)."""
_OCCLUDER_PART_MIN_PIXELS = 5
"""A depth part with fewer sampled pixels is never tested (too few for its mean flow)."""


_NEIGHBOURS_8 = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
"""The 8-neighbourhood ``(dv, du)``, in the order ties are broken (the first wins)."""


def _edge_pixel_labels(
    labels: NDArray[np.int32],
    z: NDArray[np.floating],
    rows: NDArray[np.int64],
    cols: NDArray[np.int64],
    jump_m: float,
) -> NDArray[np.int32]:
    """The labels (M,) of the mask pixels ``(rows, cols)`` of the box that lie on a depth edge
    (label 0): each takes the label of its 8-neighbour nearest in depth among the labelled ones
    within ``jump_m`` (the first such neighbour of :data:`_NEIGHBOURS_8` on a tie; 0 if none),
    so the pixels on either side of a cut join their own side."""
    pad_l = np.pad(labels, 1)
    pad_z = np.pad(z, 1, constant_values=np.inf)
    r, c = rows + 1, cols + 1
    gaps = np.empty((rows.size, len(_NEIGHBOURS_8)))
    near = np.empty((rows.size, len(_NEIGHBOURS_8)), dtype=np.int32)
    here = pad_z[r, c]
    for i, (dv, du) in enumerate(_NEIGHBOURS_8):
        near[:, i] = pad_l[r + dv, c + du]
        gaps[:, i] = np.abs(pad_z[r + dv, c + du] - here)
    gaps[(near <= 0) | ~(gaps <= jump_m)] = np.inf
    best = np.argmin(gaps, axis=1)
    found = np.isfinite(gaps[np.arange(rows.size), best])
    return np.where(found, near[np.arange(rows.size), best], 0).astype(np.int32)


def occluder_free(
    pixels: PixelSet,
    depth_m: NDArray[np.floating],
    u: NDArray[np.int64],
    v: NDArray[np.int64],
    z: F64,
    y: F64,
    J: F64,
    config: VelocityKFConfig,
) -> NDArray[np.bool_]:
    """Which sampled pixels to keep: not those of a part of the mask that lies in front of the
    object and moves otherwise (a hand the mask has spilled onto).

    The mask of frame k-1 is cut where adjacent pixels differ in depth by more than
    ``config.occluder_depth_jump_m``; the part holding most sampled pixels is the object, and its
    pixels' least-squares twist predicts the flow of the others. A part is dropped when its
    median depth is more than the jump in front of the object's and its mean flow residual lies
    outside the ``config.occluder_probability`` prediction region of one pixel (the object's
    twist covariance propagated, plus one pixel's flow noise, the robust spread of the object's
    residuals): with exact or white-noise flow a hand's flow differs by pixels from the
    object's. A part whose flow a dense estimator (DIS, NVOF) has smoothed to within that
    region is kept, and so is every part behind or beside the object; with such flow the test
    can also drop a part of the object itself whose flow error differs (docs/roft.md, "Round
    8").

    Args:
        pixels: the mask of frame k-1 (all its pixels, before the stride).
        depth_m: (H, W) z-depth of frame k-1 [m].
        u, v: (N,) columns and rows of the sampled, valid pixels.
        z: (N,) their depth [m].
        y: (N, 2) their flow [px].
        J: (N, 2, 6) their flow Jacobian [px per (m/s), px per (rad/s)].
        config: the filter settings.

    Returns:
        (N,) bool, True for the pixels to use.
    """
    keep = np.ones(len(u), dtype=bool)
    jump = float(config.occluder_depth_jump_m or 0.0)
    window = mask_window(pixels)
    h, w = pixels.shape
    rows, cols = window.bits.shape
    # the window cropped to the image (no mask pixel lies outside it)
    r_lo, c_lo = max(0, -window.r0), max(0, -window.c0)
    r_hi, c_hi = min(rows, h - window.r0), min(cols, w - window.c0)
    box = window.bits[r_lo:r_hi, c_lo:c_hi].astype(bool)
    v0, u0 = window.r0 + r_lo, window.c0 + c_lo
    zb = depth_m[v0 : v0 + box.shape[0], u0 : u0 + box.shape[1]]
    if zb.dtype != np.float32:  # (float32 depths: their near differences are exact in float32)
        zb = zb.astype(np.float64)
    box &= zb > 0.0
    cut = np.zeros_like(box)
    dx = (np.abs(np.diff(zb, axis=1)) > jump) & box[:, 1:] & box[:, :-1]
    cut[:, 1:] |= dx
    cut[:, :-1] |= dx
    dy = (np.abs(np.diff(zb, axis=0)) > jump) & box[1:, :] & box[:-1, :]
    cut[1:, :] |= dy
    cut[:-1, :] |= dy
    n_parts, labels = cv2.connectedComponents((box & ~cut).astype(np.uint8), connectivity=4)
    if n_parts <= 2:  # the background label and at most one part
        return keep
    labels = np.asarray(labels, dtype=np.int32)
    rows, cols = v - v0, u - u0
    part = labels[rows, cols]  # 0: an edge pixel no part claims (kept, not tested)
    edge = np.flatnonzero(part == 0)
    if edge.size:
        part[edge] = _edge_pixel_labels(labels, zb, rows[edge], cols[edge], jump)
    counts = np.bincount(part, minlength=n_parts)
    counts[0] = 0
    main = int(np.argmax(counts))
    on_main = part == main
    A = J[on_main].reshape(-1, 6)
    H = A.T @ A
    try:
        twist = np.linalg.solve(H, A.T @ y[on_main].reshape(-1))
        H_inv = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return keep
    residual = y[on_main] - flow_rows_at(J[on_main], twist)
    # per-component flow variance: the median of |r|^2 (chi-square, 2 dof: median 1.386 s^2) / 2
    var_px2 = max(median(np.sum(residual * residual, axis=1)) / (2.0 * 1.3863), 1e-12)
    limit = chi2_quantile(config.occluder_probability, 2)
    z_main = median(z[on_main])
    for label in np.unique(part[(part != 0) & ~on_main]):
        idx = np.flatnonzero(part == label)
        if len(idx) < _OCCLUDER_PART_MIN_PIXELS or not median(z[idx]) < z_main - jump:
            continue
        mean_residual = (y[idx] - J[idx] @ twist).mean(axis=0)
        J_mean = J[idx].mean(axis=0)
        C = var_px2 * (J_mean @ H_inv @ J_mean.T + np.eye(2))
        if float(mean_residual @ np.linalg.solve(C, mean_residual)) > limit:
            keep[idx] = False
    return keep


def _measurement_jacobian(
    intrinsics: CameraIntrinsics,
    u: NDArray[np.int64],
    v: NDArray[np.int64],
    z: F64,
    y: F64,
    dt_s: float,
    config: VelocityKFConfig,
) -> F64:
    """(N, 2, 6) flow Jacobian of the measurement's pixels, evaluated at the pixel of k-1 or,
    with ``config.midpoint_jacobian``, half the pixels' median displacement ``y`` (N, 2) [px]
    further (VelocityKFConfig)."""
    shift = np.zeros(2)  # where the Jacobian is evaluated, from each pixel of k-1 [px]
    if config.midpoint_jacobian and u.size:
        shift = 0.5 * column_medians(y)
    return flow_jacobian(intrinsics, u + shift[0], v + shift[1], z, dt_s)


def flow_measurement(
    pixels: PixelSet,
    depth_m: NDArray[np.floating],
    flow: FlowField,
    intrinsics: CameraIntrinsics,
    dt_s: float,
    config: VelocityKFConfig,
    *,
    stride: int | None = None,
    linearization_twist: ArrayLike | None = None,
    next_depth_m: NDArray[np.floating] | None = None,
) -> FlowMeasurement:
    """Builds the flow measurement from the mask and depth of frame k-1 and the flow F_k
    (the Jacobian at each pixel of k-1, or half the pixels' median displacement further with
    ``config.midpoint_jacobian``).

    Args:
        pixels: mask of frame k-1; every ``config.subsampling_stride``-th pixel (row-major list)
            is used, before the validity filter, as the reference does.
        depth_m: (H, W) z-depth of frame k-1 [m]; pixels outside (0, depth_maximum_m) are dropped.
        flow: F_k, frame k-1 -> k; NaN, invalid or huge vectors are dropped.
        intrinsics: the camera.
        dt_s: time between the two frames [s].
        config: the filter settings.
        stride: the subsampling stride (default ``config.subsampling_stride`` as given; the
            tracker passes ``config.stride(width)``).
        linearization_twist: (6,) ``(v_o [m/s], w [rad/s])`` at which
            ``config.finite_motion_correction`` corrects the flow (the tracker passes the
            velocity filter's interval mean once it has one); None: the pixels' own
            least-squares twist.
        next_depth_m: (H, W) z-depth of frame k [m]: with ``config.depth_rate``, each pixel's
            depth change where the flow carries it is measured too (:func:`depth_rate_rows`);
            None: the flow alone.
    """
    step = stride if stride is not None else config.subsampling_stride
    index, u, v = pixels.strided(step)
    z = np.take(depth_m.reshape(-1), index).astype(np.float64)
    w = pixels.shape[1]
    dense = flow.flow_px.shape[:2] == pixels.shape  # read at the pixels' own indices
    f, ok = lookup_flow(flow, u, v, index if dense else None)
    ok &= (z > 0.0) & (z < config.depth_maximum_m)
    if config.depth_band_m is not None and ok.any():
        ok &= np.abs(z - median(z[ok])) < config.depth_band_m
    if not ok.all():
        u, v, z, f = u[ok], v[ok], z[ok], f[ok]
    y = f.view(np.float32).reshape(-1, 2).astype(np.float64)  # (du, dv) per pixel
    flow_px = y  # as measured: where each point went (the corrections below change y)
    J: F64 | None = None
    if config.occluder_depth_jump_m is not None and u.size >= _OCCLUDER_MIN_PIXELS:
        J = _measurement_jacobian(intrinsics, u, v, z, y, dt_s, config)
        keep = occluder_free(pixels, depth_m, u, v, z, y, J, config)
        if not keep.all():  # the midpoint moves with the pixels kept
            u, v, z, y, J = u[keep], v[keep], z[keep], y[keep], None
            flow_px = y
    if J is None:
        J = _measurement_jacobian(intrinsics, u, v, z, y, dt_s, config)
    relinearize: Callable[[F64], F64] | None = None
    if config.finite_motion_correction and linearization_twist is not None:
        motion, measured, jacobian = _FiniteMotion(intrinsics, u, v, z), y, J

        def corrected_at(twist: F64) -> F64:
            return motion.corrected(measured, jacobian, dt_s, twist)

        y = corrected_at(np.asarray(linearization_twist, dtype=np.float64))
        relinearize = corrected_at
    elif config.finite_motion_correction and u.size >= _FINITE_MOTION_MIN_PIXELS:
        # no filter estimate yet: at the pixels' own least-squares twist, re-fitted on the
        # corrected flow
        motion, measured = _FiniteMotion(intrinsics, u, v, z), y
        for _ in range(_FINITE_MOTION_FITS):
            fit = np.linalg.lstsq(J.reshape(-1, 6), y.reshape(-1), rcond=None)[0]
            y = motion.corrected(measured, J, dt_s, np.asarray(fit, dtype=np.float64))
    cell_weight = None
    if config.independent_pixels_per_cell and flow.grid_px > 1 and u.size:
        g = flow.grid_px
        _, inverse, counts = np.unique(
            (v // g) * (w // g + 1) + u // g, return_inverse=True, return_counts=True
        )
        cell_weight = 1.0 / counts[inverse].astype(np.float64)
    depth_rate = None
    if config.depth_rate and next_depth_m is not None and u.size:
        depth_rate = depth_rate_rows(
            intrinsics, u, v, z, flow_px, next_depth_m, dt_s, config, cell_weight
        )
    return FlowMeasurement(
        y_px=y,
        J=J,
        u_px=u,
        v_px=v,
        cell_weight=cell_weight,
        relinearize=relinearize,
        depth_rate=depth_rate,
        grid_px=flow.grid_px,
    )


def laplacian_likelihood(innovation_px: F64, pairs: str = "correct") -> F64:
    """Per-pixel robust weights ``(N,)`` in (0, 1] from innovations ``(N, 2)`` [px].

    ``mu`` = median and ``b`` = mean absolute deviation of the innovation norms; each pixel gets
    ``max(exp(-| |e_j| - mu | / b) / (2 b), 1e-6)``, divided by the largest; all 1 if
    ``b <= 1e-4``. ``pairs = "reference"`` takes ``mu`` and ``b`` from the reference's mis-paired
    norms (element r with element r + N of the stacked vector (du_0, dv_0, du_1, ...)).
    """
    e = np.asarray(innovation_px, dtype=np.float64)
    norms = np.sqrt(np.einsum("ij,ij->i", e, e))
    if pairs == "reference":
        flat = e.reshape(-1)
        n = e.shape[0]
        stats_norms = np.hypot(flat[:n], flat[n:])
    else:
        stats_norms = norms
    mu = median(stats_norms)
    distance = np.abs(norms - mu)
    spread = distance if stats_norms is norms else np.abs(stats_norms - mu)
    b = float(spread.sum()) / spread.shape[0]
    if not b > _MIN_SPREAD:
        return np.ones(e.shape[0])
    lik = np.maximum(np.exp(distance * (-1.0 / b)) / (2.0 * b), _LIKELIHOOD_FLOOR)
    out: F64 = lik / float(lik.max())
    return out


class VelocityKF:
    """Linear KF of the spatial twist (v_o, w); batched information-form update.

    One motion model: ``constant`` (the reference's random-walk twist) or
    ``constant_acceleration`` (``velocity.motion_model = "auto"`` runs one of each:
    :func:`roft_sim.trackers.roft.velocity_selector.make_velocity_filter` builds the filter a
    configuration asks for).

    With the reference settings (``adapt_flow_noise`` off) the constant model is the
    reference's filter; the adaptive parts are described on :class:`VelocityKFConfig`.
    """

    def __init__(
        self,
        config: VelocityKFConfig,
        width_px: int | None = None,
        model: Literal["constant", "constant_acceleration"] = "constant",
    ):
        """Args:
        config: the settings.
        width_px: image width [px] for the resolution scaling of the flow noise (None: the
            noise as given).
        model: the motion model.
        """
        self._config = config
        self._model = model
        self._Q_base = np.concatenate([config.sigma_linear, config.sigma_angular]).astype(
            np.float64
        )
        self._R = np.asarray(
            config.flow_variance_px2(width_px) if width_px is not None else config.cov_flow,
            dtype=np.float64,
        )
        self.reset()

    def reset(self) -> None:
        cfg = self._config
        self.x: F64 = np.concatenate([cfg.initial_v_mps, cfg.initial_w_radps]).astype(np.float64)
        """(6,) mean (v_o [m/s], w [rad/s]): the mean twist over the last corrected interval."""
        self.P: F64 = np.diag(np.concatenate([cfg.cov_v0, cfg.cov_w0])).astype(np.float64)
        """(6, 6) covariance."""
        self.x_frame: F64 = self.x.copy()
        """(6,) the twist reported for the last frame: ``x`` for the constant model, the twist
        at the frame for the constant-acceleration model."""
        self.q_diag: F64 = self._Q_base.copy()
        """(6,) the process noise variance per frame."""
        self.flow_sigma_px: F64 = np.sqrt(self._R)
        """(2,) the flow noise standard deviation used by the last update [px]."""
        # the constant-acceleration model: (12,) state (twist at t_s [m/s, rad/s], its
        # rate [m/s^2, rad/s^2]) at time _t_s [s], covariance (12, 12); the prior covariance of
        # the twist is the constant model's at its first update (cov_*0 plus one frame of Q)
        self.X: F64 = np.concatenate([self.x, np.zeros(6)])
        """(12,) ``constant_acceleration`` state: (twist at the last update's frame, its rate
        d/dt) [m/s, rad/s, m/s^2, rad/s^2], camera frame."""
        self.P_X: F64 = np.diag(
            np.concatenate(
                [
                    np.diag(self.P) + self._Q_base,
                    np.repeat([cfg.cov_rate0_linear, cfg.cov_rate0_angular], 3),
                ]
            )
        )
        """(12, 12) covariance of ``X``."""
        self._t_s: float | None = None
        self._twist_noise_sum = np.zeros(6)
        self._twist_noise_weight = 0.0
        self.twist_noise: F64 = np.zeros(6)
        """(6,) the constant-acceleration model: the variance of the flow's interval-mean twist
        that the per-pixel noise does not explain [(m/s)^2, (rad/s)^2]."""
        self.updates = 0
        """Number of corrections so far (0: the twist is the prior, no flow has been used)."""
        self._priors: dict[tuple[float | None, ...], tuple[F64, _Prior]] = {}
        self._transitions: dict[float, tuple[F64, F64]] = {}
        self.rows: _Rows | None = None
        """The weighted rows of the last update (None before it)."""
        self.fit: tuple[F64, F64] | None = None
        """The pixels of the last update on their own: their weighted least-squares interval-mean
        twist ``m_ls`` (6,) [m/s, rad/s] and its information ``P_ls^-1`` (6, 6) (the robust
        weights and flow noise of that update); None before the first update or when the pixels
        did not observe the whole twist."""

    def copy(self) -> VelocityKF:
        """An independent copy of this filter (its arrays are never changed in place, so they
        are shared until either filter replaces them)."""
        out = copy.copy(self)
        out._priors = {}  # a cache of this filter's state
        return out

    def _robust_weights(
        self,
        measurement: FlowMeasurement,
        x_prior: F64,
        prior: _Prior,
        *,
        with_noise: bool = True,
    ) -> tuple[F64, F64, F64, F64]:
        """The per-pixel weights and flow noise of one update from the prior twist.

        Args:
            measurement: the flow pixels (``J`` (N, 2, 6), ``y_px`` (N, 2) [px]).
            x_prior: (6,) prior spatial twist ``(v_o [m/s], w [rad/s])``, camera frame.
            prior: its covariance (and inverse).
            with_noise: estimate the flow noise (``adapt_flow_noise``); False when only the
                update is wanted (the relinearisation).

        Returns:
            ``(innovation (N, 2) [px], lik (N,), R (2,) [px^2], dx (6,))``: the Laplacian
            likelihood weights (times the grid-cell weights), the flow noise (``cov_flow``, or
            the robust spread of the residuals when ``adapt_flow_noise`` and larger), and the
            update of the twist with the configured noise (the residuals' reference).
        """
        cfg = self._config
        J, y = measurement.J, measurement.y_px
        innovation = y - flow_rows_at(J, x_prior)  # (N, 2)
        if cfg.weight_flow:
            lik = laplacian_likelihood(innovation, cfg.reweighting_pairs)
        else:
            lik = np.ones(len(measurement))
        if measurement.cell_weight is not None:
            lik = lik * measurement.cell_weight
        R = self._R
        J2 = J.reshape(-1, 6)
        dx = _update_step(prior, J2, innovation, (lik[:, None] / R[None, :]).reshape(-1))
        if with_noise and cfg.adapt_flow_noise:
            residual = y - flow_rows_at(J, x_prior + dx)
            spread = MAD_TO_SIGMA * column_medians(np.abs(residual))
            R = np.maximum(R, spread**2)
        return innovation, lik, R, dx

    def _exact_flow_ratio(
        self, measurement: FlowMeasurement, lik: F64, innovation: F64, x_prior: F64, R: F64
    ) -> float:
        """``exact_flow_spread_px``: the factor on the flow noise, from the robust spread of the
        pixels' residuals about their own weighted least-squares twist (no prior: the prior's
        lag would show in the residuals of any flow), 1 for any estimated flow.

        Only a dense flow (one vector per pixel) whose vectors are nearly all distinct, at least
        ``_EXACT_FLOW_MIN_VECTORS`` of them, can count as exact: a few distinct vectors (a
        small object on NVOF's 4x4 grid, quantised flow of a still object) are fitted by six
        parameters without residual whatever their error.

        Args:
            measurement: the pixels (``J`` (N, 2, 6), ``y_px`` (N, 2) [px], ``grid_px``).
            lik: (N,) their robust weights.
            innovation: (N, 2) ``y - J x_prior`` [px].
            x_prior: (6,) the twist the flow is linearised about [m/s, rad/s].
            R: (2,) the flow noise [px^2] (the weights' scale only).
        """
        J, y = measurement.J, measurement.y_px
        if measurement.grid_px != 1 or len(y) < _EXACT_FLOW_MIN_VECTORS:
            return 1.0
        if measurement.distinct_vectors() < max(_EXACT_FLOW_MIN_VECTORS, 0.9 * len(y)):
            return 1.0
        J2 = J.reshape(-1, 6)
        fit = _least_squares(
            J2, (lik[:, None] / R[None, :]).reshape(-1), innovation.reshape(-1), x_prior
        )
        if fit is None:
            return 1.0
        spread = MAD_TO_SIGMA * float(column_medians(np.abs(y - flow_rows_at(J, fit[0]))).max())
        ratio = (spread / float(self._config.exact_flow_spread_px or np.inf)) ** 2
        return min(max(ratio, _EXACT_FLOW_NOISE_RATIO), 1.0)

    def _weighted_rows(self, measurement: FlowMeasurement, x_prior: F64, prior: _Prior) -> _Rows:
        """Every measurement row of one update, weighted, from the prior twist.

        Args:
            measurement: the flow pixels and, with ``depth_rate``, their depth changes.
            x_prior: (6,) prior spatial twist ``(v_o [m/s], w [rad/s])``, camera frame.
            prior: its covariance (and inverse).

        Returns:
            The flow's two rows per pixel (``dt * J`` [px per (m/s), px per (rad/s)], weights
            ``lik / R`` [1/px^2], values [px]; :meth:`_robust_weights`, R times
            :meth:`_exact_flow_ratio`) followed by the depth-change rows ([m per (m/s), m per
            (rad/s)], [1/m^2], [m]; :func:`_depth_rate_weights`), and the flow noise.
        """
        innovation, lik, R, _ = self._robust_weights(measurement, x_prior, prior)
        cfg = self._config
        if cfg.adapt_flow_noise and cfg.exact_flow_spread_px is not None:
            # here, not in _robust_weights: relinearized() uses only its update, not R
            R = R * self._exact_flow_ratio(measurement, lik, innovation, x_prior, R)
        J = measurement.J.reshape(-1, 6)
        W = (lik[:, None] / R[None, :]).reshape(-1)
        z = measurement.y_px.reshape(-1)
        nu = innovation.reshape(-1)
        rows = measurement.depth_rate
        if rows is not None and self._config.depth_rate and len(rows):
            flow_sigma_px = float(np.sqrt(np.mean(R)))
            nu_z, W_z = _depth_rate_weights(rows, x_prior, flow_sigma_px, self._config)
            J = np.vstack([J, rows.J])
            W = np.concatenate([W, W_z])
            z = np.concatenate([z, rows.dz_m])
            nu = np.concatenate([nu, nu_z])
        return _Rows(J, W, z, R, x_prior, nu)

    def step(
        self,
        measurement: FlowMeasurement | None,
        *,
        frames: float = 1.0,
        t_s: float | None = None,
        dt_s: float | None = None,
    ) -> bool:
        """Predicts over ``frames`` nominal frames and corrects with ``measurement``.

        Args:
            measurement: the flow measurement of the interval, or None.
            frames: how many nominal frame intervals the flow spans (Q scales with it).
            t_s: time of the current frame [s] (for the constant-acceleration model).
            dt_s: the interval the flow spans [s] (for the constant-acceleration model).

        Returns:
            True if the belief was updated; False if there was no measurement or fewer than
            ``min_pixels`` valid pixels, in which case the previous corrected belief is kept
            (the prediction is undone, as in the reference).
        """
        cfg = self._config
        if measurement is None or len(measurement) < cfg.min_pixels:
            return False
        if measurement.relinearize is not None:
            measurement = self.relinearized(measurement, frames, t_s, dt_s)
        if self._model == "constant_acceleration":
            if t_s is None or dt_s is None:
                raise ValueError(
                    "the constant-acceleration model needs the frame time t_s and the "
                    "interval dt_s the flow spans"
                )
            mean_pred, prior = self._interval_prior(frames, t_s, dt_s)
            self.correct_with_rows(self._weighted_rows(measurement, mean_pred, prior), t_s, dt_s)
            return True
        self.updates += 1
        x_pred, prior = self._interval_prior(frames, t_s, dt_s)
        rows = self._weighted_rows(measurement, x_pred, prior)
        update = _Update(prior, rows.J, rows.innovation, rows.W)
        self.flow_sigma_px = np.sqrt(rows.R)
        self.fit = update.least_squares(x_pred)
        self.rows = rows
        x_new = x_pred + update.dx
        self.x_frame = x_new
        self.x = x_new
        self.P = update.P_post
        self._priors.clear()
        return True

    def relinearized(
        self,
        measurement: FlowMeasurement,
        frames: float,
        t_s: float | None,
        dt_s: float | None,
    ) -> FlowMeasurement:
        """``measurement`` with its flow corrected for the finite motion at this filter's own
        estimate of the interval (the robust update from the predicted interval mean, twice:
        iterated-EKF steps; nothing of the filter changes) and ``relinearize`` cleared.
        :meth:`step` calls it when the measurement can be relinearised."""
        x_pred, prior = self._interval_prior(frames, t_s, dt_s)
        relinearize = measurement.relinearize
        assert relinearize is not None  # checked by the caller
        for _ in range(_RELINEARIZATIONS):
            dx = self._robust_weights(measurement, x_pred, prior, with_noise=False)[3]
            measurement = dataclasses.replace(measurement, y_px=relinearize(x_pred + dx))
        return dataclasses.replace(measurement, relinearize=None)

    def _interval_prior(
        self, frames: float, t_s: float | None, dt_s: float | None
    ) -> tuple[F64, _Prior]:
        """The predicted interval-mean twist (6,) and its covariance (6, 6, with its inverse)
        that the flow of the interval ``(t_s - dt_s, t_s]`` is weighed against: ``x`` and ``P``
        plus ``frames`` frames of Q for the constant model; ``M X-`` and ``M P- M^T`` for
        ``constant_acceleration`` (constant-model form without the times). Kept until the
        next update: the relinearisation and the update weigh against the same prior."""
        accel = self._model == "constant_acceleration" and t_s is not None and bool(dt_s)
        key = (t_s, dt_s) if accel else (frames,)
        cached = self._priors.get(key)
        if cached is not None:
            return cached
        if accel and t_s is not None and dt_s is not None:
            X_pred, P_X = self._predict_constant_acceleration(t_s, dt_s)
            M = _interval_mean_map(dt_s)
            out = (M @ X_pred, _Prior(M @ P_X @ M.T))
        else:
            out = (self.x, _Prior(self.P + np.diag(self.q_diag * max(frames, 1e-9))))
        self._priors[key] = out
        return out

    def predicted_interval_mean(self, t_s: float, dt_s: float) -> F64:
        """The mean twist (6,) [m/s, rad/s] this filter predicts for the interval
        ``(t_s - dt_s, t_s]`` before seeing its flow: ``x`` for the constant model, ``M F X``
        (the predicted twist at ``t_s`` less half an interval of its rate) for
        ``constant_acceleration``."""
        if self._model != "constant_acceleration":
            return self.x.copy()
        X_pred, _ = self._predict_constant_acceleration(t_s, dt_s)
        out: F64 = X_pred[:6] - 0.5 * dt_s * X_pred[6:]
        return out

    def _predict_constant_acceleration(self, t_s: float, dt_s: float) -> tuple[F64, F64]:
        """``X`` (12,) and ``P_X`` (12, 12) carried from the last update to ``t_s`` [s] (over
        the flow's interval ``dt_s`` [s] before the first update)."""
        h = max(t_s - self._t_s if self._t_s is not None else dt_s, 0.0)
        F, Q = self._transition(h)
        return F @ self.X, F @ self.P_X @ F.T + Q

    def _transition(self, h: float) -> tuple[F64, F64]:
        """The constant-acceleration model's ``F = [[I, h I], [0, I]]`` (12, 12) and white-jerk
        ``Q = q [[h^3/3, h^2/2], [h^2/2, h]]`` per component (12, 12) over ``h`` [s]."""
        cached = self._transitions.get(h)
        if cached is not None:
            return cached
        cfg = self._config
        eye = np.eye(6)
        F = np.zeros((12, 12))
        F[:6, :6] = eye
        F[:6, 6:] = h * eye
        F[6:, 6:] = eye
        q = np.repeat([cfg.rate_psd_linear, cfg.rate_psd_angular], 3)
        Q = np.zeros((12, 12))
        Q[:6, :6] = np.diag(q * h**3 / 3.0)
        Q[:6, 6:] = np.diag(q * h**2 / 2.0)
        Q[6:, :6] = np.diag(q * h**2 / 2.0)
        Q[6:, 6:] = np.diag(q * h)
        if len(self._transitions) > 8:  # the frame interval rarely varies
            self._transitions.clear()
        self._transitions[h] = (F, Q)
        return F, Q

    def _initialise_constant_acceleration(
        self, m_ls: F64, P_ls: F64, P_pred: F64, t_s: float, dt_s: float
    ) -> None:
        """The first flow initialises the ``constant_acceleration`` state (a Bayesian update of
        the zero prior would split the object's whole initial twist between the twist and the
        rate, and covariance matching would read it as twist noise: with ground-truth inputs
        that was 91 cm/s of error on frame 1 of TUM room1 at 640x360 and 10-29 cm/s on the
        next ten frames, docs/roft.md).

        The pixels fix the interval mean ``m_ls`` (6,) with covariance ``P_ls`` (6, 6); the
        rate ``b`` keeps its prior (zero mean, covariance ``P_b`` from ``P_pred`` (12, 12)),
        and the twist at ``t_s`` is ``m_ls + b dt_s / 2``: ``X = (m_ls, 0)``, ``P_X = [[P_ls +
        P_b dt^2 / 4, P_b dt / 2], [P_b dt / 2, P_b]]``.
        """
        P_b = P_pred[6:, 6:]
        half = 0.5 * dt_s
        self.X = np.concatenate([m_ls, np.zeros(6)])
        self.P_X = np.block([[P_ls + half**2 * P_b, half * P_b], [half * P_b, P_b]])
        self._t_s = t_s
        self.x = m_ls.copy()
        self.P = P_ls.copy()
        self.x_frame = m_ls.copy()

    def correct_with_rows(self, rows: _Rows, t_s: float, dt_s: float) -> None:
        """One predict/correct of the constant-acceleration state with the interval's rows,
        weighed about this model's own prediction of the interval mean.

        Predicts ``X`` from its time to ``t_s`` (``F = [[I, h I], [0, I]]``, white jerk
        ``Q = q [[h^3/3, h^2/2], [h^2/2, h]]`` per component). The flow over ``(t_s - dt_s, t_s]``
        measures the interval mean ``M X = twist - rate dt / 2``; the pixels are first reduced to
        their least-squares interval mean ``m_ls`` with covariance ``P_ls`` (the information
        form of the constant model, robust weights included), then ``m_ls`` corrects ``X`` with
        noise ``P_ls + diag(r)``: ``r`` is the running mean of
        ``nu^2 - diag(M P- M^T + P_ls)`` over ``rate_noise_memory`` updates (covariance
        matching on the innovations ``nu = m_ls - M X-``), the error of the flow's twist that
        the per-pixel noise does not explain (pixels that are wrong together: a stale mask, flow
        smoothed across the silhouette). Without ``r`` the rate would follow that error. Leaves
        the interval mean and its covariance in ``x`` / ``P`` (the UKF's measurement) and the
        twist at ``t_s`` in ``x_frame``.
        """
        cfg = self._config
        self.updates += 1
        X_pred, P_pred = self._predict_constant_acceleration(t_s, dt_s)
        M = _interval_mean_map(dt_s)
        mean_pred, prior = self._interval_prior(1.0, t_s, dt_s)  # M X-, M P- M^T
        P_mean = prior.P
        J2, W, innovation = rows.J, rows.W, rows.innovation_at(mean_pred)
        self.flow_sigma_px = np.sqrt(rows.R)
        self.rows = rows
        self._priors.clear()
        JtW = J2.T * W
        info_ls = JtW @ J2
        try:
            P_ls = np.linalg.inv(info_ls)
        except np.linalg.LinAlgError:  # the pixels do not observe the whole twist
            P_ls = None
        if P_ls is None or not np.isfinite(P_ls).all():
            # pixel-level update without the twist noise
            self.fit = None
            update = _Update(_Prior(P_pred), J2 @ M, innovation, W)
            dX, P_post = update.dx, update.P_post
        else:
            P_ls = 0.5 * (P_ls + P_ls.T)
            nu = P_ls @ (JtW @ innovation.reshape(-1))  # m_ls - M X-
            self.fit = (mean_pred + nu, info_ls)
            if self.updates == 1:
                self._initialise_constant_acceleration(mean_pred + nu, P_ls, P_pred, t_s, dt_s)
                return
            keep = 1.0 - 1.0 / cfg.rate_noise_memory
            sample = np.maximum(nu**2 - np.diag(P_mean) - np.diag(P_ls), 0.0)
            self._twist_noise_sum = keep * self._twist_noise_sum + sample
            self._twist_noise_weight = keep * self._twist_noise_weight + 1.0
            self.twist_noise = self._twist_noise_sum / self._twist_noise_weight
            S = P_mean + P_ls + np.diag(self.twist_noise)
            K = np.linalg.solve(S, M @ P_pred).T  # (12, 6) = P- M^T S^-1
            dX = K @ nu
            P_post = P_pred - K @ S @ K.T
        self.X = X_pred + dX
        self.P_X = 0.5 * (P_post + P_post.T)
        self._t_s = t_s
        self.x = M @ self.X
        P = M @ self.P_X @ M.T
        self.P = 0.5 * (P + P.T)
        self.x_frame = self.X[:6].copy()


@functools.lru_cache(maxsize=16)
def _interval_mean_map(dt_s: float) -> F64:
    """``M`` (6, 12): the ``constant_acceleration`` state (twist at the interval's end, its
    rate) to the mean twist over the interval of ``dt_s`` [s], ``twist - rate dt_s / 2``
    (cached: never change it)."""
    eye = np.eye(6)
    return np.hstack([eye, -0.5 * dt_s * eye])


def _least_squares(J2: F64, W: F64, innovation: F64, x_prior: F64) -> tuple[F64, F64] | None:
    """The pixels' own weighted least-squares twist and its information.

    Args:
        J2: (M, 6) every measurement row's Jacobian (the flow's two per pixel [px per (m/s),
            px per (rad/s)], then any depth-change rows [m per (m/s), m per (rad/s)]).
        W: (M,) their weights (robust weight / noise variance) [1/px^2, 1/m^2].
        innovation: (M,) measurement minus the prediction of ``x_prior`` [px, m].
        x_prior: (6,) the twist the innovation was taken from [m/s, rad/s].

    Returns:
        ``(m_ls (6,) [m/s, rad/s], J^T W J (6, 6))``, or None when ``J^T W J`` is singular.
    """
    JtW = J2.T * W
    return _solved_fit(JtW @ J2, JtW @ innovation.reshape(-1), x_prior)


def _solved_fit(info: F64, rhs: F64, x_prior: F64) -> tuple[F64, F64] | None:
    """``(x_prior + info^-1 rhs, info)``, or None when ``info`` (6, 6) is singular or the
    solution not finite."""
    try:
        d = np.linalg.solve(info, rhs)
    except np.linalg.LinAlgError:
        return None
    if not np.isfinite(d).all():
        return None
    return x_prior + d, info


@dataclass(frozen=True, slots=True)
class _Rows:
    """Every weighted measurement row of one update: the flow's two rows per pixel, then any
    depth-change rows (:meth:`VelocityKF._weighted_rows`)."""

    J: F64
    """(M, 6) the rows [px per (m/s), px per (rad/s); m per (m/s), m per (rad/s)]."""
    W: F64
    """(M,) their weights [1/px^2, 1/m^2]."""
    z: F64
    """(M,) the measured values [px, m]."""
    R: F64
    """(2,) the flow noise variance [px^2]."""
    x_prior: F64
    """(6,) the twist the weights were taken about [m/s, rad/s]."""
    innovation: F64
    """(M,) ``z - J x_prior`` (the depth rows' as their weights saw it)."""

    def innovation_at(self, x: F64) -> F64:
        """(M,) the rows' innovations from the twist ``x`` (6,)."""
        if x is self.x_prior:
            return self.innovation
        out: F64 = self.z - self.J @ x
        return out


class _Prior:
    """A prior covariance ``P`` (n, n) and its inverse, computed once."""

    __slots__ = ("P", "P_inv")

    def __init__(self, P: F64):
        self.P = P
        self.P_inv = np.asarray(np.linalg.inv(P), dtype=np.float64)


def _update_step(prior: _Prior, J2: F64, innovation: F64, weight: F64) -> F64:
    """The update ``dx`` (n,) of :class:`_Update` alone (one solve, no posterior covariance)."""
    JtW = J2.T * weight
    out = np.linalg.solve(prior.P_inv + JtW @ J2, JtW @ innovation.reshape(-1))
    return np.asarray(out, dtype=np.float64)


class _Update:
    """The information-form update of a prior by weighted linear rows: ``P+ = (P^-1 + J^T W
    J)^-1`` (symmetrised), ``dx = P+ J^T W nu``.

    Args:
        prior: the prior covariance (n, n) and its inverse.
        J2: (M, n) the rows.
        innovation: (M,) or (M/2, 2) their innovations.
        weight: (M,) their weights.
    """

    __slots__ = ("JtWJ", "rhs", "P_post", "dx")

    def __init__(self, prior: _Prior, J2: F64, innovation: F64, weight: F64):
        JtW = J2.T * weight  # (n, M)
        self.JtWJ: F64 = JtW @ J2
        self.rhs: F64 = JtW @ innovation.reshape(-1)
        P_post = np.linalg.inv(prior.P_inv + self.JtWJ)
        self.P_post: F64 = 0.5 * (P_post + P_post.T)
        self.dx: F64 = self.P_post @ self.rhs

    def least_squares(self, x_prior: F64) -> tuple[F64, F64] | None:
        """The rows' own weighted least-squares solution about ``x_prior`` and its
        information (:func:`_least_squares` of the same rows)."""
        return _solved_fit(self.JtWJ, self.rhs, x_prior)
