"""Monte-Carlo scenarios whose truth follows a known stochastic model: the ground on which a
filter's consistency (NEES within chi-square bounds) can be tested.

A consistency test needs truth drawn from the very model the filter assumes; a rendered
trajectory is not (its motion is smooth and deterministic). :class:`ConstantVelocityPoseModel`
is the white-noise-acceleration constant-velocity model of ROFT's pose UKF and the pose-only
baselines, plus a pose detector with Gaussian position and rotation noise:

- position and velocity: per frame of length ``dt``, ``(p, v)`` gets process noise with
  covariance ``S_a [[dt^3/3, dt^2/2], [dt^2/2, dt]]`` (continuous white acceleration of power
  spectral density ``S_a`` [m^2/s^3], discretised exactly) and ``p_k = p_(k-1) + v_(k-1) dt +
  n_p``;
- angular velocity: a random walk, ``w_k = w_(k-1) + n_w`` with variance ``Q_w`` per frame;
  orientation ``R_k = exp([w_(k-1) dt]x) R_(k-1)`` (camera frame);
- detections: ``p + N(0, R_p)`` and ``exp([n_q]x) R`` with ``n_q ~ N(0, R_q)`` (left
  perturbation, camera frame), on every frame (a fault configuration thins and delays them);
- the initial truth is drawn around the prior mean (zero velocities) with the prior covariance,
  so a filter started with :attr:`PoseScenario.initial` is consistent from frame 0.

:func:`draw_pose_scenario` draws one run as an :class:`~roft_sim.datasets.base.InMemorySequence`
(tiny blank images: pose-only trackers never look at them); :func:`run_pose_monte_carlo` runs a
tracker over R independently drawn scenarios under a fault configuration.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import DetectorPoses, InMemorySequence
from roft_sim.errors import ConfigError
from roft_sim.faults import FaultConfig, ObservationStream
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import matrix_from_rotvec
from roft_sim.records import Estimate, PoseTrack
from roft_sim.testing.analytic_scene import AnalyticBox
from roft_sim.trackers import Tracker, run_tracker

if TYPE_CHECKING:
    from roft_sim.trackers.roft import PoseUKFConfig

F64 = NDArray[np.float64]
Vec3 = tuple[float, float, float]

__all__ = [
    "ConstantVelocityPoseModel",
    "PoseScenario",
    "MonteCarloRuns",
    "draw_pose_scenario",
    "run_pose_monte_carlo",
    "POSE_SET",
]

POSE_SET = "noisy"
"""Name of the detector pose set of a drawn scenario."""


def _check(owner: str, name: str, values: Vec3, *, allow_zero: bool) -> None:
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape != (3,) or not np.isfinite(arr).all() or (arr < 0).any():
        raise ConfigError(f"{owner}.{name} must be three finite values >= 0, got {values}")
    if not allow_zero and (arr == 0).any():
        raise ConfigError(f"{owner}.{name} must be > 0, got {values}")


@dataclass(frozen=True, slots=True, kw_only=True)
class ConstantVelocityPoseModel:
    """Stochastic object motion and pose detector (see the module docstring). Variances are
    variances, per axis, camera frame."""

    accel_psd_m2ps3: Vec3 = (1.0, 1.0, 1.0)
    """``S_a``: power spectral density of the white linear acceleration [m^2/s^3]."""
    angular_rw_var_radps2: Vec3 = (0.01, 0.01, 0.01)
    """``Q_w``: variance of the angular-velocity change per frame [(rad/s)^2]."""
    position_noise_var_m2: Vec3 = (1e-3, 1e-3, 1e-3)
    """``R_p``: detector position noise variance [m^2]."""
    rotation_noise_var_rad2: Vec3 = (0.01, 0.01, 0.01)
    """``R_q``: detector rotation noise variance (left rotation vector) [rad^2]."""
    initial_position_var_m2: Vec3 = (1e-3, 1e-3, 1e-3)
    """Prior variance of the position [m^2]."""
    initial_rotation_var_rad2: Vec3 = (1e-3, 1e-3, 1e-3)
    """Prior variance of the orientation (left rotation vector) [rad^2]."""
    initial_velocity_var_m2ps2: Vec3 = (1e-3, 1e-3, 1e-3)
    """Prior variance of the object-origin velocity [(m/s)^2] (prior mean 0)."""
    initial_angular_var_rad2ps2: Vec3 = (1e-3, 1e-3, 1e-3)
    """Prior variance of the angular velocity [(rad/s)^2] (prior mean 0)."""
    start_position_m: Vec3 = (0.0, 0.0, 0.6)
    """Prior mean of the position, camera frame [m]."""
    start_rotvec_rad: Vec3 = (0.3, -0.2, 0.1)
    """Prior mean of the orientation as a rotation vector [rad]."""

    def __post_init__(self) -> None:
        owner = "ConstantVelocityPoseModel"
        for name in ("accel_psd_m2ps3", "angular_rw_var_radps2"):
            _check(owner, name, getattr(self, name), allow_zero=True)
        for name in (
            "position_noise_var_m2",
            "rotation_noise_var_rad2",
            "initial_position_var_m2",
            "initial_rotation_var_rad2",
            "initial_velocity_var_m2ps2",
            "initial_angular_var_rad2ps2",
        ):
            _check(owner, name, getattr(self, name), allow_zero=False)
        for name in ("start_position_m", "start_rotvec_rad"):
            if not np.isfinite(np.asarray(getattr(self, name), dtype=np.float64)).all():
                raise ConfigError(f"{owner}.{name} must be finite, got {getattr(self, name)}")

    @classmethod
    def matching(cls, pose_ukf: PoseUKFConfig, **overrides: Vec3) -> ConstantVelocityPoseModel:
        """The model a :class:`roft_sim.trackers.roft.PoseUKFConfig` assumes (process noise,
        measurement noise and prior), so that filter is consistent on it by construction."""
        cfg = pose_ukf
        values = {
            "accel_psd_m2ps3": cfg.sigma_linear,
            "angular_rw_var_radps2": cfg.sigma_angular,
            "position_noise_var_m2": cfg.meas_cov_x,
            "rotation_noise_var_rad2": cfg.meas_cov_q,
            "initial_position_var_m2": cfg.cov_x0,
            "initial_rotation_var_rad2": cfg.cov_q0,
            "initial_velocity_var_m2ps2": cfg.cov_v0,
            "initial_angular_var_rad2ps2": cfg.cov_w0,
        }
        values.update(overrides)
        return cls(**values)

    def initial_covariance(self) -> F64:
        """(12, 12) prior covariance in :data:`~roft_sim.records.ESTIMATE_COVARIANCE_ORDER`."""
        return np.diag(
            np.concatenate(
                [
                    self.initial_position_var_m2,
                    self.initial_rotation_var_rad2,
                    self.initial_velocity_var_m2ps2,
                    self.initial_angular_var_rad2ps2,
                ]
            )
        ).astype(np.float64)

    def process_noise(self, dt_s: float) -> F64:
        """(9, 9) covariance of the per-frame noise on ``(p, v, w)`` over a step of ``dt_s``."""
        S = np.diag(self.accel_psd_m2ps3).astype(np.float64)
        Q = np.zeros((9, 9))
        Q[0:3, 0:3] = S * dt_s**3 / 3.0
        Q[0:3, 3:6] = Q[3:6, 0:3] = S * dt_s**2 / 2.0
        Q[3:6, 3:6] = S * dt_s
        Q[6:9, 6:9] = np.diag(self.angular_rw_var_radps2)
        return Q


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseScenario:
    """One drawn run: the truth, a sequence carrying it and its detections, the prior."""

    sequence: InMemorySequence
    """Ground truth ``gt``, the detector pose set :data:`POSE_SET` (one pose per frame), blank
    images, no flow and no masks."""
    initial: Estimate
    """The prior: frame 0, zero velocities, the model's prior covariance (pass it to
    ``tracker.reset``)."""
    truth: PoseTrack
    """The drawn truth, frames 0..N-1."""


def _draw_gaussian(rng: np.random.Generator, cov: F64) -> F64:
    return rng.multivariate_normal(np.zeros(cov.shape[0]), cov, method="cholesky")


def draw_pose_scenario(
    model: ConstantVelocityPoseModel,
    *,
    n_frames: int,
    rng: np.random.Generator,
    fps: int = 30,
    name: str = "cv_scenario",
) -> PoseScenario:
    """Draws the truth of ``n_frames`` frames and a detection on every frame.

    Args:
        model: the motion and detector model.
        n_frames: frames to draw (>= 1).
        rng: the run's generator (truth and detector noise come from it, in that order).
        fps: camera rate [Hz]; frame k at ``k / fps`` s.
        name: the sequence name.
    """
    if n_frames < 1 or fps < 1:
        raise ConfigError(f"need n_frames >= 1 and fps >= 1, got {n_frames} and {fps}")
    dt = 1.0 / fps
    R0 = matrix_from_rotvec(np.asarray(model.start_rotvec_rad, dtype=np.float64))
    p0 = np.asarray(model.start_position_m, dtype=np.float64)
    P0 = model.initial_covariance()
    e0 = _draw_gaussian(rng, P0)  # (t, r, v, w) error, ESTIMATE_COVARIANCE_ORDER
    p, R = p0 + e0[0:3], matrix_from_rotvec(e0[3:6]) @ R0
    v, w = e0[6:9].copy(), e0[9:12].copy()
    Q = model.process_noise(dt)
    T = np.empty((n_frames, 4, 4))
    V = np.empty((n_frames, 3))
    W = np.empty((n_frames, 3))
    for k in range(n_frames):
        if k > 0:
            n = _draw_gaussian(rng, Q)
            p, R = p + v * dt + n[0:3], matrix_from_rotvec(w * dt) @ R
            v, w = v + n[3:6], w + n[6:9]
        T[k] = transform_from_rt(R, p)
        V[k], W[k] = v, w
    truth = PoseTrack(t_s=np.arange(n_frames) / fps, T_cam_obj=T, v_obj_mps=V, w_radps=W)
    sd_p = np.sqrt(np.asarray(model.position_noise_var_m2, dtype=np.float64))
    sd_q = np.sqrt(np.asarray(model.rotation_noise_var_rad2, dtype=np.float64))
    detected = T.copy()
    detected[:, :3, 3] += rng.normal(size=(n_frames, 3)) * sd_p
    detected[:, :3, :3] = matrix_from_rotvec(rng.normal(size=(n_frames, 3)) * sd_q) @ T[:, :3, :3]
    w_px, h_px = 8, 6
    intrinsics = CameraIntrinsics(
        fx_px=8.0, fy_px=8.0, cx_px=3.5, cy_px=2.5, width_px=w_px, height_px=h_px
    )
    rgb = np.zeros((h_px, w_px, 3), dtype=np.uint8)
    depth = np.zeros((h_px, w_px), dtype=np.float32)
    rgb.flags.writeable = depth.flags.writeable = False
    sequence = InMemorySequence(
        name=name,
        object_name="analytic_box",
        intrinsics=intrinsics,
        fps=fps,
        rgb_frames=[rgb] * n_frames,
        depth_frames=[depth] * n_frames,
        gt=truth,
        detector_pose_sets={
            POSE_SET: DetectorPoses(T_cam_obj=detected, valid=np.ones(n_frames, dtype=bool))
        },
        model=AnalyticBox().object_model(),
        extra_metadata={"generator": "roft_sim.testing.monte_carlo"},
    )
    initial = Estimate(
        k=0,
        T_cam_obj=transform_from_rt(R0, p0),
        v_obj_mps=np.zeros(3),
        w_radps=np.zeros(3),
        covariance=P0,
    )
    return PoseScenario(sequence=sequence, initial=initial, truth=truth)


@dataclass(frozen=True, slots=True, kw_only=True)
class MonteCarloRuns:
    """R independent runs of one tracker (feed them to
    :func:`roft_sim.testing.consistency_checks.check_consistency`)."""

    estimates: tuple[tuple[Estimate, ...], ...]
    """(R,) runs, each the estimates of frames 0..N-1."""
    truths: tuple[PoseTrack, ...]
    """(R,) ground truth of each run."""


def run_pose_monte_carlo(
    make_tracker: Callable[[InMemorySequence], Tracker],
    model: ConstantVelocityPoseModel,
    faults: FaultConfig,
    *,
    runs: int,
    n_frames: int,
    seed: int,
    fps: int = 30,
) -> MonteCarloRuns:
    """Runs a tracker over ``runs`` scenarios drawn from ``model`` under ``faults``.

    Run r draws its truth and detections from child r of ``SeedSequence(seed)`` and its fault
    schedule from that child's own child, so runs are independent and reproducible; every
    tracker is reset with the scenario's prior (:attr:`PoseScenario.initial`).

    Args:
        make_tracker: builds a fresh tracker for a scenario's sequence (e.g.
            ``lambda seq: tracker_for("pose-only-ukf", seq)``).
        model: the truth and detector model.
        faults: fault configuration of the pose stream (rate, delays, losses, ...).
        runs: number of Monte-Carlo runs R (>= 1).
        n_frames: frames per run.
        seed: the seed of everything.
        fps: camera rate [Hz].
    """
    if runs < 1:
        raise ConfigError(f"runs must be >= 1, got {runs}")
    estimates, truths = [], []
    for r, child in enumerate(np.random.SeedSequence(seed).spawn(runs)):
        scenario = draw_pose_scenario(
            model, n_frames=n_frames, rng=np.random.default_rng(child), fps=fps, name=f"mc_{r}"
        )
        stream = ObservationStream(
            scenario.sequence,
            faults,
            seed=child.spawn(1)[0],
            flow_source=None,
            pose_set=POSE_SET,
            mask_set=None,
            include_rgb=False,
        )
        tracker = make_tracker(scenario.sequence)
        estimates.append(tuple(run_tracker(tracker, list(stream), scenario.initial)))
        truths.append(scenario.truth)
    return MonteCarloRuns(estimates=tuple(estimates), truths=tuple(truths))
