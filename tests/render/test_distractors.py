"""Distractor objects: one resting on the table (its lowest point on the table top), one moved by
its own trajectory; each has its own segment id, body, exact pose (checked by projecting its
mesh onto its mask) and flow."""

from __future__ import annotations

import numpy as np
import pytest
from stand_ins import SinusoidalTrajectory, open_renderer, small_scenario, textured_mesh_file

from roft_sim.errors import ConfigError
from roft_sim.geometry import project_points, transform_points
from roft_sim.render import ground_truth_flow
from roft_sim.render.ground_truth import SEGMENT_DISTRACTOR
from roft_sim.scene.config import BackgroundConfig, DistractorConfig, SceneConfig, TableConfig
from roft_sim.trajectories import SyntheticMotionConfig

pytestmark = pytest.mark.render


def _scene(*distractors, table=True):
    return SceneConfig(
        table=TableConfig(texture_px=64, height_m=0.2, enabled=table),
        background=BackgroundConfig(texture_px=64, distance_m=1.2),
        distractors=distractors,
    )


def test_resting_and_moving_distractors_have_their_own_ground_truth(tmp_path):
    import trimesh

    box = textured_mesh_file(tmp_path, "box", trimesh.creation.box(extents=(0.09, 0.03, 0.07)))
    can = textured_mesh_file(tmp_path, "can", trimesh.creation.cylinder(radius=0.034, height=0.1))
    resting = DistractorConfig(name=box, position_m=(-0.12, 0.6), yaw_rad=0.4)
    moving = DistractorConfig(
        name=can,
        trajectory=SyntheticMotionConfig(seed=4, working_distance_m=(0.7, 0.9)),
    )
    scenario = small_scenario(scene=_scene(resting, moving))
    with open_renderer(scenario, trajectory=SinusoidalTrajectory(p0_m=(0.1, -0.05, 0.45))) as r:
        f0, f1 = r.render_frame(3), r.render_frame(4)
        meshes = [d.mesh for d in r.distractors]
    assert f0.body_names[-2:] == ("distractor0", "distractor1")
    assert f0.distractor_names == (box, can)
    # Resting: its lowest vertex lies on the table top (world y = height).
    T_world_d0 = f0.T_world_cam @ f0.T_cam_distractors[0]
    lowest = transform_points(T_world_d0, meshes[0].vertices_m)[:, 1].max()
    assert lowest == pytest.approx(0.2, abs=1e-9)
    ids = f0.segment_ids()
    for i, name in enumerate(("distractor0", "distractor1")):
        b = f0.body_names.index(name)
        mask = f0.body_index == b
        assert mask.sum() > 30, f"{name} not visible"
        assert (ids[mask] == SEGMENT_DISTRACTOR).all()
        # Its pose: the projected mesh vertices cover its visible mask's bounding box.
        uv = project_points(
            scenario.intrinsics, transform_points(f0.T_cam_distractors[i], meshes[i].vertices_m)
        )
        v, u = np.nonzero(mask)
        assert uv[:, 0].min() - 1 <= u.min() and u.max() <= uv[:, 0].max() + 1
        assert uv[:, 1].min() - 1 <= v.min() and v.max() <= uv[:, 1].max() + 1
    moved = np.linalg.norm(f1.T_cam_distractors[1][:3, 3] - f0.T_cam_distractors[1][:3, 3])
    assert moved > 1e-3
    assert np.array_equal(f1.T_cam_distractors[0], f0.T_cam_distractors[0])  # static camera
    flow = ground_truth_flow(f0, f1, scenario.intrinsics)
    moving_px = (f0.body_index == f0.body_names.index("distractor1")) & flow.valid
    assert np.linalg.norm(flow.flow_px[moving_px], axis=1).mean() > 0.2


def test_a_resting_distractor_needs_the_table():
    with pytest.raises(ConfigError, match="rests on the table"):
        _scene(DistractorConfig(name="009_gelatin_box"), table=False)


def test_relative_distractor_paths_resolve_against_the_scenario_file(tmp_path):
    from roft_sim.scenario import load_scenario

    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "s.toml").write_text(
        'name = "s"\nframes = 2\n[camera]\nwidth_px = 64\nheight_px = 48\nfx_px = 60.0\n'
        'fy_px = 60.0\ncx_px = 31.5\ncy_px = 23.5\n[object]\nname = "009_gelatin_box"\n'
        '[trajectory]\nkind = "synthetic"\n[[scene.distractors]]\nname = "meshes/can.obj"\n'
    )
    scenario = load_scenario(tmp_path / "sub" / "s.toml")
    assert scenario.scene.distractors[0].name == str(tmp_path / "sub" / "meshes" / "can.obj")
