"""A Mask R-CNN-like segmenter: the ground-truth visible mask with a detector's artefacts.

The reference masks (``mrcnn_ycbv_bop_pbr``) come from Mask R-CNN run at 640x480: Fast-YCB frames
(1280x720) are zero-padded to 1280x960 (centred), resized to 640x480, segmented, and the 0/255
mask is resized back with bilinear interpolation and cropped, so edges take intermediate values;
ROFT's reader counts any value > 1 as object (``roft_reference.md`` sections 8.5). This model
reproduces that chain around the ground truth (docs/sensors.md):

1. miss with probability ``miss_probability + occlusion_miss_gain (1 - visible_fraction)``
   (and always when fewer than ``min_visible_px`` pixels are visible);
2. pad to the inference aspect ratio (centred) and area-resize the visible mask to the
   inference size;
3. boundary noise at that resolution: the mask's signed distance plus a per-frame global
   offset (dilation > 0, erosion < 0) and a smooth random field (``boundary_noise_px`` std,
   ``boundary_noise_scale_px`` correlation), thresholded at 0; both scaled by
   ``1 + occlusion_boundary_gain (1 - visible_fraction)`` (an occluded object has more, and
   less certain, boundary);
4. the mask head's coarse grid: the box crop is area-resized to ``mask_head_px`` squared
   (28 in Mask R-CNN), resized back bilinearly and thresholded at 0.5;
5. occasionally a spurious blob (another instance of the class, OR-ed in like the reference
   tool does);
6. the 0/255 mask is resized back bilinearly, cropped, and thresholded like the reader.

Boundary distances (dilation, boundary noise and its correlation length, blob radii) are in
pixels of the network's INPUT (``inference_size_px``; full-resolution pixels when it is None):
the network sees the same 640x480 padded image whether the camera gives 1280x720 or 640x360, so
its boundary errors are a property of that image, and relative to the object they do not change
with the camera resolution. ``min_visible_px`` is in full-resolution pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError

Bool = NDArray[np.bool_]
U8 = NDArray[np.uint8]
F32 = NDArray[np.float32]

__all__ = ["SegmenterConfig", "simulate_mask", "simulate_mask_uint8", "mask_iou"]


@dataclass(frozen=True, slots=True, kw_only=True)
class SegmenterConfig:
    """Artefacts of the Mask R-CNN-like segmenter (TOML-loadable; see the module doc).

    Defaults give a mean IoU of 0.90-0.95 with the visible mask on Fast-YCB-sized objects, the
    same at 1280x720 and 640x360 (docs/sensors.md): an assumption of a well fine-tuned network,
    not a calibration (the reference masks are not available here). Boundary distances are in
    pixels of the network's input image (module doc).
    """

    miss_probability: float = 0.03
    """Probability of no mask on a frame."""
    min_visible_px: int = 100
    """Fewer visible pixels than this (full resolution) is always a miss."""
    dilation_sigma_px: float = 0.5
    """Std of the per-frame global dilation (> 0) / erosion (< 0) of the boundary [network
    input px]."""
    dilation_bias_px: float = 0.0
    """Mean of that dilation [network input px]."""
    boundary_noise_px: float = 1.0
    """Std of the smooth random boundary displacement [network input px]."""
    boundary_noise_scale_px: float = 8.0
    """Correlation length (Gaussian std) of that displacement along the boundary [network input
    px]."""
    spurious_blob_probability: float = 0.02
    """Probability per frame of one spurious blob somewhere in the image."""
    spurious_blob_radius_px: tuple[float, float] = (5.0, 20.0)
    """Range of the blob's semi-axes [network input px]."""
    inference_size_px: tuple[int, int] | None = (640, 480)
    """(width, height) at which the network runs; None = full resolution (no resize)."""
    mask_head_px: int = 28
    """Side of the mask head's grid (Mask R-CNN: 28); 0 = no mask-head quantisation."""
    read_threshold: int = 1
    """Upscaled 0..255 values above this are object (ROFT's reader: > 1). 127 = plain
    bilinear-and-round."""
    occlusion_miss_gain: float = 0.3
    """Added miss probability per unit of occluded fraction ``1 - visible_fraction``."""
    occlusion_boundary_gain: float = 1.5
    """Boundary noise and dilation std are multiplied by ``1 + gain (1 - visible_fraction)``."""

    def __post_init__(self) -> None:
        owner = "SegmenterConfig"
        for name in ("miss_probability", "spurious_blob_probability"):
            value = getattr(self, name)
            if not 0 <= value <= 1:
                raise ConfigError(f"{owner}.{name} must be in [0, 1], got {value}")
        for name in (
            "dilation_sigma_px",
            "boundary_noise_px",
            "boundary_noise_scale_px",
            "occlusion_miss_gain",
            "occlusion_boundary_gain",
        ):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ConfigError(f"{owner}.{name} must be a finite number >= 0, got {value}")
        if not np.isfinite(self.dilation_bias_px):
            raise ConfigError(f"{owner}.dilation_bias_px must be finite")
        lo, hi = self.spurious_blob_radius_px
        if not 0 < lo <= hi:
            raise ConfigError(
                f"{owner}.spurious_blob_radius_px must be 0 < min <= max, got {lo, hi}"
            )
        if self.inference_size_px is not None and min(self.inference_size_px) < 8:
            raise ConfigError(
                f"{owner}.inference_size_px must be at least 8x8 or None, got "
                f"{self.inference_size_px}"
            )
        if self.mask_head_px < 0 or self.min_visible_px < 0:
            raise ConfigError(f"{owner}.mask_head_px and min_visible_px must be >= 0")
        if not 0 <= self.read_threshold < 255:
            raise ConfigError(
                f"{owner}.read_threshold must be in [0, 254], got {self.read_threshold}"
            )


def mask_iou(a: Bool, b: Bool) -> float:
    """Intersection over union of two (H, W) bool masks; 1 when both are empty."""
    union = np.count_nonzero(a | b)
    return np.count_nonzero(a & b) / union if union else 1.0


def _padding(h: int, w: int, wi: int, hi: int) -> tuple[int, int, int, int]:
    """(padded height, padded width, top, left) of the centred pad to aspect wi:hi."""
    if w * hi >= h * wi:
        hp, wp = int(round(w * hi / wi)), w
    else:
        hp, wp = h, int(round(h * wi / hi))
    return hp, wp, (hp - h) // 2, (wp - w) // 2


def _signed_distance(mask: Bool) -> F32:
    """Signed distance to the boundary [px]: > 0 inside, < 0 outside, boundary at 0."""
    m = mask.astype(np.uint8)
    inside = cv2.distanceTransform(m, cv2.DIST_L2, 5)
    outside = cv2.distanceTransform(1 - m, cv2.DIST_L2, 5)
    return np.where(mask, inside - 0.5, 0.5 - outside).astype(np.float32)


def _noisy_boundary(mask: Bool, field: F32, offset_px: float, noise_px: float) -> Bool:
    """``_signed_distance(mask) + offset_px + noise_px * field > 0`` (float32), computed on the
    mask's bounding box grown by the farthest reach of the noise only.

    A pixel at distance ``D`` outside the mask is set only if ``0.5 - D + offset_px + noise_px
    field > 0``, so none farther than ``reach = 0.5 + offset_px + noise_px max(field)`` is; the
    chamfer distance is at least the larger of the row and column offsets, so no pixel outside
    the box grown by ``ceil(reach) + 2`` (2 px for float32 rounding) is set. Inside the box both
    distance transforms give the full image's values: every object pixel and the zeros next to
    them are in it, and the transform's sums are integers (OpenCV's 5x5 chamfer), so the
    result is the full-image formula's bit for bit (tested against it), in a fraction of the
    time for an object smaller than the image.

    Args:
        mask: (h, w) bool mask with at least one pixel, network input resolution.
        field: (h, w) float32 unit-std boundary noise field.
        offset_px: global dilation [network input px].
        noise_px: std of the boundary displacement [network input px].

    Returns:
        (h, w) bool noisy mask.
    """
    h, w = mask.shape
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    reach = 0.5 + float(offset_px) + float(noise_px) * max(float(field.max()), 0.0)
    grow = max(int(np.ceil(reach)), 0) + 2
    r0, r1 = max(int(rows[0]) - grow, 0), min(int(rows[-1]) + 1 + grow, h)
    c0, c1 = max(int(cols[0]) - grow, 0), min(int(cols[-1]) + 1 + grow, w)
    sdf = _signed_distance(mask[r0:r1, c0:c1])
    noisy = sdf + np.float32(offset_px) + np.float32(noise_px) * field[r0:r1, c0:c1]
    out = np.zeros((h, w), dtype=bool)
    out[r0:r1, c0:c1] = noisy > 0
    return out


def _smooth_field(rng: np.random.Generator, shape: tuple[int, int], sigma_px: float) -> F32:
    """(h, w) float32 Gaussian random field of unit std, correlated by a Gaussian of
    ``sigma_px`` (white noise below 0.3 px).

    White noise blurred by ``sigma_px`` and renormalised, drawn on a grid ``step`` = floor(
    ``sigma_px`` / 2) px coarse (so at least two samples per correlation length: the blur's
    correlation, ``exp(-d^2 / (4 sigma^2))``, then changes by under 7 % between samples) and
    bilinearly upsampled: the field of the full-resolution draw in distribution (std and
    correlation tested against it) for ``step^2`` fewer draws: 1.3 ms instead of 12 ms at
    640x480 with the default 8 px."""
    h, w = shape
    if sigma_px < 0.3:
        return rng.standard_normal(shape).astype(np.float32)
    step = max(1, int(sigma_px // 2))
    hc, wc = -(-h // step) + 1, -(-w // step) + 1
    white = rng.standard_normal((hc, wc)).astype(np.float32)
    sigma = sigma_px / step
    ksize = 2 * int(np.ceil(3.0 * sigma)) + 1
    k1 = cv2.getGaussianKernel(ksize, sigma, cv2.CV_64F)[:, 0]
    blurred = cv2.GaussianBlur(white, (ksize, ksize), sigma, borderType=cv2.BORDER_REFLECT)
    coarse = blurred / np.float32(np.sum(k1**2))
    if step == 1:
        return coarse[:h, :w].copy()
    # corner-aligned upsampling: coarse sample (i, j) lands on pixel (i step, j step)
    rows = np.arange(h, dtype=np.float32) / step
    cols = np.arange(w, dtype=np.float32) / step
    map_x, map_y = np.meshgrid(cols, rows)
    field = cv2.remap(coarse, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return cast(F32, field)  # float32 in, float32 out


def _mask_head(mask: Bool, grid_px: int) -> Bool:
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    if rows.size == 0:
        return mask
    r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    crop = mask[r0:r1, c0:c1].astype(np.float32)
    coarse = cv2.resize(crop, (grid_px, grid_px), interpolation=cv2.INTER_AREA)
    back = cv2.resize(coarse, (c1 - c0, r1 - r0), interpolation=cv2.INTER_LINEAR)
    out = np.zeros_like(mask)
    out[r0:r1, c0:c1] = back > 0.5
    return out


def simulate_mask_uint8(
    gt_mask: Bool,
    config: SegmenterConfig,
    rng: np.random.Generator,
    *,
    visible_fraction: float = 1.0,
) -> U8 | None:
    """The segmenter's mask as the reference tool writes it: (H, W) uint8 0..255 with
    intermediate values on the edges from the bilinear upscale; None for a miss.

    Args:
        gt_mask: (H, W) bool ground-truth VISIBLE mask, full resolution.
        config: artefact statistics.
        rng: generator for this frame (e.g. ``frame_rng(seed, k)``).
        visible_fraction: visible mask area over the unoccluded silhouette's, in [0, 1]
            (1: not occluded); raises the miss rate and the boundary noise.
    """
    if not 0.0 <= visible_fraction <= 1.0:
        raise ValueError(f"visible_fraction must be in [0, 1], got {visible_fraction}")
    occluded = 1.0 - visible_fraction
    gt = np.asarray(gt_mask, dtype=bool)
    if gt.ndim != 2:
        raise ValueError(f"gt_mask must be a 2-D bool array, got shape {gt.shape}")
    h, w = gt.shape
    c = config
    if c.inference_size_px is None:
        wi, hi = w, h
        hp, wp, top, left = h, w, 0, 0
    else:
        wi, hi = c.inference_size_px
        hp, wp, top, left = _padding(h, w, wi, hi)
    scale = wi / wp  # full-resolution px -> network input px

    # Draws, in a fixed order (a miss ends the frame: each frame has its own generator).
    p_miss = c.miss_probability + c.occlusion_miss_gain * occluded
    if rng.random() < p_miss or np.count_nonzero(gt) < max(c.min_visible_px, 1):
        return None
    noise_gain = 1.0 + c.occlusion_boundary_gain * occluded
    offset_px = c.dilation_bias_px + noise_gain * c.dilation_sigma_px * rng.standard_normal()
    field = _smooth_field(rng, (hi, wi), c.boundary_noise_scale_px)
    blob = rng.random() < c.spurious_blob_probability
    blob_centre = rng.uniform([left, top], [left + w, top + h]) * scale
    blob_axes = rng.uniform(*c.spurious_blob_radius_px, size=2)
    blob_angle = rng.uniform(0.0, 180.0)

    if c.inference_size_px is None:
        low = gt
    else:
        padded = np.zeros((hp, wp), np.float32)
        padded[top : top + h, left : left + w] = gt
        low = cv2.resize(padded, (wi, hi), interpolation=cv2.INTER_AREA) >= 0.5
    if not low.any():
        return None  # too small for the network at its resolution
    low = _noisy_boundary(low, field, offset_px, noise_gain * c.boundary_noise_px)
    if c.mask_head_px > 0:
        low = _mask_head(low, c.mask_head_px)
    low_u8 = low.astype(np.uint8) * 255
    if blob:
        cv2.ellipse(
            low_u8,
            (int(round(blob_centre[0])), int(round(blob_centre[1]))),
            (max(int(round(blob_axes[0])), 1), max(int(round(blob_axes[1])), 1)),
            blob_angle,
            0.0,
            360.0,
            255,
            thickness=-1,
        )
    if c.inference_size_px is None:
        out = low_u8
    else:
        up = cv2.resize(low_u8, (wp, hp), interpolation=cv2.INTER_LINEAR)
        out = np.ascontiguousarray(up[top : top + h, left : left + w])
    if not (out > c.read_threshold).any():
        return None
    return out


def simulate_mask(
    gt_mask: Bool,
    config: SegmenterConfig,
    rng: np.random.Generator,
    *,
    visible_fraction: float = 1.0,
) -> Bool | None:
    """The segmenter's mask as a tracker reads it: (H, W) bool (values above
    ``read_threshold``), or None for a miss. Same draws as :func:`simulate_mask_uint8`."""
    out = simulate_mask_uint8(gt_mask, config, rng, visible_fraction=visible_fraction)
    return None if out is None else out > config.read_threshold
