"""Analytic rigid flow: reprojection, stride composition, occlusion and forward-backward checks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from roft_sim.geometry import CameraIntrinsics, matrix_from_rotvec, transform_from_rt
from roft_sim.geometry.rigid_flow import object_and_static_motions, rigid_flow

CAM = CameraIntrinsics(
    fx_px=200.0, fy_px=200.0, cx_px=80.3, cy_px=59.7, width_px=160, height_px=120
)


def _plane_depth(z_m: float) -> np.ndarray:
    return np.full(CAM.shape, z_m, dtype=np.float32)


def test_pure_translation_parallel_to_image_gives_uniform_flow():
    depth = _plane_depth(1.0)
    M = transform_from_rt(np.eye(3), [0.01, -0.02, 0.0])
    flow, valid = rigid_flow(CAM, depth, np.zeros(CAM.shape, int), M[None])
    inner = valid.copy()
    assert inner[10:-10, 10:-10].all()
    np.testing.assert_allclose(
        flow[valid], np.broadcast_to([2.0, -4.0], flow[valid].shape), atol=1e-4
    )


def test_static_world_has_zero_flow_and_unknown_body_is_invalid():
    depth = _plane_depth(1.5)
    body = np.zeros(CAM.shape, int)
    body[:, :10] = -1
    flow, valid = rigid_flow(CAM, depth, body, object_and_static_motions(np.eye(4), np.eye(4)))
    assert not valid[:, :10].any() and valid[:, 10:].all()
    assert np.abs(flow).max() < 1e-9


def test_stride_two_equals_chained_point_motion():
    depth = _plane_depth(0.8)
    M1 = transform_from_rt(matrix_from_rotvec([0.0, 0.02, 0.01]), [0.01, 0.0, 0.005])
    M2 = transform_from_rt(matrix_from_rotvec([0.01, -0.01, 0.0]), [0.0, 0.01, -0.004])
    f2, v2 = rigid_flow(CAM, depth, np.zeros(CAM.shape, int), (M2 @ M1)[None])
    # track one interior pixel through both motions
    f1, _ = rigid_flow(CAM, depth, np.zeros(CAM.shape, int), M1[None])
    u, v = 70, 50
    X = np.array([(u - CAM.cx_px) / CAM.fx_px * 0.8, (v - CAM.cy_px) / CAM.fy_px * 0.8, 0.8])
    X2 = (M2 @ M1 @ np.append(X, 1))[:3]
    uv2 = [CAM.fx_px * X2[0] / X2[2] + CAM.cx_px, CAM.fy_px * X2[1] / X2[2] + CAM.cy_px]
    np.testing.assert_allclose(f2[v, u], np.array(uv2) - [u, v], atol=1e-4)
    assert v2[v, u]
    assert not np.allclose(f1[v, u], f2[v, u])


def test_occlusion_by_nearer_surface_is_invalid():
    depth = _plane_depth(1.0)
    M = transform_from_rt(np.eye(3), [0.05, 0.0, 0.0])
    depth_to = _plane_depth(1.0)
    depth_to[:, 100:] = 0.5  # something nearer covers the right part in the later frame
    flow, valid = rigid_flow(CAM, depth, np.zeros(CAM.shape, int), M[None], depth_to_m=depth_to)
    target_u = np.arange(CAM.width_px) + 10.0
    assert not valid[:, (target_u >= 99.5) & (target_u < 159.5)].any()
    assert valid[20:-20, 20:80].all()


def test_forward_backward_consistency():
    """Forward flow on a plane, then rigid_flow's BACKWARD flow (inverse motion, depth of the moved
    plane computed analytically) sampled where each pixel lands, brings it back."""
    z0 = 0.9
    depth = _plane_depth(z0)
    M = transform_from_rt(matrix_from_rotvec([0.01, 0.03, -0.02]), [0.02, -0.01, 0.03])
    body = np.zeros(CAM.shape, int)
    fwd, valid = rigid_flow(CAM, depth, body, M[None])
    # The plane z = z0 after the motion: normal n' = R e_z, offset d' = z0 + n' . t; a pixel's
    # ray r = K^-1 [u, v, 1] meets it at z-depth d' / (n' . r).
    n = M[:3, :3] @ [0.0, 0.0, 1.0]
    d = z0 + n @ M[:3, 3]
    v, u = np.mgrid[0 : CAM.height_px, 0 : CAM.width_px].astype(np.float64)
    rays = np.stack([(u - CAM.cx_px) / CAM.fx_px, (v - CAM.cy_px) / CAM.fy_px, np.ones_like(u)])
    depth_later = (d / np.einsum("i,ihw->hw", n, rays)).astype(np.float32)
    bwd, valid_bwd = rigid_flow(CAM, depth_later, body, np.linalg.inv(M)[None])
    rows, cols = np.nonzero(valid)
    tu, tv = cols + fwd[rows, cols, 0], rows + fwd[rows, cols, 1]
    keep = (tu >= 0) & (tu <= CAM.width_px - 1) & (tv >= 0) & (tv <= CAM.height_px - 1)
    rows, cols, tu, tv = rows[keep], cols[keep], tu[keep], tv[keep]
    # bilinear; the flow of a plane is smooth, so interpolation adds little
    back = np.stack([map_coordinates(bwd[..., i], [tv, tu], order=1) for i in range(2)], -1)
    corners = map_coordinates(valid_bwd.astype(float), [tv, tu], order=1) > 1 - 1e-9
    rows, cols, back = rows[corners], cols[corners], back[corners]
    err = np.linalg.norm(fwd[rows, cols] + back, axis=-1)
    assert len(err) > 0.8 * valid.size and np.abs(fwd[valid]).max() > 1.0
    assert err.max() < 1e-3, f"forward-backward error {err.max():.2e} px"


def test_later_depth_of_another_shape_is_a_clear_error():
    depth = _plane_depth(1.0)
    M = transform_from_rt(np.eye(3), [0.01, 0.0, 0.0])
    for shape in ((60, 80), (240, 320)):  # smaller: index error; larger: silently wrong pixels
        with pytest.raises(ValueError, match=r"depth_to_m \(\d+, \d+\) must match the camera"):
            rigid_flow(
                CAM, depth, np.zeros(CAM.shape, int), M[None], depth_to_m=np.ones(shape, np.float32)
            )


def _per_pixel_reference(cam, depth, body, motions, depth_to, tol=(0.005, 0.01)):
    """The textbook form, one pixel at a time in float64 (the oracle of the fast paths)."""
    flow = np.zeros(cam.shape + (2,))
    valid = np.zeros(cam.shape, bool)
    for r in range(cam.height_px):
        for c in range(cam.width_px):
            z, b = float(depth[r, c]), int(body[r, c])
            if z <= 0 or b < 0:
                continue
            X = np.array([(c - cam.cx_px) / cam.fx_px * z, (r - cam.cy_px) / cam.fy_px * z, z, 1])
            x, y, z_to = (motions[b] @ X)[:3]
            if z_to <= 0:
                continue
            u, v = cam.fx_px * x / z_to + cam.cx_px, cam.fy_px * y / z_to + cam.cy_px
            if not (-0.5 <= u < cam.width_px - 0.5 and -0.5 <= v < cam.height_px - 0.5):
                continue
            seen = float(depth_to[int(np.rint(v)), int(np.rint(u))])
            if 0 < seen < z_to - (tol[0] + tol[1] * z_to):
                continue
            flow[r, c] = (u - c, v - r)
            valid[r, c] = True
    return flow, valid


@pytest.mark.parametrize("static_moves", [False, True])
def test_box_and_identity_fast_paths_match_a_per_pixel_float64_reference(static_moves):
    """Interleaved bodies (overlapping bounding boxes), a still or moving static world, holes and
    an occluder: the float32 box/identity implementation agrees with the per-pixel oracle."""
    rng = np.random.default_rng(3)
    cam = CameraIntrinsics(
        fx_px=90.0, fy_px=95.0, cx_px=31.2, cy_px=23.9, width_px=64, height_px=48
    )
    depth = rng.uniform(0.6, 1.4, cam.shape).astype(np.float32)
    depth[rng.random(cam.shape) < 0.05] = 0.0
    body = np.zeros(cam.shape, int)
    body[10:30, 15:40] = 1
    body[15:35, 20:50][rng.random((20, 30)) < 0.5] = 2  # the hand's box overlaps the object's
    body[0:3, :] = -1
    depth_to = rng.uniform(0.6, 1.4, cam.shape).astype(np.float32)
    still = transform_from_rt(matrix_from_rotvec([0.0, 0.01, -0.02]), [0.01, 0.0, 0.002])
    motions = np.stack(
        [
            still if static_moves else np.eye(4),
            transform_from_rt(matrix_from_rotvec([0.05, -0.02, 0.03]), [0.03, -0.02, 0.05]),
            transform_from_rt(matrix_from_rotvec([-0.04, 0.03, 0.0]), [-0.02, 0.04, -0.03]),
        ]
    )
    flow, valid = rigid_flow(cam, depth, body, motions, depth_to_m=depth_to)
    ref_flow, ref_valid = _per_pixel_reference(cam, depth, body, motions, depth_to)
    # float32 may round a target onto the other side of a pixel edge: allow a handful
    assert np.count_nonzero(valid != ref_valid) <= 3
    assert ref_valid.sum() > 0.3 * valid.size
    both = valid & ref_valid
    np.testing.assert_allclose(flow[both], ref_flow[both], atol=2e-4)
    assert (flow[~valid] == 0).all()
    if not static_moves:
        assert (flow[body == 0] == 0).all()
