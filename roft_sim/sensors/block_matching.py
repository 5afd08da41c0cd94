"""Hierarchical block matching on NVOF's 4x4 grid: a block-matching NVOF-like flow.

NVIDIA's optical-flow hardware (NVOF) is a block matcher: one vector per 4x4 block, found by
searching displacements that minimise a matching cost (NVIDIA Optical Flow SDK; OpenCV
``cv::cuda::NvidiaHWOpticalFlow``: "block-based optical flow vectors" with a per-vector cost),
refined to 1/4 px. It does not average motion across a block's neighbours the way DIS's patch
averaging and variational refinement do. :func:`block_matching_flow` imitates it:

1. grey images, a Gaussian pyramid (``cv2.pyrDown``) of up to ``levels`` levels;
2. at every level, one vector per ``grid_px`` block, matched over a ``window_px`` window
   centred on the block with the mean absolute difference (SAD / pixels) as cost;
3. coarse to fine: at the coarsest level the search runs over ``+-top_search_px`` around 0;
   at a finer level each block takes the best (lowest-cost) of four predictors, twice the
   vectors of the four nearest coarse blocks (its parent and the parent's neighbours towards
   it), and searches ``+-search_px`` around it, so a block on a motion boundary can take the
   motion of either side instead of the average;
4. at the finest level, sub-pixel refinement by a half- then quarter-pixel search around the
   best integer shift on a bicubic-interpolated second image (as a video encoder's quarter-pel
   search; a V or parabola fit of the integer costs was off by up to 0.15 px on integer
   shifts, so it is not used).

Deterministic (no randomness, no threads in numpy's part). The output is float (not quantised):
:class:`BlockMatchingFlowSource` (spec ``bm``) gives it on the 4x4 grid, and ``nvof-like:bm``
rounds it to NVOF's 1/4 px and S10.5 through
:class:`~roft_sim.sensors.flow_sources.NvofLikeFlowSource` (the one place of that conversion).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import Sequence
from roft_sim.errors import ConfigError
from roft_sim.records import FlowField
from roft_sim.sensors.flow_source_base import NVOF_GRID_PX, check_frame_pair

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = ["BlockMatchingConfig", "block_matching_flow", "BlockMatchingFlowSource"]


@dataclass(frozen=True, slots=True, kw_only=True)
class BlockMatchingConfig:
    """Settings of :func:`block_matching_flow` (defaults: NVOF 1.0's 4x4 grid)."""

    grid_px: int = NVOF_GRID_PX
    """Block side [px]: one vector per block, at every pyramid level."""
    window_px: int = 8
    """Side of the matching window, centred on the block [px]; >= ``grid_px``, same parity."""
    search_px: int = 2
    """Search radius around the chosen predictor at levels below the coarsest [level px]."""
    top_search_px: int = 4
    """Search radius around 0 at the coarsest level [coarsest-level px]."""
    levels: int = 5
    """Most pyramid levels (1 = no pyramid); fewer when a level would be under
    ``min_level_px``. Reach: about ``top_search_px 2^(L-1) + search_px (2^(L-1) - 1)`` px."""
    min_level_px: int = 16
    """Smallest shorter side of a pyramid level [px]."""

    def __post_init__(self) -> None:
        owner = "BlockMatchingConfig"
        for name in ("grid_px", "window_px", "levels", "min_level_px", "top_search_px"):
            if getattr(self, name) < 1:
                raise ConfigError(f"{owner}.{name} must be >= 1, got {getattr(self, name)}")
        if self.search_px < 1:
            raise ConfigError(f"{owner}.search_px must be >= 1, got {self.search_px}")
        if self.window_px < self.grid_px or (self.window_px - self.grid_px) % 2:
            raise ConfigError(
                f"{owner}.window_px must be >= grid_px ({self.grid_px}) and differ from it by an "
                f"even number (a window centred on the block), got {self.window_px}"
            )


def _as_grey_pair(grey0: NDArray[np.generic], grey1: NDArray[np.generic]) -> tuple[F32, F32]:
    a, b = np.asarray(grey0), np.asarray(grey1)
    for name, img in (("grey0", a), ("grey1", b)):
        if img.ndim != 2:
            raise ValueError(
                f"block matching needs grey (H, W) images, got {name} of shape {img.shape}; "
                "convert RGB with cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)"
            )
        if not (np.issubdtype(img.dtype, np.integer) or np.issubdtype(img.dtype, np.floating)):
            raise ValueError(f"{name} must hold numbers, got dtype {img.dtype}")
    if a.shape != b.shape:
        raise ValueError(
            f"block matching needs two images of the same shape, got {a.shape} and {b.shape}"
        )
    out = (a.astype(np.float32), b.astype(np.float32))
    if not (np.isfinite(out[0]).all() and np.isfinite(out[1]).all()):
        raise ValueError("block matching images contain NaN or inf")
    return out


def _pyramid(img: F32, config: BlockMatchingConfig) -> list[F32]:
    """Finest first."""
    levels = [img]
    while len(levels) < config.levels and min(levels[-1].shape) // 2 >= config.min_level_px:
        levels.append(cv2.pyrDown(levels[-1]).astype(np.float32))
    return levels


def _windows(img: F32, top: I64, left: I64, side: int) -> F32:
    """(..., side, side) windows of ``img`` with top-left corners ``(top, left)`` (both (...)
    [px]); pixels outside the image repeat the border."""
    h, w = img.shape
    steps = np.arange(side)
    rows = np.clip(top[..., None, None] + steps[:, None], 0, h - 1)
    cols = np.clip(left[..., None, None] + steps[None, :], 0, w - 1)
    out: F32 = img[rows, cols]
    return out


def _quarter_shifts(img: F32) -> F32:
    """(4, 4, h, w) ``img`` sampled at quarter-pixel offsets: ``[qy, qx](y, x) = img(y + qy/4,
    x + qx/4)`` (bicubic, border replicated), the interpolated reference of quarter-pel search."""
    h, w = img.shape
    out = np.empty((4, 4, h, w), np.float32)
    for qy in range(4):
        for qx in range(4):
            shift = np.array([[1, 0, -qx / 4], [0, 1, -qy / 4]], np.float32)  # dst(p)=img(p+q)
            out[qy, qx] = cv2.warpAffine(
                img, shift, (w, h), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE
            )
    return out


def _quarter_pel(p0: F32, img1: F32, top: I64, left: I64, quarters: I64, cost0: F32) -> I64:
    """Half- then quarter-pixel search around integer block vectors (like a video encoder's
    motion search on an interpolated reference).

    Args:
        p0: (n, win, win) windows of the first image.
        img1: (h, w) second image.
        top, left: (n,) top-left corners of the windows [px].
        quarters: (n, 2) block vectors (x, y) [1/4 px], multiples of 4.
        cost0: (n,) their costs [grey levels].

    Returns:
        (n, 2) refined block vectors (x, y) [1/4 px].
    """
    win = p0.shape[1]
    pad = win + 4  # replicated border: windows whose corner is clipped into it stay whole
    padded = cv2.copyMakeBorder(img1, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
    shifted = _quarter_shifts(np.asarray(padded, np.float32))
    hp, wp = shifted.shape[2:]
    flat = shifted.reshape(-1)
    # (win, win) offsets of a window's pixels in one padded image, row-major
    inner = (np.arange(win)[:, None] * wp + np.arange(win)[None, :]).reshape(1, win, win)
    best, best_cost = quarters.copy(), cost0.copy()
    for step in (2, 1):
        centre = best.copy()
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx == 0 and dy == 0:
                    continue
                cand = centre + np.array([dx, dy]) * step
                whole, frac = np.divmod(cand, 4)
                y = np.clip(top + whole[:, 1] + pad, 0, hp - win)
                x = np.clip(left + whole[:, 0] + pad, 0, wp - win)
                corner = ((frac[:, 1] * 4 + frac[:, 0]) * hp + y) * wp + x  # (n,)
                c = np.abs(p0 - flat[corner[:, None, None] + inner]).mean(axis=(1, 2))
                better = c < best_cost
                best = np.where(better[..., None], cand, best)
                best_cost = np.where(better, c, best_cost)
    return best


def _search(p0: F32, img1: F32, top: I64, left: I64, centre: I64, radius: int) -> tuple[I64, F32]:
    """Whole-pixel search of ``+-radius`` around ``centre`` for n blocks.

    Args:
        p0: (n, win, win) windows of the first image.
        img1: (h, w) second image.
        top, left: (n,) top-left corners of the windows [px].
        centre: (n, 2) integer vectors (x, y) [px] to search around.
        radius: search radius [px].

    Returns:
        ``(vec, cost)``: (n, 2) best integer vectors (x, y) [px] (the first in row-major order
        of the shifts on ties) and (n,) their costs, the mean absolute difference [grey levels].
    """
    win = p0.shape[1]
    p1 = _windows(img1, top + centre[:, 1] - radius, left + centre[:, 0] - radius, win + 2 * radius)
    best_cost = np.full(p0.shape[0], np.inf, np.float32)
    best = np.zeros_like(centre)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            i, j = dy + radius, dx + radius
            c = np.abs(p0 - p1[:, i : i + win, j : j + win]).mean(axis=(1, 2))
            better = c < best_cost
            best[better] = (dx, dy)
            best_cost = np.where(better, c, best_cost)
    return centre + best, best_cost


def _match_level(
    img0: F32,
    img1: F32,
    predictors: I64,
    radius: int,
    config: BlockMatchingConfig,
    *,
    subpixel: bool,
) -> F64:
    """One pyramid level: a search around every distinct predictor of a block, the best wins.

    Args:
        img0, img1: (h, w) float32 grey images of this level.
        predictors: (P, hb, wb, 2) integer candidate vectors (x, y) [level px]; on equal cost
            the earlier predictor wins.
        radius: search radius around each predictor [level px].
        config: the matcher's settings.
        subpixel: refine to a quarter pixel (finest level).

    Returns:
        (hb, wb, 2) float64 block vectors (x, y) [level px], whole pixels unless ``subpixel``.
    """
    g, win = config.grid_px, config.window_px
    n_pred, hb, wb = predictors.shape[:3]
    rows, cols = np.indices((hb, wb)).reshape(2, -1)
    top, left = g * rows - (win - g) // 2, g * cols - (win - g) // 2
    p0 = _windows(img0, top, left, win)  # (n, win, win)
    preds = predictors.reshape(n_pred, hb * wb, 2)
    best = preds[0].copy()
    best_cost = np.full(hb * wb, np.inf, np.float32)
    for k in range(n_pred):
        # blocks whose k-th predictor differs from its earlier ones (most blocks have one)
        new = np.ones(hb * wb, bool)
        for j in range(k):
            new &= (preds[k] != preds[j]).any(axis=1)
        idx = np.flatnonzero(new)
        vec, cost = _search(p0[idx], img1, top[idx], left[idx], preds[k, idx], radius)
        better = cost < best_cost[idx]
        best[idx[better]] = vec[better]
        best_cost[idx[better]] = cost[better]
    if subpixel:
        refined: F64 = _quarter_pel(p0, img1, top, left, 4 * best, best_cost) / 4.0
        return np.reshape(refined, (hb, wb, 2))
    whole: F64 = best.reshape(hb, wb, 2).astype(np.float64)
    return whole


def _predictors(coarse: F64, hb: int, wb: int) -> I64:
    """(4, hb, wb, 2) integer predictors of a level's blocks: twice the vectors of the four
    nearest blocks of the coarser level (``coarse``: (hbc, wbc, 2) [coarse px])."""
    hbc, wbc = coarse.shape[:2]
    i, j = np.arange(hb), np.arange(wb)
    pi, pj = np.minimum(i // 2, hbc - 1), np.minimum(j // 2, wbc - 1)
    ni = np.clip(pi + np.where(i % 2, 1, -1), 0, hbc - 1)
    nj = np.clip(pj + np.where(j % 2, 1, -1), 0, wbc - 1)
    up = np.rint(2.0 * coarse).astype(np.int64)
    return np.stack([up[r][:, c] for r in (pi, ni) for c in (pj, nj)])


def block_matching_flow(
    grey0: NDArray[np.generic],
    grey1: NDArray[np.generic],
    config: BlockMatchingConfig | None = None,
) -> F64:
    """Flow from ``grey0`` to ``grey1`` by hierarchical block matching (see the module).

    Args:
        grey0, grey1: (H, W) grey images (uint8 or float, same shape) of the two frames.
        config: the matcher's settings (default :class:`BlockMatchingConfig`).

    Returns:
        (ceil(H/g), ceil(W/g), 2) float64 flow (x, y) [px] of each ``g`` x ``g`` block
        (``g = config.grid_px``): pixel ``p`` of block ``[p_v // g, p_u // g]`` moves to
        ``p + F``; not quantised.

    Raises:
        ValueError: the images are not grey, differ in shape or hold NaN/inf.
    """
    config = config if config is not None else BlockMatchingConfig()
    a, b = _as_grey_pair(grey0, grey1)
    pyr0, pyr1 = _pyramid(a, config), _pyramid(b, config)
    g = config.grid_px
    flow: F64 | None = None
    for level in range(len(pyr0) - 1, -1, -1):
        h, w = pyr0[level].shape
        hb, wb = -(-h // g), -(-w // g)
        if flow is None:
            predictors = np.zeros((1, hb, wb, 2), np.int64)
            radius = config.top_search_px
        else:
            predictors = _predictors(flow, hb, wb)
            radius = config.search_px
        flow = _match_level(
            pyr0[level], pyr1[level], predictors, radius, config, subpixel=level == 0
        )
    assert flow is not None  # at least one level
    return flow


class BlockMatchingFlowSource:
    """Block-matching flow (:func:`block_matching_flow`) on the grey rgb images (spec ``bm``,
    or ``bm:<window_px>``).

    One float vector per 4x4 block (``grid_px = 4``), every block valid; wrap it as
    ``nvof-like:bm`` for NVOF's 1/4 px and S10.5. Any stride, deterministic (``seed`` is kept
    for the common signature and ignored).
    """

    __slots__ = ("config", "seed")

    def __init__(self, config: BlockMatchingConfig | None = None, seed: int = 0) -> None:
        self.config = config if config is not None else BlockMatchingConfig()
        self.seed = int(seed)

    @property
    def name(self) -> str:
        """``bm``, or ``bm:<window_px>`` for another window than the default."""
        window = self.config.window_px
        return "bm" if window == BlockMatchingConfig().window_px else f"bm:{window}"

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField:
        check_frame_pair(sequence, from_k, to_k)
        grey = [
            cv2.cvtColor(np.ascontiguousarray(sequence.rgb(k)), cv2.COLOR_RGB2GRAY)
            for k in (from_k, to_k)
        ]
        flow = block_matching_flow(grey[0], grey[1], self.config)
        return FlowField(
            flow_px=flow.astype(np.float32), from_k=from_k, to_k=to_k, grid_px=self.config.grid_px
        )
