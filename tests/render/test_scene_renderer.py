"""SceneRenderer behaviour: determinism, frame independence, motion blur, hand occluder, sensor
depth, errors."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from stand_ins import SinusoidalTrajectory, open_renderer, small_scenario

from roft_sim.errors import ConfigError
from roft_sim.geometry import invert_transform
from roft_sim.render import ground_truth_flow
from roft_sim.scene.config import (
    BackgroundConfig,
    HandConfig,
    RenderConfig,
    SceneConfig,
    TableConfig,
)
from roft_sim.sensors.depth_noise import KinectAzureDepthNoise

pytestmark = pytest.mark.render


def _assert_frames_identical(a, b):
    for name in ("rgb", "depth_m", "sensor_depth_m", "segmentation", "body_index", "T_cam_obj"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_same_scenario_and_seed_give_identical_frames_in_any_order():
    scenario = small_scenario(render=RenderConfig(depth_noise=KinectAzureDepthNoise()))
    with open_renderer(scenario) as r:
        first = [r.render_frame(k) for k in (2, 7)]
    with open_renderer(scenario) as r:
        later_first = r.render_frame(7)
        again = r.render_frame(2)
    _assert_frames_identical(first[0], again)
    _assert_frames_identical(first[1], later_first)


def test_the_seed_changes_textures_and_noise_but_not_ground_truth():
    a_scn = small_scenario(seed=1, render=RenderConfig(depth_noise=KinectAzureDepthNoise()))
    b_scn = small_scenario(seed=2, render=RenderConfig(depth_noise=KinectAzureDepthNoise()))
    with open_renderer(a_scn) as r:
        a = r.render_frame(3)
    with open_renderer(b_scn) as r:
        b = r.render_frame(3)
    np.testing.assert_array_equal(a.depth_m, b.depth_m)
    np.testing.assert_array_equal(a.T_cam_obj, b.T_cam_obj)
    background = a.body_index == 0
    assert np.abs(a.rgb[background].astype(int) - b.rgb[background]).mean() > 5
    assert not np.array_equal(a.sensor_depth_m, b.sensor_depth_m)


def test_frame_contents_and_ground_truth_consistency():
    scenario = small_scenario()
    with open_renderer(scenario) as r:
        f = r.render_frame(5)
    h, w = scenario.intrinsics.shape
    assert f.rgb.shape == (h, w, 3) and f.rgb.dtype == np.uint8
    assert f.depth_m.dtype == np.float32 and f.segmentation.dtype == np.int32
    assert f.t_s == pytest.approx(5 / 30)
    assert f.object_mask.sum() > 300
    np.testing.assert_array_equal(f.object_mask, f.body_index == 1)
    np.testing.assert_array_equal(f.sensor_depth_m, f.depth_m)  # kind = "none"
    expected = SinusoidalTrajectory().sample([5 / 30]).T_ref_obj[0]
    np.testing.assert_allclose(f.T_cam_obj, expected, atol=1e-12)
    np.testing.assert_allclose(f.T_cam_bodies[0], invert_transform(f.T_world_cam))
    np.testing.assert_allclose(f.T_cam_bodies[1], f.T_cam_obj)
    assert f.body_names == ("static", "object")


def test_motion_blur_averages_renders_over_the_exposure_and_keeps_ground_truth():
    """Blurred frame k (30 fps, 5 sub-frames, full exposure) is the mean of the sharp frames
    5k-2 ... 5k+2 of the same scene rendered at 150 fps (the sub-frame times)."""
    blur_scn = small_scenario(render=RenderConfig(motion_blur_subframes=5, exposure_fraction=1.0))
    camera_150 = dataclasses.replace(blur_scn.camera, fps=150)
    sharp_scn = small_scenario(camera=camera_150, frames=60)
    k = 6
    with open_renderer(blur_scn) as r:
        blurred = r.render_frame(k)
    with open_renderer(sharp_scn) as r:
        subframes = [r.render_frame(5 * k + i) for i in range(-2, 3)]
    expected = np.rint(np.mean([f.rgb.astype(np.float64) for f in subframes], axis=0))
    np.testing.assert_array_equal(blurred.rgb, expected.astype(np.uint8))
    middle = subframes[2]
    assert middle.t_s == pytest.approx(blurred.t_s)
    for name in ("depth_m", "segmentation", "T_cam_obj", "v_obj_mps", "w_radps"):
        np.testing.assert_array_equal(getattr(middle, name), getattr(blurred, name), name)
    assert np.abs(blurred.rgb.astype(int) - middle.rgb)[middle.object_mask].mean() > 0.5


def test_hand_occluder_hides_part_of_the_object_and_moves_with_it():
    with_hand = small_scenario(
        scene=SceneConfig(
            table=TableConfig(texture_px=64),
            background=BackgroundConfig(texture_px=64),
            hand=HandConfig(enabled=True, kind="proxy"),
        )
    )
    no_hand = small_scenario(
        scene=SceneConfig(
            table=TableConfig(texture_px=64), background=BackgroundConfig(texture_px=64)
        )
    )
    with open_renderer(with_hand) as r:
        h0, h1 = r.render_frame(3), r.render_frame(4)
        hand_geoms = [g for g in range(r.model.ngeom) if r.built.geom_body[g] == 2]
    with open_renderer(no_hand) as r:
        bare = r.render_frame(3)
    assert h0.body_names == ("static", "object", "hand")
    hand_px = np.isin(h0.segmentation, hand_geoms)
    assert hand_px.sum() > 50 and (h0.body_index[hand_px] == 2).all()
    assert not (h0.object_mask & hand_px).any()
    hidden = bare.object_mask & ~h0.object_mask
    assert hidden.sum() > 20 and hand_px[hidden].all()  # the hand is what hides the object
    flow = ground_truth_flow(h0, h1, with_hand.intrinsics)
    assert flow.valid[hand_px].mean() > 0.8 and np.abs(flow.flow_px[hand_px]).max() > 0.3
    # Object pixels whose target is hidden by the hand in the later frame (the hand at least
    # 2 cm nearer than the object there) are invalid: the occlusion test.
    with open_renderer(no_hand) as r:
        bare1 = r.render_frame(4)
    rows, cols = np.nonzero(h0.object_mask)
    target = np.rint(np.stack([cols, rows], -1) + flow.flow_px[rows, cols]).astype(int)
    inside = (target[:, 0] >= 0) & (target[:, 0] < 160) & (target[:, 1] >= 0) & (target[:, 1] < 120)
    rows, cols, target = rows[inside], cols[inside], target[inside]
    seen = h1.depth_m[target[:, 1], target[:, 0]]
    hidden_by_hand = seen < bare1.depth_m[target[:, 1], target[:, 0]] - 0.02
    assert not flow.valid[rows, cols][hidden_by_hand].any()
    assert flow.valid[rows, cols][~hidden_by_hand].mean() > 0.9


def test_sensor_depth_uses_the_noise_model_and_leaves_ground_truth_exact():
    scenario = small_scenario(render=RenderConfig(depth_noise=KinectAzureDepthNoise()))
    with open_renderer(scenario) as r:
        f = r.render_frame(1)
    both = (f.depth_m > 0) & (f.sensor_depth_m > 0)
    noise = (f.sensor_depth_m - f.depth_m)[both & (f.body_index == 0)]
    assert 0.0003 < np.median(np.abs(noise)) < 0.003


def test_trajectory_too_short_and_bad_frame_index_are_errors():
    scenario = small_scenario(frames=40)
    with pytest.raises(ConfigError, match="trajectory ends at 1.000 s"):
        open_renderer(scenario, trajectory=SinusoidalTrajectory(end_s=1.0))
    with open_renderer(small_scenario(frames=3)) as r:
        with pytest.raises(IndexError, match="frame 3 outside 0..2"):
            r.render_frame(3)
        r.close()
        with pytest.raises(RuntimeError, match="after close"):
            r.render_frame(0)
