"""The OpenGL contexts the offscreen renderers of a thread share (roft_sim.render.gl_contexts)."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import mujoco
import numpy as np
import pytest
from stand_ins import SMALL_CAMERA, SinusoidalTrajectory, grid_box_mesh

from roft_sim.geometry import quat_from_matrix
from roft_sim.render.gl_contexts import free_idle_gl_contexts
from roft_sim.render.offscreen import OffscreenRenderer
from roft_sim.render.scene_builder import BuiltScene, build_scene
from roft_sim.scene.config import HandConfig, RenderConfig, SceneConfig

pytestmark = pytest.mark.render

W, H = SMALL_CAMERA.width_px, SMALL_CAMERA.height_px


def _scene(texture_px: int, hand: bool, seed: int) -> BuiltScene:
    return build_scene(
        intrinsics=SMALL_CAMERA,
        object_mesh=grid_box_mesh(n=4, texture_px=texture_px),
        scene=SceneConfig(hand=HandConfig(enabled=hand, side="random")),
        render=RenderConfig(msaa_samples=4),
        rng=np.random.default_rng(seed),
    )


def _frames(built: BuiltScene) -> list[tuple[np.ndarray, ...]]:
    """rgb, depth and geom ids of three poses, rendered by a new renderer closed after."""
    data = mujoco.MjData(built.model)
    out = []
    with OffscreenRenderer(built.model, W, H) as renderer:
        for T in SinusoidalTrajectory().sample(np.array([0.0, 0.5, 1.1])).T_ref_obj:
            data.mocap_pos[built.object_mocap] = T[:3, 3]
            data.mocap_quat[built.object_mocap] = quat_from_matrix(T[:3, :3])
            mujoco.mj_kinematics(built.model, data)
            mujoco.mj_camlight(built.model, data)
            renderer.update(data, built.camera_id)
            b = renderer.render(rgb=True, depth=True, segmentation=True)
            assert b.rgb is not None and b.depth_m is not None and b.geom_id is not None
            out.append((b.rgb, b.depth_m, b.geom_id))
    return out


def _in_a_new_thread(fn, *args):
    """``fn(*args)`` on a thread of its own: a thread without contexts, freed after."""

    def run():
        try:
            return fn(*args)
        finally:
            free_idle_gl_contexts()

    with ThreadPoolExecutor(1) as pool:
        return pool.submit(run).result()


def test_renderers_of_a_thread_share_its_context_and_the_next_one_reuses_it():
    def check() -> None:
        a, b = _scene(32, False, 0), _scene(64, True, 1)
        first = OffscreenRenderer(a.model, W, H)
        second = OffscreenRenderer(b.model, W, H)
        shared = first._gl
        assert shared is not None and second._gl is shared and shared.users == 2
        first.close()
        second.close()
        first.close()  # idempotent: releases once
        assert shared.users == 0
        # the next renderer of that size draws in the idle context instead of a new one
        with OffscreenRenderer(a.model, W, H) as third:
            assert third._gl is shared and shared.users == 1
            # another size gets its own; the one in use is not freed
            with OffscreenRenderer(a.model, W // 2, H // 2) as small:
                assert small._gl is not shared and small._gl is not None
                other = small._gl
        assert shared.users == 0 and other.users == 0
        assert free_idle_gl_contexts() == 2
        assert free_idle_gl_contexts() == 0

    _in_a_new_thread(check)


def test_acquiring_another_size_frees_the_idle_contexts():
    def check() -> None:
        a = _scene(32, False, 0)
        OffscreenRenderer(a.model, W, H).close()
        with OffscreenRenderer(a.model, W // 2, H // 2):
            # the idle W x H context was freed when the new size was acquired
            assert free_idle_gl_contexts() == 0
        assert free_idle_gl_contexts() == 1

    _in_a_new_thread(check)


def test_each_thread_draws_in_its_own_context():
    a = _scene(32, False, 0)
    both_hold_one = threading.Barrier(2, timeout=60)

    def held_context():
        with OffscreenRenderer(a.model, W, H) as renderer:
            both_hold_one.wait()  # both threads hold a renderer at once
            return renderer._gl

    with ThreadPoolExecutor(2) as pool:
        futures = [pool.submit(_in_a_new_thread, held_context) for _ in range(2)]
        first, second = (f.result() for f in futures)
    assert first is not None and second is not None and first is not second


def test_pixels_do_not_depend_on_what_the_shared_context_drew_before():
    a, b = _scene(32, False, 0), _scene(64, True, 1)
    fresh = _in_a_new_thread(_frames, a)

    def after_another_scene():
        _frames(b)  # another model, other textures and a hand, drawn first in the context
        return _frames(a)

    reused = _in_a_new_thread(after_another_scene)
    for (rgb, depth, ids), (rgb2, depth2, ids2) in zip(fresh, reused, strict=True):
        np.testing.assert_array_equal(rgb, rgb2)
        np.testing.assert_array_equal(depth, depth2)
        np.testing.assert_array_equal(ids, ids2)
