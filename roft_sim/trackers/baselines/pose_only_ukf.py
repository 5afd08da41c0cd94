"""``pose-only-ukf``: ROFT's tracker with pose measurements only, delays handled by replay.

A pose captured at frame c restarts the filter from its belief at c-1 and replays the
predictions up to now (ROFT's pose synchronisation). Its settings, shared with ``naive-delay``,
and why they are what they are: :mod:`roft_sim.trackers.baselines.pose_only`.
"""

from __future__ import annotations

from roft_sim.trackers.base import TrackerContext
from roft_sim.trackers.baselines.pose_only import PoseOnlyUkfConfig
from roft_sim.trackers.roft.config import (
    CovarianceScaleConfig,
    OutlierRejectionConfig,
    RoftConfig,
)
from roft_sim.trackers.roft.tracker import RoftTracker

__all__ = ["create_pose_only_ukf"]


def _roft_config(config: PoseOnlyUkfConfig, *, resync: bool) -> RoftConfig:
    return RoftConfig(
        use_flow=False,
        use_velocity=False,
        use_pose_resync=resync,
        pose=config.pose,
        sync=config.sync,
        outlier_rejection=OutlierRejectionConfig(enable=False),
        gate=config.gate,
        # the baselines report their filter's own covariance (as naive-delay, its own class)
        covariance_scale=CovarianceScaleConfig(enable=False),
    )


def create_pose_only_ukf(config: PoseOnlyUkfConfig, context: TrackerContext) -> RoftTracker:
    """The delay-aware pose-only UKF (replays from each pose's capture frame)."""
    return RoftTracker(_roft_config(config, resync=True), context)
