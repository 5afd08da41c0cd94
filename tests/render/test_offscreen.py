"""OffscreenRenderer: the segmentation pass's single-sample framebuffer."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from stand_ins import SMALL_CAMERA, SinusoidalTrajectory, grid_box_mesh

from roft_sim.errors import ConfigError
from roft_sim.geometry import quat_from_matrix
from roft_sim.render.offscreen import OffscreenRenderer
from roft_sim.render.scene_builder import build_scene
from roft_sim.scene.config import HandConfig, RenderConfig, SceneConfig

pytestmark = pytest.mark.render


def test_segmentation_pass_is_single_sample_and_equals_the_multisampled_one():
    # a textured box on the table with the proxy hand in front of it: many edges, three bodies
    built = build_scene(
        intrinsics=SMALL_CAMERA,
        object_mesh=grid_box_mesh(n=6, texture_px=64),
        scene=SceneConfig(hand=HandConfig(enabled=True, side="random")),
        render=RenderConfig(msaa_samples=4),
        rng=np.random.default_rng(0),
    )
    data = mujoco.MjData(built.model)
    flag = mujoco.mjtRndFlag
    with OffscreenRenderer(built.model, SMALL_CAMERA.width_px, SMALL_CAMERA.height_px) as r:
        for T in SinusoidalTrajectory().sample(np.array([0.0, 0.4, 1.3])).T_ref_obj:
            for mocap in (built.object_mocap, built.hand_mocap):
                assert mocap is not None
                data.mocap_pos[mocap] = T[:3, 3]
                data.mocap_quat[mocap] = quat_from_matrix(T[:3, :3])
            mujoco.mj_kinematics(built.model, data)
            mujoco.mj_camlight(built.model, data)
            r.update(data, built.camera_id)
            out = r.render(rgb=True, depth=True, segmentation=True)
            assert out.geom_id is not None and out.depth_m is not None
            assert len(np.unique(out.geom_id)) >= 3
            # the same pass drawn into the colour pass's multisampled framebuffer and resolved
            ctx = r._ctx
            assert ctx is not None and ctx.offSamples == 4 and r._flat_context().offSamples == 0
            saved = r.scene.flags.copy()
            r.scene.flags[flag.mjRND_SEGMENT] = r.scene.flags[flag.mjRND_IDCOLOR] = True
            r.scene.flags[flag.mjRND_SHADOW] = False
            mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, ctx)
            mujoco.mjr_render(r._rect, r.scene, ctx)
            np.copyto(r.scene.flags, saved)
            ids = np.empty((r.height_px, r.width_px, 3), np.uint8)
            buffer = np.empty((r.height_px, r.width_px), np.float32)
            mujoco.mjr_readPixels(ids, buffer, r._rect, ctx)
            np.testing.assert_array_equal(r._geom_ids(ids[::-1]), out.geom_id)
            np.testing.assert_array_equal(r._z_depth(buffer[::-1]), out.depth_m)


@pytest.mark.parametrize("shadows", [False, True])
def test_a_shadow_map_is_made_only_where_shadows_are_cast(shadows):
    """MuJoCo allocates a shadowsize x shadowsize depth texture in every rendering context (about
    0.04 s of start-up per context on llvmpipe at 4096 px): the colour pass's context gets one
    only when the scene casts shadows, the segmentation pass's never; shadows still fall."""
    built = build_scene(
        intrinsics=SMALL_CAMERA,
        object_mesh=grid_box_mesh(n=6, texture_px=64),
        scene=SceneConfig(),
        render=RenderConfig(msaa_samples=4, shadows=shadows),
        rng=np.random.default_rng(0),
    )
    assert built.model.vis.quality.shadowsize == (4096 if shadows else 0)
    data = mujoco.MjData(built.model)
    T = SinusoidalTrajectory().sample(np.array([0.4])).T_ref_obj[0]
    data.mocap_pos[built.object_mocap] = T[:3, 3]
    data.mocap_quat[built.object_mocap] = quat_from_matrix(T[:3, :3])
    mujoco.mj_kinematics(built.model, data)
    mujoco.mj_camlight(built.model, data)
    with OffscreenRenderer(built.model, SMALL_CAMERA.width_px, SMALL_CAMERA.height_px) as r:
        r.update(data, built.camera_id)
        plain = r.render(rgb=True, depth=True, segmentation=True, shadows=False)
        assert r._ctx is not None and r._ctx.shadowSize == (4096 if shadows else 0)
        assert r._flat_context().shadowSize == 0
        assert built.model.vis.quality.shadowsize == (4096 if shadows else 0)  # restored
        if shadows:
            shadowed = r.render(rgb=True, depth=False, shadows=True).rgb
            assert shadowed is not None and plain.rgb is not None
            assert not np.array_equal(shadowed, plain.rgb)  # without a shadow map they are equal
        else:
            with pytest.raises(ConfigError, match="no shadow map"):
                r.render(rgb=True, shadows=True)


def test_segmentation_context_holds_one_texel_per_texture_and_leaves_the_model_as_it_was():
    """The segmentation pass samples no texture, so its context uploads each texture as 1x1
    (the ids and depth it gives equal the colour pass's: the test above); the model keeps its
    texture sizes and the colour pass its images."""
    from OpenGL import GL

    built = build_scene(
        intrinsics=SMALL_CAMERA,
        object_mesh=grid_box_mesh(n=6, texture_px=64),
        scene=SceneConfig(),
        render=RenderConfig(msaa_samples=4),
        rng=np.random.default_rng(0),
    )
    model = built.model
    sizes = (model.tex_width.copy(), model.tex_height.copy())
    assert model.ntex >= 2 and sizes[0].max() > 1
    data = mujoco.MjData(model)
    T = SinusoidalTrajectory().sample(np.array([0.4])).T_ref_obj[0]
    data.mocap_pos[built.object_mocap] = T[:3, 3]
    data.mocap_quat[built.object_mocap] = quat_from_matrix(T[:3, :3])
    mujoco.mj_kinematics(model, data)
    mujoco.mj_camlight(model, data)
    with OffscreenRenderer(model, SMALL_CAMERA.width_px, SMALL_CAMERA.height_px) as r:
        r.update(data, built.camera_id)
        before = r.render(rgb=True, depth=False, segmentation=False).rgb
        r.render(rgb=False, depth=True, segmentation=True)
        np.testing.assert_array_equal(model.tex_width, sizes[0])
        np.testing.assert_array_equal(model.tex_height, sizes[1])
        after = r.render(rgb=True, depth=False, segmentation=False).rgb
        np.testing.assert_array_equal(after, before)

        def level0_width(ctx: mujoco.MjrContext, i: int) -> int:
            flat = model.tex_type[i] == mujoco.mjtTexture.mjTEXTURE_2D
            target = GL.GL_TEXTURE_2D if flat else GL.GL_TEXTURE_CUBE_MAP
            query = GL.GL_TEXTURE_2D if flat else GL.GL_TEXTURE_CUBE_MAP_POSITIVE_X
            GL.glBindTexture(target, ctx.texture[i])
            return int(GL.glGetTexLevelParameteriv(query, 0, GL.GL_TEXTURE_WIDTH))

        assert r._ctx is not None and r._flat_ctx is not None
        for i in range(model.ntex):
            assert level0_width(r._ctx, i) == sizes[0][i]
            assert level0_width(r._flat_ctx, i) == 1
