"""``roft-sim trajectory stats|export``, run in-process."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from roft_sim.cli import main
from roft_sim.testing import assert_pose_close
from roft_sim.trajectories import (
    CSV_COLUMNS,
    FAST_YCB_CAMERA,
    CapturedMotionConfig,
    SyntheticMotionConfig,
    build_trajectory,
    read_trajectory_csv,
    sample_at_rate,
)

HEADER = ",".join(CSV_COLUMNS)


def csv_header(path: Path) -> str:
    return next(line for line in path.read_text().splitlines() if not line.startswith("#"))


def test_stats_json_on_a_tum_room(
    tum_paths: dict[str, Path], capsys: pytest.CaptureFixture
) -> None:
    argv = ["trajectory", "stats", str(tum_paths["room4"]), "--format", "tum", "--lowpass-hz", "10"]
    argv += ["--drift-window-s", "2", "--json"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["duration_s"] == pytest.approx(111.36, abs=0.01)
    assert report["rate_hz"] == pytest.approx(120.05, abs=0.01)
    for key in ("linear_speed_mps", "angular_speed_dps"):
        assert set(report[key]) >= {"peak", "p95", "median"}
    assert 200 < report["angular_speed_dps"]["peak"] < 260
    assert report["excluded_samples"] > 0


def test_stats_table_on_a_bvh_hand(
    bvh_paths: dict[str, Path], capsys: pytest.CaptureFixture
) -> None:
    argv = ["trajectory", "stats", str(bvh_paths["002_05"]), "--format", "bvh"]
    argv += ["--joint", "CC_Base_R_Hand", "--relative-to", "CC_Base_Pelvis", "--lowpass-hz", "10"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "rate 60.000 Hz, 927 samples" in out
    assert "angular [deg/s]" in out and "linear [m/s]" in out


def test_export_synthetic_rereads_to_1e9(tmp_path: Path) -> None:
    out = tmp_path / "traj.csv"
    argv = ["trajectory", "export", "--synthetic", "--seed", "4", "--duration-s", "5"]
    assert main([*argv, "--fps", "30", "--out", str(out)]) == 0
    assert csv_header(out).startswith(HEADER)
    track = read_trajectory_csv(out)
    expected = sample_at_rate(
        build_trajectory(SyntheticMotionConfig(seed=4, duration_s=5.0), FAST_YCB_CAMERA), 30.0
    )
    assert len(track) == 151
    np.testing.assert_array_equal(track.t_s, np.arange(151) / 30.0)
    assert_pose_close(track.T_cam_obj, expected.T_ref_obj, atol_m=1e-9, atol_rad=1e-9)
    np.testing.assert_allclose(track.v_obj_mps, expected.v_mps, rtol=0, atol=1e-12)
    np.testing.assert_allclose(track.w_radps, expected.w_radps, rtol=0, atol=1e-12)
    # an existing file is kept unless --overwrite
    assert main([*argv, "--out", str(out)]) == 2
    assert main([*argv, "--out", str(out), "--overwrite"]) == 0


def test_export_placed_capture_and_reexport_csv(tmp_path: Path, bvh_paths: dict[str, Path]) -> None:
    out, again = tmp_path / "hand.csv", tmp_path / "again.csv"
    source = ["--format", "bvh", "--joint", "CC_Base_L_Hand", "--relative-to", "CC_Base_Pelvis"]
    assert (
        main(
            [
                "trajectory",
                "export",
                str(bvh_paths["002_06"]),
                *source,
                "--fps",
                "30",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    track = read_trajectory_csv(out)
    config = CapturedMotionConfig(
        path=bvh_paths["002_06"], format="bvh", joint="CC_Base_L_Hand", relative_to="CC_Base_Pelvis"
    )
    placed = build_trajectory(config, FAST_YCB_CAMERA).sample(track.t_s)
    assert_pose_close(track.T_cam_obj, placed.T_ref_obj, atol_m=1e-9, atol_rad=1e-9)
    z = track.T_cam_obj[:, 2, 3]
    assert z.min() >= 0.4 and z.max() <= 0.9  # placed at the working distance
    # the CSV is a camera-frame format: exporting it again at the same rate keeps every pose
    assert (
        main(
            [
                "trajectory",
                "export",
                str(out),
                "--format",
                "csv",
                "--fps",
                "30",
                "--out",
                str(again),
            ]
        )
        == 0
    )
    assert_pose_close(
        read_trajectory_csv(again).T_cam_obj, track.T_cam_obj, atol_m=1e-9, atol_rad=1e-9
    )


@pytest.mark.parametrize(
    ("argv", "code", "message"),
    [
        (["trajectory", "stats", "x.txt", "--format", "tum", "--synthetic"], 2, "not both"),
        (["trajectory", "stats", "x.txt"], 2, "give FILE and --format"),
        (
            ["trajectory", "stats", "--format", "bvh", "{bvh}", "--joint", "Hnd"],
            2,
            "available joints",
        ),
        (["trajectory", "stats", "{bvh}", "--format", "tum"], 1, "line 1: 1 fields, expected 8"),
        (["trajectory", "stats", "missing.txt", "--format", "tum"], 1, "does not exist"),
        (["trajectory", "stats", "--synthetic", "--duration-s", "0.5"], 2, "too short"),
        (
            ["trajectory", "export", "--synthetic", "--out", "{tmp}/no/such/dir/t.csv"],
            2,
            "does not exist",
        ),
    ],
)
def test_cli_errors_exit_2_for_usage_and_1_for_bad_files(
    argv: list[str],
    code: int,
    message: str,
    bvh_paths: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture,
) -> None:
    argv = [a.format(bvh=bvh_paths["002_05"], tmp=tmp_path) for a in argv]
    assert main(argv) == code
    assert message in capsys.readouterr().err


def test_stats_ignore_placement_export_needs_it_in_view(
    bvh_paths: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """The right hand's scooping in 002_06 is too tall for 0.4-0.9 m: stats still report it,
    export refuses until the working distance is widened."""
    source = [str(bvh_paths["002_06"]), "--format", "bvh", "--joint", "CC_Base_R_Hand"]
    source += ["--relative-to", "CC_Base_Pelvis"]
    assert main(["trajectory", "stats", *source]) == 0
    assert "placed in view: 30 % of the samples" in capsys.readouterr().out
    out = tmp_path / "r.csv"
    assert main(["trajectory", "export", *source, "--out", str(out)]) == 2
    assert "only 30 % of the motion stays in view" in capsys.readouterr().err
    wider = ["--working-distance-m", "0.6", "1.6"]
    assert main(["trajectory", "export", *source, *wider, "--out", str(out)]) == 0
    z = read_trajectory_csv(out).T_cam_obj[:, 2, 3]
    assert z.min() > 0.4 and z.max() < 1.7
