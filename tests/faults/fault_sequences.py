"""Tiny in-memory sequences and a stand-in flow source for the fault and stream tests."""

from __future__ import annotations

import dataclasses

import numpy as np

from roft_sim.datasets.base import DetectorPoses, InMemorySequence, Sequence
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import transform_from_pq
from roft_sim.records import FlowField, PoseTrack

W_PX, H_PX = 32, 24


def make_sequence(
    n_frames: int = 40,
    *,
    pose_miss: tuple[int, ...] = (),
    mask_miss: tuple[int, ...] = (),
    fps: int = 30,
    seed: int = 0,
) -> InMemorySequence:
    """A 32x24 sequence whose images encode their frame index (rgb[..., 0] == k % 256, depth
    == 0.5 + k / 1000 m), ground truth moving along x, detector poses = ground truth + 1 cm in
    z (so a test can tell detector from ground truth), masks = a 6x6 square moving 0.5 px/frame.
    """
    rng = np.random.default_rng(seed)
    K = CameraIntrinsics(
        fx_px=30.0, fy_px=30.0, cx_px=15.5, cy_px=11.5, width_px=W_PX, height_px=H_PX
    )
    rgb = [np.full((H_PX, W_PX, 3), k % 256, dtype=np.uint8) for k in range(n_frames)]
    for image in rgb:
        image[..., 1] = rng.integers(0, 255, size=(H_PX, W_PX), dtype=np.uint8)
    depth = [np.full((H_PX, W_PX), 0.5 + k / 1000.0, dtype=np.float32) for k in range(n_frames)]
    t = np.arange(n_frames) / fps
    p = np.stack([0.01 * np.arange(n_frames), np.zeros(n_frames), np.full(n_frames, 0.6)], 1)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n_frames, 1))
    T_gt = transform_from_pq(p, q)
    gt = PoseTrack(
        t_s=t,
        T_cam_obj=T_gt,
        v_obj_mps=np.tile([0.3, 0.0, 0.0], (n_frames, 1)),
        w_radps=np.zeros((n_frames, 3)),
    )
    T_det = T_gt.copy()
    T_det[:, 2, 3] += 0.01
    valid = np.ones(n_frames, dtype=bool)
    valid[list(pose_miss)] = False
    T_det[~valid] = np.eye(4)
    masks = []
    for k in range(n_frames):
        m = np.zeros((H_PX, W_PX), dtype=bool)
        u0 = 4 + k // 2 % 20
        m[9:15, u0 : u0 + 6] = True
        masks.append(m)
    detector_masks = [None if k in mask_miss else masks[k].copy() for k in range(n_frames)]
    return InMemorySequence(
        name="tiny",
        object_name="003_cracker_box",
        intrinsics=K,
        fps=fps,
        rgb_frames=rgb,
        depth_frames=depth,
        gt=gt,
        gt_masks=masks,
        detector_masks={"mrcnn": detector_masks},
        detector_pose_sets={"dope": DetectorPoses(T_cam_obj=T_det, valid=valid)},
    )


@dataclasses.dataclass
class StrideFlowSource:
    """Stand-in for roft_sim.sensors flow sources: a constant flow of ``(to_k - from_k, 0)`` px
    (one pixel per frame to the right), recording every request."""

    name: str = "stride-test"
    calls: list = dataclasses.field(default_factory=list)

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField | None:
        self.calls.append((from_k, to_k))
        h, w = sequence.intrinsics.shape
        f = np.zeros((h, w, 2), dtype=np.float32)
        f[..., 0] = to_k - from_k
        return FlowField(flow_px=f, from_k=from_k, to_k=to_k)
