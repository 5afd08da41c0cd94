"""The renderer-free analytic box stream: exact depth, mask, velocities, flow and depth renderer."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.errors import ConfigError
from roft_sim.geometry import (
    backproject_pixels,
    invert_transform,
    project_points,
    rotvec_from_matrix,
    transform_from_rt,
    transform_points,
)
from roft_sim.testing.analytic_scene import (
    AnalyticBox,
    AnalyticBoxDepthRenderer,
    AnalyticMotion,
    analytic_box_sequence,
    default_intrinsics,
    raycast_box,
)


def test_fronto_parallel_face_depth_is_exact():
    cam = default_intrinsics(64, 48)
    box = AnalyticBox(size_m=(0.1, 0.08, 0.06))
    T = transform_from_rt(np.eye(3), [0.0, 0.0, 0.5])
    depth, face, hit = raycast_box(box.half_extents_m, T, cam)
    v, u = 24, 32
    assert depth[v, u] == pytest.approx(0.5 - 0.03, abs=1e-12)
    assert face[v, u] == 4  # the -z face (axis 2, negative side)
    assert hit[v, u, 2] == pytest.approx(-0.03, abs=1e-12)
    # silhouette width: |X| <= 0.05 at Z = 0.47 -> |u - cx| <= fx * 0.05 / 0.47
    cols = np.flatnonzero(depth[v] > 0)
    half_width_px = cam.fx_px * 0.05 / 0.47
    assert cols.min() == int(np.ceil(cam.cx_px - half_width_px))
    assert cols.max() == int(np.floor(cam.cx_px + half_width_px))


def test_mask_pixels_backproject_onto_the_box_surface(small_seq):
    k = 11
    mask = small_seq.mask(k, "gt")
    v, u = np.nonzero(mask)
    X = backproject_pixels(small_seq.intrinsics, np.stack([u, v], 1), small_seq.depth(k)[v, u])
    p_obj = transform_points(invert_transform(small_seq.gt.T_cam_obj[k]), X)
    h = AnalyticBox().half_extents_m
    # every point is on a face: its largest normalised coordinate is 1 (float32 depth)
    assert np.abs(np.max(np.abs(p_obj) / h, axis=1) - 1.0).max() < 2e-5
    assert not (small_seq.depth(k)[~mask] < 1.2 - 1e-6).any()  # the rest is the wall


def test_velocities_are_the_derivatives_of_the_poses():
    motion = AnalyticMotion()
    eps = 1e-6
    t = np.array([0.1, 0.77, 1.5])
    a, b, c = motion.track(t - eps), motion.track(t), motion.track(t + eps)
    v_fd = (c.T_cam_obj[:, :3, 3] - a.T_cam_obj[:, :3, 3]) / (2 * eps)
    w_fd = rotvec_from_matrix(
        c.T_cam_obj[:, :3, :3] @ np.swapaxes(a.T_cam_obj[:, :3, :3], 1, 2)
    ) / (2 * eps)
    np.testing.assert_allclose(b.v_obj_mps, v_fd, atol=1e-7)
    np.testing.assert_allclose(b.w_radps, w_fd, atol=1e-6)


def test_motion_is_fast(small_seq):
    speed = np.linalg.norm(small_seq.gt.v_obj_mps, axis=1)
    spin = np.linalg.norm(small_seq.gt.w_radps, axis=1)
    assert speed.max() > 0.3 and spin.max() > 3.0  # m/s, rad/s: Fast-YCB-like


def test_gt_flow_moves_surface_points_to_their_projection(small_seq):
    k = 20
    cam = small_seq.intrinsics
    flow = small_seq.flow(k, "gt")
    assert (flow.from_k, flow.to_k) == (k - 1, k)
    v, u = np.nonzero(flow.valid & small_seq.mask(k - 1, "gt"))
    X = backproject_pixels(cam, np.stack([u, v], 1), small_seq.depth(k - 1)[v, u])
    T0, T1 = small_seq.gt.T_cam_obj[k - 1], small_seq.gt.T_cam_obj[k]
    uv1 = project_points(cam, transform_points(T1 @ invert_transform(T0), X))
    np.testing.assert_allclose(np.stack([u, v], 1) + flow.flow_px[v, u], uv1, atol=2e-3)
    assert len(u) > 0.8 * small_seq.mask(k - 1, "gt").sum()


def test_depth_renderer_matches_the_sequence_depth(small_seq):
    k = 7
    out = AnalyticBoxDepthRenderer().render_depth(
        small_seq.gt.T_cam_obj[[k, k]], small_seq.intrinsics
    )
    assert out.shape == (2, 120, 160) and out.dtype == np.float32
    mask = small_seq.mask(k, "gt")
    np.testing.assert_array_equal(out[0][mask], small_seq.depth(k)[mask])
    assert (out[0][~mask] == 0).all()
    with pytest.raises(ValueError, match=r"shape \(N, 4, 4\)"):
        AnalyticBoxDepthRenderer().render_depth(np.eye(4), small_seq.intrinsics)


def test_sequence_carries_gt_sets(tiny_seq):
    assert tiny_seq.mask_sets() == ("gt",) and tiny_seq.flow_sets() == ("gt",)
    assert tiny_seq.flow(0, "gt") is None
    det = tiny_seq.detector_poses("gt")
    np.testing.assert_array_equal(det.T_cam_obj, tiny_seq.gt.T_cam_obj)
    assert tiny_seq.object_model().model_points_m.shape[1] == 3


def test_bad_inputs_say_what_is_wrong():
    with pytest.raises(ConfigError, match="three positive lengths"):
        AnalyticBox(size_m=(0.1, -0.1, 0.1))
    with pytest.raises(ConfigError, match="closer than 5 cm"):
        analytic_box_sequence(n_frames=2, motion=AnalyticMotion(center_m=(0.0, 0.0, 0.05)))
    with pytest.raises(ConfigError, match="n_frames >= 1"):
        analytic_box_sequence(n_frames=0)
