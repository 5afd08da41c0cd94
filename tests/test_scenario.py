"""Scenario files: every shipped scenario loads; bad keys and values give errors that name the
file, the key and the fix; relative paths and seeds behave."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from roft_sim.assets.registry import FAST_YCB_OBJECTS
from roft_sim.errors import ConfigError
from roft_sim.scenario import Scenario, load_scenario
from roft_sim.scene.config import CameraSwayConfig, HandConfig
from roft_sim.sensors.depth_noise import NoDepthNoise, RealSenseDepthNoise
from roft_sim.trajectories import SyntheticMotionConfig

REPO = Path(__file__).resolve().parent.parent
SHIPPED = sorted(  # scenario files: not the fault presets, sweep files or tracker configurations
    p
    for p in (REPO / "scenarios").rglob("*.toml")
    if not {"faults", "sweeps", "trackers"} & set(p.relative_to(REPO).parts)
)

MINIMAL = """
name = "minimal"
frames = 10
[camera]
width_px = 64
height_px = 48
fx_px = 60.0
fy_px = 60.0
cx_px = 31.5
cy_px = 23.5
[object]
name = "003_cracker_box"
[trajectory]
kind = "synthetic"
"""


def _write(tmp_path: Path, text: str, name: str = "scenario.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("path", SHIPPED, ids=[str(p.relative_to(REPO)) for p in SHIPPED])
def test_every_shipped_scenario_loads(path):
    scenario = load_scenario(path)
    assert scenario.n_frames >= 30
    if isinstance(scenario.trajectory, SyntheticMotionConfig):
        assert scenario.trajectory.duration_s >= (scenario.n_frames - 1) / scenario.fps


def test_fast_ycb_scenarios_use_the_fast_ycb_camera_and_fast_motion():
    folder = REPO / "scenarios" / "fast_ycb"
    assert sorted(p.stem for p in folder.glob("*.toml")) == sorted(FAST_YCB_OBJECTS)
    for name in FAST_YCB_OBJECTS:
        s = load_scenario(folder / f"{name}.toml")
        k = s.intrinsics
        assert (k.width_px, k.height_px, s.fps) == (1280, 720, 30)
        # Fast-YCB's 55 deg horizontal field of view, derived here rather than copied from the file
        fov_fx_px = (k.width_px / 2) / math.tan(math.radians(55.0) / 2)
        assert k.fx_px == k.fy_px == pytest.approx(fov_fx_px, rel=1e-12)
        assert (k.cx_px, k.cy_px) == (640.0, 360.0)
        assert s.object.name == name and s.camera.motion is None
        # kind = "hand-motion" with source = "bursty", resolved on load into the minimum-jerk
        # motion the DOPE-like estimator is calibrated on, whether or not ../shared is there
        # (tests/trajectories/test_trajectory_continuous.py checks the file's other choices)
        assert isinstance(s.trajectory, SyntheticMotionConfig)


def test_ci_scenarios_are_small_short_and_need_no_files():
    for path in sorted((REPO / "scenarios" / "ci").glob("*.toml")):
        s = load_scenario(path)
        assert s.intrinsics.width_px <= 320 and s.n_frames / s.fps <= 3.0
        assert isinstance(s.trajectory, SyntheticMotionConfig) and s.object.mesh is None


def test_minimal_scenario_defaults(tmp_path):
    s = load_scenario(_write(tmp_path, MINIMAL))
    assert s.n_frames == 10 and s.fps == 30 and s.seed == 0
    assert s.render.depth_noise == NoDepthNoise() and not s.scene.hand.enabled
    assert s.camera.motion is None and s.frame_time_s(3) == pytest.approx(0.1)


def test_nested_tables_and_kinds_load(tmp_path):
    text = (
        MINIMAL
        + """
[camera.motion]
kind = "sway"
frequency_hz = 1.5
[scene.hand]
enabled = true
finger_count = 3
[render.depth_noise]
kind = "realsense"
subpixel_px = 0.1
"""
    )
    s = load_scenario(_write(tmp_path, text))
    assert s.camera.motion == CameraSwayConfig(frequency_hz=1.5)
    assert s.scene.hand == HandConfig(enabled=True, finger_count=3)
    assert s.render.depth_noise == RealSenseDepthNoise(subpixel_px=0.1)


@pytest.mark.parametrize(
    "edit, message",
    [
        (("frames = 10", "frames = 10\nfps = 30"), r"unknown key 'fps' for Scenario"),
        (
            ("[object]", "[scene.table]\nheigth_m = 0.3\n[object]"),
            r"scene.table: unknown key 'heigth_m'.*did you mean 'height_m'",
        ),
        (("fx_px = 60.0", "fx_px = 'sixty'"), r"camera.fx_px: expected a number, got 'sixty'"),
        (("fx_px = 60.0\n", ""), r"missing required key 'fx_px' for CameraConfig"),
        (("fx_px = 60.0", "fx_px = -60.0"), r"focal lengths must be positive"),
        (("frames = 10", "frames = 10\nduration_s = 2.0"), r"exactly one of duration_s"),
        (("frames = 10", ""), r"exactly one of duration_s"),
        (("frames = 10", "duration_s = 0.01"), r"shorter than one frame at 30 fps"),
        (('name = "003_cracker_box"', "name = 'x'\nmesh = 'x.obj'"), r"exactly one of name"),
        (('kind = "synthetic"', 'kind = "synth"'), r"kind = 'synth' is not known.*'synthetic'"),
        (
            ("[trajectory]", "[render]\nmsaa_samples = 3\n[trajectory]"),
            r"render: .*msaa_samples must be one of 0, 2, 4, 8, 16",
        ),
        (
            ("[trajectory]", "[render.depth_noise]\nkind = 'tof'\n[trajectory]"),
            r"render.depth_noise: kind = 'tof' is not known",
        ),
        (
            ("[trajectory]", "[scene.hand]\npalm_side = 'left'\n[trajectory]"),
            r"scene.hand.palm_side: got 'left', expected one of '\+x'",
        ),
        (("frames = 10", "frames = 10\nseed = -1"), r"seed must be >= 0"),
        (
            ("[trajectory]", "[render]\nzfar_m = 1.0\n[trajectory]"),
            r"background.distance_m = 1.6 m lies beyond render.zfar_m = 1.0 m",
        ),
        (
            ("[trajectory]", "[camera.motion]\nfrequency_hz = 1.0\n[trajectory]"),
            r"camera.motion: missing key 'kind'; add kind = one of .*'sway'",
        ),
    ],
)
def test_bad_scenarios_name_the_file_and_key(tmp_path, edit, message):
    old, new = edit
    assert old in MINIMAL
    path = _write(tmp_path, MINIMAL.replace(old, new, 1))
    with pytest.raises(ConfigError, match=message) as info:
        load_scenario(path)
    assert "scenario.toml" in str(info.value)


def test_missing_file_and_invalid_toml(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        load_scenario(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="is not valid TOML"):
        load_scenario(_write(tmp_path, "name = \n"))


def test_relative_paths_resolve_against_the_scenario_folder(tmp_path):
    sub = tmp_path / "deep"
    sub.mkdir()
    text = MINIMAL.replace('name = "003_cracker_box"', 'mesh = "meshes/thing.obj"')
    s = load_scenario(_write(sub, text))
    assert s.object.mesh == sub.resolve() / "meshes" / "thing.obj"
    absolute = MINIMAL.replace('name = "003_cracker_box"', f'mesh = "{tmp_path / "a.obj"}"')
    assert load_scenario(_write(sub, absolute, "b.toml")).object.mesh == tmp_path / "a.obj"
    captured = MINIMAL.replace(
        'kind = "synthetic"', 'kind = "file"\nformat = "tum"\npath = "motion/walk.txt"'
    )
    s = load_scenario(_write(sub, captured, "c.toml"))
    assert s.trajectory.path == sub.resolve() / "motion" / "walk.txt"


def test_seed_sequences_are_per_subsystem_and_index():
    s = load_scenario_text(MINIMAL + "")
    draw = lambda *key: s.rng(*key).integers(0, 2**62)  # noqa: E731
    assert draw("depth_noise", 3) == draw("depth_noise", 3)
    assert draw("depth_noise", 3) != draw("depth_noise", 4)
    assert draw("depth_noise", 3) != draw("scene_textures", 3)
    other = Scenario(**{**_fields(s), "seed": s.seed + 1})
    assert other.rng("depth_noise", 3).integers(0, 2**62) != draw("depth_noise", 3)
    entropy = s.seed_sequence("scene_textures").entropy
    assert entropy == s.seed


def load_scenario_text(text: str) -> Scenario:
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        return load_scenario(_write(Path(d), text))


def _fields(s: Scenario) -> dict:
    import dataclasses

    return {f.name: getattr(s, f.name) for f in dataclasses.fields(s)}


@pytest.mark.render
@pytest.mark.slow  # about 7 s, most of it generating the procedural stand-in's texture
def test_ci_scenario_renders_on_the_embedded_default():
    from roft_sim.render import SceneRenderer, ground_truth_flow

    scenario = load_scenario(REPO / "scenarios" / "ci" / "cracker_box.toml")
    with SceneRenderer(scenario) as renderer:
        assert renderer.object_assets.source == "procedural"
        f0, f1 = renderer.render_frame(20), renderer.render_frame(21)
    assert f0.object_mask.sum() > 500
    flow = ground_truth_flow(f0, f1, scenario.intrinsics)
    assert np.isfinite(f0.v_obj_mps).all()
    # Oracle: every object pixel moved by the object's relative pose and projected. Frame 20
    # turns a face of the box away, so about a tenth of its pixels are hidden in frame 21 by the
    # box itself; each invalid pixel must be hidden (or leave the image), each valid one seen
    # and moved exactly as the oracle moves it.
    from roft_sim.geometry import backproject_pixels, project_points

    k = scenario.intrinsics
    vs, us = np.nonzero(f0.object_mask)
    uv0 = np.stack([us, vs], axis=1)
    p0 = backproject_pixels(k, uv0, f0.depth_m[vs, us])
    T = f1.T_cam_obj @ np.linalg.inv(f0.T_cam_obj)
    p1 = p0 @ T[:3, :3].T + T[:3, 3]
    uv1 = project_points(k, p1)
    tu, tv = np.rint(uv1).astype(int).T
    inside = (tu >= 0) & (tu < k.width_px) & (tv >= 0) & (tv < k.height_px)
    row, col = np.clip(tv, 0, k.height_px - 1), np.clip(tu, 0, k.width_px - 1)
    behind_m = p1[:, 2] - np.where(inside, f1.depth_m[row, col], 0.0)
    valid = flow.valid[vs, us]
    assert 0.8 < valid.mean() < 1.0  # this pair has self-occlusion
    np.testing.assert_allclose(flow.flow_px[vs, us][valid], (uv1 - uv0)[valid], atol=2e-3)
    assert (~inside[~valid] | (behind_m[~valid] > 0.005)).all()
    assert (inside[valid] & (behind_m[valid] <= 0.005 + 0.01 * p1[valid, 2])).all()


@pytest.mark.render
@pytest.mark.slow
@pytest.mark.parametrize("name", ["mustard_hand_moving_camera", "tomato_off_centre_blur"])
def test_every_ci_scenario_renders(name):
    from roft_sim.render import SceneRenderer, ground_truth_flow

    scenario = load_scenario(REPO / "scenarios" / "ci" / f"{name}.toml")
    with SceneRenderer(scenario) as renderer:
        frames = [renderer.render_frame(k) for k in (0, 1, scenario.n_frames - 1)]
    flow = ground_truth_flow(frames[0], frames[1], scenario.intrinsics)
    assert frames[0].object_mask.sum() > 200 and flow.valid.mean() > 0.8
    if scenario.camera.motion is not None:
        static = (frames[0].body_index == 0) & flow.valid
        assert np.median(np.linalg.norm(flow.flow_px[static], axis=-1)) > 0.1


def test_docs_list_every_key_and_the_example_loads(tmp_path):
    import dataclasses
    import re

    from roft_sim.scenario import CameraConfig, ObjectConfig
    from roft_sim.scene.config import (
        BackgroundConfig,
        LightConfig,
        RenderConfig,
        SceneConfig,
        TableConfig,
    )
    from roft_sim.sensors.depth_noise import KinectAzureDepthNoise

    doc = (REPO / "docs" / "scenarios.md").read_text()
    configs = (
        Scenario,
        CameraConfig,
        CameraSwayConfig,
        ObjectConfig,
        SceneConfig,
        TableConfig,
        BackgroundConfig,
        LightConfig,
        HandConfig,
        RenderConfig,
        RealSenseDepthNoise,
        KinectAzureDepthNoise,
    )
    missing = [
        f"{cls.__name__}.{f.name}"
        for cls in configs
        for f in dataclasses.fields(cls)
        if not any(
            token in doc
            for token in (f"`{f.name}`", f"`{f.name}", f"{f.name}`", f"[{f.name}]", f".{f.name}]")
        )
    ]
    assert not missing, f"undocumented keys: {missing}"
    example = re.findall(r"```toml\n(.*?)```", doc, flags=re.S)[-1]
    s = load_scenario(_write(tmp_path, example))
    assert s.scene.hand.enabled and s.render.motion_blur_subframes == 3
