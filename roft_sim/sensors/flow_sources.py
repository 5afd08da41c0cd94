"""Optical-flow sources: where a tracker's flow comes from (docs/sensors.md).

A flow source turns a :class:`~roft_sim.datasets.base.Sequence` into the flow between two of its
frames, ``F`` mapping pixels of ``from_k`` to ``to_k`` (``p + F(p)``, full-resolution pixels):

=====================  ============================================================================
spec                   source
=====================  ============================================================================
``gt``                 :class:`GroundTruthFlowSource`: exact motion field from depth, gt mask and
                       poses, any stride (``roft_sim.geometry.rigid_flow``)
``gt+noise[:<s>]``     :class:`NoisyGroundTruthFlowSource`: gt plus a configurable end-point-error
                       model (:class:`FlowNoiseConfig` defaults; ``:<s>`` sets ``sigma_px``)
``dis[:<preset>]``     :class:`DisFlowSource`: OpenCV DIS on the grey rgb images, any stride
``bm[:<window_px>]``   :class:`~roft_sim.sensors.block_matching.BlockMatchingFlowSource`: a
                       hierarchical block matcher on the grey rgb images, one vector per 4x4
                       block (NVOF's hardware method; ``nvof-like:bm`` adds its 1/4 px, S10.5);
                       ``:<window_px>`` sets the matching window (default 8)
``nvof-like:<inner>``  :class:`NvofLikeFlowSource`: any source as one vector per 4x4 block (its
                       medoid), in NVOF's S10.5 int16, like the reference ``nvof_1_slow`` set
``nvof-model``         :class:`~roft_sim.sensors.nvof_error_model.NvofErrorModelFlowSource`: the
                       exact flow with an error model fitted to real NVIDIA hardware flow
                       (boundary spill, sub-pixel noise, large-displacement failures), 4x4, S10.5
``stored:<set>``       :class:`StoredFlowSource`: the sequence's stored flow set (stride 1 only)
``nvof-hw[:<level>]``  :class:`~roft_sim.sensors.nvof_hardware.NvofHardwareFlowSource`: real NVIDIA
                       hardware flow (NVOF API 1.0, the reference dumper's settings; needs an
                       NVIDIA GPU and driver); ``:<level>`` = ``slow`` (default), ``medium``,
                       ``fast``
=====================  ============================================================================

Stochastic sources are deterministic per ``(seed, from_k, to_k)``: each call draws from its own
generator ``SeedSequence([seed, from_k, to_k])``, so the flow of a frame pair never depends on
which other pairs were asked for, or in which order.

The pieces every source shares (the protocol, the stored and exact sources, NVOF's S10.5 format,
:func:`frame_rng`) live in :mod:`roft_sim.sensors.flow_source_base` and are re-exported here.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import Sequence
from roft_sim.errors import ConfigError
from roft_sim.records import FlowField
from roft_sim.sensors.flow_source_base import (
    NVOF_GRID_PX,
    NVOF_PRECISION_PX,
    FlowSource,
    GroundTruthFlowSource,
    StoredFlowSource,
    check_finite_at_least,
    check_frame_pair,
    check_s10_5_precision,
    flow_px_from_s10_5,
    frame_rng,
    s10_5_from_flow_px,
)

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

__all__ = [
    "FlowSource",
    "StoredFlowSource",
    "GroundTruthFlowSource",
    "FlowNoiseConfig",
    "apply_flow_noise",
    "NoisyGroundTruthFlowSource",
    "DisFlowSource",
    "make_dis",
    "DIS_PRESETS",
    "NvofLikeFlowSource",
    "block_cells",
    "block_mean_flow",
    "one_motion_per_block",
    "NVOF_GRID_PX",
    "NVOF_PRECISION_PX",
    "s10_5_from_flow_px",
    "flow_px_from_s10_5",
    "check_s10_5_precision",
    "make_flow_source",
    "frame_rng",
    "FLOW_SOURCE_SPECS",
]

FLOW_SOURCE_SPECS = (
    "gt",
    "gt+noise[:<sigma_px>]",
    "dis[:<preset>]",
    "bm[:<window_px>]",
    "nvof-like:<inner>",
    "nvof-model",
    "stored:<set>",
    "nvof-hw[:<perf level>]",
)
"""The spec forms :func:`make_flow_source` understands."""


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowNoiseConfig:
    """End-point-error model of :class:`NoisyGroundTruthFlowSource` (TOML-loadable).

    Per valid pixel: ``F = F_gt + e``, with ``e`` Gaussian of per-component standard deviation
    ``sqrt(sigma_px^2 + (relative_sigma |F_gt|)^2)``, spatially correlated by a Gaussian blur of
    ``correlation_px`` (the blur is renormalised, so ``sigma_px`` stays the per-pixel std). A
    fraction of pixels are gross outliers, and square holes are marked invalid. The defaults
    give a mean end-point error of about 0.4 px plus 1 % outliers: a plausible good dense flow,
    NOT calibrated against NVOF (no reference data is available to do so).
    """

    sigma_px: float = 0.3
    """Per-component std of the additive error [px]."""
    relative_sigma: float = 0.05
    """Per-component std per pixel of true flow magnitude [px/px]."""
    correlation_px: float = 2.0
    """Std of the Gaussian blur that correlates the error field [px]; 0 = white noise."""
    outlier_fraction: float = 0.01
    """Fraction of valid pixels replaced by ``F_gt + u``, ``u`` uniform in a disc."""
    outlier_max_px: float = 20.0
    """Radius of that disc [px]."""
    hole_fraction: float = 0.0
    """Fraction of ``hole_size_px`` squares marked invalid."""
    hole_size_px: int = 8
    """Side of a hole square [px]."""

    def __post_init__(self) -> None:
        owner = "FlowNoiseConfig"
        for name in ("sigma_px", "relative_sigma", "correlation_px", "outlier_max_px"):
            check_finite_at_least(owner, name, getattr(self, name), 0.0)
        for name in ("outlier_fraction", "hole_fraction"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ConfigError(f"{owner}.{name} must be in [0, 1], got {value}")
        if self.hole_size_px < 1:
            raise ConfigError(f"{owner}.hole_size_px must be >= 1, got {self.hole_size_px}")


def _correlated_normal(rng: np.random.Generator, shape: tuple[int, int], sigma_px: float) -> F64:
    """(H, W, 2) standard normal field, blurred by ``sigma_px`` and renormalised to unit std."""
    white = rng.standard_normal(shape + (2,))
    if sigma_px <= 0:
        return white
    ksize = 2 * int(np.ceil(3.0 * sigma_px)) + 1
    k1 = cv2.getGaussianKernel(ksize, sigma_px, cv2.CV_64F)[:, 0]
    gain = float(np.sum(k1**2))  # std of the blurred field = gain (separable 2-D kernel)
    blurred: NDArray[Any] = cv2.GaussianBlur(
        white, (ksize, ksize), sigma_px, sigmaY=sigma_px, borderType=cv2.BORDER_REFLECT
    )
    return blurred / gain


def apply_flow_noise(
    flow: FlowField, config: FlowNoiseConfig, rng: np.random.Generator
) -> FlowField:
    """``flow`` with the :class:`FlowNoiseConfig` error model applied (a new record).

    Args:
        flow: exact flow (any grid; the noise parameters are in flow-grid cells when
            ``grid_px > 1``).
        config: the error model.
        rng: generator for this frame pair.
    """
    f = flow.flow_px.astype(np.float64)
    shape = f.shape[:2]
    valid = np.ones(shape, bool) if flow.valid is None else flow.valid.copy()
    e = _correlated_normal(rng, shape, config.correlation_px)
    mag = np.linalg.norm(f, axis=2, keepdims=True)
    noisy = f + e * np.sqrt(config.sigma_px**2 + (config.relative_sigma * mag) ** 2)
    out = rng.random(shape) < config.outlier_fraction
    radius = config.outlier_max_px * np.sqrt(rng.random(shape))
    angle = rng.uniform(0.0, 2.0 * np.pi, shape)
    jump = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=2)
    noisy = np.where(out[..., None], f + jump, noisy)
    if config.hole_fraction > 0:
        s = config.hole_size_px
        blocks = rng.random((-(-shape[0] // s), -(-shape[1] // s))) < config.hole_fraction
        holes = np.repeat(np.repeat(blocks, s, 0), s, 1)[: shape[0], : shape[1]]
        valid &= ~holes
    noisy[~valid] = 0.0
    return FlowField(
        flow_px=noisy.astype(np.float32),
        from_k=flow.from_k,
        to_k=flow.to_k,
        grid_px=flow.grid_px,
        valid=valid,
    )


class NoisyGroundTruthFlowSource:
    """Ground-truth flow plus the :class:`FlowNoiseConfig` end-point-error model."""

    __slots__ = ("config", "seed", "_gt")

    def __init__(self, config: FlowNoiseConfig | None = None, seed: int = 0) -> None:
        self.config = config if config is not None else FlowNoiseConfig()
        self.seed = int(seed)
        self._gt = GroundTruthFlowSource()

    name = "gt+noise"

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField:
        exact = self._gt.flow(sequence, from_k, to_k)
        return apply_flow_noise(exact, self.config, frame_rng(self.seed, from_k, to_k))


DIS_PRESETS: dict[str, tuple[int, int | None, int | None, int | None]] = {
    "ultrafast": (cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, None, None, None),
    "fast": (cv2.DISOPTICAL_FLOW_PRESET_FAST, None, None, None),
    "medium": (cv2.DISOPTICAL_FLOW_PRESET_MEDIUM, None, None, None),
    "medium4": (cv2.DISOPTICAL_FLOW_PRESET_MEDIUM, 2, None, None),
}
"""OpenCV DIS settings by name: ``(preset, finest scale, patch size [px], patch stride [px])``,
None = the preset's value.

``medium4`` is ``medium`` (patch 8, stride 3, 25 descent and 5 variational iterations) stopped
at pyramid level 2, 1/4 resolution: one patch search per 4x4 pixels, NVOF 1.0's output grid,
whose field OpenCV upsamples bilinearly to full resolution (``medium`` goes on to level 1,
1/2 resolution; ``fast`` and ``ultrafast`` stop at level 2 with fewer iterations)."""


def make_dis(preset: str) -> cv2.DISOpticalFlow:
    """A new OpenCV DIS object with the settings named ``preset`` (:data:`DIS_PRESETS`)."""
    if preset not in DIS_PRESETS:
        raise ConfigError(
            f"unknown DIS preset {preset!r}; expected one of {', '.join(DIS_PRESETS)}"
        )
    base, finest_scale, patch_px, stride_px = DIS_PRESETS[preset]
    dis = cv2.DISOpticalFlow.create(base)
    if finest_scale is not None:
        dis.setFinestScale(finest_scale)
    if patch_px is not None:
        dis.setPatchSize(patch_px)
    if stride_px is not None:
        dis.setPatchStride(stride_px)
    return dis


class DisFlowSource:
    """OpenCV's Dense Inverse Search flow (Kroeger et al. 2016) on the grey rgb images.

    Computed directly between ``from_k`` and ``to_k`` (any stride, no chaining). A real
    algorithm's errors: texture-dependent, smoothed over motion boundaries, no validity mask.
    DIS is deterministic; ``seed`` is kept for the common signature and ignored.
    """

    __slots__ = ("preset", "seed")

    def __init__(self, preset: str = "medium", seed: int = 0) -> None:
        if preset not in DIS_PRESETS:
            raise ConfigError(
                f"unknown DIS preset {preset!r}; expected one of {', '.join(DIS_PRESETS)}"
            )
        self.preset = preset
        self.seed = int(seed)

    @property
    def name(self) -> str:
        return f"dis:{self.preset}"

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField:
        check_frame_pair(sequence, from_k, to_k)
        grey = [
            cv2.cvtColor(np.ascontiguousarray(sequence.rgb(k)), cv2.COLOR_RGB2GRAY)
            for k in (from_k, to_k)
        ]
        dis = make_dis(self.preset)
        flow = dis.calc(grey[0], grey[1], None)  # type: ignore[call-overload]  # None: allocate
        return FlowField(flow_px=flow.astype(np.float32), from_k=from_k, to_k=to_k, grid_px=1)


def block_cells(flow_px: F32, grid_px: int) -> F32 | None:
    """The pixels of every block, block pixel by block pixel: one contiguous copy that
    :func:`block_mean_flow` and :func:`one_motion_per_block` can share.

    Args:
        flow_px: (H, W, 2) float32 flow [px], full resolution.
        grid_px: block side g [px].

    Returns:
        (g * g, H / g, W / g, 2) float32 [px], entry ``[i * g + j, r, c]`` = the vector at
        row ``r * g + i``, column ``c * g + j`` of ``flow_px`` (block ``(r, c)``'s row i,
        column j); None when H or W is not a multiple of g or a vector is not finite (the
        callers' general path).
    """
    h, w = flow_px.shape[:2]
    g = int(grid_px)
    if h % g or w % g or not bool(np.isfinite(flow_px).all()):
        return None
    blocks = np.asarray(flow_px, dtype=np.float32).reshape(h // g, g, w // g, g, 2)
    return np.ascontiguousarray(blocks.transpose(1, 3, 0, 2, 4)).reshape(g * g, h // g, w // g, 2)


def block_mean_flow(
    flow_px: F32, grid_px: int, *, cells: F32 | None = None
) -> tuple[F64, NDArray[np.bool_]]:
    """Mean of a dense flow over each ``grid_px`` x ``grid_px`` block's finite pixels.

    The sums run in float64, block pixel by block pixel in row-major order (row 0 of the block
    left to right, then row 1, ...), which is the order of numpy's ``sum(axis=(1, 3))`` on the
    ``(hg, g, wg, g, 2)`` view: the result is bit for bit the one of that reduction (and of the
    version before this function), in about a tenth of its time (the multi-axis reduction
    walks the array with a stride per element).

    Args:
        flow_px: (H, W, 2) float32 flow [px], full resolution; NaN/inf = no flow at a pixel.
        grid_px: block side g [px]; blocks on the right and bottom border are partial.
        cells: :func:`block_cells` of ``flow_px`` if the caller has it (the same sums, on
            contiguous slices: a fifth of the time); None = read the blocks in place.

    Returns:
        ``(mean, valid)``: (ceil(H/g), ceil(W/g), 2) float64 block mean [px] (0 where a block
        has no finite pixel) and (ceil(H/g), ceil(W/g)) bool, True where it has one.
    """
    h, w = flow_px.shape[:2]
    g = int(grid_px)
    hg, wg = -(-h // g), -(-w // g)
    if cells is not None:
        total = cells[0].astype(np.float64)
        for cell in cells[1:]:  # block pixel (0, 1), (0, 2), ...: the order below
            total += cell
        return total / float(g * g), np.ones((hg, wg), dtype=np.bool_)
    if h % g == 0 and w % g == 0 and bool(np.isfinite(flow_px).all()):
        blocks = flow_px.reshape(hg, g, wg, g, 2)
        total = blocks[:, 0, :, 0].astype(np.float64)
        for i in range(g):
            for j in range(g):
                if i or j:
                    total += blocks[:, i, :, j]
        return total / float(g * g), np.ones((hg, wg), dtype=np.bool_)
    padded = np.full((hg * g, wg * g, 2), np.nan, dtype=np.float32)
    padded[:h, :w] = flow_px
    blocks = padded.reshape(hg, g, wg, g, 2)
    total = np.zeros((hg, wg, 2), dtype=np.float64)
    count = np.zeros((hg, wg), dtype=np.int64)
    for i in range(g):
        for j in range(g):
            cell = blocks[:, i, :, j]
            ok = cast(NDArray[np.bool_], np.isfinite(cell).all(axis=2))  # (hg, wg) array
            total += np.where(ok[..., None], cell, np.float32(0.0))
            count += ok
    valid = count > 0
    mean = np.where(valid[..., None], total / np.maximum(count, 1)[..., None], 0.0)
    return mean, valid


class NvofLikeFlowSource:
    """Any flow reduced to NVOF 1.0's output: one vector per ``grid_px`` block, S10.5 int16.

    One vector per block, like NVOF's hardware, which does block-based matching: one vector per
    block with a matching cost (NVIDIA Optical Flow SDK; OpenCV ``cv::cuda::NvidiaHWOpticalFlow``:
    "block-based optical flow vectors", with a per-vector cost buffer), so a block's vector is a
    displacement that matches the block. A block whose inner vectors agree within
    ``precision_px`` (one motion) gets their mean; a block with more spread (a motion boundary)
    gets their L1 medoid, one of the motions in it (the majority's), not their average, which
    matches neither (the average was used for every block before and put a ring of mixed
    motion around every object). Rounded to the hardware's ``precision_px`` (1/4 px,
    :data:`NVOF_PRECISION_PX`), stored in S10.5 and saturated to +-1024 px. So against the inner
    flow at a pixel the error is at most ``precision_px / 2`` plus the flow's spread within the
    block.
    Blocks without a valid pixel are invalid (0). Consumers read the vector of pixel ``(u, v)``
    at ``[v // 4, u // 4]``. The estimation errors (large displacements, low texture, smoothing
    across motion boundaries) are the inner source's: pair it with ``dis`` (docs/sensors.md
    measures them per kind of pixel).
    """

    __slots__ = ("inner", "grid_px", "precision_px")

    def __init__(
        self,
        inner: FlowSource,
        *,
        grid_px: int = NVOF_GRID_PX,
        precision_px: float = NVOF_PRECISION_PX,
    ) -> None:
        if grid_px < 1:
            raise ConfigError(f"grid_px must be >= 1, got {grid_px}")
        check_s10_5_precision("precision_px", precision_px)
        self.inner = inner
        self.grid_px = int(grid_px)
        self.precision_px = float(precision_px)

    @property
    def name(self) -> str:
        return f"nvof-like:{self.inner.name}"

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField | None:
        inner = self.inner.flow(sequence, from_k, to_k)
        if inner is None:
            return None
        h, w = sequence.intrinsics.shape
        dense = inner.dense(h, w)
        g = self.grid_px
        cells = block_cells(dense, g)  # one copy for the mean and the spread
        mean, valid = block_mean_flow(dense, g, cells=cells)
        block = one_motion_per_block(dense, mean, g, self.precision_px, cells=cells)
        rounded = np.round(block / self.precision_px) * self.precision_px
        flow = flow_px_from_s10_5(s10_5_from_flow_px(rounded))
        return FlowField(
            flow_px=flow,
            from_k=from_k,
            to_k=to_k,
            grid_px=g,
            valid=None if (valid.all() and inner.valid is None) else valid,
        )


def one_motion_per_block(
    flow_px: F32, mean_px: F64, grid_px: int, spread_px: float, *, cells: F32 | None = None
) -> F64:
    """One vector per block: the block mean where the block holds one motion, else one of its
    motions (see :class:`NvofLikeFlowSource`).

    A block whose finite vectors agree within ``spread_px`` on both components keeps its mean;
    any other block (a motion boundary) gets its L1 medoid, the finite vector with the least
    summed L1 distance to the others (the first such in row-major order on ties), i.e. the
    majority's motion. The spread comes from strided minima and maxima (16 array operations for
    4x4 blocks) and the medoid is computed for the mixed blocks alone, so smooth flow costs
    little more than the mean.

    Args:
        flow_px: (H, W, 2) float32 flow [px], full resolution; NaN/inf = no flow at a pixel.
        mean_px: (ceil(H/g), ceil(W/g), 2) float64 block means [px], from
            :func:`block_mean_flow` (0 for a block without a finite pixel).
        grid_px: block side g [px].
        spread_px: the largest per-component spread of one motion [px].
        cells: :func:`block_cells` of ``flow_px`` if the caller has it; None = computed here
            when H and W are multiples of g and every vector is finite.

    Returns:
        (ceil(H/g), ceil(W/g), 2) float64 block vectors [px].
    """
    h, w = flow_px.shape[:2]
    g = int(grid_px)
    hg, wg = mean_px.shape[:2]
    if cells is None:
        cells = block_cells(flow_px, g)
    if cells is not None:
        blocks = np.asarray(flow_px, dtype=np.float32).reshape(hg, g, wg, g, 2)
        # block pixel (i, j) of every block as one contiguous slice, so the spread is two
        # reductions over the first axis, elementwise over contiguous slices (the strided
        # minimum and maximum below take several times as long)
        spread = (cells.max(axis=0) - cells.min(axis=0)).max(axis=2)
    else:
        padded = np.full((hg * g, wg * g, 2), np.nan, dtype=np.float32)
        padded[:h, :w] = flow_px
        padded[~np.isfinite(padded).all(axis=2)] = np.nan
        blocks = padded.reshape(hg, g, wg, g, 2)
        lo = np.full((hg, wg, 2), np.inf, dtype=np.float32)
        hi = np.full((hg, wg, 2), -np.inf, dtype=np.float32)
        for i in range(g):
            for j in range(g):
                np.fmin(lo, blocks[:, i, :, j], out=lo)  # fmin/fmax skip NaN
                np.fmax(hi, blocks[:, i, :, j], out=hi)
        spread = (hi - lo).max(axis=2)  # -inf where a block has no finite vector
    out = np.array(mean_px, dtype=np.float64, copy=True)
    rows, cols = np.nonzero(spread > spread_px)
    for start in range(0, rows.size, 2048):
        r, c = rows[start : start + 2048], cols[start : start + 2048]
        # (n, g * g, 2): the mixed blocks' vectors in row-major order, NaN = no flow
        v = blocks[r, :, c, :].reshape(r.size, g * g, 2)
        ok = cast(NDArray[np.bool_], np.isfinite(v).all(axis=2))
        z = np.where(ok[..., None], v, np.float32(0.0))
        dist = np.abs(z[:, :, None, 0] - z[:, None, :, 0]) + np.abs(
            z[:, :, None, 1] - z[:, None, :, 1]
        )
        cost = np.einsum("cij,cj->ci", dist, ok.astype(np.float32))
        best = np.where(ok, cost, np.inf).argmin(axis=1)
        out[r, c] = z[np.arange(r.size), best]
    return out


def make_flow_source(spec: str, *, seed: int) -> FlowSource:
    """Builds a flow source from its spec string (see the module docstring).

    Args:
        spec: ``gt``, ``gt+noise``, ``gt+noise:<sigma_px>``, ``dis``, ``dis:<preset>``,
            ``bm``, ``bm:<window_px>``, ``nvof-like:<inner spec>``, ``nvof-model``,
            ``stored:<set>``,
            ``nvof-hw`` or ``nvof-hw:<perf level>`` (built without touching the GPU).
        seed: seed of stochastic sources (each frame pair draws from
            ``SeedSequence([seed, from_k, to_k])``).

    Raises:
        ConfigError: unknown spec.
    """
    kind, _, arg = spec.partition(":")
    kind = kind.strip()
    if kind == "gt" and not arg:
        return GroundTruthFlowSource()
    if kind == "gt+noise" and not arg:
        return NoisyGroundTruthFlowSource(FlowNoiseConfig(), seed)
    if kind == "gt+noise":
        try:
            sigma_px = float(arg)
        except ValueError:
            sigma_px = float("nan")
        if not (np.isfinite(sigma_px) and sigma_px >= 0):
            raise ConfigError(
                f"flow source {spec!r}: 'gt+noise:<sigma_px>' needs a number of pixels >= 0, "
                "e.g. 'gt+noise:1'"
            )
        return NoisyGroundTruthFlowSource(FlowNoiseConfig(sigma_px=sigma_px), seed)
    if kind == "dis":
        return DisFlowSource(arg or "medium", seed)
    if kind == "bm":
        from roft_sim.sensors.block_matching import (  # lazily: only this source needs it
            BlockMatchingConfig,
            BlockMatchingFlowSource,
        )

        if not arg:
            return BlockMatchingFlowSource(seed=seed)
        if not arg.isdigit():
            raise ConfigError(
                f"flow source {spec!r}: 'bm:<window_px>' needs a whole number of pixels, "
                "e.g. 'bm:16'"
            )
        return BlockMatchingFlowSource(BlockMatchingConfig(window_px=int(arg)), seed=seed)
    if kind == "nvof-like" and arg:
        return NvofLikeFlowSource(make_flow_source(arg, seed=seed))
    if kind == "nvof-model" and not arg:
        from roft_sim.sensors.nvof_error_model import NvofErrorModelFlowSource

        return NvofErrorModelFlowSource(seed=seed)
    if kind == "stored" and arg:
        return StoredFlowSource(arg)
    if kind == "nvof-hw":
        from roft_sim.sensors.nvof_hardware import NvofHardwareFlowSource  # loads no GPU library

        return NvofHardwareFlowSource(arg or "slow")
    hint = ""
    if kind == "nvof-like":
        hint = " ('nvof-like' needs an inner source, e.g. 'nvof-like:dis' or 'nvof-like:gt')"
    elif kind == "stored":
        hint = " ('stored' needs a set name, e.g. 'stored:nvof_1_slow')"
    raise ConfigError(
        f"unknown flow source {spec!r}{hint}; expected one of {', '.join(FLOW_SOURCE_SPECS)}"
    )
