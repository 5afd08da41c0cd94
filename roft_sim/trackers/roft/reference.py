"""The ``reference`` configuration: ROFT as the C++ reference (hsp-iit/roft) runs it, and the
ordered list of this package's deviations from it.

Every value of :func:`reference_config` is named with its source in
``../shared/reference/roft_reference.md`` (the report on hsp-iit/roft + bayes-filters-lib).
Applying every entry of :data:`DEVIATIONS` to it, in order, gives ``RoftConfig()`` (the default);
``roft-sim paper`` adds them one at a time to measure each one's effect (the attribution table,
docs/paper.md).

Not reproducible by configuration (documented in docs/roft.md, "Deviations"): the replay's loss
of alternate poses (report 5.4a), the skipped frames after a missed pose (5.4b), pose 0 fused
twice (5.4c), the ``cv::remap`` copy of pixel (0, 0) into unhit pixels (2.3) and the 1e-4 rad
small-angle cut in exp/log (4.2). Those are defects of the implementation, not settings.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

from roft_sim.trackers.roft.config import (
    CovarianceScaleConfig,
    MaskSyncConfig,
    PoseGateConfig,
    PoseSyncConfig,
    PoseUKFConfig,
    RoftConfig,
    VelocityKFConfig,
)

__all__ = ["Deviation", "DEVIATIONS", "RoftReferenceConfig", "apply_deviations", "reference_config"]

_rep = dataclasses.replace


def _reference_mask() -> MaskSyncConfig:
    return MaskSyncConfig(
        flow_aided=True,  # segmentation_dataset.flow_aided = true (report 7.2, section 2)
        rounding="truncate",  # C truncation int(t) of the tracked position (report 2.3)
        cleanup="none",  # no hole filling, erosion, dilation or morphology (report 2.3)
        subpixel=False,  # the mask image is re-warped every frame: integer starts (report 2.2-2.3)
    )


def _reference_velocity() -> VelocityKFConfig:
    return VelocityKFConfig(
        sigma_linear=(0.1, 0.1, 0.1),  # kinematic_model.velocity.sigma_linear (report 3.1, 7.2)
        sigma_angular=(0.1, 0.1, 0.1),  # kinematic_model.velocity.sigma_angular (report 3.1)
        initial_v_mps=(0.0, 0.0, 0.0),  # initial_condition.velocity.v (report 7.2)
        initial_w_radps=(0.0, 0.0, 0.0),  # initial_condition.velocity.w (report 7.2)
        cov_v0=(1e-3, 1e-3, 1e-3),  # initial_condition.velocity.cov_v (report 7.2)
        cov_w0=(1e-3, 1e-3, 1e-3),  # initial_condition.velocity.cov_w (report 7.2)
        cov_flow=(1.0, 1.0),  # measurement_model.velocity.cov_flow, px^2 (report 3.3)
        noise_reference_width_px=None,  # used as given whatever the resolution (report 3.2-3.3)
        depth_maximum_m=2.0,  # measurement_model.velocity.depth_maximum (report 3.2)
        subsampling_stride=35,  # measurement_model.velocity.subsampling_radius (report 3.2)
        weight_flow=True,  # measurement_model.velocity.weight_flow (report 3.3)
        reweighting_pairs="reference",  # column-major mis-pairing in SKFCorrection (report 3.3)
        min_pixels=3,  # observability minimum, hard-coded (report 7.3)
        mask_erosion_px=0,  # the flow is read on the whole mask of k-1 (report 3.2)
        depth_band_m=None,  # only 0 < D < depth_maximum (report 3.2)
        occluder_depth_jump_m=None,  # every mask pixel is the object's (report 3.2)
        depth_rate=False,  # the flow alone measures the twist (paper eq. 9, report 3.2)
        midpoint_jacobian=False,  # eq. 9 at the pixel of frame k-1 (report 3.2)
        finite_motion_correction=False,  # the flow is eq. 9's linear model alone (report 3.2)
        adapt_flow_noise=False,  # fixed R (report 3.3)
        exact_flow_spread_px=None,  # fixed R (report 3.3)
        independent_pixels_per_cell=False,  # every sampled pixel is one measurement (report 3.4)
        skip_stale_velocity=False,  # the KF mean is fed to the UKF every frame (report 1.3)
        twist_covariance_to_ukf=False,  # fixed R_v, R_w in the UKF (report 4.4)
        remeasure_on_fresh_mask=False,  # a measured twist is never revised (report 1.3)
        report_unmeasured_twist=True,  # frame 0: the zero twist is written (report 1.3, 3.4)
        motion_model="constant",  # a random-walk twist, F = I (report 3.1)
    )


def _reference_pose() -> PoseUKFConfig:
    return PoseUKFConfig(
        sigma_linear=(1.0, 1.0, 1.0),  # kinematic_model.pose.sigma_linear, S_a (report 4.3, 7.2)
        sigma_angular=(1.0, 1.0, 1.0),  # kinematic_model.pose.sigma_angular (report 4.3, 7.2)
        cov_v0=(1e-3, 1e-3, 1e-3),  # initial_condition.pose.cov_v (report 4.5)
        cov_w0=(1e-3, 1e-3, 1e-3),  # initial_condition.pose.cov_w (report 4.5)
        cov_x0=(1e-3, 1e-3, 1e-3),  # initial_condition.pose.cov_x (report 4.5)
        cov_q0=(1e-3, 1e-3, 1e-3),  # initial_condition.pose.cov_q (report 4.5)
        meas_cov_v=(0.1, 0.1, 0.1),  # measurement_model.pose.cov_v (report 7.2)
        meas_cov_w=(1e-4, 1e-4, 1e-4),  # measurement_model.pose.cov_w (report 7.2)
        meas_cov_x=(1e-3, 1e-3, 1e-3),  # measurement_model.pose.cov_x (report 7.2)
        meas_cov_q=(1e-4, 1e-4, 1e-4),  # measurement_model.pose.cov_q, scripts (report 7.2)
        integrate_interval_velocity=False,  # p and q use the velocities of k-1 (report 4.3)
        alpha=1.0,  # unscented_transform.alpha (report 4.2, 7.2)
        beta=2.0,  # unscented_transform.beta (report 4.2, 7.2)
        kappa=0.0,  # unscented_transform.kappa (report 4.2, 7.2)
        coast_correlation_time_v_s=None,  # constant velocity when unmeasured (report 4.3)
        coast_correlation_time_w_s=None,  # constant velocity when unmeasured (report 4.3)
    )


def _reference_gate() -> PoseGateConfig:
    # no pose gate: only the depth test (report 6)
    return PoseGateConfig(enable=False, depth_override_coverage=None)


def _reference_sync() -> PoseSyncConfig:
    # period = delay = 6, the buffers hold 6 frames (report 2.1, 5.1-5.2)
    return PoseSyncConfig(horizon_frames=6)


def _reference_covariance_scale() -> CovarianceScaleConfig:
    # the UKF's covariance is reported as it is (report 4.4: no adaptation of P, Q or R)
    return CovarianceScaleConfig(enable=False)


def reference_config() -> RoftConfig:
    """ROFT as the C++ reference runs it (config_fast_ycb.cfg with the test scripts' values).

    The outlier test (gamma 2.0, 2.0 m depth cap, stride 2, render divider 4 or 2 at 640 px:
    report 6 and 7.3) and the switches ``use_pose`` / ``use_velocity`` / ``use_pose_resync``
    (report 7.2, all true) are the package defaults, which are the reference's; the pose gate is
    off (not in the reference).
    """
    return RoftConfig(
        mask=_reference_mask(),
        velocity=_reference_velocity(),
        pose=_reference_pose(),
        gate=_reference_gate(),
        sync=_reference_sync(),
        covariance_scale=_reference_covariance_scale(),
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class RoftReferenceConfig(RoftConfig):
    """:class:`RoftConfig` whose defaults are :func:`reference_config`'s: the settings type of
    the ``roft-reference`` tracker (a TOML file overrides single keys of the reference)."""

    mask: MaskSyncConfig = field(default_factory=_reference_mask)
    velocity: VelocityKFConfig = field(default_factory=_reference_velocity)
    pose: PoseUKFConfig = field(default_factory=_reference_pose)
    gate: PoseGateConfig = field(default_factory=_reference_gate)
    sync: PoseSyncConfig = field(default_factory=_reference_sync)
    covariance_scale: CovarianceScaleConfig = field(default_factory=_reference_covariance_scale)


@dataclass(frozen=True, slots=True)
class Deviation:
    """One deliberate difference between this package's default and the reference."""

    name: str
    """Short identifier (a row of the attribution table)."""
    description: str
    """One line: what changes."""
    apply: Callable[[RoftConfig], RoftConfig]
    """Returns the configuration with this deviation applied."""


_DEFAULT = RoftConfig()


def _restore(section: str, *names: str) -> Callable[[RoftConfig], RoftConfig]:
    """Sets the fields ``names`` of the ``section`` config (``mask``, ``velocity``, ...) back to
    their ``RoftConfig()`` values."""

    def apply(c: RoftConfig) -> RoftConfig:
        default = getattr(_DEFAULT, section)
        changes = {name: getattr(default, name) for name in names}
        return _rep(c, **{section: _rep(getattr(c, section), **changes)})

    return apply


DEVIATIONS: tuple[Deviation, ...] = (
    Deviation(
        "horizon",
        f"poses and masks up to {_DEFAULT.sync.horizon_frames} frames old are replayed (the "
        "reference's buffers hold the fixed 6)",
        _restore("sync", "horizon_frames"),
    ),
    Deviation(
        "mask_nearest",
        "a tracked point lands in its nearest pixel, not the C-truncated one",
        _restore("mask", "rounding"),
    ),
    Deviation(
        "mask_subpixel_close",
        "mask points keep sub-pixel positions between frames; 3x3 closing after each step",
        _restore("mask", "cleanup", "subpixel"),
    ),
    Deviation(
        "metric_erosion",
        "the flow is read on the mask eroded by a 5 mm band (at most half the mask removed)",
        _restore("velocity", "mask_erosion_px", "mask_erosion_m", "mask_erosion_max_removed"),
    ),
    Deviation(
        "depth_band",
        "flow pixels more than 15 cm in depth from the mask's median depth are not used",
        _restore("velocity", "depth_band_m"),
    ),
    Deviation(
        "midpoint_jacobian",
        "each pixel's flow Jacobian is evaluated at the midpoint of its measured displacement",
        _restore("velocity", "midpoint_jacobian"),
    ),
    Deviation(
        "resolution_scaling",
        "flow R and pixel stride given at 1280 px and scaled by (W / 1280)^2",
        _restore("velocity", "noise_reference_width_px"),
    ),
    Deviation(
        "reweighting_pairs",
        "Laplacian weights from the true (du, dv) pairs, not the column-major mis-pairing",
        _restore("velocity", "reweighting_pairs"),
    ),
    Deviation(
        "adaptive_flow_noise",
        "flow R from the robust residual spread, lowered for flow that fits to a hundredth "
        "of a pixel (exact flow); one measurement per flow grid cell",
        _restore(
            "velocity", "adapt_flow_noise", "exact_flow_spread_px", "independent_pixels_per_cell"
        ),
    ),
    Deviation(
        "skip_stale_velocity",
        "no velocity measurement to the UKF when the KF did not update",
        _restore("velocity", "skip_stale_velocity"),
    ),
    Deviation(
        "twist_covariance",
        "the KF's covariance is added to the UKF's velocity measurement noise",
        _restore("velocity", "twist_covariance_to_ukf"),
    ),
    Deviation(
        "interval_velocity",
        "the UKF integrates the pose with the new (interval-mean) velocity the flow measures",
        _restore("pose", "integrate_interval_velocity"),
    ),
    Deviation(
        "adaptive_gate",
        "poses whose innovation is far beyond the spread of the accepted ones are rejected "
        "(chi-square gate on an adapted variance; flips and jumps the depth test lets through)",
        lambda c: _rep(c, gate=_rep(_DEFAULT.gate, depth_override_coverage=None)),
    ),
    Deviation(
        "covariance_scale",
        "the reported covariance is calibrated online from the filter's innovations (velocity "
        "blocks: twist-change factor; pose block: Joseph-form excess of the estimated pose "
        "noise); the estimates are unchanged",
        _restore("covariance_scale", "enable"),
    ),
    Deviation(
        "fresh_mask_remeasure",
        "when a delayed mask arrives, the flows since its capture are measured again on it and "
        "the velocity KF and the pose UKF are replayed with the corrected twists",
        _restore("velocity", "remeasure_on_fresh_mask"),
    ),
    Deviation(
        "unmeasured_twist",
        "no spatial twist is reported before the velocity KF has used any flow (frame 0)",
        _restore("velocity", "report_unmeasured_twist"),
    ),
    Deviation(
        "adaptive_motion_model",
        "the reported twist mixes the constant and a constant-acceleration velocity KF, "
        "weighted by how well each predicted the flow (the UKF keeps the constant model's)",
        _restore("velocity", "motion_model"),
    ),
    Deviation(
        "occluder_parts",
        "parts of the mask in front of the object (depth jumps > 2 cm) whose flow disagrees "
        "with the object's rigid motion are not used",
        _restore("velocity", "occluder_depth_jump_m", "occluder_probability"),
    ),
    Deviation(
        "finite_motion",
        "the flow is corrected for the finite rigid motion over the interval (SE(3) "
        "exponential at the filter's twist), so the linear model holds at fast turns",
        _restore("velocity", "finite_motion_correction"),
    ),
    Deviation(
        "coast_decay",
        "while no twist is measured (no flow, no mask), the pose UKF's velocities follow the "
        "autocorrelation of hand-held motion towards zero (Gaussian, 0.2 s linear, 0.11 s "
        "angular)",
        _restore("pose", "coast_correlation_time_v_s", "coast_correlation_time_w_s"),
    ),
    Deviation(
        "depth_rate",
        "the velocity KF also measures the twist with each flow point's depth change over the "
        "interval (range flow: v_z + w_x Y - w_y X), robustly weighted",
        _restore("velocity", "depth_rate"),
    ),
    Deviation(
        "depth_override",
        "a pose the adaptive gate rejects re-initialises the track's position (and its "
        "orientation, where the depth prefers it) when, rendered at its capture frame, it covers "
        "the mask's depth samples, the track less than half as many, and the track fits the "
        "depth there gamma times worse",
        _restore("gate", "depth_override_coverage"),
    ),
)
"""The deviations in the order the attribution table adds them; applying all of them to
:func:`reference_config` gives ``RoftConfig()`` (tested)."""


def apply_deviations(config: RoftConfig, count: int | None = None) -> RoftConfig:
    """``config`` with the first ``count`` deviations applied (all when None)."""
    chosen = DEVIATIONS if count is None else DEVIATIONS[:count]
    for deviation in chosen:
        config = deviation.apply(config)
    return config
