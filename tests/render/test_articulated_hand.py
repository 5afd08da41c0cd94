"""The articulated hand: a grasp that touches the object without entering it (checked against
the mesh itself, not only MuJoCo's hull distances), fingers that move yet never interpenetrate,
its own ground-truth segment id, and exact flow on every link."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from stand_ins import SinusoidalTrajectory, grid_box_mesh, open_renderer, small_scenario

from roft_sim.assets import sample_surface_points
from roft_sim.assets.registry import FAST_YCB_OBJECTS
from roft_sim.geometry import (
    backproject_pixels,
    invert_transform,
    project_points,
    transform_points,
)
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
        points = sample_surface_points(mesh.vertices_m, mesh.faces, 60000, seed=seed)
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
    points = sample_surface_points(mesh.vertices_m, mesh.faces, 30000, seed=0)
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
    hand_config = HandConfig(enabled=True, motion=motion, side="random")  # in view
    scenario = small_scenario(seed=2, scene=_scene(hand_config), frames=30)
    trajectory = SinusoidalTrajectory(p0_m=(0.0, 0.0, 0.45), rot_amplitude_rad=0.3)
    with open_renderer(scenario, trajectory=trajectory) as r:
        # The pair of frames (k, k + 2) across which the fingers move most (a re-grip).
        angles = [r.finger_motion.planned_angles_rad(k / 30) for k in range(30)]
        k = max(range(28), key=lambda i: np.abs(angles[i + 2] - angles[i]).max())
        assert np.abs(angles[k + 2] - angles[k]).max() > 0.1
        f0 = r.render_frame(k)
        links0 = _link_poses_world(r)
        f1 = r.render_frame(k + 2)
        links1 = _link_poses_world(r)
    ids = f0.segment_ids()
    hand = ids == SEGMENT_HAND
    assert hand.sum() > 200 and (ids == SEGMENT_OBJECT).sum() > 200
    assert not (hand & f0.object_mask).any()
    assert (f0.body_index[hand] >= 2).all()
    flow = ground_truth_flow(f0, f1, scenario.intrinsics)
    # Oracle: each hand pixel back-projected, carried by ITS link's MuJoCo poses (read from the
    # simulator's data, by body name), projected into the later camera.
    intr = scenario.intrinsics
    sel = flow.valid & hand
    v, u = np.nonzero(sel)
    X_cam0 = backproject_pixels(intr, np.column_stack([u, v]).astype(float), f0.depth_m[v, u])
    X_world0 = transform_points(f0.T_world_cam, X_cam0)
    expected = np.empty((len(u), 2))
    names = np.array(f0.body_names)[f0.body_index[v, u]]
    for name in set(names):
        rows = names == name
        M = links1[name] @ invert_transform(links0[name])
        X_cam1 = transform_points(invert_transform(f1.T_world_cam) @ M, X_world0[rows])
        expected[rows] = project_points(intr, X_cam1)
    err = np.linalg.norm(np.column_stack([u, v]) + flow.flow_px[v, u] - expected, axis=1)
    assert sel.sum() > 150 and np.percentile(err, 99) < 0.01, np.percentile(err, 99)
    # The same oracle tells a hand moved rigidly with its palm (the proxy's model) apart.
    M_palm = links1["hand"] @ invert_transform(links0["hand"])
    X_rigid = transform_points(invert_transform(f1.T_world_cam) @ M_palm, X_world0)
    assert np.linalg.norm(project_points(intr, X_rigid) - expected, axis=1).max() > 0.5


def _link_poses_world(renderer) -> dict[str, np.ndarray]:
    """(4, 4) world pose of every hand link, read from MuJoCo's data by body name."""
    m, d = renderer.model, renderer._data
    out = {}
    for name in renderer.body_names:
        if name.startswith("hand"):
            T = np.eye(4)
            T[:3, :3] = d.xmat[m.body(name).id].reshape(3, 3)
            T[:3, 3] = d.xpos[m.body(name).id]
            out[name] = T
    return out


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
    FAST_YCB_OBJECTS,
)
def test_grasp_on_real_ycb_meshes_never_enters_them(name, shared_ycb_dir):
    """The real (concave, 8-30k vertex) scans: no surface point inside the hand over a
    sequence with re-grips, at least two digits touching."""
    from roft_sim.assets import load_object

    mesh = load_object(name, assets_dir=shared_ycb_dir, prefer="ycb").mesh
    motion = HandMotionConfig(regrip_rate_hz=2.0, flexion_jitter_rad=0.15)
    scenario = small_scenario(seed=7, scene=_scene(HandConfig(enabled=True, motion=motion)))
    points = sample_surface_points(mesh.vertices_m, mesh.faces, 60000, seed=1)
    with open_renderer(scenario, mesh=mesh) as r:
        assert sum(r.grasp.in_contact) >= 2, r.grasp.in_contact
        for k in (0, 4, 8, 11):
            r.render_frame(k)
            depth, _ = _depth_inside_hand(r, points)
            assert depth < PENETRATION_TOL_M, f"{name} frame {k}: {1000 * depth:.2f} mm inside"


def _palm_facing_camera(r) -> float:
    """Mean over the frames of (outward normal of the palm's object side) . (unit direction from
    the object to the camera), object frame: < 0 = the palm is behind the object."""
    outward = -r.grasp.T_obj_hand[:3, 2]  # the hand's +z points into the object
    return float((r._camera_dirs_obj() @ outward).mean())


def test_palm_goes_on_a_side_facing_away_from_the_camera():
    mesh = grid_box_mesh(half_extents_m=(0.03, 0.03, 0.03), texture_px=64)  # every side fits
    facing = {}
    for side in ("away_from_camera", "random"):
        facing[side] = []
        for seed in range(6):
            hand = HandConfig(enabled=True, side=side)
            scenario = small_scenario(seed=seed, scene=_scene(hand), frames=30)
            with open_renderer(scenario, mesh=mesh) as r:
                facing[side].append(_palm_facing_camera(r))
    assert max(facing["away_from_camera"]) < -0.3, facing
    assert max(facing["random"]) > 0.3, facing  # a random side can face the camera
