"""The independent Fast-YCB checker passes our output and catches seeded defects."""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
from dataset_fixtures import plate_sequence

from roft_sim.cli import main
from roft_sim.datasets import check_fast_ycb_sequence, write_sequence
from roft_sim.datasets.fast_ycb_check import run_fast_ycb_check
from roft_sim.errors import ConfigError
from roft_sim.geometry.se3 import v_o_from_v_obj


@pytest.fixture(scope="module")
def good_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("good")
    return write_sequence(
        plate_sequence(n_frames=8), "fast-ycb", root, flow_encodings={"nvof_1_slow": "s10.5"}
    )


@pytest.fixture
def dataset(good_dataset: Path, tmp_path: Path) -> Path:
    """A fresh copy to damage."""
    return Path(shutil.copytree(good_dataset, tmp_path / good_dataset.name))


def test_our_output_passes(good_dataset: Path):
    report = run_fast_ycb_check(good_dataset)
    assert report.problems == []
    notes = "\n".join(report.notes)
    assert "gt: flow vs. motion field" in notes and "nvof_1_slow: flow vs. motion" in notes
    assert "velocities (linear)" in notes and "velocities (angular)" in notes


def test_moving_camera_output_passes(tmp_path: Path):
    path = write_sequence(plate_sequence(n_frames=5, moving_camera=True), "fast-ycb", tmp_path)
    assert check_fast_ycb_sequence(path) == []


def test_wrong_depth_header(dataset: Path):
    path = dataset / "depth" / "3.float"
    data = bytearray(path.read_bytes())
    data[:16] = struct.pack("<QQ", 48, 64)  # width and height swapped
    path.write_bytes(bytes(data))
    assert check_fast_ycb_sequence(dataset) == [f"{path}: header says 48x64, cam_K.json 64x48"]


def test_truncated_flow_file(dataset: Path):
    path = dataset / "optical_flow" / "gt" / "2.float"
    path.write_bytes(path.read_bytes()[:-8])
    (problem,) = check_fast_ycb_sequence(dataset)
    assert problem.startswith(f"{path}: ") and "header says" in problem


def test_missing_rgb_file(dataset: Path):
    (dataset / "rgb" / "5.png").unlink()
    assert check_fast_ycb_sequence(dataset) == [f"{dataset / 'rgb'}: 1 files missing (indices 5)"]


def test_zero_padded_or_stray_files(dataset: Path):
    (dataset / "rgb" / "3.png").rename(dataset / "rgb" / "03.png")
    problems = check_fast_ycb_sequence(dataset)
    assert any("03.png: unexpected file" in p for p in problems)
    assert any("files missing (indices 3)" in p for p in problems)


def test_non_unit_axis(dataset: Path):
    path = dataset / "gt" / "poses.txt"
    lines = path.read_text().splitlines()
    row = lines[4].split()
    row[3] = str(float(row[3]) * 1.01)
    lines[4] = " ".join(row)
    path.write_text("\n".join(lines) + "\n")
    problems = check_fast_ycb_sequence(dataset)
    assert any(p.startswith(f"{path}, line 5: axis norm") for p in problems), problems


def test_angle_outside_0_pi(dataset: Path):
    path = dataset / "dope" / "poses.txt"
    lines = path.read_text().splitlines()
    row = lines[0].split()
    row[3:7] = ["1", "0", "0", "4"]
    lines[0] = " ".join(row)
    path.write_text("\n".join(lines) + "\n")
    assert check_fast_ycb_sequence(dataset) == [f"{path}, line 1: angle 4.0 is outside [0, pi]"]


def test_dope_misses_are_fine_but_gt_zero_rows_are_not(dataset: Path):
    assert "0 0 0 0 0 0 0" in (dataset / "dope" / "poses.txt").read_text().splitlines()
    path = dataset / "gt" / "poses.txt"
    lines = path.read_text().splitlines()
    lines[2] = "0 0 0 0 0 0 0"
    path.write_text("\n".join(lines) + "\n")
    problems = check_fast_ycb_sequence(dataset)
    assert f"{path}, line 3: a row of zeros (no pose)" in problems


def _rewrite_velocities(dataset: Path, change) -> Path:
    path = dataset / "gt" / "velocities.txt"
    rows = np.loadtxt(path)
    rows = change(rows)
    np.savetxt(path, rows)
    return path


@pytest.mark.parametrize(
    "change",
    [
        pytest.param(lambda r: -r, id="sign-flipped"),
        pytest.param(lambda r: np.roll(r, 2, axis=0), id="shifted-two-frames"),
        pytest.param(lambda r: r * [1000, 1000, 1000, 1, 1, 1], id="mm-per-second"),
        pytest.param(lambda r: r[:, [3, 4, 5, 0, 1, 2]], id="w-before-v"),
    ],
)
def test_inconsistent_velocities(dataset: Path, change):
    path = _rewrite_velocities(dataset, change)
    problems = check_fast_ycb_sequence(dataset)
    assert any(p.startswith(f"{path}: ") and "finite differences" in p for p in problems), problems


def test_roft_spatial_velocity_instead_of_object_velocity_is_caught(dataset: Path):
    T = plate_sequence(n_frames=8).gt.T_cam_obj

    def to_v_o(rows):
        return np.hstack([v_o_from_v_obj(rows[:, :3], rows[:, 3:], T[:, :3, 3]), rows[:, 3:]])

    path = _rewrite_velocities(dataset, to_v_o)
    problems = check_fast_ycb_sequence(dataset)
    assert len(problems) == 1 and problems[0].startswith(f"{path}: linear velocities disagree")


def test_reversed_flow_is_caught(dataset: Path):
    folder = dataset / "optical_flow" / "gt"
    for path in folder.glob("*.float"):
        data = path.read_bytes()
        flow = -np.frombuffer(data, "<f4", offset=20)
        path.write_bytes(data[:20] + flow.astype("<f4").tobytes())
    problems = check_fast_ycb_sequence(dataset)
    assert (
        problems == [p for p in problems if p.startswith(f"{folder}: the flow looks reversed")]
        and len(problems) == 1
    )


def test_flow_off_by_one_frame_is_caught(dataset: Path):
    folder = dataset / "optical_flow" / "gt"
    data = {i: (folder / f"{i}.float").read_bytes() for i in range(1, 8)}
    for i in range(1, 8):  # file i now holds F_{i+1}
        (folder / f"{i}.float").write_bytes(data[min(i + 1, 7)])
    problems = check_fast_ycb_sequence(dataset)
    assert len(problems) == 1
    assert problems[0].startswith(f"{folder}: file k seems to hold the flow from frame k to k+1")


def test_flow_file_0_is_a_defect(dataset: Path):
    shutil.copy(
        dataset / "optical_flow" / "gt" / "1.float", dataset / "optical_flow" / "gt" / "0.float"
    )
    problems = check_fast_ycb_sequence(dataset)
    assert any("0.float: flow file 0 must not exist" in p for p in problems)


def test_unknown_flow_type(dataset: Path):
    path = dataset / "optical_flow" / "nvof_1_slow" / "4.float"
    data = bytearray(path.read_bytes())
    data[:4] = struct.pack("<i", 5)
    path.write_bytes(bytes(data))
    assert check_fast_ycb_sequence(dataset) == [
        f"{path}: OpenCV type 5, expected 13 (CV_32FC2) or 11 (CV_16SC2)"
    ]


def test_mask_of_wrong_size_and_values(dataset: Path):
    import cv2

    path = dataset / "masks" / "gt" / "003_cracker_box_1.png"
    cv2.imwrite(str(path), np.full((10, 10), 7, np.uint8))
    problems = check_fast_ycb_sequence(dataset)
    assert f"{path}: 10x10 px, cam_K.json says 64x48" in problems
    assert f"{path}: values other than 0 and 255" in problems


def test_cam_k_key_order_matters_for_roft_scripts(dataset: Path):
    path = dataset / "cam_K.json"
    text = path.read_text().splitlines()
    text[4], text[5] = text[5], text[4]
    path.write_text("\n".join(text) + "\n")
    problems = check_fast_ycb_sequence(dataset)
    assert any(p.startswith(f"{path}, line 5: expected the 'fx' entry") for p in problems)


def test_nan_row_and_row_count(dataset: Path):
    path = dataset / "dope" / "poses.txt"
    lines = path.read_text().splitlines()
    lines[1] = "nan 0 0 1 0 0 0"
    path.write_text("\n".join(lines[:-1]) + "\n")
    problems = check_fast_ycb_sequence(dataset)
    assert f"{path}, line 2: NaN or inf" in problems


def test_metadata_must_match_and_state_the_velocity_convention(dataset: Path):
    import json

    path = dataset / "metadata.json"
    meta = json.loads(path.read_text())
    meta["n_frames"] = 9
    del meta["conventions"]["velocity"]
    path.write_text(json.dumps(meta))
    problems = check_fast_ycb_sequence(dataset)
    assert f"{path}: n_frames = 9 but data.txt has 8 rows" in problems
    assert any("velocity convention" in p for p in problems)


def test_missing_cam_k_stops_early(dataset: Path):
    (dataset / "cam_K.json").unlink()
    assert check_fast_ycb_sequence(dataset) == [f"{dataset / 'cam_K.json'}: missing"]


def test_cli_check_exit_codes(good_dataset: Path, dataset: Path, capsys):
    assert main(["dataset", "check", str(good_dataset)]) == 0
    assert capsys.readouterr().out.startswith("OK ")
    (dataset / "depth" / "0.float").unlink()
    assert main(["dataset", "check", str(dataset)]) == 1
    out = capsys.readouterr().out
    assert out.startswith("FAIL") and "files missing (indices 0)" in out


def test_cli_check_json_and_other_formats(tmp_path: Path, capsys):
    import json

    seq = plate_sequence(n_frames=3)
    for fmt in ("bop", "hdf5", "fast-ycb"):
        write_sequence(seq, fmt, tmp_path / fmt)
    assert main(["dataset", "check", str(tmp_path), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert sorted(r["format"] for r in result["sequences"]) == ["bop", "fast-ycb", "hdf5"]
    assert all(r["problems"] == [] for r in result["sequences"])
    depth = tmp_path / "bop" / "000001" / "depth" / "000001.png"  # scenes are numbered
    depth.write_bytes(depth.read_bytes()[:40])
    assert main(["dataset", "check", str(tmp_path / "bop")]) == 1
    assert "frame 1 depth" in capsys.readouterr().out


def test_cli_info_and_convert(tmp_path: Path, capsys):
    import json

    write_sequence(plate_sequence(n_frames=3), "fast-ycb", tmp_path / "src")
    assert main(["dataset", "info", str(tmp_path / "src"), "--json"]) == 0
    (info,) = json.loads(capsys.readouterr().out)["sequences"]
    assert info["n_frames"] == 3 and info["flow_sets"]["nvof_1_slow"]["grid_px"] == 4
    assert info["pose_sets"]["dope"]["valid_fraction"] == 1.0 and info["seed"] == 3
    assert main(["dataset", "convert", str(tmp_path / "src"), "--to", "hdf5", "--out",
                 str(tmp_path / "out")]) == 0  # fmt: skip
    assert (tmp_path / "out" / "plate_seq.h5").is_file()
    assert main(["dataset", "convert", str(tmp_path / "src"), "--to", "hdf5", "--out",
                 str(tmp_path / "out")]) == 2  # fmt: skip
    assert "not empty" in capsys.readouterr().err
    assert main(["dataset", "info", str(tmp_path / "nothing")]) == 2


@pytest.mark.parametrize("verb", ["check", "info", "convert"])
def test_cli_a_missing_path_is_a_usage_error_like_run(verb: str, tmp_path: Path, capsys):
    """Review regression: a missing PATH exited 1 while an empty folder (and roft-sim run with a
    missing path) exit 2."""
    out = tmp_path / "out"
    extra = ["--to", "hdf5", "--out", str(out)] if verb == "convert" else []
    missing = tmp_path / "nothing"
    assert main(["dataset", verb, str(missing), *extra]) == 2
    assert f"dataset path {str(missing)!r} does not exist" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["dataset", verb, str(tmp_path / "empty"), *extra]) == 2
    assert "no sequence found under" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("frames", ["0", "-1"])
def test_cli_check_needs_at_least_one_flow_frame(good_dataset: Path, frames: str, capsys):
    """Review regression: --max-flow-frames -1 silently skipped the flow-direction check."""
    assert main(["dataset", "check", str(good_dataset), "--max-flow-frames", frames]) == 2
    assert "--max-flow-frames must be at least 1" in capsys.readouterr().err


def test_library_check_needs_at_least_one_flow_frame(good_dataset: Path):
    with pytest.raises(ConfigError, match="max_flow_frames must be >= 1, got 0"):
        run_fast_ycb_check(good_dataset, max_flow_frames=0)
