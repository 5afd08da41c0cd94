"""Streaming writers: determinism, resume after an interruption, parallel workers, completeness."""

from __future__ import annotations

import dataclasses
import hashlib
import multiprocessing
import pickle
from pathlib import Path

import numpy as np
import pytest
from dataset_fixtures import assert_sequences_equal, plate_sequence

from roft_sim.datasets import dataset_frames, open_sequence, open_writer
from roft_sim.datasets import writer_base as writer_base_module
from roft_sim.errors import ConfigError, DatasetFormatError

FORMATS = ["fast-ycb", "hdf5", "bop"]
ENCODINGS = {"nvof_1_slow": "s10.5"}


def tree_digest(path: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file under ``path`` (or of the file itself)."""
    if path.is_file():
        return {path.name: hashlib.sha256(path.read_bytes()).hexdigest()}
    return {
        str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


def open_for(seq, fmt: str, root: Path, *, resume: bool = False, **kw):
    return open_writer(
        fmt, root, sequence_name="seq", object_name=seq.object_name, intrinsics=seq.intrinsics,
        fps=seq.fps, n_frames=len(seq), metadata={"seed": 3}, object_model=seq.model,
        flow_encodings=ENCODINGS if "nvof_1_slow" in seq.flows else {}, resume=resume, **kw,
    )  # fmt: skip


def write_all(seq, fmt: str, root: Path) -> Path:
    writer = open_for(seq, fmt, root)
    for frame in dataset_frames(seq):
        writer.write_frame(frame)
    return writer.finalize()


@pytest.mark.parametrize("fmt", FORMATS)
def test_same_inputs_give_byte_identical_files(tmp_path: Path, fmt: str):
    seq = plate_sequence(n_frames=4)
    a = tree_digest(write_all(seq, fmt, tmp_path / "a"))
    b = tree_digest(write_all(seq, fmt, tmp_path / "b"))
    assert a == b
    assert not any(".tmp" in name or "parts" in name for name in a)


@pytest.mark.parametrize("fmt", FORMATS)
def test_resume_after_an_interruption_gives_the_identical_dataset(
    tmp_path: Path, fmt: str, monkeypatch: pytest.MonkeyPatch
):
    seq = plate_sequence(n_frames=6)
    frames = list(dataset_frames(seq))
    reference = tree_digest(write_all(seq, fmt, tmp_path / "reference"))

    writer = open_for(seq, fmt, tmp_path / "run")
    for k in (4, 0, 2):
        writer.write_frame(frames[k])
    # Frame 5 is interrupted after its images, before its record: it must not count.
    real_write = writer_base_module.atomic_write_text

    def interrupted(path, text):
        if Path(path).name.startswith("frame_"):
            raise KeyboardInterrupt
        real_write(path, text)

    monkeypatch.setattr(writer_base_module, "atomic_write_text", interrupted)
    with pytest.raises(KeyboardInterrupt):
        writer.write_frame(frames[5])
    monkeypatch.undo()
    # A stale temp file of a killed process is left behind too.
    stale = writer.parts_dir if fmt == "hdf5" else writer.sequence_path / "rgb"
    (stale / ".1.png.999.tmp").write_bytes(b"partial")
    assert writer.completed_frames() == {0, 2, 4}
    with pytest.raises(DatasetFormatError, match=r"3 of 6 frames are missing \(1, 3, 5\)"):
        writer.finalize()

    resumed = open_for(seq, fmt, tmp_path / "run", resume=True)
    assert resumed.completed_frames() == {0, 2, 4}
    for k in sorted(set(range(6)) - resumed.completed_frames()):
        resumed.write_frame(frames[k])
    path = resumed.finalize()
    assert tree_digest(path) == reference
    assert resumed.finalize() == path  # idempotent
    again = open_for(seq, fmt, tmp_path / "run", resume=True)
    assert again.completed_frames() == set(range(6))
    with pytest.raises(DatasetFormatError, match="already finalized"):
        again.write_frame(frames[0])


def _write_frames(args: tuple[bytes, list[int]]) -> list[int]:
    writer_bytes, ks = args
    writer = pickle.loads(writer_bytes)
    seq = plate_sequence(n_frames=6)
    frames = list(dataset_frames(seq))
    for k in ks:
        writer.write_frame(frames[k])
    return ks


@pytest.mark.parametrize("fmt", FORMATS)
def test_parallel_worker_processes_share_a_pickled_writer(tmp_path: Path, fmt: str):
    seq = plate_sequence(n_frames=6)
    reference = tree_digest(write_all(seq, fmt, tmp_path / "reference"))
    writer = open_for(seq, fmt, tmp_path / "parallel")
    blob = pickle.dumps(writer)
    ctx = multiprocessing.get_context("spawn" if fmt == "hdf5" else "fork")
    with ctx.Pool(2) as pool:
        pool.map(_write_frames, [(blob, [5, 3, 1]), (blob, [0, 2, 4])])
    assert writer.completed_frames() == set(range(6))
    assert tree_digest(writer.finalize()) == reference


@pytest.mark.parametrize("fmt", FORMATS)
def test_non_empty_output_is_refused_without_resume(tmp_path: Path, fmt: str):
    seq = plate_sequence(n_frames=2, nvof=False)
    open_for(seq, fmt, tmp_path)
    with pytest.raises(ConfigError, match="unfinished sequence; pass resume=True"):
        open_for(seq, fmt, tmp_path)
    write_all(seq, fmt, tmp_path / "done")
    with pytest.raises(ConfigError, match="already holds a finished sequence"):
        open_for(seq, fmt, tmp_path / "done")


@pytest.mark.parametrize("fmt", FORMATS)
def test_resume_with_other_settings_is_refused(tmp_path: Path, fmt: str):
    seq = plate_sequence(n_frames=2, nvof=False)
    open_for(seq, fmt, tmp_path)
    other = dataclasses.replace(seq, fps=15)
    with pytest.raises(ConfigError, match=r"different settings \(fps differ\)"):
        open_for(other, fmt, tmp_path, resume=True)


def test_a_folder_that_is_no_sequence_is_refused(tmp_path: Path):
    (tmp_path / "seq").mkdir()
    (tmp_path / "seq" / "notes.txt").write_text("mine")
    seq = plate_sequence(n_frames=1, nvof=False)
    with pytest.raises(ConfigError, match="is not an unfinished roft_sim sequence"):
        open_for(seq, "fast-ycb", tmp_path, resume=True)


@pytest.mark.parametrize("fmt", FORMATS)
def test_frames_that_disagree_are_refused_at_finalize(tmp_path: Path, fmt: str):
    seq = plate_sequence(n_frames=3, nvof=False)
    frames = list(dataset_frames(seq))
    frames[1] = dataclasses.replace(frames[1], detector_poses={})
    writer = open_for(seq, fmt, tmp_path)
    for f in frames:
        writer.write_frame(f)
    with pytest.raises(DatasetFormatError, match=r"disagree on detector pose sets .* frames 1\)"):
        writer.finalize()


def test_frames_with_ground_truth_on_some_frames_only_are_refused(tmp_path: Path):
    seq = plate_sequence(n_frames=3, nvof=False)
    frames = list(dataset_frames(seq))
    frames[2] = dataclasses.replace(
        frames[2], gt_T_cam_obj=None, gt_v_obj_mps=None, gt_w_radps=None
    )
    writer = open_for(seq, "fast-ycb", tmp_path)
    for f in frames:
        writer.write_frame(f)
    with pytest.raises(DatasetFormatError, match="disagree on ground-truth poses"):
        writer.finalize()


def test_time_stamps_must_increase(tmp_path: Path):
    seq = plate_sequence(n_frames=3, nvof=False)
    frames = list(dataset_frames(seq))
    frames[2] = dataclasses.replace(frames[2], t_s=0.0)
    writer = open_for(seq, "hdf5", tmp_path)
    for f in frames:
        writer.write_frame(f)
    with pytest.raises(DatasetFormatError, match=r"time stamps must increase"):
        writer.finalize()


def test_writer_checks_frame_index_and_resolution(tmp_path: Path):
    seq = plate_sequence(n_frames=2, nvof=False)
    writer = open_for(seq, "fast-ycb", tmp_path)
    frame = next(dataset_frames(seq))
    with pytest.raises(ValueError, match="frame index 7 is outside 0..1"):
        writer.write_frame(dataclasses.replace(frame, k=7))
    small = plate_sequence(n_frames=1, width_px=32, height_px=24, nvof=False)
    with pytest.raises(ValueError, match="is 32x24 but the sequence camera is 64x48"):
        writer.write_frame(next(dataset_frames(small)))


@pytest.mark.slow  # writes long sequences to measure memory
def test_memory_stays_flat_in_sequence_length(tmp_path: Path):
    """Writing 6x more frames needs no more Python heap (frames stream to disk)."""
    import gc
    import tracemalloc

    seq = plate_sequence(n_frames=2, nvof=False)
    frame0, frame1 = list(dataset_frames(seq))

    def peak(n: int, fmt: str, root: Path) -> int:
        writer = open_writer(
            fmt, root, sequence_name="s", object_name="o", intrinsics=seq.intrinsics, fps=30,
            n_frames=n, metadata={}, object_model=None,
        )  # fmt: skip
        gc.collect()
        tracemalloc.start()
        for k in range(n):
            base = frame0 if k == 0 else frame1
            flows = {} if k == 0 else {
                name: dataclasses.replace(f, from_k=k - 1, to_k=k) for name, f in base.flows.items()
            }  # fmt: skip
            writer.write_frame(dataclasses.replace(base, k=k, t_s=k / 30, flows=flows))
        writer.finalize()
        _, top = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        return top

    for fmt in FORMATS:
        short, long = peak(10, fmt, tmp_path / f"{fmt}10"), peak(60, fmt, tmp_path / f"{fmt}60")
        # < 2 kB per extra frame (a frame's arrays alone are ~40 kB, its record ~6 kB)
        assert long - short < 100_000, (fmt, short, long)


def test_frame_validation_messages():
    seq = plate_sequence(n_frames=2, nvof=False)
    f0, f1 = list(dataset_frames(seq))
    with pytest.raises(ValueError, match="depth_m must be a float32"):
        dataclasses.replace(f0, depth_m=f0.depth_m.astype(np.float64))
    with pytest.raises(ValueError, match="depth_m must be finite and >= 0"):
        dataclasses.replace(f0, depth_m=np.full_like(f0.depth_m, np.nan))
    with pytest.raises(ValueError, match="frame 0 has no previous frame"):
        dataclasses.replace(f0, flows=f1.flows)
    with pytest.raises(ValueError, match="datasets store F_k from frame 0 to 1"):
        bad = dataclasses.replace(f1.flows["gt"], from_k=-1)
        dataclasses.replace(f1, flows={"gt": bad})
    with pytest.raises(ValueError, match="not a rigid transform"):
        dataclasses.replace(f0, gt_T_cam_obj=np.diag([2.0, 1, 1, 1]))
    with pytest.raises(ValueError, match="reserved for ground truth"):
        dataclasses.replace(f0, detector_masks={"gt": None})
    with pytest.raises(ValueError, match="not usable as a folder name"):
        dataclasses.replace(f0, detector_poses={"../x": None})
    with pytest.raises(ValueError, match="give both gt_v_obj_mps and gt_w_radps"):
        dataclasses.replace(f0, gt_w_radps=None)
    with pytest.raises(ValueError, match="has NaN/inf; store finite vectors"):
        nan_flow = dataclasses.replace(f1.flows["gt"], flow_px=f1.flows["gt"].flow_px * np.nan)
        dataclasses.replace(f1, flows={"gt": nan_flow})


def test_open_writer_option_errors(tmp_path: Path):
    seq = plate_sequence(n_frames=1, nvof=False)
    with pytest.raises(ConfigError, match="depth_scale_mm applies to the bop format only"):
        open_for(seq, "fast-ycb", tmp_path, depth_scale_mm=1.0)
    with pytest.raises(ConfigError, match="unknown dataset format 'png'"):
        open_for(seq, "png", tmp_path)
    with pytest.raises(ConfigError, match="compression_level must be an int in 1..9"):
        open_for(seq, "hdf5", tmp_path, compression_level=12)
    with pytest.raises(ConfigError, match=r"metadata keys \['fps'\] are written by the dataset"):
        open_writer(
            "hdf5", tmp_path, sequence_name="s", object_name="o", intrinsics=seq.intrinsics,
            fps=30, n_frames=1, metadata={"fps": 1}, object_model=None,
        )  # fmt: skip
    with pytest.raises(ConfigError, match="must be a plain folder name"):
        open_writer(
            "hdf5", tmp_path, sequence_name="a/b", object_name="o", intrinsics=seq.intrinsics,
            fps=30, n_frames=1, metadata={}, object_model=None,
        )  # fmt: skip
    with pytest.raises(ValueError, match="NaN"):
        open_writer(
            "hdf5", tmp_path, sequence_name="s", object_name="o", intrinsics=seq.intrinsics,
            fps=30, n_frames=1, metadata={"x": float("nan")}, object_model=None,
        )  # fmt: skip


def test_flow_encoding_for_an_unknown_set_is_refused_at_finalize(tmp_path: Path):
    seq = plate_sequence(n_frames=2, nvof=False)
    writer = open_writer(
        "fast-ycb", tmp_path, sequence_name="s", object_name="o", intrinsics=seq.intrinsics,
        fps=30, n_frames=2, metadata={}, object_model=None, flow_encodings={"nvof": "s10.5"},
    )  # fmt: skip
    for f in dataset_frames(seq):
        writer.write_frame(f)
    with pytest.raises(DatasetFormatError, match=r"flow_encodings names sets \['nvof'\]"):
        writer.finalize()


def test_unfinished_sequences_are_reported_by_the_readers(tmp_path: Path):
    seq = plate_sequence(n_frames=3, nvof=False)
    for fmt in FORMATS:
        writer = open_for(seq, fmt, tmp_path / fmt)
        writer.write_frame(next(dataset_frames(seq)))
        with pytest.raises(DatasetFormatError, match="unfinished"):
            open_sequence(writer.sequence_path)


def test_round_trip_after_resume_still_reads_back_exactly(tmp_path: Path):
    seq = plate_sequence(n_frames=4)
    frames = list(dataset_frames(seq))
    writer = open_for(seq, "hdf5", tmp_path)
    writer.write_frame(frames[2])
    resumed = open_for(seq, "hdf5", tmp_path, resume=True)
    for k in (0, 1, 3):
        resumed.write_frame(frames[k])
    assert_sequences_equal(open_sequence(resumed.finalize()), seq)
