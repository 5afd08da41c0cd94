"""Write then read gives back every array: bit-exactly for fast-ycb and hdf5, to the format's
precision for BOP (depth quantised to depth_scale; everything else exact)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from dataset_fixtures import assert_sequences_equal, intrinsics, plate_sequence, render_plate

from roft_sim.datasets import (
    GT_FULL_MASK_SET,
    DatasetFrame,
    dataset_frames,
    open_sequence,
    open_writer,
    write_sequence,
)
from roft_sim.datasets.bop import DEFAULT_DEPTH_SCALE_MM
from roft_sim.records import FlowField

FORMATS = ["fast-ycb", "hdf5", "bop"]
ENCODINGS = {"nvof_1_slow": "s10.5"}


def bop_depth_tolerance_m(depth_m: np.ndarray, scale_mm: float = DEFAULT_DEPTH_SCALE_MM) -> float:
    """Half a depth_scale step plus float32 rounding of the largest depth."""
    return 0.5 * scale_mm / 1000 + float(np.spacing(np.float32(depth_m.max())))


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("moving_camera", [False, True])
def test_round_trip(tmp_path: Path, fmt: str, moving_camera: bool):
    seq = plate_sequence(n_frames=5, moving_camera=moving_camera)
    path = write_sequence(seq, fmt, tmp_path, flow_encodings=ENCODINGS)
    back = open_sequence(path)
    tol = bop_depth_tolerance_m(np.stack(seq.depth_frames)) if fmt == "bop" else 0.0
    assert_sequences_equal(back, seq, depth_atol_m=tol)
    assert back.metadata()["seed"] == 3 and back.metadata()["scenario"] == {"name": "plate"}
    assert back.metadata()["format"] == fmt


@pytest.mark.parametrize("fmt", FORMATS)
def test_round_trip_without_ground_truth(tmp_path: Path, fmt: str):
    seq = plate_sequence(n_frames=3, with_gt=False, nvof=False)
    back = open_sequence(write_sequence(seq, fmt, tmp_path))
    assert back.ground_truth() is None
    tol = bop_depth_tolerance_m(np.stack(seq.depth_frames)) if fmt == "bop" else 0.0
    assert_sequences_equal(back, seq, depth_atol_m=tol)


def test_bop_depth_is_exact_when_already_quantised(tmp_path: Path):
    seq = plate_sequence(n_frames=2, nvof=False)
    step = DEFAULT_DEPTH_SCALE_MM / 1000
    quantised = [
        (np.rint(d.astype(np.float64) / step) * step).astype(np.float32) for d in seq.depth_frames
    ]
    import dataclasses

    seq = dataclasses.replace(seq, depth_frames=quantised)
    back = open_sequence(write_sequence(seq, "bop", tmp_path))
    for k in range(2):
        assert back.depth(k).tobytes() == quantised[k].tobytes()


def test_bop_depth_error_is_within_half_a_step_and_not_zero(tmp_path: Path):
    seq = plate_sequence(n_frames=2, nvof=False)
    back = open_sequence(write_sequence(seq, "bop", tmp_path, depth_scale_mm=1.0))
    err = np.abs(back.depth(1).astype(np.float64) - seq.depth(1))
    assert 0 < err.max() <= 0.5e-3 + 1e-7
    assert back.metadata()["format_options"]["depth_scale_mm"] == 1.0


def test_bop_refuses_depth_beyond_uint16_range(tmp_path: Path):
    seq = plate_sequence(n_frames=1, nvof=False)
    writer = open_writer(
        "bop", tmp_path, sequence_name="s", object_name="o", intrinsics=seq.intrinsics, fps=30,
        n_frames=1, metadata={}, object_model=None, depth_scale_mm=0.01,
    )  # fmt: skip
    frame = next(dataset_frames(seq))
    with pytest.raises(ValueError, match="exceeds the uint16 range.*raise depth_scale_mm"):
        writer.write_frame(frame)


def _frames_with_full_masks(n: int) -> list[DatasetFrame]:
    seq = plate_sequence(n_frames=n, nvof=False)
    out = []
    for frame in dataset_frames(seq):
        full = render_plate(seq.intrinsics, seq.gt.T_cam_obj[frame.k], frame.k)[3]
        import dataclasses

        out.append(dataclasses.replace(frame, gt_mask_full=full))
    return out


@pytest.mark.parametrize("fmt", FORMATS)
def test_full_masks_round_trip(tmp_path: Path, fmt: str):
    frames = _frames_with_full_masks(3)
    assert not np.array_equal(frames[0].gt_mask_full, frames[0].gt_mask)  # the bar occludes
    writer = open_writer(
        fmt, tmp_path, sequence_name="s", object_name="obj", intrinsics=intrinsics(), fps=30,
        n_frames=3, metadata={}, object_model=None,
    )  # fmt: skip
    for f in reversed(frames):  # any order
        writer.write_frame(f)
    back = open_sequence(writer.finalize())
    assert GT_FULL_MASK_SET in back.mask_sets()
    for f in frames:
        assert np.array_equal(back.mask(f.k, GT_FULL_MASK_SET), f.gt_mask_full)
        assert np.array_equal(back.mask(f.k, "gt"), f.gt_mask)


def test_bop_scene_gt_info_matches_the_masks(tmp_path: Path):
    import json

    frames = _frames_with_full_masks(2)
    writer = open_writer(
        "bop", tmp_path, sequence_name="000001", object_name="003_cracker_box",
        intrinsics=intrinsics(), fps=30, n_frames=2, metadata={}, object_model=None,
    )  # fmt: skip
    for f in frames:
        writer.write_frame(f)
    scene = writer.finalize()
    info = json.loads((scene / "scene_gt_info.json").read_text())["1"][0]
    full, visib, depth = frames[1].gt_mask_full, frames[1].gt_mask, frames[1].depth_m
    rows, cols = np.nonzero(visib)
    # bop_toolkit's misc.calc_2d_bbox: width = x_max - x_min (no + 1)
    assert info["bbox_visib"] == [
        int(cols.min()), int(rows.min()), int(np.ptp(cols)), int(np.ptp(rows))
    ]  # fmt: skip
    assert info["px_count_all"] == full.sum() and info["px_count_visib"] == visib.sum()
    assert info["px_count_valid"] == (full & (depth > 0)).sum()
    assert info["visib_fract"] == pytest.approx(visib.sum() / full.sum())
    gt = json.loads((scene / "scene_gt.json").read_text())["1"][0]
    assert gt["obj_id"] == 2  # the YCB-V id of 003_cracker_box
    np.testing.assert_allclose(gt["cam_t_m2c"], frames[1].gt_T_cam_obj[:3, 3] * 1000, rtol=1e-15)
    assert gt["cam_R_m2c"] == frames[1].gt_T_cam_obj[:3, :3].ravel().tolist()  # row-major
    csv_rows = (scene / "extras" / "poses" / "dope.csv").read_text().splitlines()
    assert csv_rows[0] == "scene_id,im_id,obj_id,score,R,t,time"
    assert csv_rows[1].startswith("1,0,2,1,")


@pytest.mark.parametrize("compression", ["gzip", "lzf"])
def test_hdf5_compression_options(tmp_path: Path, compression: str):
    seq = plate_sequence(n_frames=3)
    path = write_sequence(seq, "hdf5", tmp_path, compression=compression)
    import h5py

    with h5py.File(path, "r") as f:
        assert f["rgb"].compression == compression
        assert f["rgb"].chunks == (1, 48, 64, 3)
        assert f["depth_m"].attrs["units"] == "m"
        assert f.attrs["format"] == "roft_sim-hdf5"
    assert_sequences_equal(open_sequence(path), seq)


def test_a_detector_that_always_misses_keeps_its_set(tmp_path: Path):
    seq = plate_sequence(n_frames=3, nvof=False)
    frames = [f for f in dataset_frames(seq)]
    import dataclasses

    frames = [dataclasses.replace(f, detector_masks={"never": None}) for f in frames]
    for fmt in FORMATS:
        writer = open_writer(
            fmt, tmp_path / fmt, sequence_name="s", object_name="o", intrinsics=seq.intrinsics,
            fps=30, n_frames=3, metadata={}, object_model=None,
        )  # fmt: skip
        for f in frames:
            writer.write_frame(f)
        back = open_sequence(writer.finalize())
        assert "never" in back.mask_sets(), fmt
        assert all(back.mask(k, "never") is None for k in range(3)), fmt


def test_flow_validity_is_stored_only_when_given(tmp_path: Path):
    seq = plate_sequence(n_frames=3)
    path = write_sequence(seq, "fast-ycb", tmp_path)
    back = open_sequence(path)
    assert back.flow(1, "gt").valid is not None and back.flow(1, "nvof_1_slow").valid is None
    assert not (path / "optical_flow_valid" / "nvof_1_slow").exists()


def test_flow_field_samples_like_roft_after_the_round_trip(tmp_path: Path):
    seq = plate_sequence(n_frames=2)
    back = open_sequence(write_sequence(seq, "fast-ycb", tmp_path, flow_encodings=ENCODINGS))
    f: FlowField = back.flow(1, "nvof_1_slow")
    assert f.grid_px == 4 and f.flow_px.shape == (12, 16, 2)
    u, v = np.array([5, 63]), np.array([7, 47])
    np.testing.assert_array_equal(f.sample(u, v), f.flow_px[v // 4, u // 4])


@pytest.mark.parametrize("fmt", FORMATS)
def test_readers_implement_the_protocol_and_pickle(tmp_path: Path, fmt: str):
    import pickle

    from roft_sim.datasets import Sequence

    seq = plate_sequence(n_frames=3)
    back = open_sequence(write_sequence(seq, fmt, tmp_path))
    assert isinstance(back, Sequence)
    back.rgb(1)  # opens files (HDF5 keeps its file open)
    clone = pickle.loads(pickle.dumps(back))
    assert np.array_equal(clone.rgb(2), seq.rgb(2))
    assert clone.flow_sets() == back.flow_sets() and clone.mask_sets() == back.mask_sets()
