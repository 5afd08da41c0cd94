"""The articulated hand: a grasp that touches the object without entering it (checked against
the mesh itself, not only MuJoCo's hull distances), fingers that move yet never interpenetrate,
its own ground-truth segment id, and exact flow on every link."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from stand_ins import SinusoidalTrajectory, grid_box_mesh, open_renderer, small_scenario

from roft_sim.render import ground_truth_flow
from roft_sim.render.ground_truth import SEGMENT_HAND, SEGMENT_OBJECT
from roft_sim.scene.config import (
    BackgroundConfig,
    HandConfig,
    HandMotionConfig,
    SceneConfig,
    TableConfig,
)

pytestmark = pytest.mark.render

PENETRATION_TOL_M = 0.001


def _scene(hand: HandConfig) -> SceneConfig:
    return SceneConfig(
        table=TableConfig(texture_px=64, height_m=0.25),
        background=BackgroundConfig(texture_px=64, distance_m=1.2),
        hand=hand,
    )


def _surface_points(mesh, count: int, rng) -> np.ndarray:
    """Points drawn uniformly on the mesh surface, object frame (N, 3) [m]."""
    tri = mesh.vertices_m[mesh.faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    f = rng.choice(len(tri), count, p=area / area.sum())
    u, v = rng.random((2, count))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[f]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def _depth_inside_hand(renderer, points_obj: np.ndarray) -> tuple[float, float]:
    """(deepest penetration, smallest clearance) [m] of the object's surface points into the
    hand's geoms as MuJoCo placed them, computed here from the geoms' sizes and poses."""
    m, d, b = renderer.model, renderer._data, renderer.built
    T = np.eye(4)
    T[:3, :3] = d.xmat[m.body("object").id].reshape(3, 3)
    T[:3, 3] = d.xpos[m.body("object").id]
    p = points_obj @ T[:3, :3].T + T[:3, 3]
    signed = []
    for g in [b.hand.palm_geom, *(g for digit in b.hand.digit_geoms for g in digit)]:
        R, c, size = d.geom_xmat[g].reshape(3, 3), d.geom_xpos[g], m.geom_size[g]
        local = (p - c) @ R  # geom frame
        if m.geom_type[g] == 6:  # box: signed distance
            q = np.abs(local) - size
            outside = np.linalg.norm(np.maximum(q, 0), axis=1)
            signed.append(outside + np.minimum(q.max(axis=1), 0))
        else:  # capsule along local z, half length size[1]
            z = np.clip(local[:, 2], -size[1], size[1])
            axis_pt = np.column_stack([np.zeros_like(z), np.zeros_like(z), z])
            signed.append(np.linalg.norm(local - axis_pt, axis=1) - size[0])
    s = np.min(signed, axis=0)
    return float(-s.min()), float(s.min())


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_grasp_touches_the_mesh_without_entering_it(seed):
    mesh = grid_box_mesh(half_extents_m=(0.035, 0.09, 0.025), texture_px=64)
    scenario = small_scenario(seed=seed, scene=_scene(HandConfig(enabled=True)), frames=2)
    with open_renderer(scenario, mesh=mesh) as r:
        r.render_frame(0)
        assert r.grasp is not None and sum(r.grasp.in_contact) >= 3, r.grasp.in_contact
        points = _surface_points(mesh, 60000, np.random.default_rng(seed))
        depth, clearance = _depth_inside_hand(r, points)
        assert depth < PENETRATION_TOL_M, f"hand enters the object by {1000 * depth:.2f} mm"
        # It touches: some surface point lies within 1 mm of a segment (sampling: 0.5 mm).
        assert clearance < 0.0015, f"nearest hand geom {1000 * clearance:.2f} mm away"
        hand = r.built.hand
        # MuJoCo's own distance agrees: nothing nearer than the contact gap minus bisection.
        geoms = [hand.palm_geom, *(g for digit in hand.digit_geoms for g in digit)]
        d = hand.min_distance_m(r.model, r._data, tuple(geoms), r.built.object_geom_id)
        assert -1e-4 < d < 0.001


def test_fingers_move_during_the_sequence_without_entering_the_object():
    motion = HandMotionConfig(regrip_rate_hz=3.0, regrip_opening_rad=0.6, flexion_jitter_rad=0.2)
    mesh = grid_box_mesh(half_extents_m=(0.035, 0.09, 0.025), texture_px=64)
    scenario = small_scenario(
        seed=5, scene=_scene(HandConfig(enabled=True, motion=motion)), frames=30
    )
    points = _surface_points(mesh, 30000, np.random.default_rng(0))
    angles = []
    with open_renderer(scenario, mesh=mesh, trajectory=SinusoidalTrajectory()) as r:
        for k in range(0, 30, 3):
            r.render_frame(k)
            angles.append(r._data.qpos.copy())
            depth, _ = _depth_inside_hand(r, points)
            assert depth < PENETRATION_TOL_M, f"frame {k}: {1000 * depth:.2f} mm inside"
    spread = np.ptp(np.array(angles), axis=0)
    assert spread.max() > np.radians(10.0), f"fingers barely move: {np.degrees(spread).max()}"


def test_hand_has_its_own_segment_id_and_exact_flow_on_every_link():
    motion = HandMotionConfig(regrip_rate_hz=3.0, regrip_opening_rad=0.6)
    scenario = small_scenario(seed=2, scene=_scene(HandConfig(enabled=True, motion=motion)))
    trajectory = SinusoidalTrajectory(p0_m=(0.0, 0.0, 0.45), rot_amplitude_rad=0.3)
    with open_renderer(scenario, trajectory=trajectory) as r:
        f0, f1 = r.render_frame(6), r.render_frame(8)
    ids = f0.segment_ids()
    hand = ids == SEGMENT_HAND
    assert hand.sum() > 200 and (ids == SEGMENT_OBJECT).sum() > 200
    assert not (hand & f0.object_mask).any()
    assert (f0.body_index[hand] >= 2).all()
    flow = ground_truth_flow(f0, f1, scenario.intrinsics)
    # Oracle: each valid hand pixel lands on the same link in the later frame (the links move
    # differently; moving the hand as one rigid body would send finger pixels off their link).
    h, w = f0.shape
    yy, xx = np.mgrid[0:h, 0:w]
    tx = np.rint(xx + flow.flow_px[..., 0]).astype(int).clip(0, w - 1)
    ty = np.rint(yy + flow.flow_px[..., 1]).astype(int).clip(0, h - 1)
    sel = flow.valid & hand
    same = f1.body_index[ty, tx] == f0.body_index
    assert sel.sum() > 150
    assert same[sel].mean() > 0.97, f"only {same[sel].mean():.3f} land on their link"


def test_proxy_kind_keeps_the_rigid_capsules():
    scenario = small_scenario(scene=_scene(HandConfig(enabled=True, kind="proxy")), frames=2)
    with open_renderer(scenario) as r:
        assert r.body_names == ("static", "object", "hand") and r.grasp is None
    scenario = dataclasses.replace(scenario, scene=_scene(HandConfig(enabled=True)))
    with open_renderer(scenario) as r:
        assert len(r.body_names) == 3 + 15 and r.grasp is not None


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",
    [
        "003_cracker_box",
        "004_sugar_box",
        "005_tomato_soup_can",
        "006_mustard_bottle",
        "009_gelatin_box",
        "010_potted_meat_can",
    ],
)
def test_grasp_on_real_ycb_meshes_never_enters_them(name, shared_ycb_dir):
    """The real (concave, 8-30k vertex) scans: no surface point inside the hand over a
    sequence with re-grips, at least two digits touching."""
    from roft_sim.assets import load_object

    mesh = load_object(name, assets_dir=shared_ycb_dir, prefer="ycb").mesh
    motion = HandMotionConfig(regrip_rate_hz=2.0, flexion_jitter_rad=0.15)
    scenario = small_scenario(seed=7, scene=_scene(HandConfig(enabled=True, motion=motion)))
    points = _surface_points(mesh, 60000, np.random.default_rng(1))
    with open_renderer(scenario, mesh=mesh) as r:
        assert sum(r.grasp.in_contact) >= 2, r.grasp.in_contact
        for k in (0, 4, 8, 11):
            r.render_frame(k)
            depth, _ = _depth_inside_hand(r, points)
            assert depth < PENETRATION_TOL_M, f"{name} frame {k}: {1000 * depth:.2f} mm inside"
