"""Synthetic sequences for the dataset tests (no rendering): a ray-cast square plate.

The plate (side ``2 * HALF_SIDE_M``, in the object x-y plane) moves with closed-form pose and
velocity; depth, masks and rgb are computed per pixel by intersecting each ray with the plate's
plane, and ground-truth flow comes from :func:`roft_sim.geometry.rigid_flow.rigid_flow`. A static
bar occludes part of the image, so the visible mask differs from the full silhouette.
"""

from __future__ import annotations

import numpy as np

from roft_sim.datasets.base import DetectorPoses, InMemorySequence, Sequence
from roft_sim.geometry.camera import CameraIntrinsics, pixel_grid
from roft_sim.geometry.rigid_flow import object_and_static_motions, rigid_flow
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import matrix_from_rotvec
from roft_sim.records import FlowField, ObjectModel, PoseTrack
from roft_sim.testing import assert_pose_close

HALF_SIDE_M = 0.07
WALL_DEPTH_M = 1.5
BAR_DEPTH_M = 0.4
OMEGA_RADPS = 2 * np.pi * 1.0
AMPLITUDE_M = np.array([0.08, 0.05, 0.03])
W_RADPS = np.array([0.8, -1.2, 3.0])
R0 = matrix_from_rotvec(np.array([0.3, -0.2, 0.1]))
P0_M = np.array([0.0, 0.0, 0.55])


def intrinsics(width_px: int = 64, height_px: int = 48) -> CameraIntrinsics:
    f = 1.4 * width_px
    return CameraIntrinsics(
        fx_px=f,
        fy_px=f,
        cx_px=(width_px - 1) / 2,
        cy_px=(height_px - 1) / 2,
        width_px=width_px,
        height_px=height_px,
    )


def plate_pose(t_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``T_cam_obj`` (4, 4), ``v_obj`` (3,) [m/s], ``w`` (3,) [rad/s] at time t (exact)."""
    p = P0_M + AMPLITUDE_M * np.sin(OMEGA_RADPS * t_s)
    v = AMPLITUDE_M * OMEGA_RADPS * np.cos(OMEGA_RADPS * t_s)
    R = matrix_from_rotvec(W_RADPS * t_s) @ R0  # dR/dt = [w]x R with constant w
    return transform_from_rt(R, p), v, W_RADPS.copy()


def render_plate(cam: CameraIntrinsics, T_cam_obj: np.ndarray, k: int):
    """rgb (H,W,3) u8, depth (H,W) f32, visible mask, full mask, body index (1 = plate)."""
    uv = pixel_grid(cam)
    d = np.stack(
        [(uv[..., 0] - cam.cx_px) / cam.fx_px, (uv[..., 1] - cam.cy_px) / cam.fy_px],
        axis=-1,
    )
    rays = np.concatenate([d, np.ones(d.shape[:2] + (1,))], axis=-1)
    R, t = T_cam_obj[:3, :3], T_cam_obj[:3, 3]
    n = R[:, 2]
    s = (n @ t) / (rays @ n)
    X = rays * s[..., None]
    local = (X - t) @ R
    full = (s > 0) & (np.abs(local[..., 0]) <= HALF_SIDE_M) & (np.abs(local[..., 1]) <= HALF_SIDE_M)
    bar = (uv[..., 0] >= cam.width_px * 0.6) & (uv[..., 1] < cam.height_px * 0.4)
    visible = full & ~bar
    depth = np.full(cam.shape, WALL_DEPTH_M)
    depth[visible] = s[visible]
    depth[bar] = BAR_DEPTH_M
    depth[: cam.height_px // 8, : cam.width_px // 8] = 0.0  # a hole: no measurement
    checker = ((np.floor(local[..., 0] / 0.02) + np.floor(local[..., 1] / 0.02)) % 2).astype(int)
    rgb = np.zeros(cam.shape + (3,), np.uint8)
    rgb[...] = (((uv[..., 0] * 7 + uv[..., 1] * 13 + k) % 50) + 30).astype(np.uint8)[..., None]
    rgb[visible] = np.where(checker[visible, None] == 1, [220, 40, 30], [30, 200, 60])
    rgb[bar] = [90, 90, 200]
    body = np.where(visible, 1, 0)
    return rgb, depth.astype(np.float32), visible, full, body


def plate_model() -> ObjectModel:
    h = HALF_SIDE_M
    vertices = np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]], dtype=np.float64)
    g = np.linspace(-h, h, 7)
    points = np.stack(np.meshgrid(g, g, [0.0]), axis=-1).reshape(-1, 3)
    return ObjectModel(
        name="plate",
        vertices_m=vertices,
        faces=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64),
        model_points_m=points,
    )


def plate_sequence(
    *,
    n_frames: int = 6,
    width_px: int = 64,
    height_px: int = 48,
    fps: int = 30,
    moving_camera: bool = False,
    with_gt: bool = True,
    nvof: bool = True,
    name: str = "plate_seq",
) -> InMemorySequence:
    """An in-memory sequence with gt and nvof-like flow, gt/full masks, a detector mask set
    (``mrcnn``, miss at frame 2) and a detector pose set (``dope``, miss at frame 3)."""
    cam = intrinsics(width_px, height_px)
    rng = np.random.default_rng(3)
    t = np.arange(n_frames) / fps
    poses = [plate_pose(ti) for ti in t]
    T = np.stack([p[0] for p in poses])
    frames = [render_plate(cam, T[k], k) for k in range(n_frames)]
    if moving_camera:
        T_wc = np.stack(
            [
                transform_from_rt(matrix_from_rotvec([0, 0.05 * k, 0]), [0.01 * k, 0, 0])
                for k in range(n_frames)
            ]
        )
    else:
        T_wc = np.broadcast_to(np.eye(4), (n_frames, 4, 4)).copy()
    gt_flow: list[FlowField | None] = [None]
    nvof_flow: list[FlowField | None] = [None]
    for k in range(1, n_frames):
        M = object_and_static_motions(T[k - 1], T[k], T_wc[k - 1], T_wc[k])
        flow, valid = rigid_flow(
            cam, frames[k - 1][1], frames[k - 1][4], M, depth_to_m=frames[k][1]
        )
        gt_flow.append(FlowField(flow_px=flow, from_k=k - 1, to_k=k, grid_px=1, valid=valid))
        coarse = (np.round(flow[::4, ::4].astype(np.float64) * 32) / 32 + 0.0).astype(np.float32)
        nvof_flow.append(FlowField(flow_px=coarse, from_k=k - 1, to_k=k, grid_px=4))
    det_masks = [f[2] & (rng.random(cam.shape) > 0.05) for f in frames]
    det_masks[min(2, n_frames - 1)] = None
    noise = np.stack(
        [
            transform_from_rt(matrix_from_rotvec(rng.normal(0, 0.02, 3)), rng.normal(0, 0.005, 3))
            for _ in range(n_frames)
        ]
    )
    det_T = T @ noise
    det_valid = np.ones(n_frames, bool)
    if n_frames > 3:
        det_valid[3] = False
        det_T[3] = np.eye(4)
    flows = {"gt": gt_flow}
    if nvof:
        flows["nvof_1_slow"] = nvof_flow
    gt = PoseTrack(
        t_s=t,
        T_cam_obj=T,
        v_obj_mps=np.stack([p[1] for p in poses]),
        w_radps=np.stack([p[2] for p in poses]),
    )
    return InMemorySequence(
        name=name,
        object_name="003_cracker_box",
        intrinsics=cam,
        fps=fps,
        rgb_frames=[f[0] for f in frames],
        depth_frames=[f[1] for f in frames],
        gt=gt if with_gt else None,
        gt_masks=[f[2] for f in frames] if with_gt else None,
        flows=flows,
        detector_masks={"mrcnn": det_masks},
        detector_pose_sets={"dope": DetectorPoses(T_cam_obj=det_T, valid=det_valid)},
        T_world_cam=T_wc,
        model=plate_model(),
        extra_metadata={"scenario": {"name": "plate"}, "seed": 3},
    )


def assert_sequences_equal(
    actual: Sequence,
    expected: Sequence,
    *,
    depth_atol_m: float = 0.0,
    atol_m: float = 1e-9,
    atol_rad: float = 1e-9,
    skip_mask_sets: tuple[str, ...] = (),
) -> None:
    """Every array bit-exactly equal (depth within ``depth_atol_m``), poses within tolerances."""
    assert len(actual) == len(expected)
    assert actual.intrinsics == expected.intrinsics
    assert actual.fps == expected.fps
    assert actual.object_name == expected.object_name
    assert set(actual.flow_sets()) == set(expected.flow_sets())
    exp_masks = [m for m in expected.mask_sets() if m not in skip_mask_sets]
    act_masks = [m for m in actual.mask_sets() if m not in skip_mask_sets]
    assert sorted(act_masks) == sorted(exp_masks)
    assert set(actual.pose_sets()) == set(expected.pose_sets())
    for k in range(len(expected)):
        assert actual.time_s(k) == expected.time_s(k)
        a, e = actual.rgb(k), expected.rgb(k)
        assert a.dtype == np.uint8 and np.array_equal(a, e), f"rgb {k}"
        a, e = actual.depth(k), expected.depth(k)
        assert a.dtype == np.float32 and a.shape == e.shape
        if depth_atol_m == 0.0:
            assert a.tobytes() == e.tobytes(), f"depth {k} not bit-exact"
        else:
            assert np.abs(a - e).max() <= depth_atol_m, f"depth {k}: {np.abs(a - e).max()}"
        for s in expected.flow_sets():
            fa, fe = actual.flow(k, s), expected.flow(k, s)
            if fe is None:
                assert fa is None
                continue
            assert fa.flow_px.dtype == np.float32
            assert fa.flow_px.tobytes() == fe.flow_px.tobytes(), f"flow {s} {k}"
            assert (fa.from_k, fa.to_k, fa.grid_px) == (fe.from_k, fe.to_k, fe.grid_px)
            if fe.valid is None:
                assert fa.valid is None
            else:
                assert np.array_equal(fa.valid, fe.valid), f"flow valid {s} {k}"
        for s in exp_masks:
            ma, me = actual.mask(k, s), expected.mask(k, s)
            if me is None:
                assert ma is None, f"mask {s} {k} should be a miss"
            else:
                assert ma.dtype == np.bool_ and np.array_equal(ma, me), f"mask {s} {k}"
    for s in expected.pose_sets():
        pa, pe = actual.detector_poses(s), expected.detector_poses(s)
        assert np.array_equal(pa.valid, pe.valid)
        assert_pose_close(
            pa.T_cam_obj[pe.valid], pe.T_cam_obj[pe.valid], atol_m=atol_m, atol_rad=atol_rad
        )
    ga, ge = actual.ground_truth(), expected.ground_truth()
    if ge is None:
        assert ga is None
    else:
        assert np.array_equal(ga.t_s, ge.t_s)
        assert_pose_close(ga.T_cam_obj, ge.T_cam_obj, atol_m=atol_m, atol_rad=atol_rad)
        np.testing.assert_allclose(ga.v_obj_mps, ge.v_obj_mps, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ga.w_radps, ge.w_radps, rtol=0, atol=1e-12)
    assert_pose_close(
        actual.camera_poses(), expected.camera_poses(), atol_m=atol_m, atol_rad=atol_rad
    )
    ma, me = actual.object_model(), expected.object_model()
    if me is None:
        assert ma is None
    else:
        assert np.array_equal(ma.model_points_m, me.model_points_m)
        assert np.array_equal(ma.faces, me.faces)
        np.testing.assert_allclose(ma.vertices_m, me.vertices_m, rtol=0, atol=1e-6)
