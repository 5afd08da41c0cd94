"""The MjSpec scene builder: what it compiles (no rendering needed)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.render.camera import intrinsics_from_mujoco_camera
from roft_sim.render.scene_builder import HAND_BODY, OBJECT_BODY, STATIC_BODY, build_scene
from roft_sim.scene.config import (
    BackgroundConfig,
    HandConfig,
    RenderConfig,
    SceneConfig,
    TableConfig,
)

CAMERA = CameraIntrinsics(
    fx_px=100.0, fy_px=110.0, cx_px=30.2, cy_px=27.9, width_px=64, height_px=48
)
SMALL_TEXTURES = SceneConfig(
    table=TableConfig(texture_px=32), background=BackgroundConfig(texture_px=32)
)


class _Mesh:
    def __init__(self, with_texture: bool = True) -> None:
        box = trimesh.creation.box(extents=(0.1, 0.06, 0.2))
        self.vertices_m = np.asarray(box.vertices, dtype=np.float64)
        self.faces = np.asarray(box.faces, dtype=np.int64)
        if with_texture:
            self.uv = np.random.default_rng(0).uniform(size=(len(self.vertices_m), 2))
            self.texture_rgb = np.full((8, 8, 3), 200, np.uint8)


def _build(scene=SMALL_TEXTURES, render=None, mesh=None):
    return build_scene(
        intrinsics=CAMERA,
        object_mesh=mesh or _Mesh(),
        scene=scene,
        render=render or RenderConfig(),
        rng=np.random.default_rng(0),
    )


def test_scene_contents_and_body_map():
    scene = SceneConfig(
        table=TableConfig(texture_px=32),
        background=BackgroundConfig(texture_px=32),
        hand=HandConfig(enabled=True, kind="proxy", finger_count=3),
    )
    built = _build(scene=scene, render=RenderConfig(msaa_samples=4, znear_m=0.02, zfar_m=7.0))
    m = built.model
    assert built.geom_body[m.geom("table").id] == STATIC_BODY
    assert built.geom_body[m.geom("background").id] == STATIC_BODY
    assert built.geom_body[built.object_geom_id] == OBJECT_BODY
    hand = [g for g in range(m.ngeom) if built.geom_body[g] == HAND_BODY]
    assert len(hand) == 1 + 3 + 1  # palm, fingers, thumb
    assert (m.geom_contype == 0).all() and (m.geom_conaffinity == 0).all()
    assert (m.vis.global_.offwidth, m.vis.global_.offheight) == (64, 48)
    assert m.vis.quality.offsamples == 4
    assert m.stat.extent == 1.0
    np.testing.assert_allclose([m.vis.map.znear, m.vis.map.zfar], [0.02, 7.0], rtol=1e-6)
    back = intrinsics_from_mujoco_camera(
        m.cam_resolution[built.camera_id],
        m.cam_sensorsize[built.camera_id],
        m.cam_intrinsic[built.camera_id],
    )
    np.testing.assert_allclose(back.K, CAMERA.K, atol=1e-4)
    np.testing.assert_allclose(built.object_half_extents_m, [0.05, 0.03, 0.1])
    assert m.nmocap == 3


def test_object_texture_coordinates_are_flipped_to_mujoco():
    mesh = _Mesh()
    built = _build(mesh=mesh)
    m = built.model
    mesh_id = m.geom_dataid[built.object_geom_id]
    adr, n = m.mesh_texcoordadr[mesh_id], m.mesh_texcoordnum[mesh_id]
    texcoord = m.mesh_texcoord[adr : adr + n]
    expected = np.column_stack([mesh.uv[:, 0], 1.0 - mesh.uv[:, 1]])
    # MuJoCo keeps one texcoord per user vertex; compare as sets of rows.
    a = np.unique(np.round(texcoord, 5), axis=0)
    b = np.unique(np.round(expected, 5), axis=0)
    np.testing.assert_allclose(a, b, atol=1e-5)


def test_untextured_object_and_no_static_world():
    scene = SceneConfig(
        table=TableConfig(enabled=False), background=BackgroundConfig(enabled=False), lights=()
    )
    built = _build(scene=scene, mesh=_Mesh(with_texture=False))
    assert built.model.ngeom == 1 and built.model.ntex == 0 and built.hand_mocap is None


def test_bad_scenes_are_errors():
    with pytest.raises(ConfigError, match="must be nearer than background.distance_m"):
        _build(
            scene=SceneConfig(
                table=TableConfig(near_m=2.0, texture_px=32),
                background=BackgroundConfig(distance_m=1.5, texture_px=32),
            )
        )
    bad = _Mesh()
    bad.vertices_m = bad.vertices_m[:3]
    bad.faces = bad.faces[:0]
    with pytest.raises(ConfigError, match="needs >= 4 vertices"):
        _build(mesh=bad)
    with pytest.raises(ConfigError, match="msaa_samples must be one of"):
        RenderConfig(msaa_samples=3)
    with pytest.raises(ConfigError, match="zfar_m .* must exceed 10 x znear_m"):
        RenderConfig(znear_m=0.5, zfar_m=1.0)
    with pytest.raises(ConfigError, match="at most 8 lights"):
        SceneConfig(lights=SceneConfig().lights * 5)
