"""Baseline trackers to compare ROFT with.

| name | what it does |
|---|---|
| ``detector-hold`` | the last delivered detector pose, held until the next (paper's "DOPE") |
| ``detector-ideal`` | the same, with every frame's detection delivered undelayed by the harness |
| ``naive-delay`` | pose-only UKF that fuses delayed poses as if they were current (own class) |
| ``pose-only-ukf`` | pose-only constant-velocity UKF with correct delay handling (replay) |
"""

from roft_sim.trackers.base import TrackerSpec
from roft_sim.trackers.baselines.detector_hold import DetectorHoldConfig, DetectorHoldTracker
from roft_sim.trackers.baselines.naive_delay import create_naive_delay
from roft_sim.trackers.baselines.pose_only import PoseOnlyUkfConfig
from roft_sim.trackers.baselines.pose_only_ukf import create_pose_only_ukf

__all__ = [
    "DETECTOR_HOLD_SPEC",
    "DETECTOR_IDEAL_SPEC",
    "NAIVE_DELAY_SPEC",
    "POSE_ONLY_UKF_SPEC",
    "DetectorHoldConfig",
    "DetectorHoldTracker",
    "PoseOnlyUkfConfig",
]

DETECTOR_HOLD_SPEC = TrackerSpec(
    name="detector-hold",
    description="last delivered detector pose held until the next (the paper's DOPE row)",
    config_type=DetectorHoldConfig,
    factory=DetectorHoldTracker,
)

DETECTOR_IDEAL_SPEC = TrackerSpec(
    name="detector-ideal",
    description="every frame's own detection, undelayed, held when missing (DOPE ideal)",
    config_type=DetectorHoldConfig,
    factory=DetectorHoldTracker,
    detection_mode="ideal",
)

NAIVE_DELAY_SPEC = TrackerSpec(
    name="naive-delay",
    description="pose-only UKF fusing delayed poses as if current (the classic mistake)",
    config_type=PoseOnlyUkfConfig,
    factory=create_naive_delay,
)

POSE_ONLY_UKF_SPEC = TrackerSpec(
    name="pose-only-ukf",
    description="pose-only constant-velocity UKF, delays handled by replay (no flow)",
    config_type=PoseOnlyUkfConfig,
    factory=create_pose_only_ukf,
)
