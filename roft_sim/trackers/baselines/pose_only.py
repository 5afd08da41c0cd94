"""The filter both pose-only baselines share: ROFT's UKF on detector poses alone (no flow).

:class:`PoseOnlyUkfConfig` holds the settings of ``pose-only-ukf`` and ``naive-delay``. Both
reuse ROFT's quaternion UKF (:mod:`roft_sim.trackers.roft.pose_ukf`) with pose-only measurements,
the noise of ROFT's "w/o velocity" ablation (S_a = 1 as in the reference, Q_ww = 0.01 per step,
rotation measurement variance 0.01 rad^2), and ROFT's pose gate switched on:

- ``pose-only-ukf`` handles delays correctly: a pose captured at frame c restarts the filter from
  its belief at c-1 and replays the predictions up to now (ROFT's pose synchronisation).
- ``naive-delay`` makes the classic mistake: a delayed pose is fused at the frame it arrives, as
  if it had been captured then, so under motion the filter is pulled towards where the object
  was ``delay`` frames ago. It is its own class (:mod:`.naive_delay`: one running belief, no
  buffers, no replay), not ROFT's class with replay off; a test checks that it gives the same
  estimates as that ablation.

Why the gate (measured on six 640x480 Fast-YCB-like sequences of 240 frames, paper faults, ALL
rows ADD-AUC % / e_t cm / e_a deg): without a flow velocity, one fused 180-degree flip or 30 cm
jump of the simulated detector becomes a spurious velocity that the constant-velocity model
extrapolates (an 80 cm position error after one jump). With the gate ``pose-only-ukf`` went
from 45.7 / 18.3 / 29.8 to 47.2 / 7.2 / 27.2 and ``naive-delay`` from 58.8 / 10.8 / 26.3 to
60.0 / 5.5 / 24.6. A 45-degree gate rejected correct poses of fast turns (up to ~53 degrees
between 5 fps poses) and made both worse. ``pose-only-ukf`` stays behind ``naive-delay`` on this
fast motion: velocities differenced from 5 fps noisy poses carry ~94 deg/s of error, and
extrapolating them over the 6-frame delay costs more than lagging behind (on smooth,
near-constant-velocity motion replay wins: tests/trackers/test_tracker_baselines.py); this is
the gap ROFT's flow-based velocity fills. (S_a = 0.1 would help this fast motion, 51.8 / 5.8 /
27.1, but slows the velocity's convergence on smooth motion, so the reference's 1.0 stays.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

from roft_sim.trackers.roft.config import PoseGateConfig, PoseSyncConfig, PoseUKFConfig

__all__ = ["PoseOnlyUkfConfig"]


def _pose_only_defaults() -> PoseUKFConfig:
    # no velocity is measured, so there is no interval mean to integrate: the reference's
    # prediction order (pose integrated with the velocities of k-1) is kept
    return PoseUKFConfig(
        sigma_angular=(0.01, 0.01, 0.01),
        meas_cov_q=(0.01, 0.01, 0.01),
        integrate_interval_velocity=False,
    )


def _pose_only_gate() -> PoseGateConfig:
    return PoseGateConfig(enable=True, max_translation_m=0.15, max_rotation_deg=120.0)


@dataclass(frozen=True, slots=True, kw_only=True)
class PoseOnlyUkfConfig:
    """Settings of the pose-only UKF baselines (ROFT's UKF without velocity measurements)."""

    pose: PoseUKFConfig = field(default_factory=_pose_only_defaults)
    """The UKF (defaults: ROFT's, with sigma_angular = 0.01 and meas_cov_q = 0.01, as in its
    "w/o velocity" ablation, and the reference's prediction order; sigma_linear stays 1.0)."""
    gate: PoseGateConfig = field(default_factory=_pose_only_gate)
    """Rejects poses more than 15 cm or 120 degrees from the prediction (see the module
    docstring for why it is on and why these bounds)."""
    sync: PoseSyncConfig = field(default_factory=PoseSyncConfig)
    """Replay horizon (used by ``pose-only-ukf``; ``naive-delay`` has nothing to replay)."""
