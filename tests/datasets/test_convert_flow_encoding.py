"""`dataset convert` (and write_sequence) keep NVOF's int16 S10.5 flow as int16."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from dataset_fixtures import plate_sequence

from roft_sim.cli import main
from roft_sim.datasets import open_sequence, write_sequence
from roft_sim.datasets.formats import stored_flow_encodings


def _cv_type(path: Path) -> int:
    return int(np.frombuffer(path.read_bytes()[:4], dtype="<i4")[0])


@pytest.fixture
def source(tmp_path: Path) -> Path:
    seq = plate_sequence(n_frames=3)
    return write_sequence(
        seq, "fast-ycb", tmp_path / "src", flow_encodings={"nvof_1_slow": "s10.5"}
    )


@pytest.mark.parametrize("fmt", ["fast-ycb", "bop", "hdf5"])
def test_convert_keeps_s10_5_flow(source: Path, tmp_path: Path, fmt: str):
    assert _cv_type(source / "optical_flow" / "nvof_1_slow" / "1.float") == 11
    out = tmp_path / "out"
    assert main(["dataset", "convert", str(source), "--to", fmt, "--out", str(out)]) == 0
    (written,) = [p for p in out.iterdir() if not p.name.endswith(".json")]
    back = open_sequence(written)
    assert stored_flow_encodings(back) == {"gt": "float32", "nvof_1_slow": "s10.5"}
    if fmt == "fast-ycb":
        assert _cv_type(written / "optical_flow" / "nvof_1_slow" / "1.float") == 11  # CV_16SC2
        assert _cv_type(written / "optical_flow" / "gt" / "1.float") == 13  # CV_32FC2 stays
    elif fmt == "bop":
        assert _cv_type(written / "extras" / "flow" / "nvof_1_slow" / "000001.float") == 11
    else:
        with h5py.File(written) as f:
            dtypes = {d.dtype for d in _datasets(f) if "nvof_1_slow" in d.name}
        assert np.dtype("int16") in dtypes and np.dtype("float32") not in dtypes
    original = open_sequence(source)
    np.testing.assert_array_equal(
        back.flow(2, "nvof_1_slow").flow_px, original.flow(2, "nvof_1_slow").flow_px
    )


def _datasets(group: h5py.Group) -> list[h5py.Dataset]:
    found: list[h5py.Dataset] = []
    group.visititems(lambda _, obj: found.append(obj) if isinstance(obj, h5py.Dataset) else None)
    return found


def test_the_real_fast_ycb_without_metadata_is_probed(source: Path, tmp_path: Path):
    meta = json.loads((source / "metadata.json").read_text())
    assert meta["sets"]["flow"]["nvof_1_slow"]["encoding"] == "s10.5"
    (source / "metadata.json").unlink()  # as the real Fast-YCB: no metadata.json
    assert stored_flow_encodings(open_sequence(source)) == {
        "gt": "float32",
        "nvof_1_slow": "s10.5",
    }
    written = write_sequence(open_sequence(source), "fast-ycb", tmp_path / "copy")
    assert _cv_type(written / "optical_flow" / "nvof_1_slow" / "2.float") == 11
