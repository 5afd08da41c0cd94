"""The real NVOF flow of Fast-YCB's README figure beside the simulated flows, through one pipe.

    python benchmarks/bench_flow_picture.py FIGURE SEQUENCE [--sources S1,S2] [--frames N]
        [--min-flow-px PX] [--max-flow-px PX]

FIGURE is hsp-iit/fast-ycb's ``assets/sample_rgbd_flow_mask.png`` (the README figure: rgb |
depth | the dataset's NVOF 1.0 ``nvof_1_slow`` flow, Middlebury colours | the cracker box's
mask; it is not in this repository: download it from the Fast-YCB repository and give its
path). SEQUENCE is a simulated Fast-YCB-like sequence of the cracker box at 1280x720 (e.g.
``roft-sim generate scenarios/fast_ycb/003_cracker_box.toml --out DS --frames 150``, then
``DS/003_cracker_box``).

For each flow source and each of N frames k whose exact flow moves the object by
``--min-flow-px`` to ``--max-flow-px`` (median over the gt mask of frame k - 1, evenly spaced
among those frames), the flow ``F_(k-1 -> k)`` is colour coded at full resolution (normalised
by its largest vector), shrunk with its frame-k ``gt`` mask to the figure's 250 px width by
area averaging and read by :func:`roft_sim.sensors.flow_picture.flow_picture_stats`, as the
figure's flow and mask panels are (the figure pairs flow file k, which maps frame k - 1 to k,
with mask k). Prints one markdown row per source: the median over the frames of each statistic
(rings 1-4, thumbnail px of 5.12 full-resolution px), the figure's own row first.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Sequence as Seq

import cv2
import numpy as np

from roft_sim.datasets import open_sequence
from roft_sim.datasets.base import GT_MASK_SET, Sequence
from roft_sim.sensors.flow_picture import (
    README_PANEL_WIDTH_PX,
    FlowPictureStats,
    fast_ycb_readme_panels,
    flow_picture_stats,
    rgb_from_flow,
    thumbnail,
)
from roft_sim.sensors.flow_sources import StoredFlowSource, make_flow_source

DEFAULT_SOURCES = (
    "gt",
    "stored:nvof_1_slow",
    "nvof-like:bm",
    "nvof-like:dis:fast",
    "nvof-like:dis:ultrafast",
    "dis:medium",
)


def moving_frames(
    seq: Sequence, count: int, min_flow_px: float, max_flow_px: float
) -> list[tuple[int, float]]:
    """``count`` frames k (evenly spaced) whose exact flow ``F_(k-1 -> k)`` has a median
    magnitude over the object's frame k - 1 gt mask in [min_flow_px, max_flow_px] [px]."""
    h, w = seq.intrinsics.shape
    found = []
    for k in range(1, len(seq)):
        mask = seq.mask(k - 1, GT_MASK_SET)
        flow = seq.flow(k, "gt")
        if mask is None or flow is None or not np.asarray(mask).any():
            continue
        f = flow.dense(h, w)
        mag = float(np.nanmedian(np.hypot(f[..., 0], f[..., 1])[np.asarray(mask, bool)]))
        if min_flow_px <= mag <= max_flow_px:
            found.append((k, mag))
    if not found:
        raise SystemExit(f"no frame moves the object by {min_flow_px}-{max_flow_px} px")
    pick = np.unique(np.linspace(0, len(found) - 1, min(count, len(found))).round().astype(int))
    return [found[i] for i in pick]


def sim_picture_stats(seq: Sequence, spec: str, k: int) -> FlowPictureStats:
    """Stats of source ``spec``'s flow ``F_(k-1 -> k)`` with the frame-k gt mask, through the
    figure's pipe (full-resolution colour code, 250 px area shrink)."""
    h, w = seq.intrinsics.shape
    kind, _, arg = spec.partition(":")
    source = StoredFlowSource(arg) if kind == "stored" else make_flow_source(spec, seed=0)
    flow = source.flow(seq, k - 1, k)
    if flow is None:
        raise SystemExit(f"source {spec!r} gave no flow for frame {k}")
    mask = np.asarray(seq.mask(k, GT_MASK_SET), dtype=np.float64)
    rgb = thumbnail(rgb_from_flow(flow.dense(h, w)), README_PANEL_WIDTH_PX)
    return flow_picture_stats(rgb, thumbnail(mask, README_PANEL_WIDTH_PX))


def _fmt(values: Seq[float]) -> str:
    return " / ".join(f"{v:.2f}" for v in values)


def row(label: str, stats: list[FlowPictureStats]) -> str:
    """One markdown row: the median over frames of each statistic."""

    def med(name: str) -> np.ndarray:
        return np.median(np.array([getattr(s, name) for s in stats], dtype=np.float64), axis=0)

    return (
        f"| {label} | {len(stats)} | {_fmt(med('outside_rings'))} | "
        f"{_fmt(med('outside_rings_trailing')[:2])} ; {_fmt(med('outside_rings_leading')[:2])} | "
        f"{_fmt(med('inside_rings'))} | {med('interior_residual'):.2f} | "
        f"{med('interior_magnitude_cv'):.2f} | {med('interior_direction_std_deg'):.1f} | "
        f"{med('background_mean'):.3f} | {100 * med('spurious_fraction'):.1f} % |"
    )


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("figure", help="hsp-iit/fast-ycb assets/sample_rgbd_flow_mask.png")
    parser.add_argument("sequence", help="simulated 1280x720 cracker-box sequence folder")
    parser.add_argument("--sources", default=",".join(DEFAULT_SOURCES))
    parser.add_argument("--frames", type=int, default=12)
    parser.add_argument("--min-flow-px", type=float, default=2.0)
    parser.add_argument("--max-flow-px", type=float, default=30.0)
    parser.add_argument("--per-frame", action="store_true", help="also print every frame")
    args = parser.parse_args(argv)

    figure = cv2.imread(args.figure, cv2.IMREAD_COLOR)
    if figure is None:
        raise SystemExit(f"cannot read {args.figure}")
    flow_rgb, mask = fast_ycb_readme_panels(cv2.cvtColor(figure, cv2.COLOR_BGR2RGB))
    real = flow_picture_stats(flow_rgb, mask)
    seq = open_sequence(args.sequence)
    frames = moving_frames(seq, args.frames, args.min_flow_px, args.max_flow_px)
    print(f"frames (k, median exact |F| px): {', '.join(f'{k} ({m:.1f})' for k, m in frames)}\n")
    print(
        "| flow | frames | halo outside, rings 1-4 | rings 1-2 behind ; ahead of the motion | "
        "inside, rings 1-4 | interior blotches | interior magnitude CV | interior direction std "
        "deg | far background mean | spurious (> 0.2) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    print(row("real NVOF 1.0 (README figure)", [real]))
    print(
        f"| real: soft mask, rings 1-4 outside / inside | | "
        f"{_fmt(real.mask_outside_rings)} | | {_fmt(real.mask_inside_rings)} | | | | | |",
        flush=True,
    )
    for spec in args.sources.split(","):
        stats = [sim_picture_stats(seq, spec, k) for k, _ in frames]
        if spec == "gt":
            mo = np.median([s.mask_outside_rings for s in stats], axis=0)
            mi = np.median([s.mask_inside_rings for s in stats], axis=0)
            print(
                f"| sim: soft mask, rings 1-4 outside / inside | | {_fmt(mo)} | | {_fmt(mi)} |"
                " | | | | |"
            )
        print(row(spec, stats), flush=True)
        if args.per_frame:
            for (k, m), s in zip(frames, stats, strict=True):
                d = dataclasses.asdict(s)
                print(
                    f"  k={k} |F|={m:.1f}: "
                    + ", ".join(
                        f"{n}={np.round(v, 2).tolist()}"
                        for n, v in d.items()
                        if not n.startswith("mask")
                    )
                )


if __name__ == "__main__":
    main()
