"""A hand-built miniature of a real Fast-YCB sequence (written with struct/OpenCV, not with our
writer): string intrinsics, measured time stamps, all-zero camera rows, int16 S10.5 flow on a
4x4 grid, soft-edged Mask R-CNN masks with misses, no gt/ and no masks/gt/, no metadata."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

from roft_sim.datasets import (
    FastYcbSequence,
    check_fast_ycb_sequence,
    list_sequences,
    open_sequence,
    write_sequence,
)
from roft_sim.datasets.fast_ycb_check import run_fast_ycb_check

W, H, N = 40, 24, 4
OBJECT = "003_cracker_box"
TIMES = [0.0, 0.0342, 0.0671, 0.1003]  # measured, not exactly i/30


def _flow_int16(i: int) -> np.ndarray:
    rng = np.random.default_rng(i)
    return rng.integers(-2000, 2000, size=(H // 4, W // 4, 2)).astype(np.int16)


def _soft_mask(i: int) -> np.ndarray:
    mask = np.zeros((H, W), np.uint8)
    mask[6 : 14 + i, 10 : 22 + i] = 255
    mask[6, 10:20] = 1  # a value ROFT's threshold (> 1) drops
    mask[7, 10:20] = 128  # a bilinear edge value it keeps
    return mask


@pytest.fixture
def real_sequence(tmp_path: Path) -> Path:
    seq = tmp_path / f"{OBJECT}_real"
    for d in ("rgb", "depth", "optical_flow/nvof_1_slow", "masks/mrcnn_ycbv_bop_pbr", "dope"):
        (seq / d).mkdir(parents=True)
    (seq / "cam_K.json").write_text(
        "{\n"
        '    "name": "realsense_d415",\n'
        f'    "width": "{W}",\n'
        f'    "height": "{H}",\n'
        '    "fx": "912.7041",\n'
        '    "fy": "911.8817",\n'
        '    "cx": "20.3",\n'
        '    "cy": "11.9"\n'
        "}\n"
    )
    (seq / "data.txt").write_text("".join(f"{t} {t} 0.0 0.0 0.0 0.0 0.0 0.0 0.0\n" for t in TIMES))
    for i in range(N):
        rgb = np.full((H, W, 3), (10 * i, 100, 200), np.uint8)  # R, G, B
        assert cv2.imwrite(str(seq / "rgb" / f"{i}.png"), rgb[..., ::-1])
        depth = np.linspace(0.5, 1.5, W * H, dtype=np.float32).reshape(H, W) * (i + 1)
        depth[0, 0] = 0.0
        (seq / "depth" / f"{i}.float").write_bytes(struct.pack("<QQ", W, H) + depth.tobytes())
        if i > 0:
            (seq / "optical_flow" / "nvof_1_slow" / f"{i}.float").write_bytes(
                struct.pack("<iQQ", 11, W // 4, H // 4) + _flow_int16(i).tobytes()
            )
        if i != 2:  # a Mask R-CNN miss on frame 2: no file
            cv2.imwrite(
                str(seq / "masks" / "mrcnn_ycbv_bop_pbr" / f"{OBJECT}_{i}.png"), _soft_mask(i)
            )
    rows = [
        "0.01 -0.02 0.6 0 0 1 0.5",
        "0 0 0 0 0 0 0",
        "0.02 -0.01 0.61 0 1 0 0.25",
        "0.02 0 0.6 1 0 0 3.1",
    ]
    (seq / "dope" / "poses.txt").write_text("\n".join(rows) + "\n")
    (seq / "dope" / "poses_ycb.txt").write_text("\n".join(rows) + "\n")
    return seq


def test_reads_the_real_layout(real_sequence: Path):
    seq = open_sequence(real_sequence)
    assert isinstance(seq, FastYcbSequence)
    cam = seq.intrinsics
    assert (cam.width_px, cam.height_px, cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px) == (
        W, H, 912.7041, 911.8817, 20.3, 11.9
    )  # fmt: skip
    assert len(seq) == N and seq.fps == 30  # from the median time step
    assert [seq.time_s(k) for k in range(N)] == TIMES
    assert seq.object_name == OBJECT  # found in the mask file names
    assert np.array_equal(seq.camera_poses(), np.broadcast_to(np.eye(4), (N, 4, 4)))
    assert seq.ground_truth() is None and seq.object_model() is None
    assert seq.mask_sets() == ("mrcnn_ycbv_bop_pbr",)
    assert seq.flow_sets() == ("nvof_1_slow",)
    assert seq.pose_sets() == ("dope", "dope_ycb")
    assert seq.metadata() == {}
    assert np.array_equal(seq.rgb(1)[0, 0], [10, 100, 200])
    depth = seq.depth(3)
    assert depth[0, 0] == 0.0 and depth[-1, -1] == np.float32(1.5) * 4


def test_int16_flow_on_a_4x4_grid(real_sequence: Path):
    seq = open_sequence(real_sequence)
    assert seq.flow(0, "nvof_1_slow") is None
    flow = seq.flow(2, "nvof_1_slow")
    assert (flow.from_k, flow.to_k, flow.grid_px) == (1, 2, 4)
    assert flow.flow_px.dtype == np.float32
    np.testing.assert_array_equal(flow.flow_px, _flow_int16(2) / np.float32(32))
    # ROFT samples pixel (u, v) at F[v // 4, u // 4], block-nearest.
    assert np.array_equal(flow.sample(np.array([13]), np.array([9]))[0], flow.flow_px[2, 3])


def test_soft_masks_and_misses(real_sequence: Path):
    seq = open_sequence(real_sequence)
    mask = seq.mask(1, "mrcnn_ycbv_bop_pbr")
    assert np.array_equal(mask, _soft_mask(1) > 1)
    assert not mask[6, 10] and mask[7, 10]
    assert seq.mask(2, "mrcnn_ycbv_bop_pbr") is None


def test_detector_rows_with_misses(real_sequence: Path):
    poses = open_sequence(real_sequence).detector_poses("dope")
    assert poses.valid.tolist() == [True, False, True, True]
    np.testing.assert_allclose(poses.T_cam_obj[0][:3, 3], [0.01, -0.02, 0.6])
    np.testing.assert_allclose(
        poses.T_cam_obj[2][:3, :3], cv2.Rodrigues(np.array([0, 0.25, 0.0]))[0], atol=1e-12
    )


def test_checker_passes_and_says_what_it_skipped(real_sequence: Path):
    report = run_fast_ycb_check(real_sequence)
    assert report.problems == []
    notes = " ".join(report.notes)
    assert "metadata.json absent" in notes and "gt/poses.txt absent" in notes
    assert "flow direction not checked" in notes


def test_converts_to_our_formats_and_back(real_sequence: Path, tmp_path: Path):
    seq = open_sequence(real_sequence)
    for fmt in ("hdf5", "fast-ycb"):
        back = open_sequence(
            write_sequence(seq, fmt, tmp_path / fmt, flow_encodings={"nvof_1_slow": "s10.5"})
        )
        assert (
            back.flow(3, "nvof_1_slow").flow_px.tobytes()
            == seq.flow(3, "nvof_1_slow").flow_px.tobytes()
        )
        assert back.mask(2, "mrcnn_ycbv_bop_pbr") is None
        assert back.depth(1).tobytes() == seq.depth(1).tobytes()
        assert back.time_s(3) == TIMES[3]
    written = tmp_path / "fast-ycb" / real_sequence.name
    assert check_fast_ycb_sequence(written) == []
    # the re-written flow files are byte-identical to the hand-made real ones
    assert (written / "optical_flow/nvof_1_slow/2.float").read_bytes() == (
        real_sequence / "optical_flow/nvof_1_slow/2.float"
    ).read_bytes()


def test_ho3d_like_ground_truth_without_velocities(real_sequence: Path):
    (real_sequence / "gt").mkdir()
    (real_sequence / "gt" / "poses.txt").write_text(
        "".join("0.1 0 0.5 0 0 1 0.1\n" for _ in range(N))
    )
    (real_sequence / "gt" / "poses_ycb.txt").write_text(
        "".join("0.2 0 0.5 0 0 1 0.1\n" for _ in range(N))
    )
    seq = open_sequence(real_sequence)
    gt = seq.ground_truth()
    assert gt is not None and np.isnan(gt.v_obj_mps).all() and np.isnan(gt.w_radps).all()
    assert gt.T_cam_obj[0][0, 3] == 0.1
    assert seq.ground_truth("ycb").T_cam_obj[0][0, 3] == 0.2
    assert "gt" not in seq.pose_sets()


def test_list_sequences_of_a_dataset_root(real_sequence: Path, tmp_path: Path):
    other = tmp_path / "004_sugar_box"
    other.mkdir()
    (other / "cam_K.json").write_text((real_sequence / "cam_K.json").read_text())
    (other / "data.txt").write_text("0 0 0 0 0 1 0 0 0\n")
    (tmp_path / "notes").mkdir()
    assert list_sequences(tmp_path) == [real_sequence, other]
    assert list_sequences(real_sequence) == [real_sequence]
    assert open_sequence(other).fps == 30 and len(open_sequence(other)) == 1


def test_object_name_override(real_sequence: Path):
    seq = open_sequence(real_sequence, object_name="cracker")
    assert seq.object_name == "cracker"
    assert seq.mask(0, "mrcnn_ycbv_bop_pbr") is None  # no file under that name


def test_cam_k_as_numbers_too(real_sequence: Path):
    data = json.loads((real_sequence / "cam_K.json").read_text())
    (real_sequence / "cam_K.json").write_text(
        json.dumps({k: data[k] if k == "name" else float(data[k]) for k in data})
    )
    assert open_sequence(real_sequence).intrinsics.fx_px == 912.7041
