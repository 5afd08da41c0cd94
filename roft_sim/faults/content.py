"""Content faults: outlier poses and corrupted masks.

Each fault is applied in two steps so that schedules stay cheap and images are touched lazily:

1. ``draw(capture_k, rng, n_frames)`` (timing only): for every network run, None (untouched) or
   a small dict of the drawn parameters (a jump vector, a flip axis, a pixel shift, a seed for
   pixel-level randomness). These are recorded in the schedule and the ledger.
2. ``apply_pose`` / ``apply_mask``: turns a detection into its corrupted copy, deterministically
   from those parameters. Inputs are never modified.

Every draw takes one value per run for ALL runs, so whether run i is hit does not depend on which
other runs exist or which other faults are configured. Content faults of one stream apply in the
order they are listed (the order matters: a wrong-frame mask replaces an earlier shift; a
wrong-object pose replaces an earlier jump).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.faults.checks import check_int_range, check_positive_finite, check_probability
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.so3 import matrix_from_quat, matrix_from_rotvec

I64 = NDArray[np.int64]
F64 = NDArray[np.float64]
Bool = NDArray[np.bool_]
Params = dict[str, Any]

__all__ = [
    "CorruptionContext",
    "TranslationJump",
    "RotationFlip",
    "WrongObject",
    "MaskShift",
    "MaskMorphology",
    "EmptyMask",
    "SpuriousBlobs",
    "WrongFrameMask",
    "POSE_OUTLIER_KINDS",
    "MASK_CORRUPTION_KINDS",
]

POSE_OUTLIER_KINDS = frozenset({"translation_jump", "rotation_flip", "wrong_object"})
"""``kind`` of every fault that turns a pose into an injected outlier."""
MASK_CORRUPTION_KINDS = frozenset(
    {"mask_shift", "mask_morphology", "mask_empty", "mask_blobs", "mask_wrong_frame"}
)
"""``kind`` of every fault that corrupts a mask."""


@dataclass(frozen=True, slots=True, kw_only=True)
class CorruptionContext:
    """What content faults may use when they materialise (never ground truth)."""

    intrinsics: CameraIntrinsics
    """Camera of the sequence (image size, projection for wrong-object poses)."""
    n_frames: int
    """Number of camera frames."""
    read_mask: Callable[[int], Bool | None]
    """The detector mask of a frame (for wrong-frame masks); None = the detector missed."""


def _hit(rng: np.random.Generator, p: float, n: int) -> Bool:
    return rng.random(n) < p


def _seeds(rng: np.random.Generator, n: int) -> I64:
    return rng.integers(0, 2**63 - 1, size=n, dtype=np.int64)


# ---------------------------------------------------------------- pose outliers


@dataclass(frozen=True, slots=True, kw_only=True)
class TranslationJump:
    """With probability ``p``, the pose's translation jumps by ``min_m..max_m`` in a uniformly
    random direction (camera frame)."""

    kind: Literal["translation_jump"] = "translation_jump"
    p: float = 0.1
    """Probability per result [-]."""
    min_m: float = 0.1
    """Smallest jump [m]."""
    max_m: float = 0.3
    """Largest jump [m] (drawn uniformly in [min_m, max_m])."""
    stage: ClassVar[Literal["corruption"]] = "corruption"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        check_positive_finite("min_m", self.min_m, allow_zero=True)
        check_positive_finite("max_m", self.max_m, allow_zero=True)
        if self.max_m < self.min_m:
            raise ConfigError(f"max_m ({self.max_m}) must be >= min_m ({self.min_m})")

    def draw(self, capture_k: I64, rng: np.random.Generator, n_frames: int) -> list[Params | None]:
        n: int = capture_k.shape[0]
        hit = _hit(rng, self.p, n)
        direction = rng.standard_normal((n, 3))
        direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
        magnitude = rng.uniform(self.min_m, self.max_m, size=n)
        offset = direction * magnitude[:, None]
        return [{"offset_m": tuple(map(float, offset[i]))} if hit[i] else None for i in range(n)]

    def apply_pose(self, T_cam_obj: F64, params: Params, ctx: CorruptionContext) -> F64:
        """(4, 4) pose with its translation moved by ``offset_m`` (camera frame) [m]."""
        out = T_cam_obj.copy()
        out[:3, 3] += np.asarray(params["offset_m"])
        return out

    def describe(self) -> str:
        return f"translation jump {self.min_m:g}..{self.max_m:g} m, p={self.p:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class RotationFlip:
    """With probability ``p``, the pose is rotated by ``angle_rad`` (default 180 deg) about one
    of the object's own axes (a symmetry confusion): ``T' = T @ Rot(axis, angle)``."""

    kind: Literal["rotation_flip"] = "rotation_flip"
    p: float = 0.1
    """Probability per result [-]."""
    axes: tuple[Literal["x", "y", "z"], ...] = ("x", "y", "z")
    """Object axes to flip about, one chosen uniformly per outlier."""
    angle_rad: float = float(np.pi)
    """Flip angle [rad]."""
    stage: ClassVar[Literal["corruption"]] = "corruption"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        if not self.axes:
            raise ConfigError('axes must name at least one object axis, e.g. ["z"]')
        if not np.isfinite(self.angle_rad):
            raise ConfigError(f"angle_rad must be finite, got {self.angle_rad!r}")

    def draw(self, capture_k: I64, rng: np.random.Generator, n_frames: int) -> list[Params | None]:
        n: int = capture_k.shape[0]
        hit = _hit(rng, self.p, n)
        axis = rng.integers(0, len(self.axes), size=n)
        return [{"axis": self.axes[int(axis[i])]} if hit[i] else None for i in range(n)]

    def apply_pose(self, T_cam_obj: F64, params: Params, ctx: CorruptionContext) -> F64:
        """(4, 4) pose rotated about its own ``axis`` by ``angle_rad``."""
        rotvec = np.zeros(3)
        rotvec["xyz".index(params["axis"])] = self.angle_rad
        out = T_cam_obj.copy()
        out[:3, :3] = T_cam_obj[:3, :3] @ matrix_from_rotvec(rotvec)
        return out

    def describe(self) -> str:
        angle_deg = np.degrees(self.angle_rad)
        return f"rotation flip {angle_deg:g} deg about {list(self.axes)}, p={self.p:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class WrongObject:
    """With probability ``p``, the pose is that of another object: a uniformly random
    orientation at a uniformly random pixel, ``min_depth_m..max_depth_m`` deep."""

    kind: Literal["wrong_object"] = "wrong_object"
    p: float = 0.05
    """Probability per result [-]."""
    min_depth_m: float = 0.3
    """Nearest depth of the wrong object [m], > 0."""
    max_depth_m: float = 1.2
    """Farthest depth [m]."""
    stage: ClassVar[Literal["corruption"]] = "corruption"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        check_positive_finite("min_depth_m", self.min_depth_m)
        check_positive_finite("max_depth_m", self.max_depth_m)
        if self.max_depth_m < self.min_depth_m:
            raise ConfigError(
                f"max_depth_m ({self.max_depth_m}) must be >= min_depth_m ({self.min_depth_m})"
            )

    def draw(self, capture_k: I64, rng: np.random.Generator, n_frames: int) -> list[Params | None]:
        n: int = capture_k.shape[0]
        hit = _hit(rng, self.p, n)
        uv_rel = rng.random((n, 2))
        depth = rng.uniform(self.min_depth_m, self.max_depth_m, size=n)
        quat = rng.standard_normal((n, 4))
        quat /= np.maximum(np.linalg.norm(quat, axis=1, keepdims=True), 1e-12)
        quat *= np.where(quat[:, :1] < 0, -1.0, 1.0)
        return [
            {
                "uv_rel": tuple(map(float, uv_rel[i])),
                "depth_m": float(depth[i]),
                "quat_wxyz": tuple(map(float, quat[i])),
            }
            if hit[i]
            else None
            for i in range(n)
        ]

    def apply_pose(self, T_cam_obj: F64, params: Params, ctx: CorruptionContext) -> F64:
        """(4, 4) pose of the "wrong object" (the input pose is discarded)."""
        K = ctx.intrinsics
        u = params["uv_rel"][0] * (K.width_px - 1)
        v = params["uv_rel"][1] * (K.height_px - 1)
        z = params["depth_m"]
        out = np.eye(4)
        out[:3, :3] = matrix_from_quat(np.asarray(params["quat_wxyz"]))
        out[:3, 3] = ((u - K.cx_px) / K.fx_px * z, (v - K.cy_px) / K.fy_px * z, z)
        return out

    def describe(self) -> str:
        return f"wrong object at {self.min_depth_m:g}..{self.max_depth_m:g} m, p={self.p:g}"


# ---------------------------------------------------------------- mask corruption


@dataclass(frozen=True, slots=True, kw_only=True)
class MaskShift:
    """With probability ``p``, the mask is shifted by ``min_px..max_px`` pixels in a random
    direction (pixels shifted in from outside are empty)."""

    kind: Literal["mask_shift"] = "mask_shift"
    p: float = 0.1
    """Probability per result [-]."""
    min_px: int = 5
    """Smallest shift length [px], >= 1."""
    max_px: int = 20
    """Largest shift length [px]."""
    stage: ClassVar[Literal["corruption"]] = "corruption"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        check_int_range("min_px", self.min_px, "max_px", self.max_px, minimum=1)

    def draw(self, capture_k: I64, rng: np.random.Generator, n_frames: int) -> list[Params | None]:
        n = capture_k.shape[0]
        hit = _hit(rng, self.p, n)
        length = rng.uniform(self.min_px, self.max_px, size=n)
        angle = rng.uniform(0.0, 2.0 * np.pi, size=n)
        du = np.rint(length * np.cos(angle)).astype(np.int64)
        dv = np.rint(length * np.sin(angle)).astype(np.int64)
        du = np.where((du == 0) & (dv == 0), 1, du)  # a shift of >= 1 px, always
        return [{"du_px": int(du[i]), "dv_px": int(dv[i])} if hit[i] else None for i in range(n)]

    def apply_mask(self, mask: Bool, params: Params, ctx: CorruptionContext) -> Bool:
        du, dv = params["du_px"], params["dv_px"]
        h, w = mask.shape
        out = np.zeros_like(mask)
        if abs(du) < w and abs(dv) < h:
            out[max(dv, 0) : h + min(dv, 0), max(du, 0) : w + min(du, 0)] = mask[
                max(-dv, 0) : h + min(-dv, 0), max(-du, 0) : w + min(-du, 0)
            ]
        return out

    def describe(self) -> str:
        return f"mask shift {self.min_px}..{self.max_px} px, p={self.p:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class MaskMorphology:
    """With probability ``p``, the mask is dilated (radius > 0) or eroded (radius < 0) with an
    elliptical kernel of radius drawn uniformly from ``min_radius_px..max_radius_px``."""

    kind: Literal["mask_morphology"] = "mask_morphology"
    p: float = 0.1
    """Probability per result [-]."""
    min_radius_px: int = -5
    """Smallest signed radius [px] (negative: erosion)."""
    max_radius_px: int = 5
    """Largest signed radius [px] (positive: dilation)."""
    stage: ClassVar[Literal["corruption"]] = "corruption"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        check_int_range(
            "min_radius_px", self.min_radius_px, "max_radius_px", self.max_radius_px, minimum=None
        )

    def draw(self, capture_k: I64, rng: np.random.Generator, n_frames: int) -> list[Params | None]:
        n: int = capture_k.shape[0]
        hit = _hit(rng, self.p, n)
        r = rng.integers(self.min_radius_px, self.max_radius_px, size=n, endpoint=True)
        return [{"radius_px": int(r[i])} if hit[i] else None for i in range(n)]

    def apply_mask(self, mask: Bool, params: Params, ctx: CorruptionContext) -> Bool:
        r = params["radius_px"]
        if r == 0:
            return mask.copy()
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * abs(r) + 1, 2 * abs(r) + 1))
        m8 = mask.astype(np.uint8)
        # Outside the image counts as background for both operations.
        op = cv2.dilate if r > 0 else cv2.erode
        out = op(m8, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
        return out.astype(bool)

    def describe(self) -> str:
        return f"mask erosion/dilation {self.min_radius_px}..{self.max_radius_px} px, p={self.p:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class EmptyMask:
    """With probability ``p``, the network delivers an all-empty mask (it arrives, but shows
    nothing; the reference treats it as "no new mask")."""

    kind: Literal["mask_empty"] = "mask_empty"
    p: float = 0.05
    """Probability per result [-]."""
    stage: ClassVar[Literal["corruption"]] = "corruption"

    def __post_init__(self) -> None:
        check_probability("p", self.p)

    def draw(self, capture_k: I64, rng: np.random.Generator, n_frames: int) -> list[Params | None]:
        hit = _hit(rng, self.p, capture_k.shape[0])
        return [{} if h else None for h in hit]

    def apply_mask(self, mask: Bool, params: Params, ctx: CorruptionContext) -> Bool:
        return np.zeros_like(mask)

    def describe(self) -> str:
        return f"empty mask, p={self.p:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class SpuriousBlobs:
    """With probability ``p``, 1..``max_count`` elliptical false-positive blobs (radii
    ``min_radius_px..max_radius_px``) are added at uniformly random places."""

    kind: Literal["mask_blobs"] = "mask_blobs"
    p: float = 0.1
    """Probability per result [-]."""
    max_count: int = 2
    """Most blobs added to one mask, >= 1."""
    min_radius_px: int = 3
    """Smallest blob semi-axis [px], >= 1."""
    max_radius_px: int = 15
    """Largest blob semi-axis [px]."""
    stage: ClassVar[Literal["corruption"]] = "corruption"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        if self.max_count < 1:
            raise ConfigError(f"max_count must be >= 1, got {self.max_count}")
        check_int_range(
            "min_radius_px", self.min_radius_px, "max_radius_px", self.max_radius_px, minimum=1
        )

    def draw(self, capture_k: I64, rng: np.random.Generator, n_frames: int) -> list[Params | None]:
        n: int = capture_k.shape[0]
        hit = _hit(rng, self.p, n)
        count = rng.integers(1, self.max_count, size=n, endpoint=True)
        seed = _seeds(rng, n)
        return [
            {"count": int(count[i]), "seed": int(seed[i])} if hit[i] else None for i in range(n)
        ]

    def apply_mask(self, mask: Bool, params: Params, ctx: CorruptionContext) -> Bool:
        rng = np.random.default_rng(params["seed"])
        h, w = mask.shape
        canvas = np.zeros((h, w), dtype=np.uint8)
        for _ in range(params["count"]):
            centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
            axes = tuple(
                int(a) for a in rng.integers(self.min_radius_px, self.max_radius_px + 1, size=2)
            )
            angle = float(rng.uniform(0.0, 180.0))
            cv2.ellipse(canvas, centre, axes, angle, 0.0, 360.0, 1, thickness=-1)
        return mask | canvas.astype(np.bool_)

    def describe(self) -> str:
        return (
            f"spurious blobs (up to {self.max_count}, {self.min_radius_px}..{self.max_radius_px}"
            f" px), p={self.p:g}"
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class WrongFrameMask:
    """With probability ``p``, the mask of another frame, ``1..max_offset_frames`` away (either
    direction, clipped to the sequence), is delivered under this capture frame. A detector miss
    on that frame gives an empty mask."""

    kind: Literal["mask_wrong_frame"] = "mask_wrong_frame"
    p: float = 0.05
    """Probability per result [-]."""
    max_offset_frames: int = 6
    """Largest frame offset, >= 1."""
    stage: ClassVar[Literal["corruption"]] = "corruption"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        if self.max_offset_frames < 1:
            raise ConfigError(f"max_offset_frames must be >= 1, got {self.max_offset_frames}")

    def draw(self, capture_k: I64, rng: np.random.Generator, n_frames: int) -> list[Params | None]:
        n = capture_k.shape[0]
        hit = _hit(rng, self.p, n)
        magnitude = rng.integers(1, self.max_offset_frames, size=n, endpoint=True)
        sign = np.where(rng.random(n) < 0.5, -1, 1)
        source = capture_k + sign * magnitude
        # Off the sequence: take the other direction, then clip (a 1-frame sequence: itself).
        source = np.where((source < 0) | (source >= n_frames), capture_k - sign * magnitude, source)
        source = np.clip(source, 0, max(n_frames - 1, 0))
        return [{"source_k": int(source[i])} if hit[i] else None for i in range(n)]

    def apply_mask(self, mask: Bool, params: Params, ctx: CorruptionContext) -> Bool:
        other = ctx.read_mask(params["source_k"])
        if other is None:
            return np.zeros_like(mask)
        if other.shape != mask.shape:
            raise ConfigError(
                f"mask of frame {params['source_k']} has shape {other.shape}, expected "
                f"{mask.shape}; the mask set mixes resolutions"
            )
        return other.copy()

    def describe(self) -> str:
        return f"mask of a frame up to {self.max_offset_frames} away, p={self.p:g}"
