"""Fast-YCB encodings against hand-built bytes, scipy and OpenCV."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from roft_sim.datasets.fast_ycb_codec import (
    CV_16SC2,
    CV_32FC2,
    decode_cam_k_json,
    decode_depth_float,
    decode_flow_float,
    encode_cam_k_json,
    encode_data_txt_row,
    encode_depth_float,
    encode_flow_float,
    flow_grid_px,
    format_number,
    format_row,
    format_rows,
    parse_rows,
    pose_row_from_transform,
    transforms_from_pose_rows,
)
from roft_sim.errors import DatasetFormatError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.testing import assert_pose_close
from roft_sim.testing.strategies import transforms

P = Path("x.float")


def test_depth_bytes_match_the_reference_layout():
    depth = np.arange(6, dtype=np.float32).reshape(2, 3) / 4
    data = encode_depth_float(depth)
    assert data[:16] == struct.pack("<QQ", 3, 2)  # width then height, uint64
    assert data[16:] == struct.pack("<6f", *depth.ravel())
    out = decode_depth_float(data, P, shape=(2, 3))
    assert out.dtype == np.float32 and out.tobytes() == depth.tobytes()


def test_depth_negative_values_read_as_no_measurement():
    data = struct.pack("<QQ", 2, 1) + struct.pack("<2f", -1.0, 0.5)
    assert decode_depth_float(data, P).tolist() == [[0.0, 0.5]]


def test_float_flow_bytes_match_the_reference_layout():
    flow = np.array([[[1.5, -2.25], [0.0, 3.0]]], dtype=np.float32)  # 1 row, 2 cols
    data = encode_flow_float(flow, "float32")
    assert data[:20] == struct.pack("<iQQ", CV_32FC2, 2, 1)  # type, cols, rows
    assert data[20:] == struct.pack("<4f", 1.5, -2.25, 0.0, 3.0)
    out, cv_type = decode_flow_float(data, P)
    assert cv_type == CV_32FC2 and out.tobytes() == flow.tobytes()


def test_s10_5_flow_is_int16_times_32_and_round_trips_multiples_of_1_32():
    flow = np.array([[[1.5, -2.25], [1023.96875, -1024.0]]], dtype=np.float32)
    data = encode_flow_float(flow, "s10.5")
    assert data[:20] == struct.pack("<iQQ", CV_16SC2, 2, 1)
    assert struct.unpack("<4h", data[20:]) == (48, -72, 32767, -32768)
    out, cv_type = decode_flow_float(data, P)
    assert cv_type == CV_16SC2 and np.array_equal(out, flow)


def test_s10_5_rounds_to_1_32_px_and_refuses_out_of_range():
    out, _ = decode_flow_float(encode_flow_float(np.full((1, 1, 2), 0.01, np.float32), "s10.5"), P)
    assert np.array_equal(out, np.zeros((1, 1, 2)))
    with pytest.raises(ValueError, match="does not fit S10.5"):
        encode_flow_float(np.full((1, 1, 2), 1024.0, np.float32), "s10.5")
    with pytest.raises(ValueError, match="unknown flow encoding"):
        encode_flow_float(np.zeros((1, 1, 2), np.float32), "float16")


@pytest.mark.parametrize(
    ("rows", "cols", "shape", "grid"),
    [(720, 1280, (720, 1280), 1), (180, 320, (720, 1280), 4), (12, 17, (48, 66), 4)],
)
def test_flow_grid_is_ceil_of_width_over_cols(rows, cols, shape, grid):
    assert flow_grid_px(rows, cols, shape, P) == grid


def test_flow_grid_that_does_not_tile_the_image_is_an_error():
    with pytest.raises(DatasetFormatError, match="no whole-pixel grid"):
        flow_grid_px(100, 320, (720, 1280), P)


@pytest.mark.parametrize(
    ("x", "text"),
    [(0.0, "0"), (-0.0, "0"), (1.0, "1"), (-2.0, "-2"), (0.1, "0.1"), (1e-05, "1e-05")],
)
def test_format_number(x, text):
    assert format_number(x) == text


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_format_number_reads_back_exactly(x):
    assert float(format_number(x)) == x


def test_format_number_refuses_nan():
    with pytest.raises(ValueError, match="non-finite"):
        format_number(float("nan"))


@settings(max_examples=200, derandomize=True)
@given(
    st.lists(
        st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=3, max_size=3),
        max_size=12,
    )
)
def test_format_rows_writes_what_format_row_writes_row_by_row(rows):
    expected = "".join(format_row(r) + "\n" for r in rows)
    assert format_rows(np.array(rows, dtype=np.float64).reshape(-1, 3)) == expected


def test_format_rows_refuses_non_finite_numbers_and_other_shapes():
    assert format_rows(np.zeros((2, 0))) == "\n\n"
    assert format_rows([[0.0, -0.0, 1e-05], [2.5, -3.0, 1e16]]) == "0 0 1e-05\n2.5 -3 1e+16\n"
    with pytest.raises(ValueError, match=r"non-finite number inf \(row 1, column 0\)"):
        format_rows([[1.0, 2.0], [np.inf, 0.0]])
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        format_rows([1.0, 2.0, 3.0])


def test_parse_rows_names_the_line():
    with pytest.raises(DatasetFormatError, match=r"'p.txt', line 2: expected 3 numbers, got 2"):
        parse_rows("1 2 3\n4 5\n", Path("p.txt"), 3)
    with pytest.raises(DatasetFormatError, match=r"line 1: NaN or inf"):
        parse_rows("1 nan 3\n", Path("p.txt"), 3)
    with pytest.raises(DatasetFormatError, match=r"line 1: not a number"):
        parse_rows("1 x 3\n", Path("p.txt"), 3)
    with pytest.raises(DatasetFormatError, match="has 1 rows; the sequence has 2 frames"):
        parse_rows("1 2 3\n\n", Path("p.txt"), 3, n_rows=2)


@given(transforms())
def test_pose_rows_round_trip_through_text_to_1e_9(T):
    text = format_row(pose_row_from_transform(T)) + "\n"
    rows = parse_rows(text, P, 7)
    back, valid = transforms_from_pose_rows(rows, P, allow_zero_rows=False)
    assert valid.all()
    assert_pose_close(back[0], T, atol_m=1e-12, atol_rad=1e-9)
    axis, angle = rows[0, 3:6], rows[0, 6]
    assert abs(np.linalg.norm(axis) - 1) < 1e-12 and 0 <= angle <= np.pi


def test_pose_row_matches_scipy_and_opencv():
    rotvec = np.array([0.3, -1.1, 2.0])
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = [0.1, -0.2, 0.7]
    row = pose_row_from_transform(T)
    angle = np.linalg.norm(rotvec)
    np.testing.assert_allclose(row, [0.1, -0.2, 0.7, *(rotvec / angle), angle], atol=1e-12)
    R_cv, _ = cv2.Rodrigues(np.array(row[3:6]) * row[6])
    np.testing.assert_allclose(R_cv, T[:3, :3], atol=1e-12)


def test_zero_rows_are_misses_and_zero_axis_is_identity():
    rows = np.array([[0, 0, 0, 0, 0, 0, 0], [1, 2, 3, 0, 0, 0, 0], [0, 0, 0, 1, 0, 0, 0]], float)
    T, valid = transforms_from_pose_rows(rows, P, allow_zero_rows=True)
    assert valid.tolist() == [False, True, True]
    assert np.array_equal(T[0], np.eye(4))
    assert np.array_equal(T[1][:3, :3], np.eye(3)) and T[1][:3, 3].tolist() == [1, 2, 3]
    with pytest.raises(DatasetFormatError, match=r"line 1: a pose row of seven zeros"):
        transforms_from_pose_rows(rows, P, allow_zero_rows=False)


def test_non_unit_axis_is_an_error_naming_the_line():
    rows = np.array([[0, 0, 1, 1, 0, 0, 0.5], [0, 0, 1, 2, 0, 0, 0.5]], float)
    with pytest.raises(DatasetFormatError, match=r"'x.float', line 2: rotation axis .* norm 2"):
        transforms_from_pose_rows(rows, P, allow_zero_rows=True)


def test_static_camera_row_is_the_reference_0_0_0_1_0_0_0():
    assert encode_data_txt_row(1 / 30, np.eye(4)) == "0.03333333333333333 " * 2 + "0 0 0 1 0 0 0"


def test_cam_k_json_has_fx_fy_cx_cy_on_lines_5_to_8():
    cam = CameraIntrinsics(fx_px=1229.5, fy_px=1229.25, cx_px=640, cy_px=360, width_px=1280,
                           height_px=720)  # fmt: skip
    text = encode_cam_k_json(cam)
    lines = text.splitlines()
    # The exact parsing ROFT's test_custom.sh does: line N, strip, keep after ':', drop ','.
    values = [lines[i].strip().split(":")[1].strip().rstrip(",") for i in range(4, 8)]
    assert values == ["1229.5", "1229.25", "640", "360"]
    assert list(json.loads(text)) == ["name", "width", "height", "fx", "fy", "cx", "cy"]
    assert decode_cam_k_json(text, P) == cam


def test_cam_k_json_accepts_string_values_like_the_real_fast_ycb():
    text = json.dumps({"name": "d415", "width": "1280", "height": "720", "fx": "912.7",
                       "fy": "911.9", "cx": "650.1", "cy": "367.4"})  # fmt: skip
    cam = decode_cam_k_json(text, P)
    assert (cam.width_px, cam.height_px, cam.fx_px, cam.cy_px) == (1280, 720, 912.7, 367.4)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("{", "not valid JSON"),
        ("[1]", "must hold a JSON object"),
        ('{"fx": 1}', "has no 'fy'"),
        ('{"fx": "a", "fy": 1, "cx": 1, "cy": 1, "width": 2, "height": 2}', "fx = 'a' is not a"),
        ('{"fx": 1, "fy": 1, "cx": 1, "cy": 1, "width": 2.5, "height": 2}', "positive whole"),
        ('{"fx": -1, "fy": 1, "cx": 1, "cy": 1, "width": 2, "height": 2}', "invalid intrinsics"),
    ],
)
def test_bad_cam_k_json(text, match):
    with pytest.raises(DatasetFormatError, match=match):
        decode_cam_k_json(text, Path("cam_K.json"))
