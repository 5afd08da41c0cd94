"""Constant-velocity pose UKFs on detector poses alone (no flow, no masks).

Both reuse ROFT's quaternion UKF (:mod:`roft_sim.trackers.roft.pose_ukf`) with pose-only
measurements and the settings of ROFT's "w/o velocity" ablation (Q_ww = 0.01 per step, rotation
measurement variance 0.01 rad^2):

- ``pose-only-ukf`` handles delays correctly: a pose captured at frame c restarts the filter from
  its belief at c-1 and replays the predictions up to now (ROFT's pose synchronisation).
- ``naive-delay`` makes the classic mistake: a delayed pose is fused at the frame it arrives, as
  if it had been captured then, so under motion the filter is pulled towards where the object
  was ``delay`` frames ago.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from roft_sim.trackers.base import TrackerContext
from roft_sim.trackers.roft.config import (
    OutlierRejectionConfig,
    PoseSyncConfig,
    PoseUKFConfig,
    RoftConfig,
)
from roft_sim.trackers.roft.tracker import RoftTracker

__all__ = ["PoseOnlyUkfConfig", "create_pose_only_ukf", "create_naive_delay"]


def _pose_only_defaults() -> PoseUKFConfig:
    return PoseUKFConfig(sigma_angular=(0.01, 0.01, 0.01), meas_cov_q=(0.01, 0.01, 0.01))


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseOnlyUkfConfig:
    """Settings of the pose-only UKF baselines (ROFT's UKF without velocity measurements)."""

    pose: PoseUKFConfig = field(default_factory=_pose_only_defaults)
    """The UKF (defaults: ROFT's, with sigma_angular = 0.01 and meas_cov_q = 0.01)."""
    sync: PoseSyncConfig = field(default_factory=PoseSyncConfig)
    """Replay horizon (used by ``pose-only-ukf``; ``naive-delay`` has nothing to replay)."""


def _roft_config(config: PoseOnlyUkfConfig, *, resync: bool) -> RoftConfig:
    return RoftConfig(
        use_flow=False,
        use_velocity=False,
        use_pose_resync=resync,
        pose=config.pose,
        sync=config.sync,
        outlier_rejection=OutlierRejectionConfig(enable=False),
    )


def create_pose_only_ukf(config: PoseOnlyUkfConfig, context: TrackerContext) -> RoftTracker:
    """The delay-aware pose-only UKF (replays from each pose's capture frame)."""
    return RoftTracker(_roft_config(config, resync=True), context)


def create_naive_delay(config: PoseOnlyUkfConfig, context: TrackerContext) -> RoftTracker:
    """The pose-only UKF that fuses every delayed pose at its arrival frame."""
    return RoftTracker(_roft_config(config, resync=False), context)
