"""Captured motion end to end: placement, the shared TUM and BVH files, configs from TOML."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from roft_sim.config_files import dataclass_from_mapping, load_dataclass_toml
from roft_sim.errors import ConfigError
from roft_sim.geometry import (
    axis_angle_from_matrix,
    matrix_from_rotvec,
    project_points,
    transform_from_rt,
)
from roft_sim.testing import assert_pose_close
from roft_sim.testing.trajectory_strategies import finite_difference_errors
from roft_sim.trajectories import (
    FAST_YCB_CAMERA,
    CapturedMotionConfig,
    CapturedTrajectory,
    GraspOffset,
    PlacementConfig,
    SplinePoseTrajectory,
    SyntheticMotionConfig,
    TrajectoryConfig,
    ViewRegion,
    build_trajectory,
    read_tum,
    speed_statistics,
    write_trajectory_csv,
)
from roft_sim.trajectories.placement import camera_rotation_from_up, fit_camera_anchor

HANDS = ("CC_Base_L_Hand", "CC_Base_R_Hand")


def knot_midpoints(traj: CapturedTrajectory, stride: int = 5) -> np.ndarray:
    """Interior times between spline knots (every ``stride``-th interval)."""
    k = traj.knot_times_s
    return (k[1:-2] + 0.37 * np.diff(k)[1:-1])[::stride]


def assert_derivatives_exact(traj: CapturedTrajectory, rtol: float = 1e-6) -> None:
    errors = finite_difference_errors(traj, knot_midpoints(traj), h_s=1e-6)
    for name, err in errors.items():
        assert err.max() < rtol, (traj.source, name, float(err.max()))


# --- placement ---------------------------------------------------------------------------------


def test_view_region_points_project_inside_the_image_with_margin() -> None:
    region = ViewRegion.from_config(FAST_YCB_CAMERA, (0.4, 0.9), 0.5, 0.1)
    p = region.sample_points(2000, np.random.default_rng(0))
    assert region.contains(p).all()
    uv = project_points(FAST_YCB_CAMERA, p)
    # 5 cm inside every frustum plane: at least fx * 0.05 / z pixels inside the border
    inside_px = FAST_YCB_CAMERA.fx_px * 0.05 / p[:, 2]
    assert (uv[:, 0] >= -0.5 + 0.99 * inside_px).all()
    assert (uv[:, 0] <= 1279.5 - 0.99 * inside_px).all()
    assert (uv[:, 1] >= -0.5 + 0.99 * inside_px).all()
    assert (uv[:, 1] <= 719.5 - 0.99 * inside_px).all()
    assert not region.contains(np.array([[0.0, 0.0, 0.3], [0.0, 0.0, 1.0], [0.5, 0.0, 0.6]])).any()


def test_camera_rotation_puts_up_at_image_top_and_looks_across_the_motion() -> None:
    rng = np.random.default_rng(1)
    # motion spread along x (1 m) and up z (0.3 m), thin along y: the camera looks along -y
    p = np.column_stack(
        [rng.uniform(-0.5, 0.5, 500), rng.uniform(-0.02, 0.02, 500), rng.uniform(1, 1.3, 500)]
    )
    R = camera_rotation_from_up(p, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ [0, 0, 1.0], [0, -1, 0], atol=1e-12)  # up -> image up (-y)
    assert abs(R[2] @ [0, 1.0, 0]) == pytest.approx(1.0, abs=1e-3)  # looks along the thin axis
    yawed = camera_rotation_from_up(p, [0.0, 0.0, 1.0], np.pi / 2)
    np.testing.assert_allclose(yawed[2], np.cross([0, 0, 1.0], R[2]), atol=1e-12)


def test_fit_anchor_brings_a_fitting_motion_fully_into_view() -> None:
    region = ViewRegion.from_config(FAST_YCB_CAMERA, (0.4, 0.9), 0.5, 0.1)
    rng = np.random.default_rng(2)
    p_world = rng.uniform([-0.2, -0.08, -0.2], [0.2, 0.08, 0.2], (300, 3)) + [5.0, -3.0, 2.0]
    T, fraction = fit_camera_anchor(p_world, region)
    assert fraction == 1.0
    assert region.contains(p_world @ T[:3, :3].T + T[:3, 3]).all()
    # a motion far too large for the view keeps as many samples as possible, not all
    big = rng.uniform(-3, 3, (300, 3))
    _, fraction_big = fit_camera_anchor(big, region)
    assert 0.0 < fraction_big < 0.5


def test_grasp_offset_and_placement_compose_exactly(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    t = np.arange(60) / 30.0
    T_world_hand = transform_from_rt(
        matrix_from_rotvec(np.cumsum(rng.normal(0, 0.1, (60, 3)), axis=0)),
        np.cumsum(rng.normal(0, 0.005, (60, 3)), axis=0) + [1.0, 2.0, 1.2],
    )
    path = tmp_path / "hand.txt"
    rows = [
        f"{ti} {T[0, 3]} {T[1, 3]} {T[2, 3]} {q[1]} {q[2]} {q[3]} {q[0]}"
        for ti, T, q in zip(t, T_world_hand, _quats(T_world_hand), strict=True)
    ]
    path.write_text("\n".join(rows) + "\n")
    grasp = GraspOffset(translation_m=(0.0, 0.05, 0.1), rotvec_rad=(0.3, 0.0, -0.2))
    traj = build_trajectory(
        CapturedMotionConfig(path=path, format="tum", grasp=grasp), FAST_YCB_CAMERA
    )
    assert isinstance(traj, CapturedTrajectory) and traj.in_view_fraction == 1.0
    expected = traj.T_cam_world @ T_world_hand @ grasp.T_hand_obj
    assert_pose_close(traj.sample(t).T_ref_obj, expected, atol_m=1e-9, atol_rad=1e-9)
    np.testing.assert_allclose(traj.T_cam_world[:3, :3] @ [0, 0, 1.0], [0, -1, 0], atol=1e-12)
    assert_derivatives_exact(traj)
    # speeds of the placed object = speeds of the grasped object in the capture frame
    inner = SplinePoseTrajectory(t, T_world_hand).sample(knot_midpoints(traj))
    d = inner.T_ref_obj[:, :3, :3] @ np.array(grasp.translation_m)
    v_obj_world = inner.v_mps + np.cross(inner.w_radps, d)
    placed = traj.sample(knot_midpoints(traj))
    np.testing.assert_allclose(
        placed.linear_speed_mps, np.linalg.norm(v_obj_world, axis=1), rtol=1e-9
    )
    np.testing.assert_allclose(placed.angular_speed_radps, inner.angular_speed_radps, rtol=1e-9)


def _quats(T: np.ndarray) -> np.ndarray:
    from roft_sim.geometry import quat_from_matrix

    return quat_from_matrix(T[:, :3, :3])


def test_camera_frame_files_are_not_moved(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    T = transform_from_rt(
        matrix_from_rotvec(rng.normal(0, 0.5, (10, 3))),
        rng.uniform(-0.1, 0.1, (10, 3)) + [0, 0, 0.6],
    )
    path = tmp_path / "poses.txt"
    np.savetxt(
        path, np.column_stack([T[:, :3, 3], axis_angle_from_matrix(T[:, :3, :3])]), fmt="%.17g"
    )
    traj = build_trajectory(CapturedMotionConfig(path=path, format="fast-ycb"), FAST_YCB_CAMERA)
    assert_pose_close(traj.sample(np.arange(10) / 30.0).T_ref_obj, T, atol_m=1e-12, atol_rad=1e-9)
    np.testing.assert_array_equal(traj.T_cam_world, np.eye(4))
    assert_derivatives_exact(traj)


def test_bop_and_csv_sources_replay_with_exact_derivatives(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    n = 12
    R = matrix_from_rotvec(np.cumsum(rng.normal(0, 0.2, (n, 3)), axis=0))
    t = rng.uniform(-0.05, 0.05, (n, 3)) + [0, 0, 0.6]
    scene = {
        str(i): [
            {"cam_R_m2c": R[i].ravel().tolist(), "cam_t_m2c": (1000 * t[i]).tolist(), "obj_id": 2}
        ]
        for i in range(n)
    }
    (tmp_path / "scene_gt.json").write_text(json.dumps(scene))
    bop = build_trajectory(CapturedMotionConfig(path=tmp_path, format="bop"), FAST_YCB_CAMERA)
    assert_pose_close(
        bop.sample(np.arange(n) / 30.0).T_ref_obj,
        transform_from_rt(R, t),
        atol_m=1e-12,
        atol_rad=1e-9,
    )
    assert_derivatives_exact(bop)
    csv_path = write_trajectory_csv(tmp_path / "t.csv", bop.sample(np.arange(n) / 30.0))
    csv = build_trajectory(CapturedMotionConfig(path=csv_path, format="csv"), FAST_YCB_CAMERA)
    assert_pose_close(
        csv.sample(np.arange(n) / 30.0).T_ref_obj,
        transform_from_rt(R, t),
        atol_m=1e-12,
        atol_rad=1e-9,
    )
    assert_derivatives_exact(csv)


# --- configs -----------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class Holder:
    trajectory: TrajectoryConfig


def test_trajectory_configs_load_from_toml_by_kind(tmp_path: Path) -> None:
    toml = tmp_path / "scenario.toml"
    toml.write_text(
        '[trajectory]\nkind = "file"\npath = "motion/hand.bvh"\nformat = "bvh"\n'
        'joint = "CC_Base_L_Hand"\nrelative_to = "CC_Base_Pelvis"\nlowpass_hz = 10.0\n'
        "window_s = [1.0, 5.0]\nspeed_scale = 0.5\n"
        "[trajectory.grasp]\ntranslation_m = [0.0, 0.0, 0.08]\n"
        "[trajectory.placement]\nworking_distance_m = [0.5, 1.0]\n"
    )
    config = load_dataclass_toml(Holder, toml).trajectory
    assert isinstance(config, CapturedMotionConfig)
    assert config.window_s == (1.0, 5.0) and config.grasp.translation_m == (0.0, 0.0, 0.08)
    assert config.resolved_path(tmp_path) == tmp_path / "motion" / "hand.bvh"
    synthetic = dataclass_from_mapping(Holder, {"trajectory": {"kind": "synthetic", "seed": 9}})
    assert synthetic.trajectory == SyntheticMotionConfig(seed=9)
    with pytest.raises(ConfigError, match="unknown key 'peak_speed' .* valid keys"):
        dataclass_from_mapping(Holder, {"trajectory": {"kind": "synthetic", "peak_speed": 1.0}})


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"format": "bvh"}, "format 'bvh' needs joint"),
        ({"format": "tum", "joint": "x"}, "apply to format 'bvh' only"),
        ({"format": "tum", "object_id": 3}, "object_id applies to format 'bop' only"),
        ({"format": "tum", "sample_rate_hz": 30.0}, "sample_rate_hz applies to formats without"),
        ({"format": "tum", "window_s": (3.0, 1.0)}, "window_s must be"),
        ({"format": "tum", "lowpass_hz": -1.0}, "lowpass_hz must be positive"),
        ({"format": "tum", "speed_scale": 0.0}, "speed_scale must be positive"),
    ],
)
def test_captured_config_errors(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        CapturedMotionConfig(path=Path("x"), **kwargs)


def test_placement_config_errors() -> None:
    with pytest.raises(ConfigError, match="working_distance_m"):
        PlacementConfig(working_distance_m=(0.0, 1.0))
    with pytest.raises(ConfigError, match="min_in_view_fraction"):
        PlacementConfig(min_in_view_fraction=2.0)


# --- the shared captured files -----------------------------------------------------------------


def test_tum_rooms_derivatives_are_exact(tum_smoothed: dict[str, CapturedTrajectory]) -> None:
    for traj in tum_smoothed.values():
        assert_derivatives_exact(traj)


def test_tum_raw_derivatives_are_exact(tum_paths: dict[str, Path]) -> None:
    config = CapturedMotionConfig(
        path=tum_paths["room4"], format="tum", placement=PlacementConfig(min_in_view_fraction=0.0)
    )
    traj = build_trajectory(config, FAST_YCB_CAMERA)
    assert_derivatives_exact(traj)
    # the raw spline passes through the file's poses (placed)
    raw = read_tum(tum_paths["room4"])
    assert_pose_close(
        traj.sample(raw.t_s[:500]).T_ref_obj,
        traj.T_cam_world @ raw.T_ref_obj[:500],
        atol_m=1e-9,
        atol_rad=1e-9,
    )


def test_tum_walking_without_drift_removal_cannot_stay_in_view(tum_paths: dict[str, Path]) -> None:
    with pytest.raises(
        ConfigError, match="only 7 % of the motion stays in view.*remove_drift_window_s"
    ):
        build_trajectory(
            CapturedMotionConfig(path=tum_paths["room2"], format="tum"), FAST_YCB_CAMERA
        )


def test_tum_angular_speed_peaks_after_10_hz_smoothing(
    tum_smoothed: dict[str, CapturedTrajectory],
) -> None:
    """The published figure for these recordings: peaks 226-258 deg/s, p95 140-155 deg/s, away
    from the motion-capture dropouts that the spline bridges."""
    for room, traj in tum_smoothed.items():
        stats = speed_statistics(traj.sample_knots(), exclude_intervals_s=traj.bridged_intervals_s)
        assert 200.0 <= stats.angular_speed_dps.peak <= 260.0, room
        assert 135.0 <= stats.angular_speed_dps.p95 <= 160.0, room
        assert stats.excluded_samples < 0.15 * stats.num_samples
        assert traj.in_view_fraction > 0.5


def test_bvh_hands_derivatives_are_exact(bvh_paths: dict[str, Path]) -> None:
    for trial, path in bvh_paths.items():
        for hand in HANDS:
            for relative_to, lowpass in ((None, None), ("CC_Base_Pelvis", 10.0)):
                config = CapturedMotionConfig(
                    path=path,
                    format="bvh",
                    joint=hand,
                    relative_to=relative_to,
                    lowpass_hz=lowpass,
                    placement=PlacementConfig(min_in_view_fraction=0.0),
                )
                assert_derivatives_exact(build_trajectory(config, FAST_YCB_CAMERA))
                if trial == "002_06":
                    break


def test_bvh_left_hand_relative_to_pelvis_speeds(bvh_paths: dict[str, Path]) -> None:
    """SOURCE.md: the left hand relative to the pelvis peaks at 0.8-1.0 m/s, 164-395 deg/s."""
    for path in bvh_paths.values():
        config = CapturedMotionConfig(
            path=path,
            format="bvh",
            joint="CC_Base_L_Hand",
            relative_to="CC_Base_Pelvis",
            lowpass_hz=10.0,
        )
        traj = build_trajectory(config, FAST_YCB_CAMERA)
        stats = speed_statistics(traj.sample_knots())
        assert 0.7 <= stats.linear_speed_mps.peak <= 1.1
        assert 160.0 <= stats.angular_speed_dps.peak <= 410.0
        assert stats.rate_hz == pytest.approx(60.0)


def test_window_and_speed_scale(bvh_paths: dict[str, Path]) -> None:
    base = dict(
        path=bvh_paths["002_05"], format="bvh", joint="CC_Base_L_Hand", relative_to="CC_Base_Pelvis"
    )
    full = build_trajectory(CapturedMotionConfig(**base), FAST_YCB_CAMERA)
    cut = build_trajectory(
        CapturedMotionConfig(**base, window_s=(2.0, 6.0), speed_scale=0.5), FAST_YCB_CAMERA
    )
    assert (cut.start_s, cut.end_s) == (0.0, pytest.approx(8.0))
    # the same motion, twice as long, half the speed (placement may differ: compare speeds)
    a = full.sample(2.0 + np.linspace(0.5, 3.5, 50))  # away from the cut ends
    b = cut.sample(2.0 * np.linspace(0.5, 3.5, 50))
    np.testing.assert_allclose(b.linear_speed_mps, 0.5 * a.linear_speed_mps, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(
        b.angular_speed_radps, 0.5 * a.angular_speed_radps, rtol=1e-6, atol=1e-9
    )
