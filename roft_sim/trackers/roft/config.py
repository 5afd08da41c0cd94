"""ROFT's settings: one frozen dataclass with the reference implementation's defaults.

Every default is the value of hsp-iit/roft's ``config_fast_ycb.cfg`` as run by its test scripts
(see docs/roft.md, "Parameters"). Variances are variances (not standard deviations), as in the
reference. Load from TOML with :func:`roft_sim.trackers.load_tracker_config`; the nested tables
are ``[mask]``, ``[velocity]``, ``[pose]``, ``[outlier_rejection]``, ``[gate]`` and ``[sync]``.

The Table IV ablations of the paper are switches here; :func:`ablation_config` returns the
configuration the reference test scripts use for each of them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Literal

from roft_sim.errors import ConfigError

__all__ = [
    "MaskSyncConfig",
    "VelocityKFConfig",
    "PoseUKFConfig",
    "OutlierRejectionConfig",
    "PoseGateConfig",
    "PoseSyncConfig",
    "RoftConfig",
    "ABLATIONS",
    "ablation_config",
]

Vec3 = tuple[float, float, float]


def _check_positive(
    owner: str, name: str, values: tuple[float, ...], *, allow_zero: bool = False
) -> None:
    for v in values:
        bad = not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero)
        if bad:
            need = ">= 0" if allow_zero else "> 0"
            raise ConfigError(f"{owner}.{name} must be finite and {need}, got {values}")


@dataclass(frozen=True, slots=True, kw_only=True)
class MaskSyncConfig:
    """Flow-aided mask synchronisation (paper eqs. 1-3)."""

    flow_aided: bool = True
    """Propagate masks with the optical flow and warp delayed masks to the current frame.
    False is the "w/o segm. sync." ablation: the last received mask is used as it is."""
    rounding: Literal["nearest", "truncate"] = "nearest"
    """How a tracked sub-pixel position picks its pixel: ``nearest`` (the pixel whose centre is
    nearest, right for pixel centres at integer coordinates) or ``truncate`` (C truncation, as the
    reference, a bias of half a pixel towards the top-left)."""
    cleanup: Literal["none", "close", "majority"] = "majority"
    """Clean-up of the warped mask on 3x3 neighbourhoods after every flow step. ``majority``
    (a binary median) fills the holes forward splatting leaves where the object grows in the
    image and removes points scattered by flow noise; ``close`` (morphological closing) only
    fills holes; ``none`` is the reference: a delayed mask is tracked point by point through
    all buffered flows and rasterised once."""


@dataclass(frozen=True, slots=True, kw_only=True)
class VelocityKFConfig:
    """The linear Kalman filter of the spatial twist (v_o, w) from optical flow (eqs. 4-9)."""

    sigma_linear: Vec3 = (0.1, 0.1, 0.1)
    """Process noise VARIANCE of v_o per frame [(m/s)^2] (not scaled by dt)."""
    sigma_angular: Vec3 = (0.1, 0.1, 0.1)
    """Process noise VARIANCE of w per frame [(rad/s)^2] (not scaled by dt)."""
    initial_v_mps: Vec3 = (0.0, 0.0, 0.0)
    """Initial v_o [m/s]."""
    initial_w_radps: Vec3 = (0.0, 0.0, 0.0)
    """Initial w [rad/s]."""
    cov_v0: Vec3 = (1e-3, 1e-3, 1e-3)
    """Initial covariance diagonal of v_o [(m/s)^2]."""
    cov_w0: Vec3 = (1e-3, 1e-3, 1e-3)
    """Initial covariance diagonal of w [(rad/s)^2]."""
    cov_flow: tuple[float, float] = (1.0, 1.0)
    """Flow measurement variance (du, dv) per pixel [px^2]."""
    depth_maximum_m: float = 2.0
    """Pixels with depth outside (0, depth_maximum_m) are not used [m]."""
    subsampling_stride: int = 35
    """Use every n-th pixel of the row-major list of mask pixels (the reference's
    ``subsampling_radius``; a stride over the list, applied before validity filtering)."""
    weight_flow: bool = True
    """Robust Laplacian reweighting of each pixel's noise by its innovation norm."""
    reweighting_pairs: Literal["correct", "reference"] = "correct"
    """How the median and spread of the innovation norms are computed: ``correct`` pairs
    (du_j, dv_j) of the same pixel; ``reference`` reproduces the reference's column-major
    mis-pairing (element r with element r + N of the stacked vector)."""
    min_pixels: int = 3
    """Fewer valid pixels than this: the correction is skipped and the previous corrected belief
    kept (this also undoes the prediction's covariance growth)."""
    mask_erosion_px: int | None = None
    """Erode the mask of frame k-1 by this radius [px] before taking its pixels, so that no flow
    vector straddles the object's boundary (dense flow such as DIS smooths across it and the
    synchronised mask is never exact there). None: ``round(width / 213)`` (3 px at 640, 6 px at
    1280, 0 below 107 px); 0: the reference (no erosion)."""

    def __post_init__(self) -> None:
        _check_positive("velocity", "sigma_linear", self.sigma_linear, allow_zero=True)
        _check_positive("velocity", "sigma_angular", self.sigma_angular, allow_zero=True)
        _check_positive("velocity", "cov_v0", self.cov_v0)
        _check_positive("velocity", "cov_w0", self.cov_w0)
        _check_positive("velocity", "cov_flow", self.cov_flow)
        _check_positive("velocity", "depth_maximum_m", (self.depth_maximum_m,))
        for name in ("initial_v_mps", "initial_w_radps"):
            if not all(math.isfinite(v) for v in getattr(self, name)):
                raise ConfigError(f"velocity.{name} must be finite, got {getattr(self, name)}")
        if self.subsampling_stride < 1:
            raise ConfigError(
                f"velocity.subsampling_stride must be >= 1, got {self.subsampling_stride}"
            )
        if self.min_pixels < 1:
            raise ConfigError(f"velocity.min_pixels must be >= 1, got {self.min_pixels}")
        if self.mask_erosion_px is not None and not 0 <= self.mask_erosion_px <= 50:
            raise ConfigError(
                f"velocity.mask_erosion_px must be in [0, 50] px (or absent for the automatic "
                f"value), got {self.mask_erosion_px}"
            )

    def erosion_px(self, width_px: int) -> int:
        """The erosion radius [px] for images ``width_px`` wide."""
        if self.mask_erosion_px is not None:
            return self.mask_erosion_px
        return int(round(width_px / 213.0))


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseUKFConfig:
    """The quaternion UKF of pose and velocity (eqs. 10-13)."""

    sigma_linear: Vec3 = (1.0, 1.0, 1.0)
    """S_a: white-noise-acceleration power spectral density of v and p [m^2/s^3]; per step
    Q_vv = S_a dt, Q_vp = S_a dt^2 / 2, Q_pp = S_a dt^3 / 3."""
    sigma_angular: Vec3 = (1.0, 1.0, 1.0)
    """Q_ww: process noise VARIANCE of w per step [(rad/s)^2], not scaled by dt."""
    cov_v0: Vec3 = (1e-3, 1e-3, 1e-3)
    """Initial covariance diagonal of v [(m/s)^2]."""
    cov_w0: Vec3 = (1e-3, 1e-3, 1e-3)
    """Initial covariance diagonal of w [(rad/s)^2]."""
    cov_x0: Vec3 = (1e-3, 1e-3, 1e-3)
    """Initial covariance diagonal of the position [m^2]."""
    cov_q0: Vec3 = (1e-3, 1e-3, 1e-3)
    """Initial covariance diagonal of the rotation (tangent, left perturbation) [rad^2]."""
    meas_cov_v: Vec3 = (0.1, 0.1, 0.1)
    """Measurement variance of the spatial velocity v_o [(m/s)^2]."""
    meas_cov_w: Vec3 = (1e-4, 1e-4, 1e-4)
    """Measurement variance of w [(rad/s)^2]."""
    meas_cov_x: Vec3 = (1e-3, 1e-3, 1e-3)
    """Measurement variance of a pose's position [m^2]."""
    meas_cov_q: Vec3 = (1e-4, 1e-4, 1e-4)
    """Measurement variance of a pose's rotation (tangent) [rad^2]."""
    alpha: float = 1.0
    """Unscented transform spread."""
    beta: float = 2.0
    """Unscented transform prior-knowledge parameter (2 for Gaussians)."""
    kappa: float = 0.0
    """Unscented transform secondary scaling."""

    def __post_init__(self) -> None:
        _check_positive("pose", "sigma_linear", self.sigma_linear, allow_zero=True)
        _check_positive("pose", "sigma_angular", self.sigma_angular, allow_zero=True)
        for name in (
            "cov_v0",
            "cov_w0",
            "cov_x0",
            "cov_q0",
            "meas_cov_v",
            "meas_cov_w",
            "meas_cov_x",
            "meas_cov_q",
        ):
            _check_positive("pose", name, getattr(self, name))
        if not (math.isfinite(self.alpha) and self.alpha > 0):
            raise ConfigError(f"pose.alpha must be > 0, got {self.alpha}")
        if not (math.isfinite(self.beta) and math.isfinite(self.kappa)):
            raise ConfigError(f"pose.beta and pose.kappa must be finite: {self.beta}, {self.kappa}")
        # the smallest augmented dimension is 12 + 6: n + lambda = alpha^2 (n + kappa) > 0
        if self.alpha**2 * (18 + self.kappa) <= 0:
            raise ConfigError(f"pose.kappa = {self.kappa} makes n + lambda <= 0; use kappa >= 0")


@dataclass(frozen=True, slots=True, kw_only=True)
class OutlierRejectionConfig:
    """Depth-based rejection of outlier poses (paper section III-C-6)."""

    enable: bool = True
    """Run the test on every pose correction; False is the "w/o outlier rej." ablation."""
    gamma: float = 2.0
    """Reject when e(pose + velocity) > gamma * e(velocity only) (hard-coded 2.0 in the
    reference)."""
    depth_maximum_m: float = 2.0
    """Only measured depths in (0, depth_maximum_m) count [m]."""
    pixel_stride: int = 2
    """Use every n-th pixel of the row-major list of mask pixels."""
    render_divider: int = 0
    """Render at 1/divider of the camera resolution; 0 = the reference's rule (2 for 640-wide
    images, 4 otherwise)."""

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gamma) and self.gamma > 0):
            raise ConfigError(f"outlier_rejection.gamma must be > 0, got {self.gamma}")
        _check_positive("outlier_rejection", "depth_maximum_m", (self.depth_maximum_m,))
        if self.pixel_stride < 1:
            raise ConfigError(
                f"outlier_rejection.pixel_stride must be >= 1, got {self.pixel_stride}"
            )
        if self.render_divider < 0:
            raise ConfigError(
                f"outlier_rejection.render_divider must be >= 0 (0 = auto), got "
                f"{self.render_divider}"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseGateConfig:
    """Rejects a pose far from the filter's prediction at its capture frame (not in the
    reference). The depth test cannot see 180-degree flips of box-like objects (their depth is the
    same) nor sideways jumps; this gate catches both, in physical units rather than with the
    filter's own covariance, whose tuned measurement noise is far smaller than a detector's real
    error. So that a wrong filter cannot lock out correct poses for ever, a pose is accepted
    whatever its distance after ``max_consecutive_rejections`` rejected ones in a row."""

    enable: bool = False
    """Run the gate on every pose correction (ROFT default: off, as the reference)."""
    max_translation_m: float = 0.10
    """Largest accepted distance between the pose's position and the prediction [m]."""
    max_rotation_deg: float = 45.0
    """Largest accepted angle between the pose's orientation and the prediction [deg]."""
    max_consecutive_rejections: int = 2
    """After this many poses rejected in a row (in capture order), the next one is accepted."""

    def __post_init__(self) -> None:
        _check_positive("gate", "max_translation_m", (self.max_translation_m,))
        if not (math.isfinite(self.max_rotation_deg) and 0 < self.max_rotation_deg <= 180):
            raise ConfigError(
                f"gate.max_rotation_deg must be in (0, 180], got {self.max_rotation_deg}"
            )
        if self.max_consecutive_rejections < 0:
            raise ConfigError(
                f"gate.max_consecutive_rejections must be >= 0, got "
                f"{self.max_consecutive_rejections}"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseSyncConfig:
    """Buffers for delayed poses and masks."""

    horizon_frames: int = 30
    """How far back a delayed pose or mask may refer: one captured more than this many frames
    before the current frame is dropped (and reported). Beliefs, velocity measurements and flows
    are kept for this many frames."""

    def __post_init__(self) -> None:
        if not 0 <= self.horizon_frames <= 10_000:
            raise ConfigError(
                f"sync.horizon_frames must be in [0, 10000], got {self.horizon_frames}"
            )


@dataclass(frozen=True, slots=True, kw_only=True)
class RoftConfig:
    """Every setting of the ROFT tracker, with the reference's defaults."""

    use_pose: bool = True
    """Fuse pose detections (False: the "w/o pose" ablation; the first pose still initialises
    the filter when no initial estimate is given)."""
    use_velocity: bool = True
    """Fuse the flow-based velocity in the pose UKF (False: pose-only measurements, the
    "w/o velocity" ablation)."""
    use_pose_resync: bool = True
    """Replay the filter from a delayed pose's capture frame (False: the "w/o pose sync."
    ablation, the delayed pose is fused at the current frame as if it were current)."""
    use_flow: bool = True
    """Run the flow-based velocity Kalman filter at all. False for trackers that have no flow
    (the pose-only baselines); implies use_velocity = False."""
    mask: MaskSyncConfig = field(default_factory=MaskSyncConfig)
    velocity: VelocityKFConfig = field(default_factory=VelocityKFConfig)
    pose: PoseUKFConfig = field(default_factory=PoseUKFConfig)
    outlier_rejection: OutlierRejectionConfig = field(default_factory=OutlierRejectionConfig)
    gate: PoseGateConfig = field(default_factory=PoseGateConfig)
    sync: PoseSyncConfig = field(default_factory=PoseSyncConfig)

    def __post_init__(self) -> None:
        if self.use_velocity and not self.use_flow:
            raise ConfigError(
                "use_velocity = true needs use_flow = true (the velocity comes from the flow); "
                "set use_velocity = false for a tracker without flow"
            )


ABLATIONS: dict[str, str] = {
    "full": "ROFT as published",
    "no_pose_sync": "w/o pose sync.: delayed poses fused at the frame they arrive",
    "no_outlier_rejection": "w/o outlier rej.: every pose is fused",
    "no_mask_sync": "w/o segm. sync.: the last received mask is used as it is",
    "no_velocity": "w/o velocity: pose-only measurements (sigma_w = 0.01, cov_q = 0.01, no "
    "outlier rejection, no pose sync.)",
    "no_pose": "w/o pose: velocity only (no outlier rejection, no pose sync.)",
}
"""The ablations of the paper's Table IV that are tracker settings (the ground-truth mask and pose
rows are fed by the harness), with one-line descriptions."""


def ablation_config(name: str, base: RoftConfig | None = None) -> RoftConfig:
    """The configuration of one Table IV ablation, as the reference test scripts set it.

    Args:
        name: a key of :data:`ABLATIONS`.
        base: the configuration to modify (default: the reference defaults).

    Raises:
        ConfigError: unknown ablation name.
    """
    base = base or RoftConfig()
    rep = dataclasses.replace
    if name == "full":
        return base
    if name == "no_pose_sync":
        return rep(base, use_pose_resync=False)
    if name == "no_outlier_rejection":
        return rep(base, outlier_rejection=rep(base.outlier_rejection, enable=False))
    if name == "no_mask_sync":
        return rep(base, mask=rep(base.mask, flow_aided=False))
    if name == "no_velocity":
        return rep(
            base,
            use_velocity=False,
            use_pose_resync=False,
            outlier_rejection=rep(base.outlier_rejection, enable=False),
            pose=rep(base.pose, sigma_angular=(0.01, 0.01, 0.01), meas_cov_q=(0.01, 0.01, 0.01)),
        )
    if name == "no_pose":
        return rep(
            base,
            use_pose=False,
            use_pose_resync=False,
            outlier_rejection=rep(base.outlier_rejection, enable=False),
        )
    raise ConfigError(f"unknown ROFT ablation {name!r}; known: {', '.join(ABLATIONS)}")
