"""Builds Observation streams from an in-memory sequence and explicit delivery schedules.

A test-only stand-in for the fault stream: every pose and mask delivery is given as
(capture_k, arrival_k, detection_id[, override]), so tests control delays, order, duplicates and
drops exactly.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from hypothesis import settings

from roft_sim.datasets.base import InMemorySequence
from roft_sim.records import Estimate, FlowField, MaskDetection, Observation, PoseDetection
from roft_sim.testing.analytic_scene import AnalyticBoxDepthRenderer
from roft_sim.trackers.base import Tracker, TrackerContext


def scaled_examples(n: int) -> int:
    """``n`` examples under the default profile (60), proportionally more under ``thorough``."""
    return max(1, n * settings.default.max_examples // 60)


def make_context(seq: InMemorySequence, renderer: bool = True) -> TrackerContext:
    """The context of a tracker on ``seq``, with the analytic box depth renderer."""
    return TrackerContext(
        intrinsics=seq.intrinsics,
        fps=seq.fps,
        object_model=seq.object_model(),
        rng=np.random.default_rng(0),
        depth_renderer=AnalyticBoxDepthRenderer() if renderer else None,
    )


def run(tracker: Tracker, observations: Sequence[Observation], initial=None) -> list[Estimate]:
    tracker.reset(initial)
    return [tracker.step(o) for o in observations]


@dataclass(frozen=True)
class Delivery:
    capture_k: int
    arrival_k: int
    detection_id: int
    override: np.ndarray | None = None
    """A pose (4, 4) or mask (H, W) to deliver instead of the sequence's ground truth."""


def paper_schedule(n_frames: int, period: int = 6, delay: int = 6, first_id: int = 0):
    """Captures every ``period`` frames, delivered ``delay`` frames late; frame 0 undelayed."""
    out = []
    for i, c in enumerate(range(0, n_frames, period)):
        arrival = c if c == 0 else c + delay
        if arrival < n_frames:
            out.append(Delivery(c, arrival, first_id + i))
    return out


def build_observations(
    seq: InMemorySequence,
    *,
    poses: Iterable[Delivery] = (),
    masks: Iterable[Delivery] = (),
    flows: Sequence[FlowField | None] | None = None,
    flow_set: str = "gt",
    dropped_frames: Iterable[int] = (),
    pose_set: str = "gt",
) -> list[Observation]:
    """One Observation per frame of ``seq`` with the given deliveries (in the given order)."""
    n = len(seq)
    dropped = set(dropped_frames)
    flows = list(flows) if flows is not None else [seq.flow(k, flow_set) for k in range(n)]
    det = seq.detector_poses(pose_set)
    poses_at: dict[int, list[PoseDetection]] = {}
    for d in poses:
        T = d.override if d.override is not None else det.T_cam_obj[d.capture_k]
        poses_at.setdefault(d.arrival_k, []).append(
            PoseDetection(
                capture_k=d.capture_k,
                arrival_k=d.arrival_k,
                T_cam_obj=np.asarray(T, dtype=np.float64),
                detection_id=d.detection_id,
            )
        )
    masks_at: dict[int, list[MaskDetection]] = {}
    for d in masks:
        m = d.override if d.override is not None else seq.mask(d.capture_k, "gt")
        masks_at.setdefault(d.arrival_k, []).append(
            MaskDetection(
                capture_k=d.capture_k, arrival_k=d.arrival_k, mask=m, detection_id=d.detection_id
            )
        )
    out = []
    last_delivered = None
    for k in range(n):
        if k in dropped:
            flow = None
            rgb = depth = None
        else:
            rgb, depth = seq.rgb(k), seq.depth(k)
            flow = None
            if last_delivered is not None:
                if last_delivered == k - 1:
                    flow = flows[k]
                elif flows[k] is not None:
                    flow = _compose(flows, last_delivered, k)
            last_delivered = k
        out.append(
            Observation(
                k=k,
                t_s=seq.time_s(k),
                rgb=rgb,
                depth_m=depth,
                flow=flow,
                poses=tuple(poses_at.get(k, ())),
                masks=tuple(masks_at.get(k, ())),
            )
        )
    return out


def _compose(flows: Sequence[FlowField | None], from_k: int, to_k: int) -> FlowField | None:
    """Flow from_k -> to_k by chaining per-frame flows at rounded positions (approximate)."""
    first = flows[from_k + 1]
    if first is None:
        return None
    h, w = first.flow_px.shape[:2]
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    pu, pv = u.copy(), v.copy()
    valid = np.ones((h, w), bool)
    for j in range(from_k + 1, to_k + 1):
        f = flows[j]
        if f is None:
            return None
        iu = np.clip(np.rint(pu).astype(int), 0, w - 1)
        iv = np.clip(np.rint(pv).astype(int), 0, h - 1)
        vec = f.flow_px[iv, iu]
        if f.valid is not None:
            valid &= f.valid[iv, iu]
        pu += vec[..., 0]
        pv += vec[..., 1]
    flow = np.stack([pu - u, pv - v], axis=-1).astype(np.float32)
    return FlowField(flow_px=flow, from_k=from_k, to_k=to_k, valid=valid)
