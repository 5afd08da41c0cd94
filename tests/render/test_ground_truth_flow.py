"""Ground-truth flow and velocity against independent oracles: image warping, forward-backward
consistency, OpenCV's DIS flow, ROFT's linear flow model, finite differences of the poses, and
the analytic wall plane seen by a moving camera."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from stand_ins import SinusoidalTrajectory, grid_box_mesh, open_renderer, small_scenario

from roft_sim.geometry import (
    backproject_pixels,
    invert_transform,
    project_points,
    rotvec_from_matrix,
    transform_points,
)
from roft_sim.render import ground_truth_flow
from roft_sim.scenario import CameraConfig
from roft_sim.scene.config import BackgroundConfig, CameraSwayConfig, SceneConfig, TableConfig

pytestmark = pytest.mark.render

UNLIT = SceneConfig(
    table=TableConfig(texture_px=256, height_m=0.25),
    background=BackgroundConfig(texture_px=256, distance_m=1.2),
    lights=(),
    ambient=1.0,
)
"""Unlit (ambient only): shading does not change as the object turns, so image differences come
from motion alone (ground-truth flow is a motion field and knows nothing of shading)."""


def _smooth_box():
    """The textured stand-in with its texture blurred to about one rendered pixel, so that
    bilinear resampling of the image is accurate (the photometric test measures geometry, not
    aliasing)."""
    mesh = grid_box_mesh(texture_px=512)
    return dataclasses.replace(mesh, texture_rgb=cv2.GaussianBlur(mesh.texture_rgb, (0, 0), 8))


def _grid(shape):
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float32)
    return xx, yy


def _erode(mask, px=1):
    k = np.ones((2 * px + 1, 2 * px + 1), np.uint8)
    return cv2.erode(mask.astype(np.uint8), k).astype(bool)


@pytest.fixture(scope="module")
def unlit_frames():
    scenario = small_scenario(scene=UNLIT)
    with open_renderer(scenario, mesh=_smooth_box()) as r:
        return scenario, [r.render_frame(k) for k in (4, 5, 6)]


@pytest.fixture(scope="module")
def lit_frames():
    scenario = small_scenario()
    with open_renderer(scenario) as r:
        return scenario, [r.render_frame(k) for k in (4, 5)]


def test_warping_by_ground_truth_flow_reproduces_the_next_image(unlit_frames):
    scenario, (f0, f1, _) = unlit_frames
    flow = ground_truth_flow(f0, f1, scenario.intrinsics)
    xx, yy = _grid(f0.shape)
    inner_later = _erode(f1.object_mask)

    def photometric_error(shift_px: float) -> float:
        mx = xx + flow.flow_px[..., 0] + shift_px
        my = yy + flow.flow_px[..., 1]
        warped = cv2.remap(f1.rgb, mx, my, cv2.INTER_LINEAR)
        tgt = inner_later[
            np.clip(np.rint(my).astype(int), 0, f0.shape[0] - 1),
            np.clip(np.rint(mx).astype(int), 0, f0.shape[1] - 1),
        ]
        sel = flow.valid & f0.object_mask & tgt
        assert sel.sum() > 500
        return float(np.abs(warped.astype(float) - f0.rgb)[sel].mean())

    sel = flow.valid & f0.object_mask
    unwarped = float(np.abs(f1.rgb.astype(float) - f0.rgb)[sel].mean())
    exact = photometric_error(0.0)
    assert exact < 0.2 * unwarped, f"warped {exact:.2f} vs unwarped {unwarped:.2f} grey levels"
    # The ground truth is where the error is smallest: a third of a pixel off is clearly worse.
    assert exact < 0.7 * min(photometric_error(0.3), photometric_error(-0.3))


def test_forward_backward_consistency(unlit_frames):
    scenario, (f0, f1, _) = unlit_frames
    fwd = ground_truth_flow(f0, f1, scenario.intrinsics)
    bwd = ground_truth_flow(f1, f0, scenario.intrinsics)
    assert (bwd.from_k, bwd.to_k) == (f1.k, f0.k)
    xx, yy = _grid(f0.shape)
    mx, my = xx + fwd.flow_px[..., 0], yy + fwd.flow_px[..., 1]
    back = cv2.remap(bwd.flow_px, mx, my, cv2.INTER_LINEAR)

    # Non-occluded pixels whose four bilinear neighbours in the later frame are valid backward
    # and show the same body (interpolating across bodies mixes unrelated flows).
    def all_neighbours(mask):
        return cv2.remap(mask.astype(np.float32), mx, my, cv2.INTER_LINEAR) > 0.999

    same_body = np.zeros(f0.shape, bool)
    for b in range(len(f0.body_names)):
        same_body |= (f0.body_index == b) & all_neighbours(f1.body_index == b)
    ok = fwd.valid & all_neighbours(bwd.valid) & same_body
    assert ok.sum() > 0.8 * f0.shape[0] * f0.shape[1]
    err = np.linalg.norm(fwd.flow_px + back, axis=-1)
    assert np.percentile(err[ok], 99) < 0.05, f"p99 {np.percentile(err[ok], 99):.4f} px"
    assert np.median(err[ok]) < 0.005
    obj = ok & f0.object_mask
    assert obj.sum() > 500
    assert np.percentile(err[obj], 95) < 0.05, f"object p95 {np.percentile(err[obj], 95):.4f}"


def test_flow_of_any_stride_composes(unlit_frames):
    """Stride 2 equals stride 1 followed by stride 1 (sampled where the pixel lands)."""
    scenario, (f0, f1, f2) = unlit_frames
    k = scenario.intrinsics
    f01, f12, f02 = (ground_truth_flow(a, b, k) for a, b in ((f0, f1), (f1, f2), (f0, f2)))
    assert f02.stride == 2
    xx, yy = _grid(f0.shape)
    mx, my = xx + f01.flow_px[..., 0], yy + f01.flow_px[..., 1]
    second = cv2.remap(f12.flow_px, mx, my, cv2.INTER_LINEAR)
    ok = f01.valid & f02.valid & (cv2.remap(f12.valid.astype(np.float32), mx, my, 1) > 0.999)
    err = np.linalg.norm(f01.flow_px + second - f02.flow_px, axis=-1)[ok & f0.object_mask]
    assert err.size > 300 and np.percentile(err, 95) < 0.05


def test_dis_optical_flow_agrees_on_the_object(lit_frames):
    scenario, (f0, f1) = lit_frames
    gt = ground_truth_flow(f0, f1, scenario.intrinsics)
    grey = [cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY) for f in (f0, f1)]
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(*grey, None)
    inner = _erode(f0.object_mask, 2) & gt.valid
    epe = np.linalg.norm(dis - gt.flow_px, axis=-1)[inner]
    speed = np.linalg.norm(gt.flow_px[inner], axis=-1)
    assert np.median(speed) > 0.5  # the object does move
    assert np.median(epe) < 1.0, f"DIS median end-point error {np.median(epe):.3f} px"


def _roft_linear_flow(intrinsics, depth, rows, cols, v_o, w, dt):
    """ROFT's measurement model (roft_reference.md 3.2), written out independently."""
    fx, fy = intrinsics.fx_px, intrinsics.fy_px
    u = cols - intrinsics.cx_px
    v = rows - intrinsics.cy_px
    Z = depth[rows, cols].astype(np.float64)
    twist = np.concatenate([v_o, w])
    row_x = np.stack([fx / Z, 0 * Z, -u / Z, -u * v / fy, fx + u * u / fx, -v * fx / fy], axis=-1)
    row_y = np.stack([0 * Z, fy / Z, -v / Z, -(fy + v * v / fy), u * v / fx, u * fy / fx], axis=-1)
    return dt * np.stack([row_x @ twist, row_y @ twist], axis=-1)


def test_roft_linear_flow_model_predicts_ground_truth_flow_better_for_shorter_intervals():
    trajectory = SinusoidalTrajectory()
    relative_errors = []
    for fps in (30, 120):
        camera = CameraConfig(
            width_px=160, height_px=120, fx_px=180.0, fy_px=180.0, cx_px=79.5, cy_px=59.5, fps=fps
        )
        scenario = small_scenario(camera=camera, frames=fps)
        k = int(round(0.4 * fps))  # same start time 0.4 s for both rates
        with open_renderer(scenario, trajectory=trajectory) as r:
            f0, f1 = r.render_frame(k), r.render_frame(k + 1)
        gt = ground_truth_flow(f0, f1, scenario.intrinsics)
        rows, cols = np.nonzero(f0.object_mask & gt.valid)
        predicted = _roft_linear_flow(
            scenario.intrinsics, f0.depth_m, rows, cols, f0.v_o_mps, f0.w_radps, 1.0 / fps
        )
        actual = gt.flow_px[rows, cols]
        err = np.linalg.norm(predicted - actual, axis=-1)
        relative_errors.append(np.median(err) / np.median(np.linalg.norm(actual, axis=-1)))
    coarse, fine = relative_errors
    # First-order model: the relative error shrinks about in proportion to the interval (4x).
    assert coarse < 0.15, f"relative error at 30 fps {coarse:.3f}"
    assert fine < 0.5 * coarse, f"relative errors {coarse:.4f} (30 fps) -> {fine:.4f} (120 fps)"


def test_velocities_are_derivatives_of_the_relative_pose_also_with_a_moving_camera():
    camera = CameraConfig(
        width_px=160,
        height_px=120,
        fx_px=180.0,
        fy_px=180.0,
        cx_px=79.5,
        cy_px=59.5,
        motion=CameraSwayConfig(amplitude_m=(0.04, 0.02, 0.03), amplitude_rad=(0.05, 0.08, 0.04)),
    )
    scenario = small_scenario(camera=camera)
    with open_renderer(scenario) as r:
        h = 1e-5
        for t in (0.2, 0.9):
            s, sp, sm = r.state_at(t), r.state_at(t + h), r.state_at(t - h)
            v_fd = (sp.T_cam_obj[:3, 3] - sm.T_cam_obj[:3, 3]) / (2 * h)
            R_p, R_m = sp.T_cam_obj[:3, :3], sm.T_cam_obj[:3, :3]
            w_fd = rotvec_from_matrix(R_p @ R_m.T) / (2 * h)
            np.testing.assert_allclose(s.v_obj_mps, v_fd, atol=1e-7)
            np.testing.assert_allclose(s.w_radps, w_fd, atol=1e-7)
        f = r.render_frame(3)
    np.testing.assert_allclose(
        f.v_o_mps, f.v_obj_mps - np.cross(f.w_radps, f.T_cam_obj[:3, 3]), atol=1e-15
    )
    assert not np.allclose(f.T_world_cam, np.eye(4))


def test_moving_camera_gives_background_flow_that_matches_the_wall_geometry():
    """Independent of rendered depth and of the flow code: intersect each wall pixel's ray with
    the analytic wall plane z_world = D, move the point to the later camera, project it."""
    distance = 1.2
    camera = CameraConfig(
        width_px=160,
        height_px=120,
        fx_px=180.0,
        fy_px=180.0,
        cx_px=70.2,
        cy_px=64.9,
        motion=CameraSwayConfig(amplitude_m=(0.05, 0.03, 0.04), amplitude_rad=(0.06, 0.08, 0.03)),
    )
    scenario = small_scenario(camera=camera, scene=UNLIT)
    with open_renderer(scenario) as r:
        f0, f1 = r.render_frame(6), r.render_frame(7)
        wall_id = r.model.geom("background").id
    gt = ground_truth_flow(f0, f1, scenario.intrinsics)
    wall = (f0.segmentation == wall_id) & gt.valid
    assert wall.sum() > 3000
    rows, cols = np.nonzero(wall)
    uv = np.stack([cols, rows], axis=-1).astype(np.float64)
    ray_cam = backproject_pixels(scenario.intrinsics, uv, np.ones(len(uv)))
    T0, T1 = f0.T_world_cam, f1.T_world_cam
    ray_world = ray_cam @ T0[:3, :3].T
    origin = T0[:3, 3]
    s = (distance - origin[2]) / ray_world[:, 2]
    X_world = origin + s[:, None] * ray_world
    uv1 = project_points(scenario.intrinsics, transform_points(invert_transform(T1), X_world))
    expected = uv1 - uv
    speed = np.linalg.norm(expected, axis=-1)
    assert np.median(speed) > 0.3  # the background does move
    np.testing.assert_allclose(gt.flow_px[rows, cols], expected, atol=2e-3)
    # and OpenCV's DIS sees the same background motion
    grey = [cv2.cvtColor(f.rgb, cv2.COLOR_RGB2GRAY) for f in (f0, f1)]
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(*grey, None)
    inner = _erode(wall, 3)
    assert np.median(np.linalg.norm(dis - gt.flow_px, axis=-1)[inner]) < 0.5


def test_static_camera_has_zero_background_flow(lit_frames):
    scenario, (f0, f1) = lit_frames
    gt = ground_truth_flow(f0, f1, scenario.intrinsics)
    static = (f0.body_index == 0) & gt.valid
    assert static.sum() > 5000 and np.abs(gt.flow_px[static]).max() < 1e-9
    assert not gt.valid[f0.body_index < 0].any()
