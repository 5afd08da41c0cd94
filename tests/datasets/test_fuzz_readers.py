"""Fuzz the binary readers with byte mutations and truncations of valid files.

Each must either raise DatasetFormatError or return a valid array (right dtype, a shape that
matches the camera or the header, finite values); any other exception, a crash or a hang (an
alarm fires after a few seconds) fails the test.
"""

from __future__ import annotations

import contextlib
import signal
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from dataset_fixtures import plate_model, plate_sequence
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from roft_sim.datasets import dataset_frames, open_sequence, write_sequence
from roft_sim.datasets.fast_ycb_codec import (
    decode_depth_float,
    decode_flow_float,
    encode_depth_float,
    encode_flow_float,
)
from roft_sim.datasets.image_files import (
    decode_png_mask,
    decode_png_rgb,
    decode_png_u16,
    encode_png_mask,
    encode_png_rgb,
    encode_png_u16,
)
from roft_sim.datasets.model_files import read_mesh_ply_mm, write_mesh_ply_mm
from roft_sim.errors import DatasetFormatError

P = Path("fuzzed")
SHAPE = (12, 16)
TIME_LIMIT_S = 5


@contextlib.contextmanager
def time_limit(seconds: float):
    def fail(signum, frame):
        raise TimeoutError(f"reader did not return within {seconds} s")

    old = signal.signal(signal.SIGALRM, fail)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


@st.composite
def mutated(draw: st.DrawFn, original: bytes) -> bytes:
    """Byte flips/overwrites (biased to the header), then maybe a truncation or junk tail."""
    data = bytearray(original)
    n_edits = draw(st.integers(0, 6))
    for _ in range(n_edits):
        pos = draw(st.one_of(st.integers(0, min(40, len(data) - 1)), st.integers(0, len(data) - 1)))
        data[pos] = draw(st.integers(0, 255))
    cut = draw(st.one_of(st.none(), st.integers(0, len(data))))
    if cut is not None:
        del data[cut:]
    if draw(st.booleans()):
        data += draw(st.binary(max_size=16))
    return bytes(data)


def _run(decode: Callable[[bytes], np.ndarray], data: bytes) -> np.ndarray | None:
    with time_limit(TIME_LIMIT_S):
        try:
            return decode(data)
        except DatasetFormatError:
            return None


rng = np.random.default_rng(0)
DEPTH = rng.uniform(0.2, 3, SHAPE).astype(np.float32)
FLOW = rng.normal(0, 5, SHAPE + (2,)).astype(np.float32)
RGB = rng.integers(0, 256, SHAPE + (3,), dtype=np.uint8)
MASK = rng.random(SHAPE) > 0.5
U16 = rng.integers(0, 65535, SHAPE, dtype=np.uint16)


@given(mutated(encode_depth_float(DEPTH)))
def test_depth_float(data: bytes):
    out = _run(lambda d: decode_depth_float(d, P), data)
    if out is not None:
        assert out.dtype == np.float32 and out.ndim == 2
        assert 16 + 4 * out.size == len(data)
        assert np.isfinite(out).all() and (out >= 0).all()


@given(mutated(encode_flow_float(FLOW, "float32")) | mutated(encode_flow_float(FLOW, "s10.5")))
def test_flow_float(data: bytes):
    result = _run(lambda d: decode_flow_float(d, P), data)
    if result is not None:
        flow, cv_type = result
        assert cv_type in (11, 13) and flow.dtype == np.float32
        assert flow.ndim == 3 and flow.shape[2] == 2 and np.isfinite(flow).all()


@given(mutated(encode_png_rgb(RGB)))
def test_png_rgb(data: bytes):
    out = _run(lambda d: decode_png_rgb(d, P, shape=SHAPE), data)
    if out is not None:
        assert out.dtype == np.uint8 and out.shape == SHAPE + (3,)


@given(mutated(encode_png_mask(MASK)))
def test_png_mask(data: bytes):
    out = _run(lambda d: decode_png_mask(d, P, shape=SHAPE), data)
    if out is not None:
        assert out.dtype == np.bool_ and out.shape == SHAPE


@given(mutated(encode_png_u16(U16)))
def test_png_u16(data: bytes):
    out = _run(lambda d: decode_png_u16(d, P, shape=SHAPE), data)
    if out is not None:
        assert out.dtype == np.uint16 and out.shape == SHAPE


def _ply_bytes() -> bytes:
    with tempfile.TemporaryDirectory() as d:
        model = plate_model()
        write_mesh_ply_mm(Path(d) / "m.ply", model.vertices_m, model.faces)
        return (Path(d) / "m.ply").read_bytes()


@given(mutated(_ply_bytes()))
@settings(max_examples=30)
def test_ply_model(data: bytes):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "m.ply"
        path.write_bytes(data)
        result = _run(lambda _: read_mesh_ply_mm(path), data)
    if result is not None:
        v, f = result
        assert v.ndim == 2 and v.shape[1] == 3 and f.ndim == 2 and f.shape[1] == 3
        assert f.size == 0 or (f.min() >= 0 and f.max() < len(v))


def _hdf5_bytes() -> bytes:
    with tempfile.TemporaryDirectory() as d:
        seq = plate_sequence(n_frames=2, width_px=16, height_px=12)
        return write_sequence(seq, "hdf5", Path(d)).read_bytes()


HDF5_BYTES = _hdf5_bytes()


def _read_everything(path: Path) -> None:
    seq = open_sequence(path, "hdf5")
    try:
        for frame in dataset_frames(seq):
            assert frame.rgb.shape == (12, 16, 3) and np.isfinite(frame.depth_m).all()
        seq.object_model()
    finally:
        seq.close()


@given(mutated(HDF5_BYTES))
@settings(max_examples=40, suppress_health_check=[HealthCheck.too_slow])
def test_hdf5_file(data: bytes):
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "seq.h5"
        path.write_bytes(data)
        with time_limit(TIME_LIMIT_S), contextlib.suppress(DatasetFormatError):
            try:
                _read_everything(path)
            except ValueError as e:
                # A mutated but readable file may decode to values a record refuses (e.g. a
                # non-rigid pose): that is a ValueError from the record, which names it.
                if "DatasetFrame" not in str(e) and "transform" not in str(e):
                    raise


@pytest.mark.parametrize("n", [0, 15, 16, 17, 100])
def test_truncations_at_the_header_boundaries(n: int):
    for encoded, decode in (
        (encode_depth_float(DEPTH), lambda d: decode_depth_float(d, P)),
        (encode_flow_float(FLOW, "float32"), lambda d: decode_flow_float(d, P)),
    ):
        with pytest.raises(DatasetFormatError, match="fuzzed"):
            decode(encoded[:n])
