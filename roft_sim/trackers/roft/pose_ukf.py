"""ROFT's pose UKF on the manifold R^9 x S^3 (paper eqs. 10-13; reference report section 4).

Belief: mean ``x = (v, w, p)`` (9,) and unit quaternion ``q`` (w, x, y, z), covariance (12, 12)
over ``(v, w, p, dtheta)`` where ``dtheta`` is a LEFT (camera-frame) rotation perturbation:
``q_true = exp(dtheta / 2) ⊗ q``. ``v`` [m/s] is the velocity of the object origin, ``w``
[rad/s] the angular velocity, ``p`` [m] the origin, all in the camera frame.

The unscented transform follows the reference (bayes-filters-lib):

- process and measurement noise are AUGMENTED into the sigma points (no additive Q or R);
- the square root of the (block-diagonal) augmented covariance is taken per block by the
  symmetric eigendecomposition, which for positive semi-definite matrices is the SVD
  ``U diag(sqrt(s))`` the reference uses;
- weights from (alpha, beta, kappa) = (1, 2, 0): lambda = 0, so the centre point has mean weight
  0 and covariance weight 2;
- sigma points are ``x + dx``, ``exp(dtheta / 2) ⊗ q``; the quaternion mean is the weighted
  Markley average (eigenvector of the largest eigenvalue of ``sum W q q^T``); offsets are
  ``2 log(q_i ⊗ q_mean^*)``;
- the correction is ``K = P_xy P_yy^-1``, ``q <- exp(K nu / 2) ⊗ q`` with the innovation
  ``nu = (y - y_mean, 2 log(q_meas ⊗ q_mean^*))``, ``P <- P - K P_yy K^T``; no covariance reset.

Deviation: the reference zeroes rotation vectors shorter than 1e-4 in its exp and log maps; here
the maps are exact (series near 0), so tiny rotations are not lost. In the correction, the
state offsets of the sigma points are the exact perturbations that generated them (the
reference recomputes them with its log map; identical below pi).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.so3 import matrix_from_quat, quat_angle, quat_from_matrix
from roft_sim.records import Estimate
from roft_sim.trackers.roft.config import PoseGateConfig, PoseUKFConfig

F64 = NDArray[np.float64]

__all__ = [
    "PoseBelief",
    "PoseUKF",
    "unscented_weights",
    "markley_mean",
    "psd_sqrt",
    "gate_rejects",
    "estimate_from_belief",
    "ESTIMATE_FROM_UKF_INDEX",
    "belief_from_estimate",
]

ESTIMATE_FROM_UKF_INDEX = np.array([6, 7, 8, 9, 10, 11, 0, 1, 2, 3, 4, 5])
"""Permutation taking the UKF covariance order (v, w, p, dtheta) to
:data:`roft_sim.records.ESTIMATE_COVARIANCE_ORDER` (t, r, v, w)."""


@dataclass(frozen=True, slots=True)
class PoseBelief:
    """A Gaussian on R^9 x S^3 (immutable, so beliefs can be buffered for replay)."""

    x: F64
    """(9,) ``(v [m/s], w [rad/s], p [m])``, camera frame."""
    q: F64
    """(4,) unit quaternion (w, x, y, z) of R_cam_obj."""
    P: F64
    """(12, 12) covariance over (v, w, p, dtheta) [SI units squared]."""


def gate_rejects(
    gate: PoseGateConfig, predicted: PoseBelief, p_m: F64, q_wxyz: F64, streak: int
) -> bool:
    """True when a pose is too far from the prediction and the gate may still reject it.

    Args:
        gate: the gate's settings.
        predicted: the belief at the pose's frame, before the correction.
        p_m: (3,) the pose's position, camera frame [m].
        q_wxyz: (4,) the pose's orientation, unit quaternion (w, x, y, z).
        streak: poses rejected in a row before this one (none after
            ``gate.max_consecutive_rejections``).
    """
    if not gate.enable or streak >= gate.max_consecutive_rejections:
        return False
    distance_m = float(np.linalg.norm(p_m - predicted.x[6:9]))
    angle_deg = float(np.degrees(quat_angle(q_wxyz, predicted.q)))
    return distance_m > gate.max_translation_m or angle_deg > gate.max_rotation_deg


def estimate_from_belief(
    k: int,
    belief: PoseBelief,
    *,
    accepted_pose_ids: tuple[int, ...],
    rejected_pose_ids: tuple[int, ...],
    dropped_pose_ids: tuple[int, ...],
    diagnostics: Mapping[str, float | int | str],
    spatial_twist: F64 | None = None,
) -> Estimate:
    """The valid estimate of frame ``k`` held by ``belief``: its pose, velocities and covariance
    (reordered by :data:`ESTIMATE_FROM_UKF_INDEX`); the other fields are the ``Estimate``'s."""
    T_cam_obj = np.eye(4)
    T_cam_obj[:3, :3] = matrix_from_quat(belief.q)
    T_cam_obj[:3, 3] = belief.x[6:9]
    return Estimate(
        k=k,
        T_cam_obj=T_cam_obj,
        v_obj_mps=belief.x[0:3].copy(),
        w_radps=belief.x[3:6].copy(),
        covariance=belief.P[np.ix_(ESTIMATE_FROM_UKF_INDEX, ESTIMATE_FROM_UKF_INDEX)],
        valid=True,
        spatial_twist=spatial_twist,
        accepted_pose_ids=accepted_pose_ids,
        rejected_pose_ids=rejected_pose_ids,
        dropped_pose_ids=dropped_pose_ids,
        diagnostics=diagnostics,
    )


def belief_from_estimate(ukf: PoseUKF, initial: Estimate) -> PoseBelief:
    """The belief an ``Estimate`` describes, the inverse of :func:`estimate_from_belief`: its pose
    and velocities, and its covariance (reordered from the ``Estimate``'s order, symmetrised)
    when it has one, else ``ukf``'s configured initial covariance."""
    T = np.asarray(initial.T_cam_obj, dtype=np.float64)
    belief = ukf.initial_belief(
        T[:3, 3], quat_from_matrix(T[:3, :3]), initial.v_obj_mps, initial.w_radps
    )
    if initial.covariance is None:
        return belief
    inv = np.argsort(ESTIMATE_FROM_UKF_INDEX)
    P = np.asarray(initial.covariance, dtype=np.float64)[np.ix_(inv, inv)]
    return PoseBelief(x=belief.x, q=belief.q, P=0.5 * (P + P.T))


def unscented_weights(n: int, alpha: float, beta: float, kappa: float) -> tuple[float, F64, F64]:
    """Scaling ``c = n + lambda`` and weights ``(2n+1,)`` for the mean and the covariance."""
    lam = alpha**2 * (n + kappa) - n
    c = n + lam
    wm = np.full(2 * n + 1, 0.5 / c)
    wc = wm.copy()
    wm[0] = lam / c
    wc[0] = lam / c + (1.0 - alpha**2 + beta)
    return c, wm, wc


def psd_sqrt(M: F64) -> F64:
    """A square root ``A``, ``A A^T = M``, of a symmetric PSD matrix (eigenvalues clipped at 0)."""
    s, U = np.linalg.eigh(0.5 * (M + M.T))
    A: F64 = U * np.sqrt(np.clip(s, 0.0, None))
    return A


def markley_mean(q: F64, weights: F64) -> F64:
    """Weighted average of unit quaternions ``(N, 4)``: the eigenvector of the largest eigenvalue
    of ``sum_i w_i q_i q_i^T`` (sign-invariant), returned with w >= 0."""
    M = (q * weights[:, None]).T @ q
    _, vecs = np.linalg.eigh(M)
    mean: F64 = vecs[:, -1]
    mean = mean / np.linalg.norm(mean)
    return -mean if mean[0] < 0 else mean


_HAMILTON = np.zeros((4, 4, 4))
"""``_HAMILTON[i, j, k]``: the sign with which ``a_i b_j`` enters component k of ``a ⊗ b``."""
for _i, _j, _k, _sign in (
    (0, 0, 0, 1), (1, 1, 0, -1), (2, 2, 0, -1), (3, 3, 0, -1),
    (0, 1, 1, 1), (1, 0, 1, 1), (2, 3, 1, 1), (3, 2, 1, -1),
    (0, 2, 2, 1), (1, 3, 2, -1), (2, 0, 2, 1), (3, 1, 2, 1),
    (0, 3, 3, 1), (1, 2, 3, 1), (2, 1, 3, -1), (3, 0, 3, 1),
):  # fmt: skip
    _HAMILTON[_i, _j, _k] = _sign


def _qmul(a: F64, b: F64) -> F64:
    """Hamilton products ``a ⊗ b`` of (w, x, y, z) quaternions, (N, 4) with (N, 4) or (4,),
    or (4,) with (4,): as bilinear forms with :data:`_HAMILTON` (two array operations instead
    of thirty).

    A hot-path twin of :func:`roft_sim.geometry.quat_multiply` (tested equal)."""
    if b.ndim == 1:  # a ⊗ b = a @ M(b), M(b)[i, k] = sum_j b_j H[i, j, k]
        out: F64 = a @ np.einsum("j,ijk->ik", b, _HAMILTON)
        return out
    outer = (a[..., :, None] * b[..., None, :]).reshape(a.shape[:-1] + (16,))
    products: F64 = outer @ _HAMILTON.reshape(16, 4)
    return products


def _qexp(r: F64) -> F64:
    """Quaternions ``exp(r / 2)`` (N, 4) of rotation vectors (N, 3) [rad] (series near 0).

    Twin of :func:`roft_sim.geometry.quat_from_rotvec` without its input validation."""
    angle = np.sqrt(np.einsum("ij,ij->i", r, r))
    small = angle < 1e-6
    k = np.where(small, 0.5 - angle**2 / 48.0, np.sin(0.5 * angle) / np.where(small, 1.0, angle))
    out = np.empty((r.shape[0], 4))
    out[:, 0] = np.cos(0.5 * angle)
    out[:, 1:] = k[:, None] * r
    return out


def _qlog(q: F64) -> F64:
    """Rotation vectors ``2 log(q)`` (N, 3) [rad], angle in [0, pi], of unit quaternions (N, 4).

    Twin of :func:`roft_sim.geometry.rotvec_from_quat` (atan2 form, series near 0)."""
    q = np.where(q[:, :1] < 0.0, -q, q)
    w, vec = q[:, 0], q[:, 1:]
    s = np.sqrt(np.einsum("ij,ij->i", vec, vec))
    angle = np.minimum(2.0 * np.arctan2(s, w), np.pi)
    small = s < 1e-6
    safe_w = np.where(small, w, 1.0)
    k: F64 = np.where(
        small, 2.0 / safe_w * (1.0 - s**2 / (3.0 * safe_w**2)), angle / np.where(small, 1.0, s)
    )
    return k[:, None] * vec


def _cross(a: F64, b: F64) -> F64:
    """Row-wise cross products of (N, 3) arrays."""
    return np.stack(
        [
            a[:, 1] * b[:, 2] - a[:, 2] * b[:, 1],
            a[:, 2] * b[:, 0] - a[:, 0] * b[:, 2],
            a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0],
        ],
        axis=1,
    )


def _boxminus(q: F64, q_mean: F64) -> F64:
    """``2 log(q ⊗ q_mean^*)`` ``(N, 3)``: left rotation vectors of ``(N, 4)`` from the mean."""
    conj = q_mean * np.array([1.0, -1.0, -1.0, -1.0])
    return _qlog(_qmul(q, conj))


def _sigma_offsets(sqrt_cols: list[F64], c: float) -> F64:
    """Offsets ``(2n+1, n)`` of the augmented sigma points: 0, +sqrt(c) a_j, -sqrt(c) a_j, with
    ``a_j`` the columns of the block-diagonal square root assembled from ``sqrt_cols``."""
    n = sum(a.shape[0] for a in sqrt_cols)
    A = np.zeros((n, n))
    i = 0
    for a in sqrt_cols:
        m = a.shape[0]
        A[i : i + m, i : i + m] = a
        i += m
    s = np.sqrt(c) * A.T  # row j = sqrt(c) * column j
    return np.concatenate([np.zeros((1, n)), s, -s], axis=0)


class PoseUKF:
    """Predict and correct functions of ROFT's quaternion UKF (stateless; beliefs are values)."""

    def __init__(self, config: PoseUKFConfig):
        self._config = config
        self._S_a = np.diag(config.sigma_linear).astype(np.float64)
        self._Q_ww = np.diag(config.sigma_angular).astype(np.float64)
        self._R = {
            "v_o": np.asarray(config.meas_cov_v, dtype=np.float64),
            "w": np.asarray(config.meas_cov_w, dtype=np.float64),
            "p": np.asarray(config.meas_cov_x, dtype=np.float64),
            "q": np.asarray(config.meas_cov_q, dtype=np.float64),
        }
        self._sqrt_R = {k: np.diag(np.sqrt(r)) for k, r in self._R.items()}
        self._weights: dict[int, tuple[float, F64, F64]] = {}
        self._noise_sqrts: dict[float, F64] = {}  # dt -> psd_sqrt(process_noise(dt))

    @property
    def config(self) -> PoseUKFConfig:
        return self._config

    def initial_belief(
        self, p_m: F64, q_wxyz: F64, v_mps: F64 | None = None, w_radps: F64 | None = None
    ) -> PoseBelief:
        """Belief at a known pose with the configured initial covariance (velocities default 0)."""
        cfg = self._config
        v = np.zeros(3) if v_mps is None else np.asarray(v_mps, dtype=np.float64)
        w = np.zeros(3) if w_radps is None else np.asarray(w_radps, dtype=np.float64)
        P = np.diag(np.concatenate([cfg.cov_v0, cfg.cov_w0, cfg.cov_x0, cfg.cov_q0]))
        q = np.asarray(q_wxyz, dtype=np.float64)
        return PoseBelief(
            x=np.concatenate([v, w, np.asarray(p_m, dtype=np.float64)]),
            q=q / np.linalg.norm(q),
            P=P.astype(np.float64),
        )

    def _ut(self, n: int) -> tuple[float, F64, F64]:
        if n not in self._weights:
            cfg = self._config
            self._weights[n] = unscented_weights(n, cfg.alpha, cfg.beta, cfg.kappa)
        return self._weights[n]

    def process_noise(self, dt_s: float) -> F64:
        """(9, 9) process noise over (n_v, n_w, n_p) for a step of ``dt_s`` seconds."""
        Q = np.zeros((9, 9))
        S = self._S_a
        Q[0:3, 0:3] = S * dt_s
        Q[0:3, 6:9] = S * dt_s**2 / 2.0
        Q[6:9, 0:3] = S * dt_s**2 / 2.0
        Q[6:9, 6:9] = S * dt_s**3 / 3.0
        Q[3:6, 3:6] = self._Q_ww
        return Q

    def _process_noise_sqrt(self, dt_s: float) -> F64:
        """``psd_sqrt(process_noise(dt_s))`` (9, 9), kept per step length (the camera's frame
        interval repeats)."""
        root = self._noise_sqrts.get(dt_s)
        if root is None:
            if len(self._noise_sqrts) > 16:
                self._noise_sqrts.clear()
            root = self._noise_sqrts[dt_s] = psd_sqrt(self.process_noise(dt_s))
        return root

    def coast_factor(self, coast_s: float, dt_s: float, block: Literal["v", "w"]) -> float:
        """``rho(t) / rho(t - dt)`` of the velocity block ``v`` or ``w`` for a prediction that
        ends ``coast_s`` = t seconds after the last velocity measurement (``rho`` the Gaussian
        autocorrelation of ``pose.coast_correlation_time_*``); 1 when t = 0 or without one."""
        cfg = self._config
        sigma = cfg.coast_correlation_time_v_s if block == "v" else cfg.coast_correlation_time_w_s
        if sigma is None or coast_s <= 0.0:
            return 1.0
        start = max(0.0, coast_s - dt_s)
        return math.exp(-(coast_s**2 - start**2) / (2.0 * sigma**2))

    def predict(self, belief: PoseBelief, dt_s: float, *, coast_s: float = 0.0) -> PoseBelief:
        """Constant-velocity prediction over ``dt_s`` (reference report section 4.3).

        ``v' = v + n_v``, ``w' = w + n_w``, ``p' = p + v dt + n_p``, ``q' = exp(w dt / 2) ⊗ q``
        (w in the camera frame; p and q use the velocities before noise).

        ``coast_s`` > 0: no velocity was measured for that long at the end of this step (none
        follows it): the mean velocities are multiplied by the factors ``a_v``, ``a_w`` of
        :meth:`coast_factor` (every sigma point is moved by the mean's change), so that after t
        seconds without a measurement they are ``rho(t)`` times the last measured ones; their
        covariance is not shrunk (nothing measured makes the velocity better known) and grows
        by the process noise as usual.
        """
        c, wm, wc = self._ut(21)
        d = _sigma_offsets([psd_sqrt(belief.P), self._process_noise_sqrt(dt_s)], c)
        dx, dn = d[:, :12], d[:, 12:]
        x = belief.x + dx[:, :9]
        q = _qmul(_qexp(dx[:, 9:12]), belief.q)
        v, w, p = x[:, 0:3], x[:, 3:6], x[:, 6:9]
        if coast_s > 0.0:  # every sigma point moves by the mean's decay: the spread is kept
            v = v - (1.0 - self.coast_factor(coast_s, dt_s, "v")) * belief.x[0:3]
            w = w - (1.0 - self.coast_factor(coast_s, dt_s, "w")) * belief.x[3:6]
        v_new, w_new = v + dn[:, 0:3], w + dn[:, 3:6]
        if self._config.integrate_interval_velocity:
            v, w = v_new, w_new
        x_new = np.concatenate([v_new, w_new, p + v * dt_s + dn[:, 6:9]], axis=1)
        q_new = _qmul(_qexp(w * dt_s), q)
        x_mean = wm @ x_new
        q_mean = markley_mean(q_new, wm)
        off = np.concatenate([x_new - x_mean, _boxminus(q_new, q_mean)], axis=1)
        P = (off * wc[:, None]).T @ off
        return PoseBelief(x=x_mean, q=q_mean, P=0.5 * (P + P.T))

    def correct(
        self,
        belief: PoseBelief,
        *,
        twist: F64 | None = None,
        twist_cov: F64 | None = None,
        p_meas_m: F64 | None = None,
        q_meas_wxyz: F64 | None = None,
    ) -> PoseBelief:
        """Corrects with a spatial twist (v_o, w) and/or a pose (p, q) (reference section 4.4).

        Args:
            belief: the predicted belief.
            twist: (6,) measured ``(v_o [m/s], w [rad/s])``, modelled as ``(v - w x p, w)``.
            twist_cov: (6, 6) covariance added to the configured twist noise
                ``diag(meas_cov_v, meas_cov_w)`` (e.g. the velocity KF's own) [SI^2].
            p_meas_m: (3,) measured position [m]; give it together with ``q_meas_wxyz``.
            q_meas_wxyz: (4,) measured orientation.

        Returns:
            The corrected belief (the input itself when nothing is measured).
        """
        has_pose = p_meas_m is not None
        if has_pose != (q_meas_wxyz is not None):
            raise ValueError("give both p_meas_m and q_meas_wxyz, or neither")
        if twist is None and not has_pose:
            return belief
        parts = (["v_o", "w"] if twist is not None else []) + (["p", "q"] if has_pose else [])
        n_noise = 3 * len(parts)
        c, wm, wc = self._ut(12 + n_noise)
        noise_sqrts = [self._sqrt_R[k] for k in parts]
        if twist is not None and twist_cov is not None:
            R_twist = np.diag(np.concatenate([self._R["v_o"], self._R["w"]]))
            R_twist = R_twist + np.asarray(twist_cov, dtype=np.float64)
            noise_sqrts = [psd_sqrt(0.5 * (R_twist + R_twist.T))] + noise_sqrts[2:]
        d = _sigma_offsets([psd_sqrt(belief.P)] + noise_sqrts, c)
        dx, dn = d[:, :12], d[:, 12:]
        x = belief.x + dx[:, :9]
        v, w, p = x[:, 0:3], x[:, 3:6], x[:, 6:9]
        lin_pred: list[F64] = []
        lin_meas: list[F64] = []
        j = 0
        if twist is not None:
            lin_pred += [v - _cross(w, p) + dn[:, 0:3], w + dn[:, 3:6]]
            lin_meas.append(np.asarray(twist, dtype=np.float64))
            j = 6
        q_pred = None
        if has_pose:
            lin_pred.append(p + dn[:, j : j + 3])
            lin_meas.append(np.asarray(p_meas_m, dtype=np.float64))
            q_sig = _qmul(_qexp(dx[:, 9:12]), belief.q)
            q_pred = _qmul(_qexp(dn[:, j + 3 : j + 6]), q_sig)
        y = np.concatenate(lin_pred, axis=1)
        y_mean = wm @ y
        y_off = y - y_mean
        nu = np.concatenate(lin_meas) - y_mean
        if q_pred is not None:
            q_mean = markley_mean(q_pred, wm)
            y_off = np.concatenate([y_off, _boxminus(q_pred, q_mean)], axis=1)
            q_meas = np.asarray(q_meas_wxyz, dtype=np.float64)
            nu = np.concatenate([nu, _boxminus(q_meas[None] / np.linalg.norm(q_meas), q_mean)[0]])
        weighted = y_off * wc[:, None]
        P_yy = weighted.T @ y_off
        P_xy = dx.T @ weighted
        K = np.linalg.solve(P_yy, P_xy.T).T  # P_yy symmetric
        delta = K @ nu
        q_new = _qmul(_qexp(delta[None, 9:12])[0], belief.q)
        P = belief.P - K @ P_yy @ K.T
        return PoseBelief(
            x=belief.x + delta[:9], q=q_new / np.linalg.norm(q_new), P=0.5 * (P + P.T)
        )
