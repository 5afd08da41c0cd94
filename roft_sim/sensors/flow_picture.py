"""Statistics of a colour-coded flow picture: what a thumbnail of real NVOF flow can calibrate.

The only image of Fast-YCB's real NVOF 1.0 flow we have is the README figure of the Fast-YCB
repository (hsp-iit/fast-ycb, ``assets/sample_rgbd_flow_mask.png``, 1000x141 px: four
250x141 panels, rgb | depth | the dataset's ``nvof_1_slow`` flow in the Middlebury colour code |
the object's mask). It carries no numbers in pixels, only colours, so it is compared with the
simulated flow through one pipe that both go through:

1. the simulated flow, (H, W, 2) full-resolution pixels, is colour coded at full resolution
   with the Middlebury wheel normalised by the frame's largest vector
   (:func:`rgb_from_flow`, as the ``flow_vis`` package and the Middlebury tools do: white = no
   motion, hue = direction, saturation = magnitude / max);
2. the colour image and the visible mask are shrunk to the thumbnail's 250 px width by area
   averaging (:func:`thumbnail`);
3. the colours are decoded back into a relative flow vector per thumbnail pixel
   (:func:`relative_flow_from_rgb`: ``|f| = 1 - min(R, G, B) / 255``, exact for this code,
   since every wheel colour has one channel at 255 and one at 0), and
4. :func:`flow_picture_stats` reads the picture against its mask: the halo outside the mask
   and the attenuation inside it per ring of thumbnail pixels (one thumbnail pixel is
   1280 / 250 = 5.12 px of a 1280x720 frame), the variability of the flow inside the mask
   (what an affine motion does not explain), and the flow on the static background.

Every statistic is a ratio of saturations, so it holds whatever normaliser the picture used
(largest vector or a fixed scale), as long as the code is linear in magnitude, which the
Middlebury code is below its normaliser. Area averaging of a colour picture mixes colours
linearly, so a thumbnail pixel's ``|f|`` is the mean magnitude over its full-resolution pixels
when their directions agree (a motion boundary against a static background: exactly so).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]

__all__ = [
    "middlebury_wheel",
    "rgb_from_flow",
    "relative_flow_from_rgb",
    "thumbnail",
    "FlowPictureStats",
    "flow_picture_stats",
    "fast_ycb_readme_panels",
    "README_PANEL_WIDTH_PX",
]

README_PANEL_WIDTH_PX = 250
"""Width of one panel of the Fast-YCB README figure [thumbnail px]."""

_README_EDGE_PX = 2
"""Columns dropped at each side of a README panel: the figure's resampling mixes the panels
there (measured: column 499 of the figure is half depth, half flow; 748-750 mix flow and mask)."""


def middlebury_wheel() -> F64:
    """The Middlebury flow colour wheel (Baker et al. 2011, ``colorcode.cpp``; ``flow_vis``).

    Returns:
        (55, 3) float64 RGB in [0, 1], segments red-yellow 15, yellow-green 6, green-cyan 4,
        cyan-blue 11, blue-magenta 13, magenta-red 6, in the integer steps of the original.
    """
    segments = ((15, 0, 1), (6, 1, 0), (4, 1, 2), (11, 2, 1), (13, 2, 0), (6, 0, 2))
    rows: list[F64] = []
    for n, full, moving in segments:
        # colorcode.cpp: the channel ``full`` stays 255, ``moving`` ramps up (even segment
        # index) or down (odd), the third is 0
        ramp = np.floor(255.0 * np.arange(n) / n)
        block = np.zeros((n, 3))
        block[:, full] = 255.0
        block[:, moving] = ramp if len(rows) % 2 == 0 else 255.0 - ramp
        rows.append(block)
    return np.concatenate(rows, axis=0) / 255.0


def _wheel_colour(angle_fraction: F64) -> F64:
    """Wheel colour for ``a = atan2(-v, -u) / pi`` in [-1, 1]: (..., 3) in [0, 1]."""
    wheel = middlebury_wheel()
    n = wheel.shape[0]
    fk = (angle_fraction + 1.0) / 2.0 * (n - 1)
    k0 = np.floor(fk).astype(np.int64)
    k1 = np.where(k0 + 1 == n, 0, k0 + 1)
    f = (fk - k0)[..., None]
    out: F64 = (1.0 - f) * wheel[k0] + f * wheel[k1]
    return out


def rgb_from_flow(flow_px: NDArray[np.floating], *, max_px: float | None = None) -> U8:
    """Middlebury colour code of a flow, as ``flow_vis.flow_to_color`` draws it.

    Args:
        flow_px: (H, W, 2) flow [px] (u right, v down); non-finite vectors are drawn as no
            motion (white).
        max_px: the normaliser [px]; None = the largest finite vector of this flow.

    Returns:
        (H, W, 3) uint8 RGB: white where the flow is 0, hue from the direction, saturation
        ``|F| / max_px`` (vectors beyond ``max_px`` darkened by 0.75, as ``flow_vis`` does).
    """
    f = np.asarray(flow_px, dtype=np.float64)
    if f.ndim != 3 or f.shape[2] != 2:
        raise ValueError(f"flow_px must have shape (H, W, 2), got {f.shape}")
    f = np.where(np.isfinite(f).all(axis=2, keepdims=True), f, 0.0)
    rad = np.hypot(f[..., 0], f[..., 1])
    scale = float(rad.max()) if max_px is None else float(max_px)
    if not (np.isfinite(scale) and scale >= 0):
        raise ValueError(f"max_px must be a finite number >= 0, got {max_px}")
    rel = rad / (scale + 1e-5)  # flow_vis's epsilon
    col = _wheel_colour(np.arctan2(-f[..., 1], -f[..., 0]) / np.pi)
    inside = (rel <= 1.0)[..., None]
    col = np.where(inside, 1.0 - rel[..., None] * (1.0 - col), col * 0.75)
    return np.floor(255.0 * col).astype(np.uint8)


def relative_flow_from_rgb(rgb: U8) -> F64:
    """Relative flow vectors decoded from a Middlebury-coded picture (inverse of
    :func:`rgb_from_flow` below the normaliser).

    ``|f| = 1 - min(R, G, B) / 255`` (every wheel colour has a channel at 0 and one at 255, and
    the code blends it with white by ``|f|``); the direction is that of the wheel colour nearest
    to ``w = 1 - (1 - c) / |f|`` (one of 3600 directions). Colours mixed by resampling decode to
    about the mean of their vectors when their directions are close.

    Args:
        rgb: (H, W, 3) uint8 RGB picture.

    Returns:
        (H, W, 2) float64 relative flow (u right, v down) in units of the picture's
        normaliser; 0 where the colour is white.
    """
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    if c.ndim != 3 or c.shape[2] != 3:
        raise ValueError(f"rgb must have shape (H, W, 3), got {c.shape}")
    mag = np.clip(1.0 - c.min(axis=2), 0.0, 1.0)
    table_a = np.linspace(-1.0, 1.0, 3601)[:-1]
    table = _wheel_colour(table_a)  # (3600, 3)
    coloured = mag > 0.5 / 255.0  # white (no motion) has no direction
    w = np.clip(1.0 - (1.0 - c[coloured]) / mag[coloured][:, None], 0.0, 1.0)
    a = np.zeros(mag.shape)
    a[coloured] = table_a[cKDTree(table).query(w)[1]]
    # a = atan2(-v, -u) / pi, so (u, v) = -|f| (cos(pi a), sin(pi a))
    return np.stack([-mag * np.cos(np.pi * a), -mag * np.sin(np.pi * a)], axis=2)


def thumbnail(image: NDArray[np.generic], width_px: int) -> F64:
    """Area-averaged shrink of an image to ``width_px`` columns (rows in proportion, rounded).

    Args:
        image: (H, W) or (H, W, C) picture (uint8 colours, or a float/bool mask).
        width_px: target width [thumbnail px], <= W.

    Returns:
        (round(H width_px / W), width_px[, C]) float64, in the input's value units.
    """
    a = np.asarray(image)
    h, w = a.shape[:2]
    if not 1 <= width_px <= w:
        raise ValueError(f"width_px must be in [1, {w}], got {width_px}")
    height = max(1, round(h * width_px / w))
    out: F64 = cv2.resize(
        a.astype(np.float64), (width_px, height), interpolation=cv2.INTER_AREA
    ).astype(np.float64)
    return out


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowPictureStats:
    """What a thumbnail of a flow picture shows around and inside its object's mask.

    Rings are Euclidean distances to the mask's boundary in thumbnail pixels: ring n outside
    holds the background pixels whose distance to the nearest mask pixel is in (n - 1, n]; ring
    n inside the mask pixels whose distance to the nearest background pixel is in (n - 1, n].
    Ring magnitudes are relative to the interior's affine field at the pixel, the background's
    to ``interior_magnitude``.
    """

    interior_magnitude: float
    """Median ``|f|`` over the mask pixels deeper than ``interior_depth`` rings (normaliser
    units)."""
    outside_rings: tuple[float, ...]
    """Mean per ring outside, ring 1 first, of ``|f|`` over the magnitude the interior's affine
    field (fitted to the interior's vectors) has at that pixel."""
    outside_rings_trailing: tuple[float, ...]
    """The same over the ring pixels behind the object's motion (pixel minus mask centroid
    against the interior's mean direction < 0): where a flow on the earlier frame's pixels
    reaches beyond the later frame's mask."""
    outside_rings_leading: tuple[float, ...]
    """The same over the ring pixels ahead of the motion (>= 0)."""
    inside_rings: tuple[float, ...]
    """The same per ring inside."""
    inside_rings_trailing: tuple[float, ...]
    """The same over the ring pixels behind the motion."""
    inside_rings_leading: tuple[float, ...]
    """The same over the ring pixels ahead of the motion: where the later frame's mask covers
    pixels the earlier frame's object did not."""
    mask_outside_rings: tuple[float, ...]
    """Mean of the soft (resampled) mask per ring outside: how much of the ring is object
    because of the shrink alone."""
    mask_inside_rings: tuple[float, ...]
    """Mean of the soft mask per ring inside."""
    interior_residual: float
    """RMS of what an affine fit of the flow vectors over the interior leaves, / the norm of
    their mean vector: blotches and noise, not the object's own (rotation) field."""
    interior_magnitude_cv: float
    """Std / mean of ``|f|`` over the interior."""
    interior_direction_std_deg: float
    """Circular std of the flow direction over the interior [deg] (report unit)."""
    background_mean: float
    """Mean ``|f|`` over the background farther than ``background_px`` from the mask /
    ``interior_magnitude``."""
    spurious_fraction: float
    """Fraction of that background with ``|f|`` above ``spurious_level`` times
    ``interior_magnitude``."""
    interior_pixels: int
    """Pixels in the interior."""
    background_pixels: int
    """Pixels in the far background."""


def _distance_to_zero(nonzero: Bool) -> F64:
    """(h, w) exact Euclidean distance [px] of every True pixel to the nearest False one (0 on
    False pixels)."""
    d = cv2.distanceTransform(nonzero.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.asarray(d, dtype=np.float64)


def _ring_means(values: F64, dist: F64, select: Bool, rings: int) -> tuple[float, ...]:
    out = []
    for n in range(1, rings + 1):
        sel = select & (dist > n - 1) & (dist <= n)
        out.append(float(values[sel].mean()) if sel.any() else float("nan"))
    return tuple(out)


def flow_picture_stats(
    rgb: NDArray[np.generic],
    mask: NDArray[np.generic],
    *,
    rings: int = 4,
    interior_depth: int = 3,
    background_px: float = 8.0,
    spurious_level: float = 0.2,
) -> FlowPictureStats:
    """The statistics of :class:`FlowPictureStats` for one Middlebury-coded flow picture.

    Args:
        rgb: (h, w, 3) picture, uint8 or float in [0, 255] (a :func:`thumbnail`).
        mask: (h, w) soft or binary object mask in [0, 1] on the same pixels; object where
            >= 0.5.
        rings: rings reported on each side.
        interior_depth: rings inside the mask left out of the interior (the interior is the
            mask pixels deeper than this).
        background_px: distance from the mask beyond which the background is "far"
            [thumbnail px].
        spurious_level: ``|f|`` / ``interior_magnitude`` above which a far-background pixel
            counts as spurious flow.

    Raises:
        ValueError: shapes differ, or the mask has no interior or no far background.
    """
    c = np.clip(np.rint(np.asarray(rgb, dtype=np.float64)), 0, 255).astype(np.uint8)
    m = np.asarray(mask, dtype=np.float64)
    if c.shape[:2] != m.shape or c.ndim != 3:
        raise ValueError(f"rgb (h, w, 3) and mask (h, w) must match, got {c.shape}, {m.shape}")
    obj = m >= 0.5
    f = relative_flow_from_rgb(c)
    mag = np.hypot(f[..., 0], f[..., 1])
    # (h, w) Euclidean distance [thumbnail px] to the nearest mask / background pixel
    dist_out = _distance_to_zero(~obj)
    dist_in = _distance_to_zero(obj)
    interior = obj & (dist_in > interior_depth)
    far = ~obj & (dist_out > background_px)
    if interior.sum() < 6 or not far.any():
        raise ValueError(
            f"the mask needs an interior deeper than {interior_depth} px (has "
            f"{int(interior.sum())} px) and a background farther than {background_px} px"
        )
    ref = float(np.median(mag[interior]))
    if ref <= 0:
        raise ValueError("the flow inside the mask is zero: nothing to compare against")
    yy, xx = np.indices(obj.shape)
    design = np.stack([np.ones(obj.shape), xx, yy], axis=2).astype(np.float64)  # (h, w, 3)
    vec = f[interior]
    coef, *_ = np.linalg.lstsq(design[interior], vec, rcond=None)  # (3, 2) affine model
    model = design @ coef  # (h, w, 2): the interior's affine field, extrapolated
    residual = vec - model[interior]
    mean_vec = vec.mean(axis=0)
    # rings are read against the affine field's magnitude at the pixel (not the interior's
    # median), so a rotating object's uneven flow is not taken for a halo or an attenuation
    local = np.hypot(model[..., 0], model[..., 1])
    rel_local = mag / np.maximum(local, 0.05 * ref)
    rel = mag / ref
    angle = np.arctan2(vec[:, 1], vec[:, 0])
    resultant = float(np.hypot(np.cos(angle).mean(), np.sin(angle).mean()))
    cy, cx = (float(np.mean(a)) for a in np.nonzero(obj))
    ahead = (xx - cx) * mean_vec[0] + (yy - cy) * mean_vec[1] >= 0
    outside = ~obj
    return FlowPictureStats(
        interior_magnitude=ref,
        outside_rings=_ring_means(rel_local, dist_out, outside, rings),
        outside_rings_trailing=_ring_means(rel_local, dist_out, outside & ~ahead, rings),
        outside_rings_leading=_ring_means(rel_local, dist_out, outside & ahead, rings),
        inside_rings=_ring_means(rel_local, dist_in, obj, rings),
        inside_rings_trailing=_ring_means(rel_local, dist_in, obj & ~ahead, rings),
        inside_rings_leading=_ring_means(rel_local, dist_in, obj & ahead, rings),
        mask_outside_rings=_ring_means(m, dist_out, outside, rings),
        mask_inside_rings=_ring_means(m, dist_in, obj, rings),
        interior_residual=float(
            np.sqrt((residual**2).sum(axis=1).mean()) / max(np.hypot(*mean_vec), 1e-12)
        ),
        interior_magnitude_cv=float(mag[interior].std() / mag[interior].mean()),
        interior_direction_std_deg=float(
            np.degrees(np.sqrt(-2.0 * np.log(min(max(resultant, 1e-12), 1.0))))
        ),
        background_mean=float(rel[far].mean()),
        spurious_fraction=float((rel[far] > spurious_level).mean()),
        interior_pixels=int(interior.sum()),
        background_pixels=int(far.sum()),
    )


def fast_ycb_readme_panels(figure_rgb: U8) -> tuple[U8, F64]:
    """The flow and mask panels of Fast-YCB's README figure.

    Args:
        figure_rgb: (141, 1000, 3) uint8 RGB of hsp-iit/fast-ycb ``assets/
            sample_rgbd_flow_mask.png`` (four 250 px panels: rgb | depth | flow | mask).

    Returns:
        ``(flow_rgb, mask)``: (141, 246, 3) uint8 flow panel and (141, 246) float64 mask in
        [0, 1] (panel columns 2-247: :data:`_README_EDGE_PX` dropped each side).
    """
    a = np.asarray(figure_rgb)
    w = README_PANEL_WIDTH_PX
    if a.ndim != 3 or a.shape[1] != 4 * w or a.shape[2] < 3:
        raise ValueError(
            f"expected the (141, 1000, 3) README figure of four {w} px panels, got {a.shape}"
        )
    e = _README_EDGE_PX
    flow = a[:, 2 * w + e : 3 * w - e, :3].astype(np.uint8)
    mask = a[:, 3 * w + e : 4 * w - e, :3].astype(np.float64).mean(axis=2) / 255.0
    return flow, mask
