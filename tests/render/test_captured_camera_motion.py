"""Captured camera motion (``[camera.motion] kind = "file"``): the replayed poses match the
recorded motion anchored at the rest pose, the object's velocity relative to the moving camera is
the derivative of its relative pose, and the background flow matches a reprojection oracle built
from the recorded poses alone."""

from __future__ import annotations

import numpy as np
import pytest
from stand_ins import SinusoidalTrajectory, open_renderer, small_scenario

from roft_sim.errors import ConfigError
from roft_sim.geometry import (
    backproject_pixels,
    invert_transform,
    matrix_from_rotvec,
    project_points,
    quat_from_matrix,
    rotvec_from_matrix,
    transform_points,
)
from roft_sim.render import ground_truth_flow
from roft_sim.scenario import CameraConfig
from roft_sim.scene.camera_motion import camera_poses
from roft_sim.scene.config import CameraFileMotionConfig
from roft_sim.trajectories.placement import GraspOffset

RATE_HZ = 240.0


def _recorded_pose(t):
    """The analytic 'recorded' body pose (capture frame), (N, 4, 4)."""
    t = np.atleast_1d(t)
    T = np.broadcast_to(np.eye(4), (len(t), 4, 4)).copy()
    T[:, :3, 3] = np.column_stack(
        [1.0 + 0.08 * np.sin(2.1 * t), 0.5 + 0.05 * np.sin(1.3 * t + 1), 1.6 + 0.03 * t]
    )
    T[:, :3, :3] = matrix_from_rotvec(
        np.column_stack([0.15 * np.sin(1.7 * t), 0.3 + 0.1 * np.sin(0.9 * t), 0.05 * t])
    )
    return T


def _write_tum(path, duration_s=3.0):
    t = np.arange(0.0, duration_s, 1.0 / RATE_HZ)
    T = _recorded_pose(t)
    q = quat_from_matrix(T[:, :3, :3])  # (w, x, y, z)
    rows = [
        f"{ti + 100.0:.6f} {p[0]:.9f} {p[1]:.9f} {p[2]:.9f} {qq[1]:.9f} {qq[2]:.9f} {qq[3]:.9f} "
        f"{qq[0]:.9f}"
        for ti, p, qq in zip(t, T[:, :3, 3], q, strict=True)
    ]
    path.write_text("# timestamp tx ty tz qx qy qz qw\n" + "\n".join(rows) + "\n")
    return path


def _config(tmp_path, **kw):
    return CameraFileMotionConfig(path=_write_tum(tmp_path / "cam.txt"), format="tum", **kw)


def test_replayed_camera_is_the_recording_anchored_at_rest(tmp_path):
    T_body_cam = GraspOffset(translation_m=(0.01, -0.02, 0.03), rotvec_rad=(0.1, 0.2, -0.1))
    config = _config(tmp_path, camera_in_body=T_body_cam)
    t = np.linspace(0.0, 2.5, 11)
    poses = camera_poses(config, t)
    X = T_body_cam.T_hand_obj
    expected = invert_transform(_recorded_pose(0.0)[0] @ X) @ _recorded_pose(t) @ X
    np.testing.assert_allclose(poses.T_world_cam[0], np.eye(4), atol=1e-9)
    np.testing.assert_allclose(poses.T_world_cam, expected, atol=2e-6)
    h = 1e-4  # exact velocities: the derivatives of the recorded motion itself
    anchor = invert_transform(_recorded_pose(0.0)[0] @ X)
    Tp = anchor @ _recorded_pose(t + h) @ X
    Tm = anchor @ _recorded_pose(t - h) @ X
    v_fd = (Tp[:, :3, 3] - Tm[:, :3, 3]) / (2 * h)
    w_fd = rotvec_from_matrix(Tp[:, :3, :3] @ np.swapaxes(Tm[:, :3, :3], 1, 2)) / (2 * h)
    np.testing.assert_allclose(poses.v_world_mps, v_fd, atol=2e-4)
    np.testing.assert_allclose(poses.w_world_radps, w_fd, atol=2e-4)
    assert np.linalg.norm(poses.v_world_mps, axis=1).max() > 0.1


def test_a_scenario_longer_than_the_recording_is_an_error(tmp_path):
    with pytest.raises(ConfigError, match="camera motion .* lasts"):
        camera_poses(_config(tmp_path), np.array([0.0, 10.0]))
    with pytest.raises(ConfigError, match="needs joint"):
        CameraFileMotionConfig(path=tmp_path / "x.bvh", format="bvh")


def _scenario(config):
    camera = CameraConfig(
        width_px=160, height_px=120, fx_px=180.0, fy_px=180.0, cx_px=79.5, cy_px=59.5, fps=30,
        motion=config,
    )  # fmt: skip
    return small_scenario(camera=camera)


@pytest.mark.render
def test_relative_velocity_is_the_derivative_of_the_relative_pose(tmp_path):
    scenario = _scenario(_config(tmp_path))
    with open_renderer(scenario, trajectory=SinusoidalTrajectory()) as r:
        h = 1e-5
        for t in (0.2, 0.7, 1.3):
            s, sp, sm = r.state_at(t), r.state_at(t + h), r.state_at(t - h)
            v_fd = (sp.T_cam_obj[:3, 3] - sm.T_cam_obj[:3, 3]) / (2 * h)
            R_rel = sp.T_cam_obj[:3, :3] @ sm.T_cam_obj[:3, :3].T
            np.testing.assert_allclose(s.v_obj_mps, v_fd, atol=1e-5)
            np.testing.assert_allclose(s.w_radps, rotvec_from_matrix(R_rel) / (2 * h), atol=1e-5)
            cam = camera_poses(scenario.camera.motion, np.array([t]))
            np.testing.assert_array_equal(s.camera_v_world_mps, cam.v_world_mps[0])
            assert np.linalg.norm(s.camera_v_world_mps) > 0.01


@pytest.mark.render
def test_background_flow_matches_reprojection_with_the_recorded_poses(tmp_path):
    scenario = _scenario(_config(tmp_path))
    with open_renderer(scenario, trajectory=SinusoidalTrajectory()) as r:
        f0, f1 = r.render_frame(3), r.render_frame(4)
    flow = ground_truth_flow(f0, f1, scenario.intrinsics)
    # Oracle: world points of the static background at frame 3, seen by the camera at frame 4,
    # both camera poses taken from the analytic recording (not from the renderer).
    anchor = invert_transform(_recorded_pose(0.0)[0])
    T_w_c0 = anchor @ _recorded_pose(3 / 30)[0]
    T_w_c1 = anchor @ _recorded_pose(4 / 30)[0]
    static = (f0.body_index == 0) & flow.valid
    assert static.sum() > 5000
    v, u = np.nonzero(static)
    pix = np.column_stack([u, v]).astype(np.float64)
    p_c0 = backproject_pixels(scenario.intrinsics, pix, f0.depth_m[v, u].astype(np.float64))
    p_c1 = transform_points(invert_transform(T_w_c1) @ T_w_c0, p_c0)
    expected = project_points(scenario.intrinsics, p_c1) - pix
    err = np.linalg.norm(flow.flow_px[v, u] - expected, axis=1)
    assert np.median(np.linalg.norm(expected, axis=1)) > 0.5  # the background does move
    assert np.percentile(err, 99) < 0.02, f"p99 {np.percentile(err, 99):.4f} px"


def test_a_relative_camera_file_resolves_against_the_scenario_file(tmp_path):
    from roft_sim.scenario import load_scenario

    (tmp_path / "sub").mkdir()
    _write_tum(tmp_path / "sub" / "cam.txt")
    (tmp_path / "sub" / "s.toml").write_text(
        'name = "s"\nframes = 2\n[camera]\nwidth_px = 64\nheight_px = 48\nfx_px = 60.0\n'
        "fy_px = 60.0\ncx_px = 31.5\ncy_px = 23.5\n"
        '[camera.motion]\nkind = "file"\npath = "cam.txt"\nformat = "tum"\n'
        'lowpass_hz = 10.0\n[object]\nname = "009_gelatin_box"\n[trajectory]\nkind = "synthetic"\n'
    )
    scenario = load_scenario(tmp_path / "sub" / "s.toml")
    assert scenario.camera.motion.path == tmp_path / "sub" / "cam.txt"
    poses = camera_poses(scenario.camera.motion, np.array([0.0, 1.0]))
    np.testing.assert_allclose(poses.T_world_cam[0], np.eye(4), atol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize(
    "fmt,file,joint",
    [("tum", "tum/dataset-room1_512_16.txt", None), ("bvh", "bvh/002_05.bvh", "CC_Base_Head")],
)
def test_real_captured_camera_motion_has_exact_velocities(
    shared_trajectories_dir, fmt, file, joint
):
    """TUM VI room 1 (a hand-held rig) and a CMU mocap head, cleaned as the docs suggest: the
    camera starts at rest, its twist is the derivative of its poses, and it stays near its rest
    pose (drift removed)."""
    config = CameraFileMotionConfig(
        path=shared_trajectories_dir / file,
        format=fmt,
        joint=joint,
        lowpass_hz=10.0,
        remove_drift_window_s=2.0,
        window_s=(2.0, 14.0),
    )
    t = np.linspace(0.5, 11.0, 30)
    h = 1e-5
    poses, plus, minus = (camera_poses(config, t + d) for d in (0.0, h, -h))
    v_fd = (plus.T_world_cam[:, :3, 3] - minus.T_world_cam[:, :3, 3]) / (2 * h)
    R_p, R_m = plus.T_world_cam[:, :3, :3], minus.T_world_cam[:, :3, :3]
    w_fd = rotvec_from_matrix(R_p @ np.swapaxes(R_m, 1, 2)) / (2 * h)
    np.testing.assert_allclose(poses.v_world_mps, v_fd, atol=1e-5)
    np.testing.assert_allclose(poses.w_world_radps, w_fd, atol=1e-5)
    np.testing.assert_allclose(camera_poses(config, 0.0).T_world_cam[0], np.eye(4), atol=1e-9)
    assert np.linalg.norm(poses.T_world_cam[:, :3, 3], axis=1).max() < 0.5  # no walking away
    assert np.linalg.norm(poses.w_world_radps, axis=1).max() > 0.05  # it does move
