"""Hand-made sequences and test trackers for the harness tests.

- :func:`box_sequence`: the analytic box (exact rgb, depth, masks, flow, ground truth) plus a
  detector pose set ``dope`` that differs from the ground truth (offset, noise, misses) and a
  detector mask set ``mrcnn`` (eroded ground-truth masks, with a miss), so a test can tell what
  came from the detector and what would have been ground truth.
- :class:`EchoTracker`: reports the newest arrived pose (invalid before the first).
- :class:`SpyTracker`: records everything it receives.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from roft_sim.datasets import write_sequence
from roft_sim.datasets.base import DetectorPoses, InMemorySequence
from roft_sim.geometry.so3 import matrix_from_rotvec
from roft_sim.records import Estimate, Observation
from roft_sim.testing.analytic_scene import analytic_box_sequence, default_intrinsics
from roft_sim.trackers import TrackerContext, TrackerSpec

POSE_OFFSET_M = np.array([0.004, -0.003, 0.002])
"""Constant offset of the detector poses from the ground truth [m]."""
POSE_MISSES = (5, 11)
"""Frames on which the detector finds nothing."""
MASK_MISSES = (6,)
"""Frames on which the segmenter finds nothing."""


def box_sequence(
    n_frames: int = 24, width: int = 64, height: int = 48, *, name: str = "box", seed: int = 3
) -> InMemorySequence:
    """The analytic box with a detector pose set ``dope`` and mask set ``mrcnn`` (module doc)."""
    base = analytic_box_sequence(
        n_frames=n_frames, intrinsics=default_intrinsics(width, height), name=name
    )
    gt = base.ground_truth()
    assert gt is not None
    rng = np.random.default_rng(seed)
    T = gt.T_cam_obj.copy()
    T[:, :3, 3] += POSE_OFFSET_M + rng.normal(0.0, 0.002, (n_frames, 3))
    for k in range(n_frames):
        T[k, :3, :3] = matrix_from_rotvec(rng.normal(0.0, 0.02, 3)) @ T[k, :3, :3]
    valid = np.ones(n_frames, dtype=bool)
    for k in POSE_MISSES:
        if k < n_frames:
            valid[k] = False
            T[k] = np.eye(4)
    kernel = np.ones((3, 3), np.uint8)
    masks: list[np.ndarray | None] = []
    for k, m in enumerate(base.gt_masks or []):
        eroded = cv2.erode(m.astype(np.uint8), kernel).astype(bool)
        masks.append(None if k in MASK_MISSES else eroded)
    return dataclasses.replace(
        base,
        detector_pose_sets={"dope": DetectorPoses(T_cam_obj=T, valid=valid)},
        detector_masks={"mrcnn": masks},
    )


def write_box_dataset(root: Path, names: tuple[str, ...] = ("box_a", "box_b"), **kwargs) -> Path:
    """Writes one :func:`box_sequence` per name as Fast-YCB folders under ``root``."""
    for i, name in enumerate(names):
        write_sequence(box_sequence(name=name, seed=10 + i, **kwargs), "fast-ycb", root)
    return root


@dataclass(frozen=True, slots=True, kw_only=True)
class EchoConfig:
    """Settings of :class:`EchoTracker`."""

    draw_noise: bool = False
    """Draw one number from the context's rng per step into the diagnostics."""


class EchoTracker:
    """Reports the newest arrived pose (largest capture frame); invalid before the first."""

    def __init__(self, config: EchoConfig, context: TrackerContext) -> None:
        self.config = config
        self.context = context
        self.reset(None)

    def reset(self, initial: Estimate | None) -> None:
        self.initial = initial
        self.held: tuple[int, np.ndarray] | None = None

    def step(self, observation: Observation) -> Estimate:
        for det in observation.poses:
            if self.held is None or det.capture_k > self.held[0]:
                self.held = (det.capture_k, np.array(det.T_cam_obj))
        diagnostics: dict[str, Any] = {}
        if self.config.draw_noise:
            diagnostics["draw"] = float(self.context.rng.normal())
        if self.held is None:
            return Estimate.invalid(observation.k, diagnostics=diagnostics)
        return Estimate(
            k=observation.k,
            T_cam_obj=self.held[1],
            v_obj_mps=np.full(3, 0.01 * observation.k),
            w_radps=np.array([0.1, -0.2, 0.3]),
            accepted_pose_ids=tuple(d.detection_id for d in observation.poses),
            diagnostics=diagnostics,
        )


ECHO_SPEC = TrackerSpec(
    name="echo",
    description="test tracker: the newest arrived pose",
    config_type=EchoConfig,
    factory=EchoTracker,
)


@dataclass(slots=True)
class SpyLog:
    """What a :class:`SpyTracker` saw."""

    contexts: list[TrackerContext] = field(default_factory=list)
    resets: list[Estimate | None] = field(default_factory=list)
    observations: list[Observation] = field(default_factory=list)


SPY_LOG = SpyLog()


@dataclass(frozen=True, slots=True, kw_only=True)
class SpyConfig:
    """Settings of :class:`SpyTracker` (none)."""


class SpyTracker(EchoTracker):
    """An :class:`EchoTracker` that records its context, resets and observations in SPY_LOG."""

    def __init__(self, config: SpyConfig, context: TrackerContext) -> None:
        SPY_LOG.contexts.append(context)
        super().__init__(EchoConfig(), context)

    def reset(self, initial: Estimate | None) -> None:
        if hasattr(self, "initial"):
            SPY_LOG.resets.append(initial)
        super().reset(initial)

    def step(self, observation: Observation) -> Estimate:
        SPY_LOG.observations.append(observation)
        return super().step(observation)


SPY_SPEC = TrackerSpec(
    name="spy",
    description="test tracker recording what it receives",
    config_type=SpyConfig,
    factory=SpyTracker,
)
