"""Fault injectors and the per-frame observation stream: what a tracker sees, frame by frame.

- :func:`load_faults`, :func:`list_fault_presets`: fault configurations from
  ``scenarios/faults/*.toml`` presets (``none``, ``paper``, stress presets) or any TOML file.
- :func:`schedule_detections`: the pure timing of every stream (no images; cheap).
- :class:`ObservationStream`: one :class:`~roft_sim.records.Observation` per camera frame from a
  dataset :class:`~roft_sim.datasets.base.Sequence`, with its :class:`FaultLedger`.
- The fault models (frozen configs): timing (:class:`Rate`, :class:`BusyNetwork`, delays,
  :class:`ClockSkew`), loss (:class:`BernoulliDropout`, :class:`GilbertElliott`,
  :class:`Blackout`), content (pose outliers, mask corruption), delivery (:class:`Duplicate`,
  :class:`Stale`, :class:`Reorder`) and camera (depth and flow faults).

See docs/faults.md for every fault, its parameters and units, and the composition order.
"""

from roft_sim.faults.camera import DepthHoles, DepthNoise, FlowHoles, FlowNoise, FlowReversed
from roft_sim.faults.config import (
    CameraFault,
    CameraFaults,
    FaultConfig,
    FirstResult,
    FlowFault,
    FlowFaults,
    MaskFault,
    MaskStreamFaults,
    PoseFault,
    PoseStreamFaults,
    compose_faults,
    fault_config_from_mapping,
    fault_presets_dir,
    fault_spec_name,
    list_fault_presets,
    load_faults,
)
from roft_sim.faults.content import (
    MASK_CORRUPTION_KINDS,
    POSE_OUTLIER_KINDS,
    CorruptionContext,
    EmptyMask,
    MaskMorphology,
    MaskShift,
    RotationFlip,
    SpuriousBlobs,
    TranslationJump,
    WrongFrameMask,
    WrongObject,
)
from roft_sim.faults.delivery import Duplicate, Reorder, Stale
from roft_sim.faults.events import Corruption, DeliveryEvent, DetectionRecord
from roft_sim.faults.loss import BernoulliDropout, Blackout, GilbertElliott
from roft_sim.faults.random_mix import fault_mix_toml, random_fault_mix
from roft_sim.faults.schedule import (
    CameraSchedule,
    DetectionSchedule,
    fault_rng,
    schedule_detections,
)
from roft_sim.faults.stream import FaultLedger, FlowSource, ObservationStream
from roft_sim.faults.timeline import format_timeline
from roft_sim.faults.timing import (
    BusyNetwork,
    ClockSkew,
    EmpiricalDelay,
    FixedDelay,
    LogNormalDelay,
    Rate,
    UniformDelay,
)

__all__ = [
    # configuration
    "FaultConfig",
    "PoseStreamFaults",
    "MaskStreamFaults",
    "CameraFaults",
    "FlowFaults",
    "PoseFault",
    "MaskFault",
    "CameraFault",
    "FlowFault",
    "FirstResult",
    "load_faults",
    "list_fault_presets",
    "fault_presets_dir",
    "fault_config_from_mapping",
    "compose_faults",
    "fault_spec_name",
    "random_fault_mix",
    "fault_mix_toml",
    # schedule and stream
    "schedule_detections",
    "DetectionSchedule",
    "CameraSchedule",
    "DeliveryEvent",
    "DetectionRecord",
    "Corruption",
    "fault_rng",
    "ObservationStream",
    "FlowSource",
    "FaultLedger",
    "format_timeline",
    # fault models
    "Rate",
    "BusyNetwork",
    "FixedDelay",
    "UniformDelay",
    "LogNormalDelay",
    "EmpiricalDelay",
    "ClockSkew",
    "BernoulliDropout",
    "GilbertElliott",
    "Blackout",
    "TranslationJump",
    "RotationFlip",
    "WrongObject",
    "MaskShift",
    "MaskMorphology",
    "EmptyMask",
    "SpuriousBlobs",
    "WrongFrameMask",
    "Duplicate",
    "Stale",
    "Reorder",
    "DepthHoles",
    "DepthNoise",
    "FlowNoise",
    "FlowHoles",
    "FlowReversed",
    "CorruptionContext",
    "POSE_OUTLIER_KINDS",
    "MASK_CORRUPTION_KINDS",
]
