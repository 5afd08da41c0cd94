"""Camera-side faults: depth holes and noise bursts, and flow corruption.

Dropped camera frames are the loss faults of :mod:`roft_sim.faults.loss` listed under
``[camera]`` (the chain of a burst model steps once per camera frame).

Every fault here hits a camera frame with probability ``p``, and then stays on for
``burst_frames`` consecutive frames (a burst that starts at k covers k .. k + burst_frames - 1).
As with the detection faults, drawing is separate from applying: ``draw_frames`` gives, per
frame, None or the parameters (with a seed for pixel-level randomness), and ``apply_*`` makes a
corrupted COPY of the depth image or flow field.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.faults.checks import check_int_range, check_positive_finite, check_probability
from roft_sim.records import FlowField

I64 = NDArray[np.int64]
F32 = NDArray[np.float32]
Bool = NDArray[np.bool_]
Params = dict[str, Any]

__all__ = [
    "affected_frames",
    "DepthHoles",
    "DepthNoise",
    "FlowNoise",
    "FlowHoles",
    "FlowReversed",
]


def affected_frames(n_frames: int, p: float, burst_frames: int, rng: np.random.Generator) -> Bool:
    """(n_frames,) bool: frames hit by bursts that start with probability ``p`` per frame and
    last ``burst_frames`` frames."""
    starts = rng.random(n_frames) < p
    if burst_frames <= 1 or n_frames == 0:
        return starts
    covered = np.convolve(starts.astype(np.int64), np.ones(burst_frames, dtype=np.int64))
    return covered[:n_frames] > 0


def _check_occurrence(p: float, burst_frames: int) -> None:
    check_probability("p", p)
    if burst_frames < 1:
        raise ConfigError(f"burst_frames must be >= 1, got {burst_frames}")


def _draw_seeded(
    fault: Any, n_frames: int, rng: np.random.Generator, extra: Params | None = None
) -> list[Params | None]:
    hit = affected_frames(n_frames, fault.p, fault.burst_frames, rng)
    seeds = rng.integers(0, 2**63 - 1, size=n_frames, dtype=np.int64)
    return [{"seed": int(seeds[k]), **(extra or {})} if hit[k] else None for k in range(n_frames)]


def _occurrence_text(p: float, burst_frames: int) -> str:
    burst = f", bursts of {burst_frames} frames" if burst_frames > 1 else ""
    return f"p={p:g}{burst}"


def _ellipses(
    shape: tuple[int, int], count: int, r_lo: int, r_hi: int, rng: np.random.Generator
) -> Bool:
    h, w = shape
    canvas = np.zeros((h, w), dtype=np.uint8)
    for _ in range(count):
        centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        axes = tuple(int(a) for a in rng.integers(r_lo, r_hi + 1, size=2))
        cv2.ellipse(canvas, centre, axes, float(rng.uniform(0, 180)), 0.0, 360.0, 1, -1)
    return canvas.astype(bool)


@dataclass(frozen=True, slots=True, kw_only=True)
class _EllipticalHoles:
    """Settings shared by the hole faults: bursts of frames with 1..``max_count`` elliptical
    holes of semi-axes ``min_radius_px..max_radius_px`` image pixels."""

    p: float = 0.1
    """Probability per camera frame that a burst starts [-]."""
    burst_frames: int = 1
    """Frames each burst lasts, >= 1."""
    max_count: int = 3
    """Most holes per frame, >= 1."""
    min_radius_px: int = 5
    """Smallest hole semi-axis [px], >= 1."""
    max_radius_px: int = 30
    """Largest hole semi-axis [px]."""
    stage: ClassVar[Literal["frame"]] = "frame"

    def __post_init__(self) -> None:
        _check_occurrence(self.p, self.burst_frames)
        if self.max_count < 1:
            raise ConfigError(f"max_count must be >= 1, got {self.max_count}")
        check_int_range(
            "min_radius_px", self.min_radius_px, "max_radius_px", self.max_radius_px, minimum=1
        )

    def draw_frames(self, n_frames: int, rng: np.random.Generator) -> list[Params | None]:
        return _draw_seeded(self, n_frames, rng)


@dataclass(frozen=True, slots=True, kw_only=True)
class DepthHoles(_EllipticalHoles):
    """Elliptical holes (depth 0 = no measurement) in hit frames: 1..``max_count`` holes with
    semi-axes ``min_radius_px..max_radius_px``."""

    kind: Literal["depth_holes"] = "depth_holes"

    def apply_depth(self, depth_m: F32, params: Params) -> F32:
        """(H, W) float32 depth [m] with holes set to 0 (a new array)."""
        rng = np.random.default_rng(params["seed"])
        count = int(rng.integers(1, self.max_count + 1))
        holes = _ellipses(depth_m.shape, count, self.min_radius_px, self.max_radius_px, rng)
        return np.where(holes, np.float32(0.0), depth_m).astype(np.float32)

    def describe(self) -> str:
        return (
            f"depth holes (up to {self.max_count}, {self.min_radius_px}..{self.max_radius_px} px)"
            f", {_occurrence_text(self.p, self.burst_frames)}"
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class DepthNoise:
    """Gaussian depth noise ``N(0, sd_m)`` on every measured pixel of hit frames (0 stays 0;
    a pixel pushed to <= 0 becomes 0, "no measurement")."""

    kind: Literal["depth_noise"] = "depth_noise"
    p: float = 0.05
    """Probability per camera frame that a burst starts [-]."""
    burst_frames: int = 5
    """Frames each burst lasts, >= 1."""
    sd_m: float = 0.01
    """Noise standard deviation [m], > 0."""
    stage: ClassVar[Literal["frame"]] = "frame"

    def __post_init__(self) -> None:
        _check_occurrence(self.p, self.burst_frames)
        check_positive_finite("sd_m", self.sd_m)

    def draw_frames(self, n_frames: int, rng: np.random.Generator) -> list[Params | None]:
        return _draw_seeded(self, n_frames, rng)

    def apply_depth(self, depth_m: F32, params: Params) -> F32:
        """(H, W) float32 noisy depth [m] (a new array)."""
        rng = np.random.default_rng(params["seed"])
        noise = rng.standard_normal(depth_m.shape, dtype=np.float32)
        noise *= np.float32(self.sd_m)
        noisy = depth_m + noise
        return np.where((depth_m > 0) & (noisy > 0), noisy, np.float32(0.0)).astype(np.float32)

    def describe(self) -> str:
        return f"depth noise sd {self.sd_m:g} m, {_occurrence_text(self.p, self.burst_frames)}"


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowNoise:
    """Gaussian noise ``N(0, sd_px)`` added to both flow components of hit frames."""

    kind: Literal["flow_noise"] = "flow_noise"
    p: float = 1.0
    """Probability per camera frame that a burst starts [-]."""
    burst_frames: int = 1
    """Frames each burst lasts, >= 1."""
    sd_px: float = 0.5
    """Noise standard deviation per component [px], > 0."""
    stage: ClassVar[Literal["frame"]] = "frame"

    def __post_init__(self) -> None:
        _check_occurrence(self.p, self.burst_frames)
        check_positive_finite("sd_px", self.sd_px)

    def draw_frames(self, n_frames: int, rng: np.random.Generator) -> list[Params | None]:
        return _draw_seeded(self, n_frames, rng)

    def apply_flow(self, flow: FlowField, params: Params) -> FlowField:
        rng = np.random.default_rng(params["seed"])
        noise = rng.standard_normal(flow.flow_px.shape, dtype=np.float32)
        noise *= np.float32(self.sd_px)
        return dataclasses.replace(flow, flow_px=(flow.flow_px + noise).astype(np.float32))

    def describe(self) -> str:
        return f"flow noise sd {self.sd_px:g} px, {_occurrence_text(self.p, self.burst_frames)}"


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowHoles(_EllipticalHoles):
    """Elliptical regions of hit frames' flow marked invalid (``FlowField.valid`` False);
    1..``max_count`` holes with semi-axes ``min_radius_px..max_radius_px`` image pixels."""

    kind: Literal["flow_holes"] = "flow_holes"

    def apply_flow(self, flow: FlowField, params: Params) -> FlowField:
        rng = np.random.default_rng(params["seed"])
        count = int(rng.integers(1, self.max_count + 1))
        g = flow.grid_px
        lo, hi = max(1, self.min_radius_px // g), max(1, self.max_radius_px // g)
        holes = _ellipses(flow.flow_px.shape[:2], count, lo, max(lo, hi), rng)
        valid = np.ones(holes.shape, dtype=bool) if flow.valid is None else flow.valid
        return dataclasses.replace(flow, valid=valid & ~holes)

    def describe(self) -> str:
        return (
            f"flow holes (up to {self.max_count}, {self.min_radius_px}..{self.max_radius_px} px)"
            f", {_occurrence_text(self.p, self.burst_frames)}"
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowReversed:
    """Hit frames get flow of the wrong direction, the classic "backward flow used as forward
    flow" bug.

    ``mode = "negate"``: the forward flow with its sign flipped (to first order the backward
    flow, and works with any source). ``mode = "backward"``: the source's real backward flow
    ``k -> previous`` relabelled as ``previous -> k`` (needs a source that computes backward
    flow, e.g. ``gt`` or ``dis``; a source that cannot gives no flow on that frame).
    """

    kind: Literal["flow_reversed"] = "flow_reversed"
    p: float = 0.05
    """Probability per camera frame that a burst starts [-]."""
    burst_frames: int = 1
    """Frames each burst lasts, >= 1."""
    mode: Literal["negate", "backward"] = "negate"
    """How the wrong-direction flow is made."""
    stage: ClassVar[Literal["frame"]] = "frame"

    def __post_init__(self) -> None:
        _check_occurrence(self.p, self.burst_frames)

    def draw_frames(self, n_frames: int, rng: np.random.Generator) -> list[Params | None]:
        hit = affected_frames(n_frames, self.p, self.burst_frames, rng)
        params = {"backward": True} if self.mode == "backward" else {}
        return [dict(params) if h else None for h in hit]

    def apply_flow(self, flow: FlowField, params: Params) -> FlowField:
        """The wrong-direction flow, labelled as the forward one (``from_k < to_k``)."""
        if params.get("backward"):  # the stream asked the source for to_k -> from_k
            lo, hi = sorted((flow.from_k, flow.to_k))
            return dataclasses.replace(flow, from_k=lo, to_k=hi)
        return dataclasses.replace(flow, flow_px=(-flow.flow_px).astype(np.float32))

    def describe(self) -> str:
        how = "backward flow" if self.mode == "backward" else "sign-flipped flow"
        return f"flow reversed ({how}), {_occurrence_text(self.p, self.burst_frames)}"
