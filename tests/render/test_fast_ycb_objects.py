"""The six Fast-YCB objects (real YCB meshes from ../shared/ycb and the procedural stand-ins) in
their Fast-YCB scenarios, rendered at 640x360: silhouette, depth and flow against oracles.
Slow: about 3 s per object."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from roft_sim.assets import load_object
from roft_sim.assets.registry import FAST_YCB_OBJECTS
from roft_sim.geometry import backproject_depth, invert_transform, project_points, transform_points
from roft_sim.render import SceneRenderer, ground_truth_flow
from roft_sim.scenario import load_scenario

pytestmark = [pytest.mark.render, pytest.mark.slow]

REPO = Path(__file__).resolve().parents[2]
OBJECTS = FAST_YCB_OBJECTS
FRAMES = (45, 205, 365, 525, 685)


def _silhouette(intrinsics, vertices, faces, T_cam_obj, s=5):
    """Pixels whose centre is inside a projected triangle (fillPoly per triangle on a 5x grid)."""
    uv = project_points(intrinsics, transform_points(T_cam_obj, vertices))
    fine = np.zeros((intrinsics.height_px * s, intrinsics.width_px * s), np.uint8)
    for tri in np.rint(((uv[faces] + 0.5) * s - 0.5) * 256).astype(np.int32):
        cv2.fillPoly(fine, [tri], 1, cv2.LINE_8, 8)
    return fine[s // 2 :: s, s // 2 :: s].astype(bool)


def _surface_distance(vertices, faces, points):
    """Exact point-to-mesh distance over the 16 triangles with the nearest centroids."""
    k = min(16, len(faces))
    _, idx = cKDTree(vertices[faces].mean(axis=1)).query(points, k=k)
    idx = np.asarray(idx).reshape(len(points), k)
    repeated = np.repeat(points, k, axis=0)
    closest = trimesh.triangles.closest_point(vertices[faces[idx.ravel()]], repeated)
    return np.linalg.norm(closest - repeated, axis=1).reshape(-1, k).min(axis=1)


def _check_object(name: str, assets) -> None:
    scenario = load_scenario(REPO / "scenarios" / "fast_ycb" / f"{name}.toml")
    k = scenario.intrinsics.resized(640, 360)
    camera = dataclasses.replace(
        scenario.camera,
        width_px=k.width_px,
        height_px=k.height_px,
        fx_px=k.fx_px,
        fy_px=k.fy_px,
        cx_px=k.cx_px,
        cy_px=k.cy_px,
    )
    scenario = dataclasses.replace(scenario, camera=camera)
    vertices, faces = assets.model.vertices_m, assets.model.faces
    dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
    epes = []
    with SceneRenderer(scenario, object_assets=assets) as renderer:
        for f in FRAMES:
            f0, f1 = renderer.render_frame(f), renderer.render_frame(f + 1)
            mask = f0.object_mask
            assert mask.sum() > 300, f"frame {f}: object barely visible"
            oracle = _silhouette(k, vertices, faces, f0.T_cam_obj)
            iou = (mask & oracle).sum() / (mask | oracle).sum()
            assert iou >= 0.98, f"{name} frame {f}: IoU {iou:.4f}"
            points = backproject_depth(k, f0.depth_m)[mask]
            points = points[np.random.default_rng(0).permutation(len(points))[:1000]]
            obj = transform_points(invert_transform(f0.T_cam_obj), points)
            assert np.median(_surface_distance(vertices, faces, obj)) < 1e-3
            gt = ground_truth_flow(f0, f1, k)
            grey = [cv2.cvtColor(x.rgb, cv2.COLOR_RGB2GRAY) for x in (f0, f1)]
            flow = dis.calc(grey[0], grey[1], None)
            inner = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
            inner &= gt.valid
            epes.append(np.median(np.linalg.norm(flow - gt.flow_px, axis=-1)[inner]))
    assert np.median(epes) < 1.0, f"{name}: DIS median end-point errors {np.round(epes, 3)} px"


@pytest.mark.parametrize("name", OBJECTS)
def test_real_ycb_mesh_silhouette_depth_and_flow(name, shared_ycb_dir):
    assets = load_object(name, assets_dir=shared_ycb_dir, prefer="ycb")
    assert assets.source == "ycb"
    _check_object(name, assets)


@pytest.mark.parametrize("name", OBJECTS)
def test_procedural_stand_in_silhouette_depth_and_flow(name):
    assets = load_object(name, prefer="procedural")
    assert assets.source == "procedural"
    _check_object(name, assets)
