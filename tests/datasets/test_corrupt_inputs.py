"""Corrupt inputs to every reader raise DatasetFormatError naming the file and the problem."""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import h5py
import numpy as np
import pytest
from dataset_fixtures import plate_sequence

from roft_sim.datasets import detect_format, list_sequences, open_sequence, write_sequence
from roft_sim.errors import DatasetFormatError


@pytest.fixture(scope="module")
def written(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("written")
    seq = plate_sequence(n_frames=4)
    return {fmt: write_sequence(seq, fmt, root / fmt) for fmt in ("fast-ycb", "bop", "hdf5")}


@pytest.fixture
def fast_ycb(written: dict[str, Path], tmp_path: Path) -> Path:
    return Path(shutil.copytree(written["fast-ycb"], tmp_path / "seq"))


@pytest.fixture
def bop(written: dict[str, Path], tmp_path: Path) -> Path:
    return Path(shutil.copytree(written["bop"], tmp_path / "scene"))


@pytest.fixture
def hdf5(written: dict[str, Path], tmp_path: Path) -> Path:
    return Path(shutil.copy(written["hdf5"], tmp_path / "seq.h5"))


def _edit_line(path: Path, line: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[line - 1] = text
    path.write_text("\n".join(lines) + "\n")


# ------------------------------------------------------------------------------- fast-ycb
def test_truncated_depth(fast_ycb: Path):
    path = fast_ycb / "depth" / "2.float"
    path.write_bytes(path.read_bytes()[:-100])
    with pytest.raises(DatasetFormatError, match=rf"depth file '{path}' has .* bytes; its header"):
        open_sequence(fast_ycb).depth(2)


def test_depth_header_with_another_size(fast_ycb: Path):
    path = fast_ycb / "depth" / "1.float"
    path.write_bytes(struct.pack("<QQ", 32, 96) + path.read_bytes()[16:])
    with pytest.raises(DatasetFormatError, match=rf"'{path}' is 32x96; the camera is 64x48"):
        open_sequence(fast_ycb).depth(1)


def test_depth_header_claiming_a_huge_image(fast_ycb: Path):
    path = fast_ycb / "depth" / "1.float"
    path.write_bytes(struct.pack("<QQ", 2**40, 2**40) + path.read_bytes()[16:])
    with pytest.raises(DatasetFormatError, match="header width = 1099511627776 is not a plausible"):
        open_sequence(fast_ycb).depth(1)


def test_nan_depth(fast_ycb: Path):
    path = fast_ycb / "depth" / "0.float"
    data = bytearray(path.read_bytes())
    data[16 + 4 * 70 : 16 + 4 * 71] = struct.pack("<f", float("nan"))
    path.write_bytes(bytes(data))
    with pytest.raises(DatasetFormatError, match=r"NaN/inf values \(first at row 1, column 6\)"):
        open_sequence(fast_ycb).depth(0)


def test_flow_with_a_wrong_type_or_size(fast_ycb: Path):
    path = fast_ycb / "optical_flow" / "gt" / "1.float"
    good = path.read_bytes()
    path.write_bytes(struct.pack("<i", 6) + good[4:])
    seq = open_sequence(fast_ycb)
    with pytest.raises(DatasetFormatError, match=rf"flow file '{path}' has OpenCV type 6"):
        seq.flow(1, "gt")
    path.write_bytes(good[:4] + struct.pack("<QQ", 10, 7) + good[20:])
    with pytest.raises(DatasetFormatError, match="header says 10x7"):
        seq.flow(1, "gt")
    path.write_bytes(good[:10])
    with pytest.raises(DatasetFormatError, match="fewer than its 20-byte header"):
        seq.flow(1, "gt")


def test_missing_files(fast_ycb: Path):
    (fast_ycb / "rgb" / "3.png").unlink()
    (fast_ycb / "optical_flow" / "gt" / "2.float").unlink()
    seq = open_sequence(fast_ycb)
    with pytest.raises(DatasetFormatError, match=r"rgb file '.*rgb/3.png' is missing"):
        seq.rgb(3)
    with pytest.raises(DatasetFormatError, match=r"optical flow file '.*gt/2.float' is missing"):
        seq.flow(2, "gt")
    (fast_ycb / "data.txt").unlink()
    with pytest.raises(DatasetFormatError, match="data.txt file .* is missing"):
        open_sequence(fast_ycb, "fast-ycb")


def test_corrupt_png(fast_ycb: Path):
    path = fast_ycb / "rgb" / "1.png"
    path.write_bytes(path.read_bytes()[:60])
    with pytest.raises(DatasetFormatError, match=rf"rgb image file '{path}' is truncated"):
        open_sequence(fast_ycb).rgb(1)
    mask = fast_ycb / "masks" / "gt" / "003_cracker_box_0.png"
    mask.write_bytes(b"GIF89a" + b"\0" * 30)
    with pytest.raises(DatasetFormatError, match=rf"mask file '{mask}' is not a PNG"):
        open_sequence(fast_ycb).mask(0, "gt")


def test_png_with_a_damaged_chunk(fast_ycb: Path):
    path = fast_ycb / "masks" / "gt" / "003_cracker_box_2.png"
    data = bytearray(path.read_bytes())
    data[45] ^= 0xFF  # inside the first IDAT chunk
    path.write_bytes(bytes(data))
    with pytest.raises(DatasetFormatError, match=r"is corrupt: CRC mismatch in chunk b'IDAT'"):
        open_sequence(fast_ycb).mask(2, "gt")


def test_nan_pose_row(fast_ycb: Path):
    path = fast_ycb / "gt" / "poses.txt"
    _edit_line(path, 3, "0 nan 0.5 1 0 0 0")
    with pytest.raises(DatasetFormatError, match=rf"'{path}', line 3: NaN or inf"):
        open_sequence(fast_ycb).ground_truth()


def test_short_pose_file_and_bad_rows(fast_ycb: Path):
    path = fast_ycb / "dope" / "poses.txt"
    lines = path.read_text().splitlines()
    path.write_text("\n".join(lines[:-1]) + "\n")
    with pytest.raises(DatasetFormatError, match=rf"'{path}' has 3 rows; the sequence has 4"):
        open_sequence(fast_ycb).detector_poses("dope")
    _edit_line(path, 2, "1 2 3")
    with pytest.raises(DatasetFormatError, match=rf"'{path}', line 2: expected 7 numbers, got 3"):
        open_sequence(fast_ycb).detector_poses("dope")


def test_velocities_with_nan(fast_ycb: Path):
    path = fast_ycb / "gt" / "velocities.txt"
    _edit_line(path, 4, "0 0 0 inf 0 0")
    with pytest.raises(DatasetFormatError, match=rf"'{path}', line 4: NaN or inf"):
        open_sequence(fast_ycb).ground_truth()


def test_bad_json(fast_ycb: Path):
    (fast_ycb / "metadata.json").write_text('{"fps": 30,\n "x": }')
    with pytest.raises(DatasetFormatError, match=r"metadata file '.*metadata.json', line 2 is not"):
        open_sequence(fast_ycb)
    (fast_ycb / "metadata.json").unlink()
    (fast_ycb / "cam_K.json").write_text("{'fx': 1}")
    with pytest.raises(DatasetFormatError, match=r"cam_K.json', line 1 is not valid JSON"):
        open_sequence(fast_ycb)


def test_data_txt_with_a_bad_camera_axis(fast_ycb: Path):
    path = fast_ycb / "data.txt"
    _edit_line(path, 2, "0.04 0.04 0 0 0 0 0 0 0.3")
    with pytest.raises(DatasetFormatError, match=rf"'{path}', line 2: rotation axis"):
        open_sequence(fast_ycb)


def test_wrong_mask_size(fast_ycb: Path):
    import cv2

    path = fast_ycb / "masks" / "mrcnn" / "003_cracker_box_1.png"
    cv2.imwrite(str(path), np.zeros((5, 5), np.uint8))
    with pytest.raises(DatasetFormatError, match=rf"mask '{path}' is 5x5 px; the camera is 64x48"):
        open_sequence(fast_ycb).mask(1, "mrcnn")


def test_unknown_sets_and_frames_are_key_and_index_errors(fast_ycb: Path):
    seq = open_sequence(fast_ycb)
    with pytest.raises(KeyError, match="no flow set 'dis'"):
        seq.flow(1, "dis")
    with pytest.raises(IndexError, match="frame 4 is outside 0..3"):
        seq.rgb(4)


# ------------------------------------------------------------------------------------ BOP
def test_bop_bad_json_and_missing_files(bop: Path):
    (bop / "depth" / "000002.png").unlink()
    with pytest.raises(DatasetFormatError, match=r"depth file '.*000002.png' is missing"):
        open_sequence(bop).depth(2)
    (bop / "scene_gt.json").write_text("[1, 2]")
    with pytest.raises(DatasetFormatError, match="must hold a JSON object keyed by image id"):
        open_sequence(bop)
    (bop / "scene_camera.json").write_text('{"0": {"cam_K": [1, 2]}}')
    with pytest.raises(DatasetFormatError, match="cam_K of image 0 must be 9 finite numbers"):
        open_sequence(bop)


def test_bop_nan_pose_and_changing_intrinsics(bop: Path):
    gt = json.loads((bop / "scene_gt.json").read_text())
    gt["1"][0]["cam_t_m2c"][0] = float("nan")
    (bop / "scene_gt.json").write_text(json.dumps(gt))
    with pytest.raises(DatasetFormatError, match="cam_t_m2c of image 1 must be 3 finite numbers"):
        open_sequence(bop).ground_truth()
    cams = json.loads((bop / "scene_camera.json").read_text())
    cams["2"]["cam_K"][0] += 1
    (bop / "scene_camera.json").write_text(json.dumps(cams))
    with pytest.raises(DatasetFormatError, match="cam_K of image 2 differs from image 0"):
        open_sequence(bop)


def test_bop_depth_png_of_the_wrong_kind(bop: Path):
    import cv2

    cv2.imwrite(str(bop / "depth" / "000001.png"), np.zeros((48, 64), np.uint8))
    with pytest.raises(DatasetFormatError, match="expected a single-channel 16-bit PNG"):
        open_sequence(bop).depth(1)


def test_bop_bad_pose_csv_and_unknown_object(bop: Path):
    path = bop / "extras" / "poses" / "dope.csv"
    _edit_line(path, 3, "0,1,2,1,1 0 0,1 2 3,-1")
    with pytest.raises(DatasetFormatError, match=rf"'{path}', line 3: bad pose row"):
        open_sequence(bop).detector_poses("dope")
    with pytest.raises(DatasetFormatError, match=r"object id 7 is not in .* \(it shows \[2\]\)"):
        open_sequence(bop, object_name="obj_000007")


def _edit_json(path: Path, edit) -> None:
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


@pytest.mark.parametrize(
    ("file", "edit", "access", "message"),
    [
        (
            "scene_gt.json",
            lambda d: d["2"][0].__setitem__("obj_id", "x"),
            lambda s: s,
            r"scene_gt.json': every image needs a list of objects with an integer obj_id",
        ),
        (
            "scene_gt.json",
            lambda d: d["2"][0].pop("obj_id"),
            lambda s: s,
            r"scene_gt.json': every image needs a list of objects with an integer obj_id",
        ),
        (
            "scene_gt.json",
            lambda d: d.__setitem__("2", 5),
            lambda s: s,
            r"scene_gt.json': every image needs a list of objects with an integer obj_id",
        ),
        (
            "extras/scene_gt_velocity.json",
            lambda d: d.__setitem__("2", 5),
            lambda s: s.ground_truth(),
            r"scene_gt_velocity.json': image 2 needs a list of objects with an integer obj_id",
        ),
        (
            "extras/scene_gt_velocity.json",
            lambda d: d["2"][0].__setitem__("obj_id", "x"),
            lambda s: s.ground_truth(),
            r"scene_gt_velocity.json': image 2 needs a list of objects with an integer obj_id",
        ),
        (
            "metadata.json",
            lambda d: d.__setitem__("fps", "abc"),
            lambda s: s,
            r"metadata.json': fps = 'abc'; expected a positive integer",
        ),
        (
            "metadata.json",
            lambda d: d["intrinsics"].pop("height_px"),
            lambda s: s,
            r"metadata.json': intrinsics need integer width_px and height_px",
        ),
        (
            "metadata.json",
            lambda d: d.__setitem__("format_options", "x"),
            lambda s: s,
            r"metadata.json': format_options.obj_id = None; expected an integer",
        ),
        (
            "metadata.json",
            lambda d: d.__setitem__("ground_truth", []),
            lambda s: s.mask_sets(),
            None,
        ),
    ],
    ids=[
        "gt-obj_id-str",
        "gt-obj_id-missing",
        "gt-entry-int",
        "velocity-entry-int",
        "velocity-obj_id-str",
        "meta-fps-str",
        "meta-intrinsics-no-height",
        "meta-format_options-str",
        "meta-ground_truth-list",
    ],
)
def test_bop_malformed_json_entries_are_format_errors(bop: Path, file, edit, access, message):
    """Malformed entries raised ValueError/TypeError/KeyError/AttributeError tracebacks."""
    _edit_json(bop / file, edit)
    if message is None:  # tolerated: a malformed optional hint falls back to the default
        assert "gt_full" in access(open_sequence(bop))
        return
    with pytest.raises(DatasetFormatError, match=message):
        access(open_sequence(bop))


def test_bop_metadata_that_is_not_an_object(bop: Path):
    (bop / "metadata.json").write_text("[]")
    with pytest.raises(DatasetFormatError, match=r"metadata.json' must hold a JSON object"):
        open_sequence(bop)


def test_bop_pose_csv_with_a_nan_or_short_translation(bop: Path):
    path = bop / "extras" / "poses" / "dope.csv"
    for t_text in ("nan 2 3", "1 2"):
        _edit_line(path, 3, f"0,1,2,1,1 0 0 0 1 0 0 0 1,{t_text},-1")
        with pytest.raises(DatasetFormatError, match=rf"'{path}', line 3: bad pose row: t must"):
            open_sequence(bop).detector_poses("dope")


# ----------------------------------------------------------------------------------- HDF5
def test_truncated_hdf5(hdf5: Path):
    hdf5.write_bytes(hdf5.read_bytes()[:3000])
    with pytest.raises(DatasetFormatError, match=rf"'{hdf5}': cannot read"):
        open_sequence(hdf5)


def test_not_our_hdf5_or_not_hdf5(tmp_path: Path):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.zeros(3)
    with pytest.raises(DatasetFormatError, match="HDF5 file but not a roft_sim sequence"):
        open_sequence(other)
    text = tmp_path / "text.h5"
    text.write_text("hello")
    with pytest.raises(DatasetFormatError, match="is a file but not an HDF5 file"):
        open_sequence(text)
    with pytest.raises(DatasetFormatError, match="cannot read"):
        open_sequence(text, "hdf5")


def test_hdf5_missing_dataset_and_nan(hdf5: Path):
    with h5py.File(hdf5, "a") as f:
        f["depth_m"][1, 3, 3] = np.nan
        del f["gt/T_cam_obj"]
    seq = open_sequence(hdf5)
    with pytest.raises(DatasetFormatError, match=r"/depth_m frame 1 has NaN/inf"):
        seq.depth(1)
    with pytest.raises(DatasetFormatError, match=r"has no dataset /gt/T_cam_obj"):
        seq.ground_truth()
    seq.close()  # HDF5 refuses to open a file for writing while it is open for reading
    with h5py.File(hdf5, "a") as f:
        del f["time_s"]
    with pytest.raises(DatasetFormatError, match=r"has no dataset /time_s"):
        open_sequence(hdf5)


# -------------------------------------------------------------------------------- general
def test_detect_and_list_errors(tmp_path: Path):
    with pytest.raises(DatasetFormatError, match="does not exist"):
        detect_format(tmp_path / "nope")
    with pytest.raises(DatasetFormatError, match="is no sequence: expected cam_K.json"):
        open_sequence(tmp_path)
    with pytest.raises(DatasetFormatError, match="dataset root .* does not exist"):
        list_sequences(tmp_path / "nope")
    assert list_sequences(tmp_path) == []


def test_list_sequences_finds_all_formats_and_bop_splits(written: dict[str, Path]):
    root = written["fast-ycb"].parent.parent
    found = list_sequences(root)
    assert found == sorted(written.values())
    assert [detect_format(p) for p in found] == ["bop", "fast-ycb", "hdf5"]


def test_bop_scene_with_an_unannotated_image_cannot_be_converted(bop: Path, tmp_path: Path):
    _edit_json(bop / "scene_gt.json", lambda d: d.__setitem__("2", []))
    seq = open_sequence(bop)
    assert np.isnan(seq.ground_truth().T_cam_obj[2]).all()  # documented: NaN rows
    with pytest.raises(
        DatasetFormatError, match=r"no ground-truth pose .* 1 of 4 frames .*frame 2"
    ):
        write_sequence(seq, "hdf5", tmp_path / "out")


def test_hdf5_pose_that_is_not_rigid(hdf5: Path):
    with h5py.File(hdf5, "a") as f:
        f["gt/T_cam_obj"][3, 0, 0] = 5.0
    with pytest.raises(DatasetFormatError, match=r"/gt/T_cam_obj frame 3 is not a rigid transform"):
        open_sequence(hdf5).ground_truth()


def test_cam_k_json_with_a_boolean_size(fast_ycb: Path):
    path = fast_ycb / "cam_K.json"
    _edit_json(path, lambda d: d.__setitem__("width", True))
    with pytest.raises(DatasetFormatError, match=r"width = True is not a number"):
        open_sequence(fast_ycb)


def test_time_stamps_that_do_not_increase(fast_ycb: Path, bop: Path, hdf5: Path):
    """Review regression: the readers accepted what the writers refuse (and trackers divide by)."""
    line = (fast_ycb / "data.txt").read_text().splitlines()[1].split()
    line[0] = "0"  # frame 1 at the time of frame 0
    _edit_line(fast_ycb / "data.txt", 2, " ".join(line))
    with pytest.raises(DatasetFormatError, match=r"line 2 \(frame 1\): time stamp 0.0 s does not"):
        open_sequence(fast_ycb)
    _edit_json(bop / "extras" / "scene_time.json", lambda d: d["3"].__setitem__("t_s", 0.01))
    with pytest.raises(DatasetFormatError, match=r"scene_time.json': image 3: time stamp 0.01 s"):
        open_sequence(bop)
    with h5py.File(hdf5, "a") as f:
        f["time_s"][2] = f["time_s"][1]
    with pytest.raises(
        DatasetFormatError, match=r"/time_s frame 2: time stamp .* does not increase"
    ):
        open_sequence(hdf5)
