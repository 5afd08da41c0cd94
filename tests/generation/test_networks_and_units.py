"""The [networks] table, scenario overrides, presets and work units (no rendering)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from roft_sim.assets.registry import FAST_YCB_OBJECTS
from roft_sim.errors import ConfigError
from roft_sim.generation import (
    PRESETS,
    ScenarioOverrides,
    WorkUnit,
    parse_resolution,
    parse_shard,
    plan_work_units,
    preset_scenario_paths,
    sequence_name_for,
    shard_work_units,
    shipped_scenarios_dir,
)
from roft_sim.generation.runner import _budgeted
from roft_sim.records import PoseTrack
from roft_sim.scenario import load_scenario
from roft_sim.sensors.networks import (
    FlowSetConfig,
    NetworksConfig,
    parse_generation_flow_source,
)
from roft_sim.sensors.pose_estimator import PoseEstimatorConfig, sample_pose_detections

CI_SCENARIO = """
name = "net_test"
frames = 10
[camera]
width_px = 160
height_px = 120
fx_px = 150.0
fy_px = 150.0
cx_px = 79.5
cy_px = 59.5
[object]
name = "003_cracker_box"
[trajectory]
kind = "synthetic"
duration_s = 2.0
"""


def _load(tmp_path, extra: str):
    path = tmp_path / "s.toml"
    path.write_text(CI_SCENARIO + extra)
    return load_scenario(path)


# ------------------------------------------------------------------------ [networks] table
def test_defaults_reproduce_the_reference_fast_ycb_set_names():
    n = NetworksConfig()
    assert n.pose.enabled and n.pose.set_name == "dope"
    assert n.mask.enabled and n.mask.set_name == "mrcnn_ycbv_bop_pbr"
    assert [(f.set_name, f.source, f.encoding) for f in n.flow_sets] == [
        ("gt", "gt", "float32"),
        ("nvof_1_slow", "nvof-model", "s10.5"),
    ]
    assert n.flow_encodings == {"gt": "float32", "nvof_1_slow": "s10.5"}
    assert n.pose.estimator == PoseEstimatorConfig()


def test_a_scenario_without_networks_gets_the_defaults(tmp_path):
    assert _load(tmp_path, "").networks == NetworksConfig()


def test_networks_table_is_loaded_strictly(tmp_path):
    scenario = _load(
        tmp_path,
        """
[networks.pose]
set_name = "dope_noisy"
[networks.pose.estimator]
rotation_sigma_rad = 0.2
[networks.mask]
enabled = false
[[networks.flow_sets]]
set_name = "noisy"
source = "gt+noise"
[networks.flow_sets.noise]
sigma_px = 1.5
[[networks.flow_sets]]
set_name = "nvof"
source = "nvof-like:gt"
encoding = "s10.5"
""",
    )
    n = scenario.networks
    assert n.pose.set_name == "dope_noisy" and n.pose.estimator.rotation_sigma_rad == 0.2
    assert not n.mask.enabled
    assert [f.set_name for f in n.flow_sets] == ["noisy", "nvof"]
    assert n.flow_sets[0].noise.sigma_px == 1.5
    assert n.flow_sets[1].source_spec.inner.kind == "gt"


def test_an_empty_flow_set_list_writes_no_flow(tmp_path):
    assert _load(tmp_path, "[networks]\nflow_sets = []\n").networks.flow_sets == ()


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        ("[networks]\nflows = []\n", r"unknown key 'flows'.*did you mean 'flow_sets'"),
        ("[networks.pose]\nset_name = 'gt'\n", "reserved for ground truth"),
        ("[networks.mask]\nset_name = 'gt_full'\n", "reserved for ground truth"),
        ("[networks.mask]\nset_name = 'a/b'\n", "not usable as a folder name"),
        ("[networks.pose.estimator]\noutlier_fraction = 1.5\n", "outlier_fraction must be in"),
        (
            "[[networks.flow_sets]]\nset_name = 'f'\nsource = 'raft'\n",
            r"unknown flow source 'raft'.*gt\+noise",
        ),
        (
            "[[networks.flow_sets]]\nset_name = 'f'\nsource = 'dis:slowest'\n",
            "unknown DIS preset 'slowest'",
        ),
        (
            "[[networks.flow_sets]]\nset_name = 'f'\nsource = 'gt'\nencoding = 'int8'\n",
            "expected one of 'float32', 's10.5'",
        ),
        (
            "[[networks.flow_sets]]\nset_name = 'f'\nsource = 'gt'\n"
            "[[networks.flow_sets]]\nset_name = 'f'\nsource = 'dis'\n",
            r"set names \['f'\] appear more than once",
        ),
    ],
)
def test_bad_networks_tables_name_the_key_and_the_fix(tmp_path, extra, match):
    with pytest.raises(ConfigError, match=match):
        _load(tmp_path, extra)


def test_flow_source_grammar():
    assert parse_generation_flow_source("dis").dis_preset == "medium"
    assert parse_generation_flow_source("dis:fast").dis_preset == "fast"
    spec = parse_generation_flow_source("nvof-like:gt+noise")
    assert spec.kind == "nvof-like" and spec.inner.kind == "gt+noise" and spec.uses("gt+noise")
    assert parse_generation_flow_source("bm").bm_window_px == 8
    spec = parse_generation_flow_source("nvof-like:bm:16")
    assert spec.inner.kind == "bm" and spec.inner.bm_window_px == 16
    for bad in ("nvof-like", "nvof-like:nvof-like:gt", "stored:nvof_1_slow", "gt:x", "", "bm:x"):
        with pytest.raises(ConfigError):
            parse_generation_flow_source(bad)
    with pytest.raises(ConfigError, match="window_px"):
        parse_generation_flow_source("bm:7")  # not centred on a 4x4 block
    with pytest.raises(ConfigError, match="flow set name"):
        FlowSetConfig(set_name="../x", source="gt")


# ------------------------------------------------------------------------------- overrides
def test_resolution_override_scales_the_intrinsics_like_a_resize(tmp_path):
    scenario = load_scenario(shipped_scenarios_dir() / "fast_ycb" / "003_cracker_box.toml")
    small = ScenarioOverrides(resolution=(640, 360), frames=30, seed=7).apply(scenario)
    assert small.intrinsics == scenario.intrinsics.resized(640, 360)
    assert small.intrinsics.fx_px == pytest.approx(scenario.intrinsics.fx_px / 2)
    assert small.intrinsics.cx_px == pytest.approx((640.0 + 0.5) / 2 - 0.5)  # pixel centres
    assert (small.n_frames, small.frames, small.duration_s, small.seed) == (30, 30, None, 7)
    assert small.trajectory == scenario.trajectory  # the motion keeps its own seed
    assert ScenarioOverrides().apply(scenario) is scenario


@pytest.mark.parametrize("text", ["640", "640x", "x480", "4x4", "640*480", "-640x480"])
def test_bad_resolutions_are_refused(text):
    with pytest.raises(ConfigError, match="WIDTHxHEIGHT"):
        parse_resolution(text)
    assert parse_resolution(" 1280X720 ") == (1280, 720)


def test_overrides_are_validated():
    with pytest.raises(ConfigError, match="--frames must be >= 1"):
        ScenarioOverrides(frames=0)
    with pytest.raises(ConfigError, match="--seed must be >= 0"):
        ScenarioOverrides(seed=-1)


# --------------------------------------------------------------------------------- presets
def test_fast_ycb_preset_is_the_six_objects_named_like_the_reference():
    paths = preset_scenario_paths("fast-ycb")
    scenarios = [load_scenario(p) for p in paths]
    names = [sequence_name_for(s, PRESETS["fast-ycb"].sequence_names) for s in scenarios]
    assert names == list(FAST_YCB_OBJECTS)
    for s in scenarios:
        assert (s.intrinsics.width_px, s.intrinsics.height_px, s.fps) == (1280, 720, 30)
        assert s.networks == NetworksConfig()
    assert [sequence_name_for(load_scenario(p), "scenario") for p in paths][0] == (
        "fast_ycb_003_cracker_box"
    )


def test_unknown_preset_lists_the_known_ones():
    with pytest.raises(ConfigError, match="unknown preset 'fastycb'; expected one of fast-ycb"):
        preset_scenario_paths("fastycb")


# ------------------------------------------------------------------------------ work units
@given(
    st.lists(st.sets(st.integers(0, 60), max_size=40), min_size=1, max_size=4),
    st.integers(1, 9),
)
def test_units_cover_exactly_the_missing_frames_in_bounded_chunks(missing, chunk):
    units = plan_work_units(missing, chunk_frames=chunk)
    for seq, frames in enumerate(missing):
        covered = [k for u in units if u.sequence == seq for k in range(u.start, u.stop)]
        assert sorted(covered) == sorted(frames)  # each missing frame exactly once
    assert all(1 <= u.n_frames <= chunk for u in units)
    assert units == sorted(units)


@given(st.integers(1, 30), st.integers(1, 5))
def test_shards_are_disjoint_and_cover_every_unit(n_units, count):
    units = plan_work_units([range(n_units)], chunk_frames=1)
    shards = [shard_work_units(units, i, count) for i in range(count)]
    assert sorted(u for s in shards for u in s) == units


def test_shard_and_unit_errors():
    assert parse_shard("2/4") == (1, 4)
    for bad in ("0/4", "5/4", "a/b", "3"):
        with pytest.raises(ConfigError, match="shard"):
            parse_shard(bad)
    with pytest.raises(ConfigError, match="chunk_frames must be >= 1"):
        plan_work_units([[0]], chunk_frames=0)
    with pytest.raises(ValueError, match="invalid work unit"):
        WorkUnit(0, 5, 5)


def test_a_frame_budget_cuts_the_unit_list_exactly():
    units = plan_work_units([range(10), range(4)], chunk_frames=4)
    cut = _budgeted(units, 9)
    assert sum(u.n_frames for u in cut) == 9
    assert cut[-1] == WorkUnit(0, 8, 9)
    assert _budgeted(units, 0) == [] and _budgeted(units, None) == units


# ------------------------------------------------- the pose estimator, frame by frame
def test_pose_estimator_frame_k_depends_only_on_frame_k_pose_and_visibility():
    """The generator computes frame k's detection from the whole GT track and frame k's visible
    fraction only (other frames' visible fractions are unknown to a worker). That is exact when
    the estimator is local in its inputs, which this test holds the estimator to."""
    rng = np.random.default_rng(4)
    n = 200
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, :3, 3] = rng.uniform([-0.1, -0.1, 0.5], [0.1, 0.1, 0.9], (n, 3))
    track = PoseTrack(
        t_s=np.arange(n) / 30.0, T_cam_obj=T, v_obj_mps=np.zeros((n, 3)), w_radps=np.zeros((n, 3))
    )
    vis = rng.uniform(0.0, 1.0, n)
    config = PoseEstimatorConfig()
    full = sample_pose_detections(track, config, np.random.default_rng(9), visible_fraction=vis)
    for k in rng.choice(n, 25, replace=False):
        only_k = np.ones(n)
        only_k[k] = vis[k]
        other_poses = T.copy()
        other_poses[np.arange(n) != k, :3, 3] += 0.05
        moved = dataclasses.replace(track, T_cam_obj=other_poses)
        one = sample_pose_detections(
            moved, config, np.random.default_rng(9), visible_fraction=only_k
        )
        assert one.valid[k] == full.valid[k]
        assert one.outlier_kind[k] == full.outlier_kind[k]
        np.testing.assert_array_equal(one.T_cam_obj[k], full.T_cam_obj[k])


# ------------------------------------------------- flow-set noise under nvof-like
def test_nvof_like_gt_noise_is_drawn_in_full_resolution_pixels_then_block_reduced():
    """``nvof-like:gt+noise``: the ``noise`` lengths are full-resolution pixels (the noise is
    drawn per pixel of the exact flow), and the 4x4 block then reduces it to one vector (its L1
    medoid, the vectors disagreeing by more than 1/4 px): white noise of ``sigma_px`` leaves
    about 0.37 ``sigma_px`` per block, not ``sigma_px`` (docs/generate.md)."""
    from roft_sim.geometry import CameraIntrinsics
    from roft_sim.records import FlowField
    from roft_sim.sensors.flow_sources import FlowNoiseConfig

    sequence_generator = pytest.importorskip("roft_sim.generation.sequence_generator")

    cam = CameraIntrinsics(
        fx_px=100.0, fy_px=100.0, cx_px=63.5, cy_px=63.5, width_px=128, height_px=128
    )
    # 4 px: the block std (1.5 px) stays far above NVOF's 1/4 px rounding
    noise = FlowNoiseConfig(sigma_px=4.0, relative_sigma=0.0, correlation_px=0.0,
                            outlier_fraction=0.0)  # fmt: skip
    config = FlowSetConfig(set_name="n", source="nvof-like:gt+noise", noise=noise)
    source = sequence_generator._flow_source(config.source_spec, config, seed=3)

    class Pair:  # the exact flow of a frame pair, as the generator memoises it
        name, intrinsics = "pair", cam
        memo = {"gt": FlowField(flow_px=np.zeros((128, 128, 2), np.float32), from_k=0, to_k=1)}

        def __len__(self):
            return 2

    flow = source.flow(Pair(), 0, 1)
    assert flow.grid_px == 4 and flow.flow_px.shape == (32, 32, 2)
    assert flow.flow_px.std() == pytest.approx(0.37 * 4.0, rel=0.1)
