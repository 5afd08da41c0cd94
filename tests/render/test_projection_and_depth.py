"""Rendered mask and depth against independent oracles: the pinhole projection of the mesh
(rasterised with OpenCV), trimesh's closest-point distance, and analytic planes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import trimesh
from stand_ins import (
    OFF_CENTRE_CAMERA,
    SMALL_CAMERA,
    SinusoidalTrajectory,
    grid_box_mesh,
    render_posed,
)

from roft_sim.geometry import backproject_depth, invert_transform, project_points, transform_points
from roft_sim.scene.config import BackgroundConfig, RenderConfig, SceneConfig, TableConfig

pytestmark = pytest.mark.render

OBJECT_ONLY = SceneConfig(
    table=TableConfig(enabled=False), background=BackgroundConfig(enabled=False)
)
MESH = grid_box_mesh(n=12, texture_px=256)
POSES = SinusoidalTrajectory().sample(np.array([0.0, 0.37, 1.1])).T_ref_obj


def silhouette_oracle(intrinsics, mesh, T_cam_obj, supersample: int = 9) -> np.ndarray:
    """Pixels whose CENTRE lies inside a projected triangle, by rasterising every triangle with
    OpenCV's fillPoly on a 9x finer grid (odd, so each pixel centre is a fine pixel centre:
    ``u_fine = 9 u + 4``) and sampling it at the pixel centres. fillPoly includes its edges, which
    grows the silhouette by at most 1/9 px. Triangles are filled one by one: one fillPoly call with
    many polygons would cancel their overlaps (even-odd rule)."""
    s = supersample
    uv = project_points(intrinsics, transform_points(T_cam_obj, mesh.vertices_m))
    fine = np.zeros((intrinsics.height_px * s, intrinsics.width_px * s), np.uint8)
    tris = np.rint(((uv[mesh.faces] + 0.5) * s - 0.5) * 256).astype(np.int32)
    for tri in tris:
        cv2.fillPoly(fine, [tri], 1, lineType=cv2.LINE_8, shift=8)
    return fine[s // 2 :: s, s // 2 :: s].astype(bool)


def visible_vertices(mesh, T_cam_obj) -> np.ndarray:
    """Vertices of front-facing triangles of the convex box (visibility without rendering)."""
    p = transform_points(T_cam_obj, mesh.vertices_m)
    tri = p[mesh.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    front = np.einsum("ij,ij->i", normal, tri[:, 0]) < 0
    return np.unique(mesh.faces[front].ravel())


@pytest.mark.parametrize("intrinsics", [SMALL_CAMERA, OFF_CENTRE_CAMERA], ids=["centred", "off"])
@pytest.mark.parametrize("msaa", [0, 4])
def test_mask_matches_the_projected_mesh(intrinsics, msaa):
    for T in POSES:
        built, out = render_posed(
            intrinsics, MESH, T, scene=OBJECT_ONLY, render=RenderConfig(msaa_samples=msaa)
        )
        mask = out.geom_id == built.object_geom_id
        oracle = silhouette_oracle(intrinsics, MESH, T)
        iou = (mask & oracle).sum() / (mask | oracle).sum()
        assert iou >= 0.98, f"IoU {iou:.4f}"
        # Every visible vertex projects into the mask (1 px slack for vertices ON the silhouette,
        # where the pixel centre may lie just outside the triangle).
        ids = visible_vertices(MESH, T)
        uv = project_points(intrinsics, transform_points(T, MESH.vertices_m[ids]))
        ij = np.rint(uv).astype(int)
        inside = (
            (ij[:, 0] >= 0)
            & (ij[:, 0] < intrinsics.width_px)
            & (ij[:, 1] >= 0)
            & (ij[:, 1] < intrinsics.height_px)
        )
        grown = cv2.dilate(mask.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        hit = grown[ij[inside, 1], ij[inside, 0]]
        assert hit.mean() >= 0.99, f"{hit.mean():.4f} of visible vertices in the mask"
        # ... and without slack for those at least 1.5 px inside the oracle silhouette.
        dist = cv2.distanceTransform(oracle.astype(np.uint8), cv2.DIST_L2, 5)
        deep = dist[ij[inside, 1], ij[inside, 0]] >= 1.5
        assert mask[ij[inside, 1], ij[inside, 0]][deep].all()


@pytest.mark.parametrize("intrinsics", [SMALL_CAMERA, OFF_CENTRE_CAMERA], ids=["centred", "off"])
def test_object_depth_lies_on_the_mesh_surface(intrinsics):
    surface = trimesh.Trimesh(MESH.vertices_m, MESH.faces, process=False)
    for T in POSES:
        built, out = render_posed(intrinsics, MESH, T, scene=OBJECT_ONLY)
        mask = out.geom_id == built.object_geom_id
        assert (out.depth_m[mask] > 0).all() and (out.depth_m[~mask] == 0).all()
        p_cam = backproject_depth(intrinsics, out.depth_m)[mask]
        p_cam = p_cam[np.random.default_rng(0).permutation(len(p_cam))[:400]]
        p_obj = transform_points(invert_transform(T), p_cam)
        _, distance, _ = trimesh.proximity.closest_point_naive(surface, p_obj)
        assert np.median(distance) < 1e-3, f"median {np.median(distance) * 1e3:.3f} mm"
        assert np.percentile(distance, 90) < 2e-3


def test_depth_is_z_depth_on_a_fronto_parallel_wall_and_the_table():
    """The wall at z = D must read D everywhere (z-depth, not distance along the ray); the table
    plane y = h reads Z = h fy / (v - cy) at row v."""
    intrinsics = OFF_CENTRE_CAMERA
    scene = SceneConfig(
        table=TableConfig(height_m=0.2, texture_px=64),
        background=BackgroundConfig(distance_m=1.3, texture_px=64),
    )
    far_away = np.eye(4)
    far_away[:3, 3] = [0.0, -50.0, 0.5]  # object out of view
    built, out = render_posed(intrinsics, MESH, far_away, scene=scene)
    body = built.geom_body[out.geom_id]
    wall = out.geom_id == built.model.geom("background").id
    table = out.geom_id == built.model.geom("table").id
    assert wall.sum() > 1000 and table.sum() > 100 and (body >= 0).all()
    np.testing.assert_allclose(out.depth_m[wall], 1.3, rtol=2e-6)
    rows = np.nonzero(table)[0].astype(float)
    expected = 0.2 * intrinsics.fy_px / (rows - intrinsics.cy_px)
    np.testing.assert_allclose(out.depth_m[table], expected, rtol=2e-5)


def test_object_alone_has_no_depth_elsewhere():
    T = POSES[1]
    built, out = render_posed(SMALL_CAMERA, MESH, T, scene=OBJECT_ONLY, segmentation=False)
    assert out.geom_id is None
    oracle = silhouette_oracle(SMALL_CAMERA, MESH, T)
    has_depth = out.depth_m > 0
    iou = (has_depth & oracle).sum() / (has_depth | oracle).sum()
    assert iou >= 0.98
