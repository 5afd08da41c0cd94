"""MujocoDepthRenderer: the DepthRenderer protocol, object alone, any intrinsics."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from stand_ins import (
    OFF_CENTRE_CAMERA,
    SMALL_CAMERA,
    SinusoidalTrajectory,
    grid_box_mesh,
    render_posed,
)

from roft_sim.records import DepthRenderer, ObjectModel
from roft_sim.render import MujocoDepthRenderer
from roft_sim.scene.config import BackgroundConfig, SceneConfig, TableConfig

pytestmark = pytest.mark.render

MESH = grid_box_mesh(n=6, texture_px=64)
POSES = SinusoidalTrajectory().sample(np.array([0.1, 0.6, 1.3])).T_ref_obj
OBJECT_ONLY = SceneConfig(
    table=TableConfig(enabled=False), background=BackgroundConfig(enabled=False), lights=()
)


def _model() -> ObjectModel:
    return ObjectModel(
        name="box",
        vertices_m=MESH.vertices_m,
        faces=MESH.faces,
        model_points_m=MESH.vertices_m[::7],
    )


def test_matches_the_scene_render_of_the_object_alone_for_any_intrinsics():
    with MujocoDepthRenderer(_model()) as renderer:
        assert isinstance(renderer, DepthRenderer)
        for intrinsics in (SMALL_CAMERA, OFF_CENTRE_CAMERA, SMALL_CAMERA):
            depth = renderer.render_depth(POSES, intrinsics)
            assert depth.shape == (3, *intrinsics.shape) and depth.dtype == np.float32
            for i, T in list(enumerate(POSES))[1:]:
                _, out = render_posed(intrinsics, MESH, T, scene=OBJECT_ONLY)
                np.testing.assert_allclose(depth[i], out.depth_m, atol=1e-6)
        # a different image size builds a second scene
        half = dataclasses.replace(SMALL_CAMERA.resized(80, 60), cx_px=30.0)
        small = renderer.render_depth(POSES[0], half)
        _, out = render_posed(half, MESH, POSES[0], scene=OBJECT_ONLY)
        assert small.shape == (1, 60, 80)
        np.testing.assert_allclose(small[0], out.depth_m, atol=1e-6)


def test_accepts_assets_with_a_mesh_and_rejects_bad_poses():
    class Assets:
        mesh = MESH

    with MujocoDepthRenderer(Assets()) as renderer:
        depth = renderer.render_depth(POSES[:1], SMALL_CAMERA)
        assert (depth > 0).sum() > 300
        behind = POSES[0].copy()
        behind[2, 3] = -1.0
        assert not renderer.render_depth(behind, SMALL_CAMERA).any()
        with pytest.raises(ValueError, match="4, 4"):
            renderer.render_depth(np.eye(3), SMALL_CAMERA)


def test_silhouette_reads_only_the_box_and_equals_the_depth_above_zero(monkeypatch):
    import mujoco

    read_shapes = []
    read_pixels = mujoco.mjr_readPixels

    def spy(rgb, depth, viewport, context):
        read_shapes.append(None if depth is None else depth.shape)
        return read_pixels(rgb, depth, viewport, context)

    monkeypatch.setattr(mujoco, "mjr_readPixels", spy)
    poses = list(SinusoidalTrajectory().sample(np.linspace(0.0, 2.0, 9)).T_ref_obj)
    # cut by the image's border, close, and with a corner in front of the near plane
    for dx_m, dz_m in ((0.3, 0.0), (0.0, -0.45), (0.0, -0.53)):
        T = poses[0].copy()
        T[0, 3] += dx_m
        T[2, 3] += dz_m
        poses.append(T)
    with MujocoDepthRenderer(_model()) as renderer:
        for camera in (SMALL_CAMERA, OFF_CENTRE_CAMERA):
            for T in poses:
                expected = renderer.render_depth(T, camera)[0] > 0
                read_shapes.clear()
                got = renderer.render_silhouette(T, camera)
                np.testing.assert_array_equal(got, expected)
                assert len(read_shapes) <= 1
    with MujocoDepthRenderer(_model()) as renderer:
        assert renderer._box_px(poses[-1], SMALL_CAMERA) is None  # a corner before the near plane
        assert renderer.render_silhouette(poses[-1], SMALL_CAMERA).any()
        read_shapes.clear()
        renderer.render_silhouette(poses[0], SMALL_CAMERA)
        (shape,) = read_shapes
        assert shape[0] * shape[1] < SMALL_CAMERA.width_px * SMALL_CAMERA.height_px / 2
