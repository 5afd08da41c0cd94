"""End-point error of a flow estimate against the ground-truth motion field, per kind of pixel.

Hardware flow (NVOF) and patch-based flow (DIS) fail in known places: across motion boundaries
(one vector per block or patch mixes two motions), on large displacements (beyond the search
range) and on low texture (nothing to match). :func:`flow_error_breakdown` measures the
end-point error (EPE) of an estimate on each of these kinds of pixel, with the KITTI 2015
outlier rate (Fl: EPE > 3 px and > 5 % of the true flow), so the errors of our NVOF-like flow
can be set beside published figures; :func:`sequence_flow_errors` pools the frames of a
sequence. ``python -m roft_sim.sensors.flow_accuracy SEQUENCE [ESTIMATE_SET] [GT_SET]`` prints
the table (docs/sensors.md).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import Sequence
from roft_sim.errors import ConfigError
from roft_sim.records import FlowField

F64 = NDArray[np.float64]
Bool = NDArray[np.bool_]

__all__ = [
    "FlowErrorSummary",
    "FLOW_ERROR_CATEGORIES",
    "flow_pixel_categories",
    "flow_error_breakdown",
    "sequence_flow_errors",
]

FLOW_ERROR_CATEGORIES = (
    "all",
    "object",
    "motion_boundary",
    "large_displacement",
    "low_texture",
)
"""The kinds of pixel :func:`flow_error_breakdown` reports (they overlap; ``all`` is every
pixel with a valid ground truth and a valid estimate)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class FlowErrorSummary:
    """End-point errors of one kind of pixel."""

    category: str
    """One of :data:`FLOW_ERROR_CATEGORIES`."""
    pixels: int
    """Pixels scored (valid ground truth and valid estimate)."""
    mean_epe_px: float
    """Mean end-point error [px] (NaN without pixels)."""
    median_epe_px: float
    """Median end-point error [px]."""
    fl_pct: float
    """KITTI 2015 outlier rate [%]: EPE > 3 px and > 5 % of ``|F_gt|``."""
    invalid_pct: float
    """Share of the category's pixels with a valid ground truth where the estimate is invalid
    [%] (not in the other numbers)."""


def flow_pixel_categories(
    truth_px: F64,
    grey: NDArray[np.generic],
    object_mask: Bool | None,
    *,
    boundary_px: int = 4,
    large_displacement_px: float = 16.0,
    low_texture_std: float = 4.0,
    texture_window_px: int = 9,
) -> dict[str, Bool]:
    """(H, W) masks of the kinds of pixel (before validity).

    Args:
        truth_px: (H, W, 2) ground-truth flow [px], NaN where unknown.
        grey: (H, W) grey image of the first frame (0..255).
        object_mask: (H, W) the object's visible pixels in the first frame, or None.
        boundary_px: a motion boundary is a jump of more than 1 px in the true flow between
            neighbours (or the object mask's edge); pixels within this distance are in it.
        large_displacement_px: ``|F_gt|`` above this is a large displacement.
        low_texture_std: grey-level standard deviation in the window below this is low texture.
        texture_window_px: side of the texture window [px].
    """
    h, w = truth_px.shape[:2]
    known: Bool = np.all(np.isfinite(truth_px), axis=2)
    f = np.where(known[..., None], truth_px, 0.0)
    jump = np.zeros((h, w), dtype=bool)
    dx = np.linalg.norm(f[:, 1:] - f[:, :-1], axis=2) > 1.0
    dy = np.linalg.norm(f[1:] - f[:-1], axis=2) > 1.0
    jump[:, 1:] |= dx & known[:, 1:] & known[:, :-1]
    jump[:, :-1] |= dx & known[:, 1:] & known[:, :-1]
    jump[1:] |= dy & known[1:] & known[:-1]
    jump[:-1] |= dy & known[1:] & known[:-1]
    if object_mask is not None:
        m = object_mask.astype(np.uint8)
        jump |= cv2.morphologyEx(m, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    size = 2 * boundary_px + 1
    boundary = cv2.dilate(jump.astype(np.uint8), np.ones((size, size), np.uint8)) > 0
    g = np.asarray(grey, dtype=np.float64)
    k = (texture_window_px, texture_window_px)
    mean = cv2.blur(g, k)
    std = np.sqrt(np.maximum(cv2.blur(g * g, k) - mean * mean, 0.0))
    return {
        "all": np.ones((h, w), dtype=bool),
        "object": np.ones((h, w), bool) if object_mask is None else object_mask.astype(bool),
        "motion_boundary": boundary,
        "large_displacement": np.linalg.norm(f, axis=2) > large_displacement_px,
        "low_texture": std < low_texture_std,
    }


def _summaries(
    errors: dict[str, list[F64]], truths: dict[str, list[F64]], missing: dict[str, list[int]]
) -> dict[str, FlowErrorSummary]:
    out = {}
    for name in FLOW_ERROR_CATEGORIES:
        e = np.concatenate(errors[name]) if errors[name] else np.zeros(0)
        t = np.concatenate(truths[name]) if truths[name] else np.zeros(0)
        n_missing = sum(missing[name])
        fl = (e > 3.0) & (e > 0.05 * t)
        out[name] = FlowErrorSummary(
            category=name,
            pixels=int(e.size),
            mean_epe_px=float(e.mean()) if e.size else float("nan"),
            median_epe_px=float(np.median(e)) if e.size else float("nan"),
            fl_pct=100.0 * float(fl.mean()) if e.size else float("nan"),
            invalid_pct=100.0 * n_missing / max(n_missing + e.size, 1),
        )
    return out


def _accumulate(
    estimate: FlowField,
    truth: FlowField,
    grey: NDArray[np.generic],
    object_mask: Bool | None,
    errors: dict[str, list[F64]],
    truths: dict[str, list[F64]],
    missing: dict[str, list[int]],
) -> None:
    h, w = np.asarray(grey).shape[:2]
    t = truth.dense(h, w).astype(np.float64)
    e = estimate.dense(h, w).astype(np.float64)
    known: Bool = np.all(np.isfinite(t), axis=2)
    have: Bool = np.all(np.isfinite(e), axis=2)
    epe = np.linalg.norm(e - t, axis=2)
    mag = np.linalg.norm(np.where(known[..., None], t, 0.0), axis=2)
    for name, cat in flow_pixel_categories(t, grey, object_mask).items():
        scored = cat & known & have
        errors[name].append(epe[scored])
        truths[name].append(mag[scored])
        missing[name].append(int((cat & known & ~have).sum()))


def flow_error_breakdown(
    estimate: FlowField,
    truth: FlowField,
    grey: NDArray[np.generic],
    object_mask: Bool | None = None,
) -> dict[str, FlowErrorSummary]:
    """End-point errors of ``estimate`` against ``truth`` on one frame pair, per kind of pixel
    (:func:`flow_pixel_categories`); both flows are read at full resolution
    (``FlowField.dense``), so a 4x4-grid estimate is scored at every pixel as consumers read it.

    Args:
        estimate: the flow to score.
        truth: the ground-truth motion field of the same frame pair.
        grey: (H, W) grey image of the first frame (0..255).
        object_mask: (H, W) the object's visible pixels in the first frame, or None.
    """
    if (estimate.from_k, estimate.to_k) != (truth.from_k, truth.to_k):
        raise ConfigError(
            f"estimate is frames {estimate.from_k}->{estimate.to_k} but the truth is "
            f"{truth.from_k}->{truth.to_k}; score flows of the same frame pair"
        )
    errors: dict[str, list[F64]] = {n: [] for n in FLOW_ERROR_CATEGORIES}
    truths: dict[str, list[F64]] = {n: [] for n in FLOW_ERROR_CATEGORIES}
    missing: dict[str, list[int]] = {n: [] for n in FLOW_ERROR_CATEGORIES}
    _accumulate(estimate, truth, grey, object_mask, errors, truths, missing)
    return _summaries(errors, truths, missing)


def sequence_flow_errors(
    sequence: Sequence,
    estimate_set: str = "nvof_1_slow",
    truth_set: str = "gt",
    *,
    frames: Iterable[int] | None = None,
    mask_set: str = "gt",
) -> dict[str, FlowErrorSummary]:
    """:func:`flow_error_breakdown` pooled over the frames ``k`` (flow ``k-1 -> k``; default
    every frame from 1) of a sequence's stored flow sets.

    Raises:
        ConfigError: the sequence lacks one of the sets.
    """
    flow_sets = sequence.flow_sets()
    for name in (estimate_set, truth_set):
        if name not in flow_sets:
            raise ConfigError(
                f"sequence {sequence.name!r} has no flow set {name!r}; it has "
                f"{', '.join(flow_sets) or 'none'}"
            )
    errors: dict[str, list[F64]] = {n: [] for n in FLOW_ERROR_CATEGORIES}
    truths: dict[str, list[F64]] = {n: [] for n in FLOW_ERROR_CATEGORIES}
    missing: dict[str, list[int]] = {n: [] for n in FLOW_ERROR_CATEGORIES}
    for k in frames if frames is not None else range(1, len(sequence)):
        est, gt = sequence.flow(k, estimate_set), sequence.flow(k, truth_set)
        if est is None or gt is None:
            continue
        grey = cv2.cvtColor(sequence.rgb(k - 1), cv2.COLOR_RGB2GRAY)
        mask = sequence.mask(k - 1, mask_set) if mask_set in sequence.mask_sets() else None
        _accumulate(est, gt, grey, mask, errors, truths, missing)
    return _summaries(errors, truths, missing)


def main(argv: list[str] | None = None) -> None:  # pragma: no cover - a report script
    """Prints the breakdown of every sequence under a dataset folder."""
    import sys

    from roft_sim.datasets import find_sequences, open_sequence

    args = sys.argv[1:] if argv is None else argv
    estimate_set = args[1] if len(args) > 1 else "nvof_1_slow"
    truth_set = args[2] if len(args) > 2 else "gt"
    step = int(args[3]) if len(args) > 3 else 1
    print("| sequence | pixels | " + " | ".join(FLOW_ERROR_CATEGORIES) + " |")
    print("|---|---|" + "---|" * len(FLOW_ERROR_CATEGORIES))
    for path in find_sequences([args[0]]):
        seq = open_sequence(path)
        summary = sequence_flow_errors(
            seq, estimate_set, truth_set, frames=range(1, len(seq), step)
        )
        cells = [
            f"{s.mean_epe_px:.2f} / {s.median_epe_px:.2f} / {s.fl_pct:.1f} %"
            f" ({100 * s.pixels / max(summary['all'].pixels, 1):.0f} %)"
            for s in summary.values()
        ]
        print(f"| {seq.name} | {summary['all'].pixels} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":  # pragma: no cover
    main()
