"""What every flow source shares (:mod:`roft_sim.sensors.flow_sources` lists the sources).

The :class:`FlowSource` protocol; the per-frame-pair generators of stochastic sources
(:func:`frame_rng`); the checks of a frame pair and of a config number; NVOF's output format
(one vector per 4x4 block, S10.5 fixed point, 1/4 px precision); and the two sources the others
build on: the stored flow (:class:`StoredFlowSource`) and the exact motion field
(:class:`GroundTruthFlowSource`). The NVOF-like, block-matching and hardware sources import this
module, and :func:`~roft_sim.sensors.flow_sources.make_flow_source` imports them, so the import
graph has no cycle.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import GT_MASK_SET, Sequence
from roft_sim.errors import ConfigError
from roft_sim.geometry.rigid_flow import (
    DEFAULT_OCCLUSION_TOLERANCE,
    object_and_static_motions,
    rigid_flow,
)
from roft_sim.records import FlowField, PoseTrack

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

__all__ = [
    "FlowSource",
    "StoredFlowSource",
    "GroundTruthFlowSource",
    "NVOF_GRID_PX",
    "NVOF_PRECISION_PX",
    "s10_5_from_flow_px",
    "flow_px_from_s10_5",
    "check_s10_5_precision",
    "check_frame_pair",
    "check_finite_at_least",
    "frame_rng",
]

NVOF_GRID_PX = 4
"""NVOF 1.0 output grid: one vector per 4x4 block."""

NVOF_PRECISION_PX = 0.25
"""NVOF 1.0 (Turing) vector precision: "4x4 vectors at 1/4 pixel resolution" (NVIDIA Optical
Flow SDK product page, developer.nvidia.com/opticalflow-sdk); the S10.5 format could hold 1/32."""

_S10_5_SCALE = 32.0
"""NVOF's S10.5 fixed point: int16 with 5 fractional bits (value / 32 = pixels)."""


def frame_rng(seed: int, *keys: int) -> np.random.Generator:
    """A generator for one (seed, frame keys) combination: ``SeedSequence([seed, *keys])``.

    Args:
        seed: the subsystem's seed (>= 0).
        keys: frame indices (>= 0), e.g. ``from_k, to_k``.
    """
    entropy = [int(seed), *(int(k) for k in keys)]
    if min(entropy) < 0:
        raise ValueError(f"seed and frame keys must be >= 0, got {entropy}")
    return np.random.default_rng(np.random.SeedSequence(entropy))


@runtime_checkable
class FlowSource(Protocol):
    """Flow between two frames of a sequence."""

    @property
    def name(self) -> str:
        """Short label; for sources built by :func:`make_flow_source`, the spec string (custom
        configs are not part of it: record them separately)."""
        ...

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField | None:
        """Flow mapping pixels of frame ``from_k`` to frame ``to_k``, or None when this source
        cannot provide it (e.g. a stored set asked for a stride other than 1)."""
        ...


def check_frame_pair(sequence: Sequence, from_k: int, to_k: int) -> None:
    """Raises ValueError unless ``from_k`` and ``to_k`` are two different frames of ``sequence``."""
    n = len(sequence)
    if not (0 <= from_k < n and 0 <= to_k < n) or from_k == to_k:
        raise ValueError(
            f"flow needs two different frames in [0, {n - 1}] of sequence {sequence.name!r}, "
            f"got from_k={from_k}, to_k={to_k}"
        )


@dataclass(frozen=True, slots=True)
class StoredFlowSource:
    """The flow stored with the dataset (e.g. Fast-YCB's ``nvof_1_slow``).

    Stored sets hold consecutive-frame flow only (file ``k`` is ``F_(k-1 -> k)``), so any other
    stride gives None; use ``gt`` or ``dis`` for strides above 1.
    """

    flow_set: str
    """Name of the stored set."""

    @property
    def name(self) -> str:
        return f"stored:{self.flow_set}"

    def check_sequence(self, sequence: Sequence) -> None:
        """Raises :class:`ConfigError` when ``sequence`` has no stored set of this name."""
        if self.flow_set not in sequence.flow_sets():
            raise ConfigError(
                f"sequence {sequence.name!r} has no stored flow set {self.flow_set!r}; it has "
                f"{list(sequence.flow_sets()) or 'none'}; pick one of those or use 'gt' / 'dis'"
            )

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField | None:
        check_frame_pair(sequence, from_k, to_k)
        self.check_sequence(sequence)
        if to_k - from_k != 1:
            return None
        return sequence.flow(to_k, self.flow_set)


class GroundTruthFlowSource:
    """Exact flow (a motion field) for any stride, from the sequence's ground truth.

    Uses the depth and ``gt`` (visible) mask of ``from_k``: mask pixels move with the object's
    ground-truth pose, every other pixel with depth is static in the world and moves only with
    the camera (``camera_poses()``). Pixels are valid when they have depth, land in front of
    the camera and inside the image, and (with ``occlusion_test``) are not hidden in ``to_k``
    by a nearer surface, judged from ``depth(to_k)``. Other moving bodies (e.g. a hand
    occluder) are not in the gt mask and are treated as static, so their flow is wrong.
    """

    name = "gt"

    __slots__ = ("occlusion_test", "occlusion_tolerance", "_cache")

    def __init__(
        self,
        *,
        occlusion_test: bool = True,
        occlusion_tolerance: tuple[float, float] = DEFAULT_OCCLUSION_TOLERANCE,
    ) -> None:
        self.occlusion_test = occlusion_test
        self.occlusion_tolerance = occlusion_tolerance
        self._cache: tuple[Sequence, PoseTrack, F64] | None = None

    def _geometry(self, sequence: Sequence) -> tuple[PoseTrack, F64]:
        if self._cache is None or self._cache[0] is not sequence:
            gt = sequence.ground_truth()
            if gt is None:
                raise ConfigError(
                    f"sequence {sequence.name!r} has no ground-truth poses, so flow source 'gt' "
                    "cannot be used; use 'dis' or a stored flow set"
                )
            if GT_MASK_SET not in sequence.mask_sets():
                raise ConfigError(
                    f"sequence {sequence.name!r} has no {GT_MASK_SET!r} mask set, which flow "
                    "source 'gt' needs to tell the object from the static world"
                )
            self._cache = (sequence, gt, np.asarray(sequence.camera_poses(), dtype=np.float64))
        return self._cache[1], self._cache[2]

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField:
        check_frame_pair(sequence, from_k, to_k)
        gt, T_world_cam = self._geometry(sequence)
        depth = np.asarray(sequence.depth(from_k), dtype=np.float32)
        mask = sequence.mask(from_k, GT_MASK_SET)
        obj = np.zeros(depth.shape, bool) if mask is None else np.asarray(mask, dtype=bool)
        body = np.where(obj, 1, np.where(depth > 0, 0, -1))
        motions = object_and_static_motions(
            gt.T_cam_obj[from_k], gt.T_cam_obj[to_k], T_world_cam[from_k], T_world_cam[to_k]
        )
        flow, valid = rigid_flow(
            sequence.intrinsics,
            depth,
            body,
            motions,
            depth_to_m=sequence.depth(to_k) if self.occlusion_test else None,
            occlusion_tolerance=self.occlusion_tolerance,
        )
        return FlowField(flow_px=flow, from_k=from_k, to_k=to_k, grid_px=1, valid=valid)


def check_finite_at_least(owner: str, name: str, value: float, low: float) -> None:
    """Raises :class:`ConfigError` naming ``owner.name`` unless ``value`` is finite, >= ``low``."""
    if not (np.isfinite(value) and value >= low):
        raise ConfigError(f"{owner}.{name} must be a finite number >= {low}, got {value}")


def s10_5_from_flow_px(flow_px: NDArray[np.floating]) -> NDArray[np.int16]:
    """NVOF S10.5 fixed point: ``round(32 F)`` saturated to int16 (|F| <= 1023.97 px)."""
    q = np.rint(np.asarray(flow_px, dtype=np.float64) * _S10_5_SCALE)
    return np.clip(q, np.iinfo(np.int16).min, np.iinfo(np.int16).max).astype(np.int16)


def check_s10_5_precision(name: str, precision_px: float) -> None:
    """ConfigError unless ``precision_px`` is a whole multiple of S10.5's 1/32 px step, >= 1/32;
    ``name`` is the parameter's name for the message."""
    steps = precision_px * _S10_5_SCALE
    if not (np.isfinite(steps) and steps >= 1 and abs(steps - round(steps)) < 1e-9):
        raise ConfigError(
            f"{name} must be a whole multiple of 1/32 px (S10.5), >= 1/32, got {precision_px}; "
            "NVOF 1.0 gives 0.25"
        )


def flow_px_from_s10_5(q: NDArray[np.int16]) -> F32:
    """Pixels from NVOF S10.5 fixed point: ``q / 32`` as float32 (exact)."""
    return (np.asarray(q, dtype=np.float32) / np.float32(_S10_5_SCALE)).astype(np.float32)
