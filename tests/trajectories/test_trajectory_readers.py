"""Importers: TUM, BVH, Fast-YCB, BOP and CSV; real files where shared, errors on malformed ones."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from roft_sim.errors import ConfigError, DatasetFormatError
from roft_sim.geometry import (
    axis_angle_from_matrix,
    matrix_from_rotvec,
    transform_from_rt,
)
from roft_sim.testing import assert_pose_close
from roft_sim.trajectories import (
    BvhMotion,
    bvh_pose_samples,
    read_bop_scene_gt,
    read_bvh,
    read_fast_ycb_poses,
    read_pose_samples,
    read_trajectory_csv,
    read_tum,
    write_trajectory_csv,
)
from roft_sim.trajectories.bvh import detect_bvh_unit
from roft_sim.trajectories.samples import find_gaps
from roft_sim.trajectories.trajectory_csv import CSV_COLUMNS


def random_transforms(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return transform_from_rt(
        matrix_from_rotvec(rng.normal(0, 1.0, (n, 3))), rng.uniform(-0.3, 0.3, (n, 3)) + [0, 0, 0.7]
    )


# --- TUM ---------------------------------------------------------------------------------------


def test_tum_reads_the_shared_room_files(tum_paths: dict[str, Path]) -> None:
    samples = read_tum(tum_paths["room1"])
    assert len(samples) == 16541
    assert samples.t_s[0] == 0.0
    assert samples.nominal_rate_hz == pytest.approx(120.0, rel=1e-3)
    # first line: 1520530308.18968 0.841782 -0.219335 1.249975 0.003737 0.009717 -0.024328 0.999650
    q_xyzw = np.array([0.003737, 0.009717, -0.024328, 0.999650])
    R = Rotation.from_quat(q_xyzw / np.linalg.norm(q_xyzw)).as_matrix()
    expected = transform_from_rt(R, [0.841782, -0.219335, 1.249975])
    assert_pose_close(samples.T_ref_obj[0], expected, atol_m=1e-12, atol_rad=1e-12)
    # the second stamp 1520530308.19801 is read exactly, relative to the first
    assert samples.t_s[1] == pytest.approx(0.00833, abs=1e-12)
    np.testing.assert_array_equal(samples.up_ref, [0, 0, 1])
    assert len(find_gaps(samples.t_s)) == 28  # motion-capture dropouts
    for room in ("room2", "room4"):
        assert len(read_tum(tum_paths[room])) > 13000


TUM_GOOD = "# timestamp tx ty tz qx qy qz qw\n" + "".join(
    f"{100 + k * 0.01:.2f} 0.1 0.2 0.3 0 0 0 1\n" for k in range(5)
)


@pytest.mark.parametrize(
    ("bad_line", "message"),
    [
        ("100.05 0.1 0.2 0.3 0 0 0", r"line 7: 7 fields, expected 8 \(truncated"),
        ("100.05 0.1 nan 0.3 0 0 0 1", "line 7: NaN or infinite"),
        ("100.05 0.1 0.2 0.3 0 0 0.1 1", "line 7: quaternion .* has norm 1.00499"),
        ("100.05 0.1 0.2 0.3 0 0 0 x", "line 7: .* not a number"),
        ("100.03 0.1 0.2 0.3 0 0 0 1", "line 7: time stamp 100.03 does not increase"),
    ],
)
def test_tum_malformed_lines_name_file_line_and_fix(
    tmp_path: Path, bad_line: str, message: str
) -> None:
    path = tmp_path / "bad.txt"
    path.write_text(TUM_GOOD + bad_line + "\n")
    with pytest.raises(DatasetFormatError, match=f"bad.txt'.*{message}"):
        read_tum(path)


def test_tum_missing_or_short_file(tmp_path: Path) -> None:
    with pytest.raises(DatasetFormatError, match="does not exist"):
        read_tum(tmp_path / "nope.txt")
    path = tmp_path / "short.txt"
    path.write_text("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n")
    with pytest.raises(DatasetFormatError, match="holds 2 poses; a trajectory needs at least 4"):
        read_tum(path)


# --- BVH ---------------------------------------------------------------------------------------

TINY_BVH = """HIERARCHY
ROOT Hips
{{
  OFFSET 0 {root_y} 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT Arm
  {{
    OFFSET {arm} 0 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    JOINT Hand
    {{
      OFFSET 0 -{hand} 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {{
        OFFSET 0 -{tip} 0
      }}
    }}
  }}
}}
MOTION
Frames: {frames}
Frame Time: 0.033333
"""

TINY_VALUES = np.array(
    [
        [1.0, 2.0, 3.0, 10.0, 20.0, 30.0, 40.0, -50.0, 60.0, 5.0, 15.0, -25.0],
        [2.0, 1.0, 0.0, -30.0, 5.0, 80.0, 0.0, 90.0, 10.0, -45.0, 30.0, 60.0],
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [5.0, -4.0, 3.0, 170.0, -80.0, 45.0, 120.0, 33.0, -70.0, 11.0, -22.0, 33.0],
    ]
)


def write_tiny_bvh(path: Path, scale: float = 1.0, values: np.ndarray = TINY_VALUES) -> Path:
    """A 3-joint skeleton whose longest chain is 100 units * scale (cm when scale = 1)."""
    header = TINY_BVH.format(
        root_y=90 * scale, arm=40 * scale, hand=50 * scale, tip=10 * scale, frames=len(values)
    )
    rows = values.copy()
    rows[:, :3] *= scale
    path.write_text(header + "".join(" ".join(f"{v:.6f}" for v in r) + "\n" for r in rows))
    return path


def expected_tiny_hand(values: np.ndarray, metres_per_unit: float) -> np.ndarray:
    """Forward kinematics with scipy's intrinsic Euler angles (upper-case sequences)."""

    def local(offset: list[float], seq: str, angles: np.ndarray, pos=None) -> np.ndarray:
        t = np.array(offset, dtype=float) + (0 if pos is None else pos)
        return transform_from_rt(Rotation.from_euler(seq, angles, degrees=True).as_matrix(), t)

    out = []
    for r in values:
        root = local([0, 90, 0], "ZYX", r[3:6], pos=r[:3])
        arm = local([40, 0, 0], "XYZ", r[6:9])
        hand = local([0, -50, 0], "ZXY", r[9:12])
        out.append(root @ arm @ hand)
    T = np.array(out)
    T[:, :3, 3] *= metres_per_unit
    return T


def test_bvh_forward_kinematics_against_scipy_euler(tmp_path: Path) -> None:
    motion = read_bvh(write_tiny_bvh(tmp_path / "tiny.bvh"))
    assert motion.unit == "cm"
    assert motion.frame_time_s == 1.0 / 30.0  # 0.033333 is 1/30 rounded to 6 decimals
    assert motion.joint_names == ("Hips", "Arm", "Hand")
    samples = bvh_pose_samples(motion, "Hand")
    assert_pose_close(
        samples.T_ref_obj, expected_tiny_hand(TINY_VALUES, 0.01), atol_m=1e-12, atol_rad=1e-12
    )
    np.testing.assert_allclose(samples.t_s, np.arange(4) / 30.0)


@pytest.mark.parametrize(
    ("scale", "unit"), [(0.01, "m"), (1 / 2.54, "in"), (1.0, "cm"), (10.0, "mm")]
)
def test_bvh_unit_detection_from_skeleton_size(tmp_path: Path, scale: float, unit: str) -> None:
    motion = read_bvh(write_tiny_bvh(tmp_path / "tiny.bvh", scale=scale))
    assert motion.unit == unit
    T = bvh_pose_samples(motion, "Hand").T_ref_obj
    assert_pose_close(T, expected_tiny_hand(TINY_VALUES, 0.01), atol_m=1e-6, atol_rad=1e-12)


def test_detect_bvh_unit_boundaries() -> None:
    assert [detect_bvh_unit(x) for x in (1.3, 6.0, 7.0, 60.0, 65.0, 300.0, 330.0)] == [
        "m",
        "m",
        "in",
        "in",
        "cm",
        "cm",
        "mm",
    ]


def test_bvh_relative_to_removes_the_parent_motion(tmp_path: Path) -> None:
    motion = read_bvh(write_tiny_bvh(tmp_path / "tiny.bvh"))
    rel = bvh_pose_samples(motion, "Hand", relative_to="Hips").T_ref_obj
    hips = motion.global_transforms("Hips")
    hand = motion.global_transforms("Hand")
    expected = hips[0] @ np.linalg.inv(hips) @ hand
    assert_pose_close(rel, expected, atol_m=1e-12, atol_rad=1e-12)
    # relative to itself the joint stands still at its first pose
    still = bvh_pose_samples(motion, "Hand", relative_to="Hand").T_ref_obj
    assert_pose_close(still, np.broadcast_to(hand[0], still.shape), atol_m=1e-12, atol_rad=1e-9)


def test_bvh_reads_the_shared_files(bvh_motions: dict[str, BvhMotion]) -> None:
    frames = {"002_05": 927, "002_06": 1118}
    for trial, motion in bvh_motions.items():
        assert motion.num_frames == frames[trial]
        assert motion.frame_time_s == 1.0 / 60.0
        assert motion.unit == "cm"
        assert len(motion.joints) == 100 and motion.joints[0].name == "CC_Base_Hip"
        head_height_m = motion.global_transforms("CC_Base_Head")[:, 1, 3]
        assert (
            head_height_m.min() > 0.5 and 1.5 < head_height_m.max() < 1.9
        )  # an adult (002_06 crouches)
        for hand in ("CC_Base_L_Hand", "CC_Base_R_Hand"):
            samples = bvh_pose_samples(motion, hand, relative_to="CC_Base_Pelvis")
            assert len(samples) == frames[trial]
            assert np.isfinite(samples.T_ref_obj).all()


def test_bvh_unknown_joint_lists_the_available_ones(bvh_motions: dict[str, BvhMotion]) -> None:
    with pytest.raises(
        ConfigError, match=r"no joint 'CC_Base_L_Hnd'; did you mean 'CC_Base_L_Hand'"
    ):
        bvh_pose_samples(bvh_motions["002_05"], "CC_Base_L_Hnd")
    with pytest.raises(
        ConfigError, match="available joints: CC_Base_Hip, CC_Base_Pelvis, .*CC_Base_R_Hand"
    ):
        bvh_pose_samples(bvh_motions["002_05"], "Wrist")


def _tiny_text(tmp_path: Path) -> str:
    return write_tiny_bvh(tmp_path / "tiny.bvh").read_text()


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (
            lambda s: s.rsplit(" ", 3)[0] + "\n",
            r"line 27: frame 3 has 9 values, .* 12 channels \(truncated",
        ),
        (
            lambda s: s.replace("40.000000 -50.000000", "nan -50.000000"),
            "line 24: frame 0 contains NaN",
        ),
        (lambda s: s.replace("Frames: 4", "Frames: 5"), r"line 22: 'Frames: 5' but 4 frame lines"),
        (
            lambda s: s.replace("Xrotation Yrotation Zrotation", "Xrotation Wrotation Zrotation"),
            "line 9: unknown channel 'Wrotation' of joint 'Arm'",
        ),
        (lambda s: s.replace("MOTION", "MOTON"), "no MOTION line"),
        (
            lambda s: s.replace("OFFSET 40.0 0 0", "OFFSET 40.0 zero 0"),
            "line 8: OFFSET value 'zero'",
        ),
    ],
)
def test_bvh_malformed_files_name_line_and_fix(tmp_path: Path, edit, message: str) -> None:
    path = tmp_path / "bad.bvh"
    path.write_text(edit(_tiny_text(tmp_path)))
    with pytest.raises(DatasetFormatError, match=f"bad.bvh'.*{message}"):
        read_bvh(path)


# --- Fast-YCB ----------------------------------------------------------------------------------


def write_fast_ycb(path: Path, T: np.ndarray) -> Path:
    rows = np.column_stack([T[:, :3, 3], axis_angle_from_matrix(T[:, :3, :3])])
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(path, rows, fmt="%.17g")
    return path


def test_fast_ycb_poses_round_trip(tmp_path: Path) -> None:
    T = random_transforms(12, seed=3)
    write_fast_ycb(tmp_path / "seq" / "gt" / "poses.txt", T)
    samples = read_fast_ycb_poses(tmp_path / "seq")  # the sequence folder works too
    assert_pose_close(samples.T_ref_obj, T, atol_m=1e-15, atol_rad=1e-12)
    np.testing.assert_allclose(samples.t_s, np.arange(12) / 30.0)
    assert samples.camera_frame


@pytest.mark.parametrize(
    ("bad_line", "message"),
    [
        ("0.1 0.2 0.7 0 0 1", r"line 5: 6 fields, expected 7 \(truncated"),
        ("0.1 0.2 nan 0 0 1 0.5", "line 5: NaN"),
        ("0 0 0 0 0 0 0", "line 5: a row of seven zeros marks a missing detection"),
        ("0.1 0.2 0.7 0 0 2 0.5", "line 5: rotation axis .* has length 2"),
    ],
)
def test_fast_ycb_malformed(tmp_path: Path, bad_line: str, message: str) -> None:
    path = write_fast_ycb(tmp_path / "poses.txt", random_transforms(4, seed=4))
    path.write_text(path.read_text() + bad_line + "\n")
    with pytest.raises(DatasetFormatError, match=f"poses.txt'.*{message}"):
        read_fast_ycb_poses(path)


# --- BOP ---------------------------------------------------------------------------------------


def write_scene_gt(path: Path, T: np.ndarray, other: np.ndarray, image_ids: list[int]) -> Path:
    data = {
        str(i): [
            {
                "cam_R_m2c": other[k, :3, :3].ravel().tolist(),
                "cam_t_m2c": (1000 * other[k, :3, 3]).tolist(),
                "obj_id": 1,
            },
            {
                "cam_R_m2c": T[k, :3, :3].ravel().tolist(),
                "cam_t_m2c": (1000 * T[k, :3, 3]).tolist(),
                "obj_id": 5,
            },
        ]
        for k, i in enumerate(image_ids)
    }
    path.write_text(json.dumps(data, indent=1))
    return path


def test_bop_scene_gt_reads_one_object_in_metres(tmp_path: Path) -> None:
    T = random_transforms(6, seed=5)
    ids = [0, 1, 2, 4, 5, 6]  # image 3 missing: a gap in time
    path = write_scene_gt(tmp_path / "scene_gt.json", T, random_transforms(6, seed=6), ids)
    samples = read_bop_scene_gt(tmp_path, object_id=5, rate_hz=10.0)
    assert_pose_close(samples.T_ref_obj, T, atol_m=1e-12, atol_rad=1e-9)
    np.testing.assert_allclose(samples.t_s, np.array(ids) / 10.0)
    with pytest.raises(ConfigError, match=r"shows objects \[1, 5\]; choose one with object_id"):
        read_bop_scene_gt(path)
    with pytest.raises(ConfigError, match="no object with obj_id 7"):
        read_bop_scene_gt(path, object_id=7)


def test_bop_malformed(tmp_path: Path) -> None:
    T = random_transforms(4, seed=7)
    path = write_scene_gt(tmp_path / "scene_gt.json", T, T, [0, 1, 2, 3])
    text = path.read_text()
    path.write_text(text[:-5])
    with pytest.raises(DatasetFormatError, match=r"scene_gt.json', line \d+: not valid JSON"):
        read_bop_scene_gt(path, object_id=5)
    data = json.loads(text)
    data["2"][1]["cam_R_m2c"] = (-np.eye(3)).ravel().tolist()  # a reflection
    path.write_text(json.dumps(data))
    with pytest.raises(DatasetFormatError, match="image 2: cam_R_m2c is not a rotation"):
        read_bop_scene_gt(path, object_id=5)
    data = json.loads(text)
    data["1"][1]["cam_t_m2c"] = [1.0, 2.0]
    path.write_text(json.dumps(data))
    with pytest.raises(DatasetFormatError, match="image 1: cam_R_m2c has 9 values .* cam_t_m2c 2"):
        read_bop_scene_gt(path, object_id=5)


# --- CSV ---------------------------------------------------------------------------------------


def test_csv_write_read_is_exact(tmp_path: Path) -> None:
    from roft_sim.trajectories import (
        FAST_YCB_CAMERA,
        SyntheticMotionConfig,
        build_trajectory,
        sample_at_rate,
    )

    sample = sample_at_rate(build_trajectory(SyntheticMotionConfig(seed=3), FAST_YCB_CAMERA), 30.0)
    path = write_trajectory_csv(tmp_path / "t.csv", sample, comments=["provenance"])
    header = [ln for ln in path.read_text().splitlines() if not ln.startswith("#")][0]
    assert header.startswith(",".join(CSV_COLUMNS))
    track = read_trajectory_csv(path)
    assert_pose_close(track.T_cam_obj, sample.T_ref_obj, atol_m=1e-9, atol_rad=1e-9)
    np.testing.assert_array_equal(track.t_s, sample.t_s)
    np.testing.assert_allclose(track.v_obj_mps, sample.v_mps, rtol=0, atol=1e-15)
    np.testing.assert_allclose(track.w_radps, sample.w_radps, rtol=0, atol=1e-15)
    samples = read_pose_samples(path, "csv")
    assert samples.camera_frame and samples.t_s[0] == 0.0


CSV_HEAD = ",".join(CSV_COLUMNS) + "\n"
CSV_ROW = "{t},0.1,0.2,0.7,1,0,0,0,0,0,0,0,0,0\n"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "t,x,y\n",
            "line 1: header 't,x,y' is not a trajectory CSV header; the header must start with t_s",
        ),
        (
            CSV_HEAD + CSV_ROW.format(t=0) + "0.1,0.1,0.2\n",
            r"line 3: 3 columns, the header has 14 \(truncated",
        ),
        (CSV_HEAD + CSV_ROW.format(t="nan"), "line 2: NaN"),
        (
            CSV_HEAD + "0,0.1,0.2,0.7,1,1,0,0,0,0,0,0,0,0\n",
            r"line 2: quaternion \(qw, qx, qy, qz\) .* norm 1.41421",
        ),
        (
            CSV_HEAD + CSV_ROW.format(t=1) + CSV_ROW.format(t=1),
            "line 3: t_s = 1.0 does not increase",
        ),
    ],
)
def test_csv_malformed(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(DatasetFormatError, match=f"bad.csv'.*{message}"):
        read_trajectory_csv(path)


def test_read_pose_samples_dispatch_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="needs a joint"):
        read_pose_samples(tmp_path / "x.bvh", "bvh")
    with pytest.raises(ConfigError, match="is not one of"):
        read_pose_samples(tmp_path / "x", "c3d")  # type: ignore[arg-type]
