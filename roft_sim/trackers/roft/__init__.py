"""ROFT: optical-flow-aided 6D object pose and velocity tracking (Piga et al., RA-L 2022).

A numpy re-implementation of hsp-iit/roft; the method, its parameters and the deliberate
differences from the reference are documented in docs/roft.md. Registered as the tracker
``roft`` (entry point ``roft = "roft_sim.trackers.roft:SPEC"``) and, with the reference's
settings (:func:`reference_config`), as ``roft-reference`` (``REFERENCE_SPEC``).
"""

from roft_sim.trackers.base import TrackerContext, TrackerSpec
from roft_sim.trackers.roft.config import (
    ABLATIONS,
    MaskSyncConfig,
    OutlierRejectionConfig,
    PoseGateConfig,
    PoseSyncConfig,
    PoseUKFConfig,
    RoftConfig,
    VelocityKFConfig,
    ablation_config,
)
from roft_sim.trackers.roft.reference import (
    DEVIATIONS,
    Deviation,
    RoftReferenceConfig,
    apply_deviations,
    reference_config,
)
from roft_sim.trackers.roft.tracker import RoftTracker

__all__ = [
    "ABLATIONS",
    "DEVIATIONS",
    "Deviation",
    "REFERENCE_SPEC",
    "RoftReferenceConfig",
    "apply_deviations",
    "reference_config",
    "MaskSyncConfig",
    "OutlierRejectionConfig",
    "PoseGateConfig",
    "PoseSyncConfig",
    "PoseUKFConfig",
    "RoftConfig",
    "RoftTracker",
    "SPEC",
    "VelocityKFConfig",
    "ablation_config",
]


def _create(config: RoftConfig, context: TrackerContext) -> RoftTracker:
    return RoftTracker(config, context)


SPEC = TrackerSpec(
    name="roft",
    description="ROFT: flow-aided mask sync, velocity KF and quaternion UKF with delayed-pose "
    "replay and depth outlier rejection (Piga et al. 2022)",
    config_type=RoftConfig,
    factory=_create,
    needs_depth_renderer=True,
)
"""The registry entry of ROFT."""


REFERENCE_SPEC = TrackerSpec(
    name="roft-reference",
    description="ROFT with the C++ reference's settings (reference_config(); the deviations of "
    "the default are listed in roft_sim.trackers.roft.DEVIATIONS)",
    config_type=RoftReferenceConfig,
    factory=_create,
    needs_depth_renderer=True,
)
"""The registry entry of ROFT with the reference configuration."""
