"""NVOF-like flow from an error model fitted to real NVIDIA hardware flow (spec ``nvof-model``).

Real hardware flow (NVOF API 1.0, SLOW, 4x4 grid: ``nvof-hw``), read on our rendered sequences,
has errors of a simple shape, which this module reproduces from the exact motion field, without
an image matcher, in a few milliseconds per frame on a CPU:

- **Motion boundaries, heavy-tailed.** A block near a boundary mostly gets one of the motions
  around it, whole, rather than a blend: the hardware's boundary end-point error has a low median
  and a high mean (EVALUATION objects: median 0.32 px, mean 1.22 px, Fl 8.1 %). Modelled by reading
  each block's vector from the exact flow at a point jittered about the block's centre
  (``boundary_jitter_px``, Gaussian): exact inside smooth motion, one of the neighbouring motions
  near a boundary, with the probability the jitter puts there, so the motion spills a few
  pixels each way as the hardware's does (its share of the object's motion 0-2 / 2-4 / 4-8 px
  outside the mask: 0.39 / 0.18 / 0.05).
- **Sub-pixel noise on moving texture, none on static texture.** The hardware reads a static
  background exactly (an integer displacement matches perfectly) and moving surfaces with about
  0.3 px median error, nearly independent of the speed: per component Gaussian of
  ``sigma_px * (1 - exp(-|F| / static_speed_px))`` plus ``relative_sigma * |F|``.
- **Failures on large displacements.** Gross errors (Fl) become more frequent as the
  displacement grows: a block fails with probability ``failure_rate_per_16px * |F| / 16 px``
  (at most 1/2) and then gets a vector anywhere in a disc of radius ``max(failure_min_radius_px,
  |F|)`` about the truth.
- **The output format.** One vector per ``grid_px`` block, rounded to ``precision_px`` (1/4 px,
  NVOF 1.0) and stored as S10.5, like :class:`~roft_sim.sensors.flow_sources.NvofLikeFlowSource`.

Parameters are in pixels of the image the flow is computed on, as the hardware's are (its 4x4
blocks and matching windows are in pixels whatever the resolution). They were fitted on the
TUNING objects' hardware flows (003, 004; 1280x720, 150 frames, H100 engine) and are reported on
the EVALUATION objects (005, 006, 009) by ``python -m roft_sim.sensors.flow_accuracy``. Not
modelled: texture-dependent failures (the hardware's error on our low-texture pixels was as
small as the model's) and the Turing engine's own behaviour (the H100's is not Turing's:
docs/sensors.md, ``nvof-hw``).

Stochastic per frame pair: each ``flow(seq, from_k, to_k)`` draws from
``SeedSequence([seed, from_k, to_k])``, so a pair's flow does not depend on which pairs were
asked for before, or on how frames were split among workers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import GT_FLOW_SET, Sequence
from roft_sim.errors import ConfigError
from roft_sim.records import FlowField
from roft_sim.sensors.flow_source_base import (
    NVOF_GRID_PX,
    NVOF_PRECISION_PX,
    FlowSource,
    GroundTruthFlowSource,
    StoredFlowSource,
    check_finite_at_least,
    check_s10_5_precision,
    flow_px_from_s10_5,
    frame_rng,
    s10_5_from_flow_px,
)

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
Bool = NDArray[np.bool_]

__all__ = ["NvofErrorModelConfig", "nvof_error_model", "NvofErrorModelFlowSource"]


@dataclass(frozen=True, slots=True, kw_only=True)
class NvofErrorModelConfig:
    """Parameters of :func:`nvof_error_model` (module doc); pixels of the flow's image."""

    boundary_jitter_px: float = 3.0
    """Std of the Gaussian jitter of the point a block's vector is read at [px]."""
    sigma_px: float = 0.2
    """Per-component std of the additive error on moving blocks [px]."""
    static_speed_px: float = 0.25
    """Speed [px/frame] over which the additive error rises from 0 (static) to ``sigma_px``."""
    relative_sigma: float = 0.01
    """Per-component std per pixel of displacement [px/px]."""
    failure_rate_per_16px: float = 0.01
    """Probability that a block fails, per 16 px of its displacement (capped at 1/2)."""
    failure_min_radius_px: float = 4.0
    """A failed block's vector lies in a disc of radius ``max(this, |F|)`` about the truth [px]."""
    grid_px: int = NVOF_GRID_PX
    """Output block side [px]."""
    precision_px: float = NVOF_PRECISION_PX
    """Vector precision [px] (a whole multiple of 1/32, the S10.5 step)."""

    def __post_init__(self) -> None:
        for name in (
            "boundary_jitter_px",
            "sigma_px",
            "static_speed_px",
            "relative_sigma",
            "failure_rate_per_16px",
            "failure_min_radius_px",
        ):
            check_finite_at_least("NvofErrorModelConfig", name, getattr(self, name), 0.0)
        if self.static_speed_px <= 0:
            raise ConfigError(
                f"NvofErrorModelConfig.static_speed_px must be > 0, got {self.static_speed_px}"
            )
        if self.grid_px < 1:
            raise ConfigError(f"NvofErrorModelConfig.grid_px must be >= 1, got {self.grid_px}")
        check_s10_5_precision("NvofErrorModelConfig.precision_px", self.precision_px)


def nvof_error_model(
    exact_px: F32,
    config: NvofErrorModelConfig,
    rng: np.random.Generator,
    *,
    known_px: Bool | None = None,
) -> tuple[F32, Bool]:
    """NVOF-like block flow from an exact dense flow (module doc).

    Args:
        exact_px: (H, W, 2) float32 exact flow [px] of the first frame's pixels, NaN where
            unknown (no depth, occluded, leaving the image).
        config: the error model.
        rng: this frame pair's generator (drawn in a fixed order: jitter rows, jitter columns,
            noise, failures, failure radii, failure angles).
        known_px: (H, W) bool, True where ``exact_px`` is known; None = where both components
            are finite. When given, the values of ``exact_px`` elsewhere are never read into
            the result (they may be anything), so a flow with a validity mask needs no NaN
            copy.

    Returns:
        ``(flow, valid)``: (ceil(H/g), ceil(W/g), 2) float32 block vectors [px] on S10.5's
        ``precision_px`` steps (0 where invalid), and (ceil(H/g), ceil(W/g)) bool, True where
        the block has a pixel with a known flow.
    """
    h, w = exact_px.shape[:2]
    g = config.grid_px
    hg, wg = -(-h // g), -(-w // g)
    # per component and one axis at a time: numpy's reductions over short trailing axes are
    # several times slower
    if known_px is None:
        known_px = np.isfinite(exact_px[..., 0]) & np.isfinite(exact_px[..., 1])
    elif known_px.shape != (h, w):
        raise ValueError(f"known_px is {known_px.shape}; the flow is {h}x{w}")
    padded = np.zeros((hg * g, wg * g), dtype=bool)
    padded[:h, :w] = known_px
    valid = cast(Bool, padded.reshape(hg, g, wg * g).any(axis=1).reshape(hg, wg, g).any(axis=2))
    centre = (g - 1) / 2.0
    rows = (
        np.arange(hg)[:, None] * g
        + centre
        + rng.normal(0.0, 1.0, (hg, wg)) * (config.boundary_jitter_px)
    )
    cols = (
        np.arange(wg)[None, :] * g
        + centre
        + rng.normal(0.0, 1.0, (hg, wg)) * (config.boundary_jitter_px)
    )
    r = np.clip(np.rint(rows), 0, h - 1).astype(np.intp)
    c = np.clip(np.rint(cols), 0, w - 1).astype(np.intp)
    at = r * w + c  # flat indices: one gather instead of numpy's two-array indexing
    block = exact_px.reshape(h * w, 2)[at].astype(np.float64)
    # a jittered point without a known flow falls back to its block's mean known flow
    br, bc = np.nonzero(~known_px.reshape(h * w)[at] & valid)
    if br.size:
        i = br[:, None] * g + np.arange(g)[None, :]  # (n, g) rows of each block
        j = bc[:, None] * g + np.arange(g)[None, :]  # (n, g) columns
        inside = (i < h)[:, :, None] & (j < w)[:, None, :]  # border blocks are partial
        i, j = np.minimum(i, h - 1), np.minimum(j, w - 1)
        cells = exact_px[i[:, :, None], j[:, None, :]].astype(np.float64)  # (n, g, g, 2)
        ok = known_px[i[:, :, None], j[:, None, :]] & inside
        total = np.where(ok[..., None], cells, 0.0).sum(axis=(1, 2))
        block[br, bc] = total / ok.sum(axis=(1, 2))[:, None]
    block[~valid] = 0.0
    speed = np.sqrt(block[..., 0] ** 2 + block[..., 1] ** 2)  # np.linalg.norm's bits, faster
    sigma = np.hypot(
        config.sigma_px * -np.expm1(-speed / config.static_speed_px),
        config.relative_sigma * speed,
    )
    noisy = block + rng.standard_normal((hg, wg, 2)) * sigma[..., None]
    fails = rng.random((hg, wg)) < np.minimum(0.5, config.failure_rate_per_16px * speed / 16.0)
    radius = np.maximum(config.failure_min_radius_px, speed) * np.sqrt(rng.random((hg, wg)))
    angle = rng.uniform(0.0, 2.0 * np.pi, (hg, wg))
    jump = np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=2)
    # invalid blocks stay 0: their speed is 0, so no noise and no failure reaches them
    noisy = np.where(fails[..., None], block + jump, noisy)
    rounded = np.round(noisy / config.precision_px) * config.precision_px
    return flow_px_from_s10_5(s10_5_from_flow_px(rounded)), valid


class NvofErrorModelFlowSource:
    """Flow spec ``nvof-model``: :func:`nvof_error_model` on an exact flow.

    The exact flow is ``exact`` when given; by default, the sequence's stored ``gt`` flow set
    for consecutive frames when it has one (a generated dataset's: every rendered body moves
    with its own motion, a hand included), else :class:`GroundTruthFlowSource` (the object
    and the static world only)."""

    name = "nvof-model"

    __slots__ = ("config", "seed", "_exact", "_stored_gt", "_rigid_gt")

    def __init__(
        self,
        config: NvofErrorModelConfig | None = None,
        seed: int = 0,
        *,
        exact: FlowSource | None = None,
    ) -> None:
        self.config = config if config is not None else NvofErrorModelConfig()
        self.seed = int(seed)
        self._exact = exact
        self._stored_gt = StoredFlowSource(GT_FLOW_SET)
        self._rigid_gt = GroundTruthFlowSource()

    def _exact_source(self, sequence: Sequence, from_k: int, to_k: int) -> FlowSource:
        if self._exact is not None:
            return self._exact
        if to_k - from_k == 1 and GT_FLOW_SET in sequence.flow_sets():
            return self._stored_gt
        return self._rigid_gt

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField | None:
        exact = self._exact_source(sequence, from_k, to_k).flow(sequence, from_k, to_k)
        if exact is None:
            return None
        h, w = sequence.intrinsics.shape
        rng = frame_rng(self.seed, from_k, to_k)
        if exact.grid_px == 1 and exact.flow_px.shape[:2] == (h, w):
            # per-pixel flow: its validity mask as it is, no NaN-filled copy (same result)
            flow, valid = nvof_error_model(exact.flow_px, self.config, rng, known_px=exact.valid)
        else:
            flow, valid = nvof_error_model(exact.dense(h, w), self.config, rng)
        return FlowField(
            flow_px=flow,
            from_k=from_k,
            to_k=to_k,
            grid_px=self.config.grid_px,
            valid=None if valid.all() else valid,
        )
