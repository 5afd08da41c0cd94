"""The velocity Kalman filter: ROFT's spatial twist from optical flow (paper eqs. 4-9).

State ``x = (v_o, w)`` [m/s, rad/s], camera frame: ``v_o`` is the velocity of the body point at
the camera origin, so a body point P moves as ``dP/dt = v_o + w x P``. Motion model ``F = I``,
``Q`` per frame (not scaled by dt). Measurements: the flow F_k (frame k-1 -> k) at every n-th
mask pixel of frame k-1, predicted as ``dt * J(u, v, Z) x`` with the object-motion interaction
matrix of reference report section 3.2 (depth Z of frame k-1).

The reference updates sequentially, one 2x2 block per pixel; with a block-diagonal R that is
algebraically one batch update, done here in information form with a single 6x6 solve:
``P+ = (P-^-1 + J^T W J)^-1``, ``x+ = x- + P+ J^T W (y - J x-)``, ``W = R^-1`` (diagonal).
The robust reweighting of reference section 3.3 scales each pixel's R by the inverse of a
Laplacian likelihood of its innovation norm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import FlowField
from roft_sim.trackers.roft.config import VelocityKFConfig
from roft_sim.trackers.roft.mask_sync import PixelSet, lookup_flow

F64 = NDArray[np.float64]

__all__ = [
    "FlowMeasurement",
    "flow_measurement",
    "flow_jacobian",
    "laplacian_likelihood",
    "VelocityKF",
]

_LIKELIHOOD_FLOOR = 1e-6
_MIN_SPREAD = 1e-4


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

    def __len__(self) -> int:
        return int(self.y_px.shape[0])


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


def flow_measurement(
    pixels: PixelSet,
    depth_m: NDArray[np.floating],
    flow: FlowField,
    intrinsics: CameraIntrinsics,
    dt_s: float,
    config: VelocityKFConfig,
) -> FlowMeasurement:
    """Builds the flow measurement from the mask and depth of frame k-1 and the flow F_k.

    Args:
        pixels: mask of frame k-1; every ``config.subsampling_stride``-th pixel (row-major list)
            is used, before the validity filter, as the reference does.
        depth_m: (H, W) z-depth of frame k-1 [m]; pixels outside (0, depth_maximum_m) are dropped.
        flow: F_k, frame k-1 -> k; NaN, invalid or huge vectors are dropped.
        intrinsics: the camera.
        dt_s: time between the two frames [s].
        config: the filter settings.
    """
    index = pixels.index[:: config.subsampling_stride]
    z = np.take(depth_m.reshape(-1), index).astype(np.float64)
    w = pixels.shape[1]
    v = index // w
    u = index - v * w
    f, ok = lookup_flow(flow, u, v)
    ok &= (z > 0.0) & (z < config.depth_maximum_m)
    u, v, z, f = u[ok], v[ok], z[ok], f[ok]
    y = np.stack([f.real, f.imag], axis=1).astype(np.float64)
    return FlowMeasurement(y_px=y, J=flow_jacobian(intrinsics, u, v, z, dt_s), u_px=u, v_px=v)


def laplacian_likelihood(innovation_px: F64, pairs: str = "correct") -> F64:
    """Per-pixel robust weights ``(N,)`` in (0, 1] from innovations ``(N, 2)`` [px].

    ``mu`` = median and ``b`` = mean absolute deviation of the innovation norms; each pixel gets
    ``max(exp(-| |e_j| - mu | / b) / (2 b), 1e-6)``, divided by the largest; all 1 if
    ``b <= 1e-4``. ``pairs = "reference"`` takes ``mu`` and ``b`` from the reference's mis-paired
    norms (element r with element r + N of the stacked vector (du_0, dv_0, du_1, ...)).
    """
    e = np.asarray(innovation_px, dtype=np.float64)
    norms = np.hypot(e[:, 0], e[:, 1])
    if pairs == "reference":
        flat = e.reshape(-1)
        n = e.shape[0]
        stats_norms = np.hypot(flat[:n], flat[n:])
    else:
        stats_norms = norms
    mu = float(np.median(stats_norms))
    b = float(np.mean(np.abs(stats_norms - mu)))
    if not b > _MIN_SPREAD:
        return np.ones(e.shape[0])
    lik = np.maximum(np.exp(-np.abs(norms - mu) / b) / (2.0 * b), _LIKELIHOOD_FLOOR)
    return lik / float(lik.max())


class VelocityKF:
    """Linear KF of the spatial twist (v_o, w); batched information-form update."""

    def __init__(self, config: VelocityKFConfig):
        self._config = config
        self._Q = np.diag(np.concatenate([config.sigma_linear, config.sigma_angular]))
        self._R = np.asarray(config.cov_flow, dtype=np.float64)
        self.reset()

    def reset(self) -> None:
        cfg = self._config
        self.x: F64 = np.concatenate([cfg.initial_v_mps, cfg.initial_w_radps]).astype(np.float64)
        """(6,) mean (v_o [m/s], w [rad/s])."""
        self.P: F64 = np.diag(np.concatenate([cfg.cov_v0, cfg.cov_w0])).astype(np.float64)
        """(6, 6) covariance."""

    def step(self, measurement: FlowMeasurement | None) -> bool:
        """Predicts one frame and corrects with ``measurement``.

        Returns:
            True if the belief was updated; False if there was no measurement or fewer than
            ``min_pixels`` valid pixels, in which case the previous corrected belief is kept
            (the prediction is undone, as in the reference).
        """
        if measurement is None or len(measurement) < self._config.min_pixels:
            return False
        x_pred = self.x
        P_pred = self.P + self._Q
        J, y = measurement.J, measurement.y_px
        innovation = y - J @ x_pred  # (N, 2)
        if self._config.weight_flow:
            lik = laplacian_likelihood(innovation, self._config.reweighting_pairs)
        else:
            lik = np.ones(len(measurement))
        W = (lik[:, None] / self._R[None, :]).reshape(-1)  # (2N,) inverse variances
        J2 = J.reshape(-1, 6)
        JtW = J2.T * W  # (6, 2N)
        info = np.linalg.inv(P_pred) + JtW @ J2
        rhs = JtW @ innovation.reshape(-1)
        P_post = np.linalg.inv(info)
        P_post = 0.5 * (P_post + P_post.T)
        self.x = x_pred + P_post @ rhs
        self.P = P_post
        return True
