"""Preview videos of a scenario: rgb | depth | mask | flow side by side, to look at a scene before
generating a dataset.

Video files (``.mp4``, ``.avi``, ``.gif``) are written by the one video writer,
:class:`roft_sim.report.video.VideoWriter`.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.records import FlowField
from roft_sim.render.ground_truth import RenderedFrame
from roft_sim.report.video import VideoWriter

U8 = NDArray[np.uint8]

__all__ = [
    "flow_to_rgb",
    "depth_to_rgb",
    "mask_to_rgb",
    "preview_panel",
    "write_preview",
]


def flow_to_rgb(flow: FlowField, max_px: float) -> U8:
    """Colour-coded flow ``(Hg, Wg, 3)`` uint8 on the flow's grid: hue = direction (red = +u,
    i.e. to the right), brightness = magnitude (full at ``max_px`` [px] and above); invalid
    pixels are black."""
    f = np.nan_to_num(np.asarray(flow.flow_px, dtype=np.float32))
    magnitude, angle = cv2.cartToPolar(f[..., 0], f[..., 1], angleInDegrees=True)
    hsv = np.empty(f.shape[:2] + (3,), np.uint8)
    hsv[..., 0] = (angle / 2).astype(np.uint8)  # OpenCV hue: 0..179
    hsv[..., 1] = 255
    hsv[..., 2] = np.clip(magnitude / max(max_px, 1e-9) * 255, 0, 255).astype(np.uint8)
    rgb: NDArray[Any] = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)  # uint8, as hsv
    if flow.valid is not None:
        rgb[~flow.valid] = 0
    return rgb


def depth_to_rgb(depth_m: NDArray[np.float32], near_m: float, far_m: float) -> U8:
    """Depth ``(H, W)`` [m] coloured with the TURBO map over ``[near_m, far_m]`` (near = blue);
    no measurement (0) is black."""
    t = np.clip((depth_m - near_m) / max(far_m - near_m, 1e-9), 0, 1)
    rgb: U8 = cv2.applyColorMap((t * 255).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1].copy()
    rgb[depth_m <= 0] = 0
    return rgb


def mask_to_rgb(frame: RenderedFrame) -> U8:
    """The object mask in white on black; other bodies (the hand) in grey."""
    out = np.zeros(frame.shape + (3,), np.uint8)
    if frame.body_index is not None:
        out[frame.body_index >= 2] = 110
    if frame.object_mask is not None:
        out[frame.object_mask] = 255
    return out


def _label(panel: U8, text: str) -> U8:
    scale = max(0.35, panel.shape[0] / 600)
    thickness = max(1, int(round(scale * 2)))
    org = (6, int(18 * scale / 0.5))
    cv2.putText(panel, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), thickness + 2)
    cv2.putText(panel, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), thickness)
    return panel


def preview_panel(
    frame: RenderedFrame,
    flow: FlowField | None,
    *,
    depth_range_m: tuple[float, float],
    flow_max_px: float,
    scale: float = 1.0,
) -> U8:
    """One video frame: rgb | depth | mask | flow side by side, each labelled, ``(h, 4 w, 3)``.

    Args:
        frame: the rendered frame.
        flow: ``F_k`` (previous frame to this one), or None (black panel, e.g. at frame 0).
        depth_range_m: (near, far) of the depth colour map [m].
        flow_max_px: flow magnitude shown at full brightness [px].
        scale: resize factor of each panel.
    """
    h, w = frame.shape
    depth = depth_to_rgb(frame.depth_m, *depth_range_m)
    flow_rgb = flow_to_rgb(flow, flow_max_px) if flow is not None else np.zeros((h, w, 3), np.uint8)
    panels: list[NDArray[Any]] = [frame.rgb.copy(), depth, mask_to_rgb(frame), flow_rgb]
    if scale != 1.0:
        size = (max(1, round(w * scale)), max(1, round(h * scale)))
        panels = [cv2.resize(p, size, interpolation=cv2.INTER_AREA) for p in panels]
    labels = [
        f"rgb  k={frame.k}  t={frame.t_s:.2f} s",
        f"depth {depth_range_m[0]:.2f}-{depth_range_m[1]:.2f} m",
        "object mask",
        f"flow (full colour = {flow_max_px:.1f} px)" if flow is not None else "flow (none)",
    ]
    return np.concatenate([_label(p, t) for p, t in zip(panels, labels, strict=True)], axis=1)


def _frames_with_flow(
    renderer: Any, start: int, stop: int
) -> Iterator[tuple[RenderedFrame, FlowField | None]]:
    from roft_sim.render.ground_truth import ground_truth_flow

    previous = renderer.render_frame(start - 1) if start > 0 else None
    for k in range(start, stop):
        frame = renderer.render_frame(k)
        flow = (
            ground_truth_flow(previous, frame, renderer.intrinsics)
            if previous is not None
            else None
        )
        yield frame, flow
        previous = frame


def write_preview(
    renderer: Any,
    out: str | Path,
    *,
    frames: int | None = None,
    start: int = 0,
    scale: float = 1.0,
    flow_max_px: float | None = None,
    progress: bool = True,
) -> int:
    """Renders frames ``start ... start + frames - 1`` of a :class:`SceneRenderer` and writes the
    preview video ``out`` at the scenario's frame rate.

    Args:
        renderer: an open ``SceneRenderer`` (with segmentation).
        out: ``.mp4``, ``.avi`` or ``.gif`` file.
        frames: number of frames (default: to the end of the scenario).
        start: first frame.
        scale: resize factor of each panel.
        flow_max_px: flow magnitude at full colour [px]; default: the 99th percentile of the
            first flow field (at least 1 px), kept for the whole video.
        progress: show a tqdm progress bar on stderr.

    Returns:
        The number of video frames written.
    """
    from tqdm import tqdm

    n_total = renderer.n_frames
    if not 0 <= start < n_total:
        raise ConfigError(f"start frame {start} is outside the scenario's 0..{n_total - 1}")
    stop = n_total if frames is None else min(n_total, start + frames)
    if stop <= start:
        raise ConfigError(f"--frames must be >= 1, got {frames}")
    if not (np.isfinite(scale) and 0 < scale <= 4):
        raise ConfigError(f"--scale must lie in (0, 4], got {scale}")
    depth_range: tuple[float, float] | None = None
    with VideoWriter(out, renderer.scenario.fps) as sink:
        bar = tqdm(
            _frames_with_flow(renderer, start, stop),
            total=stop - start,
            desc="preview",
            unit="frame",
            disable=not progress,
        )
        for frame, flow in bar:
            if depth_range is None:
                valid = frame.depth_m[frame.depth_m > 0]
                lo, hi = np.percentile(valid, [1, 99]) if valid.size else (0.0, 1.0)
                depth_range = (float(lo), float(max(hi, lo + 1e-3)))
            if flow_max_px is None and flow is not None:
                mags = np.linalg.norm(flow.flow_px[flow.valid], axis=-1)
                flow_max_px = float(max(1.0, np.percentile(mags, 99))) if mags.size else 1.0
            sink.write(
                preview_panel(
                    frame,
                    flow,
                    depth_range_m=depth_range,
                    flow_max_px=flow_max_px if flow_max_px is not None else 1.0,
                    scale=scale,
                )
            )
        return sink.frames_written
