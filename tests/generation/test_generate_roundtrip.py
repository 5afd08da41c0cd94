"""A generated dataset, read back with open_sequence, equals an independent in-process render of
the same frames: every array bit-exact (BOP depth to its 0.1 mm quantum), poses to 1e-9, and the
simulated networks equal the sensors' own functions fed with the read-back ground truth.

Scenario: the CI hand + moving camera + RealSense-noise scenario at 160x120, 4 frames, so ground
truth flow has a moving background and a hand, and the sensor depth is noisy.
"""

from __future__ import annotations

import numpy as np
import pytest
from generation_cases import render_oracle, run_generate, tiny_scenario, visible_fractions

from roft_sim.datasets import GT_FULL_MASK_SET, GT_MASK_SET, check_fast_ycb_sequence, open_sequence
from roft_sim.records import PoseTrack
from roft_sim.sensors.pose_estimator import simulate_pose_detections
from roft_sim.sensors.segmenter import simulate_mask

pytestmark = pytest.mark.render

ATOL_POSE = 1e-9
"""Pose tolerance [m] and rotation-matrix entries."""
BOP_DEPTH_ATOL_M = 0.05e-3 + 1e-7
"""BOP depth: uint16 in 0.1 mm steps, rounded to nearest (docs/formats.md), plus float32 slack."""


@pytest.fixture(scope="module")
def scenario():
    return tiny_scenario(frames=4)


@pytest.fixture(scope="module")
def oracle(scenario):
    return render_oracle(scenario)


@pytest.fixture(scope="module", params=["fast-ycb", "bop", "hdf5"])
def generated(request, scenario, tmp_path_factory):
    out = tmp_path_factory.mktemp(f"gen_{request.param}")
    summary = run_generate([scenario], out, format=request.param)
    assert summary.finished and summary.frames_generated == scenario.n_frames
    (result,) = summary.sequences
    return request.param, result.path


def test_images_depth_masks_and_flows_are_bit_exact(scenario, oracle, generated):
    fmt, path = generated
    seq = open_sequence(path)
    assert len(seq) == scenario.n_frames
    assert seq.intrinsics == scenario.intrinsics
    assert seq.fps == scenario.fps
    assert set(seq.flow_sets()) == {"gt", "nvof_1_slow"}
    assert set(seq.mask_sets()) == {GT_MASK_SET, GT_FULL_MASK_SET, "mrcnn_ycbv_bop_pbr"}
    assert seq.pose_sets() == ("dope",)
    for k, frame in enumerate(oracle.frames):
        np.testing.assert_array_equal(seq.rgb(k), frame.rgb, err_msg=f"rgb {k}")
        depth = seq.depth(k)
        assert depth.dtype == np.float32
        if fmt == "bop":
            np.testing.assert_allclose(depth, frame.sensor_depth_m, rtol=0, atol=BOP_DEPTH_ATOL_M)
        else:
            np.testing.assert_array_equal(depth, frame.sensor_depth_m, err_msg=f"depth {k}")
        np.testing.assert_array_equal(seq.mask(k, GT_MASK_SET), frame.object_mask)
        np.testing.assert_array_equal(seq.mask(k, GT_FULL_MASK_SET), oracle.full_masks[k])
        if k == 0:
            continue
        gt = seq.flow(k, "gt")
        want = oracle.gt_flows[k]
        assert gt.grid_px == 1 and (gt.from_k, gt.to_k) == (k - 1, k)
        np.testing.assert_array_equal(gt.flow_px, want.flow_px, err_msg=f"gt flow {k}")
        np.testing.assert_array_equal(gt.valid, want.valid, err_msg=f"gt flow validity {k}")
        nvof = seq.flow(k, "nvof_1_slow")
        want = oracle.nvof_flows[k]
        assert nvof.grid_px == 4
        np.testing.assert_array_equal(nvof.flow_px, want.flow_px, err_msg=f"nvof flow {k}")
    # The scene really exercises the pipeline: background flow (moving camera), hand occlusion.
    assert any(np.abs(f.flow_px[f.valid]).max() > 0.5 for f in oracle.gt_flows[1:])
    assert any(
        (full & ~f.object_mask).any()
        for full, f in zip(oracle.full_masks, oracle.frames, strict=True)
    )


def test_ground_truth_poses_velocities_and_camera(scenario, oracle, generated):
    _, path = generated
    seq = open_sequence(path)
    gt = seq.ground_truth()
    cams = seq.camera_poses()
    for k, frame in enumerate(oracle.frames):
        np.testing.assert_allclose(gt.T_cam_obj[k], frame.T_cam_obj, rtol=0, atol=ATOL_POSE)
        np.testing.assert_allclose(gt.v_obj_mps[k], frame.v_obj_mps, rtol=0, atol=ATOL_POSE)
        np.testing.assert_allclose(gt.w_radps[k], frame.w_radps, rtol=0, atol=ATOL_POSE)
        np.testing.assert_allclose(cams[k], frame.T_world_cam, rtol=0, atol=ATOL_POSE)
        assert gt.t_s[k] == pytest.approx(k / scenario.fps, abs=1e-12)


def test_simulated_networks_equal_the_sensor_models_on_read_back_ground_truth(scenario, generated):
    """Detections in the file == the sensors' functions run on the file's own ground truth with
    the documented streams: the pose estimator on the whole track with
    ``scenario.rng("pose_estimator")``, the segmenter per frame with
    ``scenario.rng("segmenter", k)``."""
    _, path = generated
    seq = open_sequence(path)
    n = len(seq)
    visible = [seq.mask(k, GT_MASK_SET) for k in range(n)]
    full = [seq.mask(k, GT_FULL_MASK_SET) for k in range(n)]
    gt = seq.ground_truth()
    track = PoseTrack(
        t_s=np.arange(n) / scenario.fps,
        T_cam_obj=gt.T_cam_obj,
        v_obj_mps=gt.v_obj_mps,
        w_radps=gt.w_radps,
    )
    vis = visible_fractions(visible, full)
    want = simulate_pose_detections(
        track,
        scenario.networks.pose.estimator_for(scenario.object.name_or_path),
        scenario.rng("pose_estimator"),
        visible_fraction=vis,
    )
    got = seq.detector_poses("dope")
    assert got.valid.sum() >= 2, "the test needs detections to compare"
    np.testing.assert_array_equal(got.valid, want.valid)
    np.testing.assert_allclose(
        got.T_cam_obj[got.valid], want.T_cam_obj[want.valid], rtol=0, atol=ATOL_POSE
    )
    stored_masks = 0
    for k in range(n):
        mask = simulate_mask(
            visible[k],
            scenario.networks.mask.segmenter,
            scenario.rng("segmenter", k),
            visible_fraction=float(vis[k]),
        )
        stored = seq.mask(k, "mrcnn_ycbv_bop_pbr")
        if mask is None:
            assert stored is None, f"frame {k}: a miss must have no mask"
        else:
            np.testing.assert_array_equal(stored, mask, err_msg=f"segmenter mask {k}")
            assert not np.array_equal(mask, visible[k]), "the segmenter adds artefacts"
            stored_masks += 1
    assert stored_masks >= 2, "the test needs segmenter masks to compare"


def test_metadata_records_scenario_seed_and_sets(scenario, generated):
    fmt, path = generated
    meta = open_sequence(path).metadata()
    assert meta["seed"] == scenario.seed
    assert meta["scenario"]["name"] == scenario.name
    assert meta["scenario"]["camera"]["width_px"] == 160
    assert meta["generator"]["flow_sets"]["nvof_1_slow"] == {
        "source": "nvof-model",
        "encoding": "s10.5",
    }
    assert meta["sets"]["flow"]["nvof_1_slow"] == {"encoding": "s10.5", "grid_px": 4}
    assert meta["format"] == fmt
    assert "mujoco" in meta["generator"]["render"]


def test_format_layout_and_the_independent_fast_ycb_checker(generated):
    fmt, path = generated
    if fmt == "hdf5":
        assert path.suffix == ".h5" and path.is_file()
        assert not path.with_name(path.name + ".parts").exists()
        return
    if fmt == "bop":
        for name in ("scene_camera.json", "scene_gt.json", "scene_gt_info.json", "metadata.json"):
            assert (path / name).is_file(), name
        assert len(list((path / "mask_visib").iterdir())) == 4
        return
    assert check_fast_ycb_sequence(path) == []
    assert sorted(p.name for p in path.iterdir()) == [
        "cam_K.json",
        "data.txt",
        "depth",
        "dope",
        "gt",
        "masks",
        "metadata.json",
        "models",
        "optical_flow",
        "optical_flow_valid",
        "rgb",
    ]
    assert len(list((path / "optical_flow" / "nvof_1_slow").iterdir())) == 3  # no file for k = 0


def test_configured_flow_sources_and_disabled_networks(oracle, scenario, tmp_path):
    """gt+noise == apply_flow_noise(gt, its noise, frame_rng(flow_set_seed, k-1, k));
    nvof-like:gt == the sensors' NVOF-like reduction of gt; dis:fast == OpenCV DIS fast;
    nvof-like:bm:16 == the sensors' block matcher with a 16 px window, reduced; a disabled network
    writes no set."""
    import dataclasses

    from roft_sim.generation.sequence_generator import flow_set_seed
    from roft_sim.sensors.block_matching import BlockMatchingConfig, BlockMatchingFlowSource
    from roft_sim.sensors.flow_sources import (
        DisFlowSource,
        FlowNoiseConfig,
        NvofLikeFlowSource,
        apply_flow_noise,
        frame_rng,
    )
    from roft_sim.sensors.networks import FlowSetConfig

    noise = FlowNoiseConfig(sigma_px=0.7, outlier_fraction=0.05, hole_fraction=0.1)
    networks = dataclasses.replace(
        scenario.networks,
        pose=dataclasses.replace(scenario.networks.pose, enabled=False),
        mask=dataclasses.replace(scenario.networks.mask, enabled=False),
        flow_sets=(
            FlowSetConfig(set_name="noisy", source="gt+noise", noise=noise),
            FlowSetConfig(set_name="nvof_gt", source="nvof-like:gt", encoding="s10.5"),
            FlowSetConfig(set_name="dis_fast", source="dis:fast"),
            FlowSetConfig(set_name="nvof_bm16", source="nvof-like:bm:16", encoding="s10.5"),
        ),
    )
    custom = dataclasses.replace(scenario, networks=networks)
    (result,) = run_generate([custom], tmp_path, format="hdf5").sequences
    seq = open_sequence(result.path)
    assert seq.pose_sets() == () and set(seq.mask_sets()) == {GT_MASK_SET, GT_FULL_MASK_SET}
    assert set(seq.flow_sets()) == {"noisy", "nvof_gt", "dis_fast", "nvof_bm16"}

    class Gt:  # the oracle's exact flow as a flow source
        name = "gt"

        def flow(self, _seq, from_k, to_k):
            return oracle.gt_flows[to_k]

    class Frames:
        name, intrinsics = custom.name, custom.intrinsics

        def __len__(self):
            return custom.n_frames

        def rgb(self, k):
            return oracle.frames[k].rgb

    seed = flow_set_seed(custom, "noisy")
    for k in range(1, custom.n_frames):
        want = apply_flow_noise(oracle.gt_flows[k], noise, frame_rng(seed, k - 1, k))
        got = seq.flow(k, "noisy")
        np.testing.assert_array_equal(got.flow_px, want.flow_px)
        np.testing.assert_array_equal(got.valid, want.valid)
        assert not np.array_equal(got.flow_px, oracle.gt_flows[k].flow_px)
        want = NvofLikeFlowSource(Gt()).flow(Frames(), k - 1, k)
        np.testing.assert_array_equal(seq.flow(k, "nvof_gt").flow_px, want.flow_px)
        want = DisFlowSource("fast").flow(Frames(), k - 1, k)
        np.testing.assert_array_equal(seq.flow(k, "dis_fast").flow_px, want.flow_px)
        bm16 = BlockMatchingFlowSource(BlockMatchingConfig(window_px=16))
        want = NvofLikeFlowSource(bm16).flow(Frames(), k - 1, k)
        np.testing.assert_array_equal(seq.flow(k, "nvof_bm16").flow_px, want.flow_px)
