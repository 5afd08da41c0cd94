"""The tracker process protocol's messages: round trips and every kind of violation."""

from __future__ import annotations

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("msgpack", reason="the process extra (msgpack) is not installed")

from roft_sim.geometry.camera import CameraIntrinsics  # noqa: E402
from roft_sim.geometry.se3 import transform_from_pq  # noqa: E402
from roft_sim.records import (  # noqa: E402
    Estimate,
    FlowField,
    MaskDetection,
    ObjectModel,
    Observation,
    PoseDetection,
)
from roft_sim.testing import assert_pose_close  # noqa: E402
from roft_sim.trackers.process import codec  # noqa: E402
from roft_sim.trackers.process.codec import ProtocolError  # noqa: E402
from roft_sim.trackers.process.shared import SharedReader, SharedWriter  # noqa: E402

ATOL_M = 1e-15
ATOL_RAD = 1e-15


@pytest.fixture(scope="module")
def shared():
    """A small shared file taking every array of 1 byte or more (what does not fit: inline)."""
    writer = SharedWriter(4096, min_bytes=1)
    reader = SharedReader(writer.path, writer.size_bytes)
    writer.unlink()
    yield writer, reader
    reader.close()
    writer.close()


def _wire(message):
    """``message`` after packing and unpacking (what the other side sees)."""
    frame = codec.pack(message)
    (size,) = codec.HEADER.unpack(frame[: codec.HEADER.size])
    assert size == len(frame) - codec.HEADER.size
    return codec.unpack(frame[codec.HEADER.size :])


def _pose(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return transform_from_pq(rng.uniform(-1, 1, 3) + [0, 0, 1], q / np.linalg.norm(q))


@st.composite
def observations(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    h, w = draw(st.integers(1, 9)), draw(st.integers(1, 9))
    dropped = draw(st.booleans())
    grid = draw(st.integers(1, 3))
    flow = None
    if not dropped and draw(st.booleans()):
        hg, wg = -(-h // grid), -(-w // grid)
        flow = FlowField(
            flow_px=rng.normal(size=(hg, wg, 2)).astype(np.float32),
            from_k=3,
            to_k=4,
            grid_px=grid,
            valid=rng.random((hg, wg)) > 0.3 if draw(st.booleans()) else None,
        )
    n_poses, n_masks = draw(st.integers(0, 3)), draw(st.integers(0, 2))
    return Observation(
        k=4,
        t_s=4 / 30,
        rgb=None if dropped else rng.integers(0, 256, (h, w, 3), dtype=np.uint8),
        depth_m=None if dropped else rng.random((h, w), dtype=np.float32),
        flow=flow,
        poses=tuple(
            PoseDetection(capture_k=i, arrival_k=4, T_cam_obj=_pose(rng), detection_id=10 + i)
            for i in range(n_poses)
        ),
        masks=tuple(
            MaskDetection(capture_k=i, arrival_k=4, mask=rng.random((h, w)) > 0.5, detection_id=i)
            for i in range(n_masks)
        ),
    )


@settings(max_examples=40, deadline=None, derandomize=True)
@given(observations(), st.booleans())
def test_an_observation_crosses_unchanged(shared, observation, through_shared_file):
    """Inline, or through the shared file (the arrays that fit; the others inline)."""
    writer, reader = shared if through_shared_file else (None, None)
    message = _wire(codec.observation_message(observation, writer))
    if writer is not None and observation.rgb is not None:
        assert "shm_offset" in message["rgb"]  # the first array always fits
    got = codec.observation_from_message(message, shared=reader)
    assert (got.k, got.t_s) == (observation.k, observation.t_s)
    for name in ("rgb", "depth_m"):
        a, b = getattr(got, name), getattr(observation, name)
        assert (a is None and b is None) or (a.dtype == b.dtype and np.array_equal(a, b))
    assert (got.flow is None) == (observation.flow is None)
    if got.flow is not None:
        f, g = observation.flow, got.flow
        assert (g.from_k, g.to_k, g.grid_px) == (f.from_k, f.to_k, f.grid_px)
        assert np.array_equal(g.flow_px, f.flow_px) and g.flow_px.dtype == np.float32
        assert (g.valid is None and f.valid is None) or np.array_equal(g.valid, f.valid)
    assert len(got.poses) == len(observation.poses)
    for p, q in zip(got.poses, observation.poses, strict=True):
        assert (p.capture_k, p.arrival_k, p.detection_id) == (
            q.capture_k,
            q.arrival_k,
            q.detection_id,
        )
        assert_pose_close(p.T_cam_obj, q.T_cam_obj, atol_m=ATOL_M, atol_rad=ATOL_RAD)
    for m, n in zip(got.masks, observation.masks, strict=True):
        assert m.mask.dtype == np.bool_ and np.array_equal(m.mask, n.mask)
        assert (m.capture_k, m.detection_id) == (n.capture_k, n.detection_id)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.integers(0, 2**32 - 1), st.booleans(), st.booleans())
def test_an_estimate_crosses_unchanged(seed, with_covariance, valid):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(12, 12))
    estimate = Estimate(
        k=7,
        T_cam_obj=_pose(rng),
        v_obj_mps=rng.normal(size=3),
        w_radps=rng.normal(size=3),
        covariance=a @ a.T if with_covariance else None,
        valid=valid,
        spatial_twist=rng.normal(size=6) if with_covariance else None,
        accepted_pose_ids=(1, 2),
        rejected_pose_ids=(3,),
        dropped_pose_ids=(),
        diagnostics={"pixels": 12, "ratio": 0.5, "why": "late"},
    )
    got = codec.estimate_from_message(_wire(codec.estimate_message(estimate)), k=7)
    assert_pose_close(got.T_cam_obj, estimate.T_cam_obj, atol_m=ATOL_M, atol_rad=ATOL_RAD)
    for name in ("v_obj_mps", "w_radps", "covariance", "spatial_twist"):
        a, b = getattr(got, name), getattr(estimate, name)
        assert (a is None and b is None) or np.array_equal(a, b)
    for name in ("k", "valid", "accepted_pose_ids", "rejected_pose_ids", "dropped_pose_ids"):
        assert getattr(got, name) == getattr(estimate, name)
    assert dict(got.diagnostics) == dict(estimate.diagnostics)


def test_hello_and_reset_cross_unchanged():
    intrinsics = CameraIntrinsics(
        fx_px=500.0, fy_px=501.0, cx_px=319.5, cy_px=239.5, width_px=640, height_px=480
    )
    rng = np.random.default_rng(0)
    model = ObjectModel(
        name="box",
        vertices_m=rng.normal(size=(8, 3)),
        faces=rng.integers(0, 8, (12, 3)),
        model_points_m=rng.normal(size=(50, 3)),
    )
    hello = codec.context_from_hello(
        _wire(codec.hello_message(intrinsics=intrinsics, fps=30, object_model=model, seed=5))
    )
    assert hello.intrinsics == intrinsics and (hello.fps, hello.seed) == (30, 5)
    for name in ("vertices_m", "faces", "model_points_m"):
        assert np.array_equal(getattr(hello.object_model, name), getattr(model, name))
    assert codec.initial_from_reset(_wire(codec.reset_message(None))) is None
    initial = Estimate(k=2, T_cam_obj=_pose(rng), v_obj_mps=np.ones(3), w_radps=-np.ones(3))
    got = codec.initial_from_reset(_wire(codec.reset_message(initial)))
    assert got is not None and got.k == 2 and np.array_equal(got.w_radps, initial.w_radps)
    assert_pose_close(got.T_cam_obj, initial.T_cam_obj, atol_m=ATOL_M, atol_rad=ATOL_RAD)


def _f64(*values):
    return {
        "dtype": "float64",
        "shape": [len(values)],
        "data": struct.pack(f"<{len(values)}d", *values),
    }


def _estimate(**changes):
    message = {
        "type": "estimate",
        "k": 3,
        "valid": True,
        "t_m": _f64(0.0, 0.0, 0.5),
        "q_wxyz": _f64(1.0, 0.0, 0.0, 0.0),
        "v_obj_mps": _f64(0.0, 0.0, 0.0),
        "w_radps": _f64(0.0, 0.0, 0.0),
    }
    return {k: v for k, v in (message | changes).items() if v is not ...}


def test_a_well_formed_estimate_passes():
    estimate = codec.estimate_from_message(_estimate(), k=3)
    assert estimate.valid and estimate.T_cam_obj[2, 3] == 0.5


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"k": 4}, r"estimate\.k: received frame 4, expected 3"),
        ({"t_m": _f64(0.0, 0.5)}, r"estimate\.t_m: received shape \[2\], expected \[3\]"),
        (
            {"v_obj_mps": _f64(0.0, float("nan"), 0.0)},
            r"estimate\.v_obj_mps: received nan at index \[1\]",
        ),
        (
            {"q_wxyz": _f64(1.0, 0.1, 0.0, 0.0)},
            r"estimate\.q_wxyz: received .* norm 1\.00498.*unit quaternion \(w, x, y, z\)",
        ),
        ({"w_radps": ...}, r"estimate: missing field 'w_radps'"),
        ({"valid": 1}, r"estimate\.valid: received 1, expected true or false"),
        ({"q_xyzw": _f64(0.0, 0.0, 0.0, 1.0)}, r"estimate: unknown field 'q_xyzw'"),
        (
            {"t_m": {**_f64(0.0, 0.0, 0.5), "dtype": "float32"}},
            r"estimate\.t_m: received dtype 'float32', expected 'float64'",
        ),
        (
            {"t_m": {**_f64(0.0, 0.0, 0.5), "data": b"\0" * 20}},
            r"estimate\.t_m: received 20 bytes of data, expected 24",
        ),
        (
            {"covariance": _f64(1.0)},
            r"estimate\.covariance: received shape \[1\], expected \[12, 12\]",
        ),
        (
            {"accepted_pose_ids": [1.5]},
            r"estimate\.accepted_pose_ids: received \[1\.5\], expected a list of integers",
        ),
        ({"type": "ready"}, r"received type 'ready', expected 'estimate'"),
    ],
)
def test_a_broken_estimate_is_named(changes, match):
    with pytest.raises(ProtocolError, match=match):
        codec.estimate_from_message(_estimate(**changes), k=3)


def test_a_wrong_image_shape_and_version_are_named():
    intrinsics = CameraIntrinsics(
        fx_px=50.0, fy_px=50.0, cx_px=4.0, cy_px=3.0, width_px=8, height_px=6
    )
    observation = Observation(
        k=0, t_s=0.0, rgb=np.zeros((6, 7, 3), np.uint8), depth_m=None, flow=None
    )
    message = _wire(codec.observation_message(observation))
    with pytest.raises(
        ProtocolError, match=r"observation\.rgb: received shape \[6, 7, 3\], expected \[6, 8, 3\]"
    ):
        codec.observation_from_message(message, intrinsics=intrinsics)
    with pytest.raises(
        ProtocolError, match=r"ready \(reply to hello\)\.protocol: received version 2, expected 1"
    ):
        codec.check_ready({"type": "ready", "protocol": 2}, "hello")
    with pytest.raises(ProtocolError, match="not MessagePack"):
        codec.unpack(b"\xc1")
    shared_rgb = {
        "type": "observation",
        "rgb": {"dtype": "uint8", "shape": [6, 8, 3], "shm_offset": 0},
    }
    with pytest.raises(
        ProtocolError, match=r"observation\.rgb: received \['dtype', 'shape', 'shm_offset'\]"
    ):
        codec.observation_from_message(message | shared_rgb)  # no shared file was agreed
