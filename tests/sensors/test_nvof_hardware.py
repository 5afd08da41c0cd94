"""Real NVIDIA hardware flow (``nvof-hw``): struct layouts against NVIDIA's API 1.0 headers, the
spec, the error without a GPU, the session's hint policy and conversions on a fake engine, and
(on a machine with an NVIDIA GPU, marked ``gpu``) the engine's flow of a known shift."""

from __future__ import annotations

import ctypes

import cv2
import numpy as np
import pytest

from roft_sim.datasets.base import InMemorySequence
from roft_sim.errors import ConfigError
from roft_sim.geometry import CameraIntrinsics
from roft_sim.sensors import nvof_hardware as hw
from roft_sim.sensors.flow_sources import FLOW_SOURCE_SPECS, make_flow_source


def _hardware_present() -> bool:
    try:
        ctypes.CDLL(hw.NVOF_LIBRARY)
        ctypes.CDLL(hw.CUDA_LIBRARY)
    except OSError:
        return False
    return True


def test_parameter_structs_have_the_api_1_0_layout() -> None:
    # nvOpticalFlowCommon.h / nvOpticalFlowCuda.h (API 1.0), natural alignment on x86-64;
    # what follows a struct's last field is reserved zeros (module doc)
    assert hw._InitParams.perfLevel.offset == 20
    assert hw._InitParams.enableOutputCost.offset == 28
    assert hw._InitParams.hPrivData.offset == 32
    assert hw._BufferDescriptor.bufferFormat.offset == 12
    assert hw._ExecuteInput.disableTemporalHints.offset == 24
    assert hw._ExecuteInput.hPrivData.offset == 32
    assert hw._ExecuteOutput.hPrivData.offset == 16
    assert hw._StrideInfo.numPlanes.offset == 24
    assert ctypes.sizeof(hw._Memcpy2D) == 128  # cuda.h's CUDA_MEMCPY2D
    assert [name for name, _ in hw._FUNCTION_TABLE] == [
        "create", "init", "create_buffer", "buffer_array", "buffer_device_ptr", "buffer_strides",
        "set_streams", "execute", "destroy_buffer", "destroy", "last_error", "get_caps",
    ]  # fmt: skip


def test_spec_builds_the_source_without_touching_a_gpu() -> None:
    assert "nvof-hw[:<perf level>]" in FLOW_SOURCE_SPECS
    src = make_flow_source("nvof-hw", seed=0)
    assert isinstance(src, hw.NvofHardwareFlowSource)
    assert src.name == "nvof-hw" and src.perf_level == "slow"
    medium = make_flow_source("nvof-hw:medium", seed=0)
    assert isinstance(medium, hw.NvofHardwareFlowSource) and medium.name == "nvof-hw:medium"
    with pytest.raises(ConfigError, match="slow, medium, fast"):
        make_flow_source("nvof-hw:turbo", seed=0)


def _sequence(frames: list[np.ndarray], name: str = "seq") -> InMemorySequence:
    h, w = frames[0].shape[:2]
    cam = CameraIntrinsics(
        fx_px=100.0, fy_px=100.0, cx_px=(w - 1) / 2, cy_px=(h - 1) / 2, width_px=w, height_px=h
    )
    return InMemorySequence(
        name=name,
        object_name="texture",
        intrinsics=cam,
        fps=30,
        rgb_frames=frames,
        depth_frames=[np.ones((h, w), np.float32)] * len(frames),
    )


def test_without_the_driver_library_the_error_says_what_is_missing_and_what_to_use() -> None:
    def no_library(name: str) -> None:
        raise OSError(f"{name}: cannot open shared object file")

    rng = np.random.default_rng(0)
    seq = _sequence([rng.integers(0, 255, (64, 96, 3), dtype=np.uint8) for _ in range(2)])
    src = hw.NvofHardwareFlowSource(loader=no_library)
    with pytest.raises(hw.NvofHardwareError, match=r"libcuda\.so\.1.*nvof-like:dis"):
        src.flow(seq, 0, 1)
    assert isinstance(hw.NvofHardwareError("x"), ConfigError)  # exit code 2 in the CLI


class _FakeCudaLibrary:
    """The CUDA driver calls ``_CudaDriver`` makes; ``cuCtxSetCurrent`` fails."""

    def __init__(self) -> None:
        self.released = 0

    def cuInit(self, flags: int) -> int:
        return 0

    def cuDeviceGet(self, device: object, ordinal: int) -> int:
        return 0

    def cuDevicePrimaryCtxRetain(self, context: object, device: object) -> int:
        return 0

    def cuCtxSetCurrent(self, context: object) -> int:
        return 201  # CUDA_ERROR_INVALID_CONTEXT

    def cuGetErrorString(self, status: int, text: object) -> int:
        return 0

    def cuDevicePrimaryCtxRelease_v2(self, device: object) -> int:
        self.released += 1
        return 0


def test_a_failing_cuda_call_is_reported_and_the_retained_context_released() -> None:
    lib = _FakeCudaLibrary()
    with pytest.raises(hw.NvofHardwareError, match="cuCtxSetCurrent failed: error 201"):
        hw._CudaDriver(lib, 0)
    assert lib.released == 1


class _FakeEngine:
    """Returns S10.5 vectors ``(32 * k + 3, -16)`` for the k-th call; records the calls."""

    def __init__(self, width: int, height: int) -> None:
        self.shape = (-(-height // 4), -(-width // 4))
        self.calls: list[tuple[np.ndarray, np.ndarray, bool]] = []
        self.closed = False

    def flow_s10_5(self, previous: np.ndarray, current: np.ndarray, *, temporal_hints: bool):
        self.calls.append((previous, current, temporal_hints))
        out = np.empty((*self.shape, 2), np.int16)
        out[..., 0] = 32 * len(self.calls) + 3
        out[..., 1] = -16
        return out

    def close(self) -> None:
        self.closed = True


def test_session_hints_consecutive_pairs_only_and_converts_s10_5_to_pixels() -> None:
    rng = np.random.default_rng(1)
    frames = [rng.integers(0, 255, (70, 98, 3), dtype=np.uint8) for _ in range(8)]
    engines: list[_FakeEngine] = []

    def factory(w: int, h: int) -> _FakeEngine:
        engines.append(_FakeEngine(w, h))
        return engines[-1]

    src = hw.NvofHardwareFlowSource(engine_factory=factory)
    seq = _sequence(frames)
    pairs = [(0, 1), (1, 2), (2, 3), (5, 6), (6, 7), (3, 2)]
    flows = [src.flow(seq, a, b) for a, b in pairs]
    engine = engines[0]
    # the dumper's policy: hints on while pairs follow each other, off after a jump
    assert [c[2] for c in engine.calls] == [False, True, True, False, True, False]
    for (a, b), (prev, cur, _) in zip(pairs, engine.calls, strict=True):
        np.testing.assert_array_equal(prev, cv2.cvtColor(frames[a], cv2.COLOR_RGB2GRAY))
        np.testing.assert_array_equal(cur, cv2.cvtColor(frames[b], cv2.COLOR_RGB2GRAY))
    for i, f in enumerate(flows):
        assert f.grid_px == 4 and f.flow_px.shape == (18, 25, 2)  # ceil(70/4), ceil(98/4)
        assert f.flow_px.dtype == np.float32
        np.testing.assert_array_equal(f.flow_px[0, 0], [i + 1 + 3 / 32, -0.5])
    assert (flows[0].from_k, flows[0].to_k) == (0, 1)
    # another sequence: no hints from this one's last pair, even at the same frame numbers
    other = _sequence(frames, name="other")
    src.flow(other, 2, 3)
    assert engine.calls[-1][2] is False
    # another size: a new session, the old one closed
    small = _sequence([f[:40, :48] for f in frames[:2]])
    assert src.flow(small, 0, 1).flow_px.shape == (10, 12, 2)
    assert len(engines) == 2 and engine.closed
    src.close()
    assert engines[1].closed


def test_session_refuses_wrong_images_and_levels() -> None:
    session = hw.NvofHardwareSession(64, 48, engine=_FakeEngine(64, 48))
    grey = np.zeros((48, 64), np.uint8)
    with pytest.raises(ValueError, match=r"\(48, 64\) uint8"):
        session.flow_px(grey, np.zeros((48, 63), np.uint8), pair_id=("s", 0, 1))
    with pytest.raises(ValueError, match="uint8"):
        session.flow_px(grey, grey.astype(np.float32), pair_id=("s", 0, 1))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="at least 32x32"):
        hw.NvofHardwareSession(16, 48, engine=_FakeEngine(16, 48))
    with pytest.raises(ConfigError, match="slow, medium, fast"):
        hw.NvofHardwareSession(64, 48, perf_level="turbo", engine=_FakeEngine(64, 48))
    seq = _sequence([np.zeros((48, 64, 3), np.uint8)] * 2)
    with pytest.raises(ValueError, match="two different frames"):
        hw.NvofHardwareFlowSource(engine_factory=_FakeEngine).flow(seq, 1, 1)


@pytest.mark.gpu
@pytest.mark.skipif(not _hardware_present(), reason="no NVIDIA driver optical flow library")
def test_hardware_flow_of_a_shifted_texture_is_the_shift() -> None:
    rng = np.random.default_rng(2)
    texture = cv2.GaussianBlur(rng.integers(0, 255, (360, 640), dtype=np.uint8), (0, 0), 1.5)
    texture = cv2.normalize(texture, None, 0, 255, cv2.NORM_MINMAX)
    shift = np.float32([[1, 0, 3], [0, 1, -2]])  # content moves 3 px right, 2 px up
    moved = cv2.warpAffine(texture, shift, (640, 360), borderMode=cv2.BORDER_REFLECT)
    frames = [np.repeat(img[..., None], 3, axis=2) for img in (texture, moved, texture)]
    src = hw.NvofHardwareFlowSource()
    try:
        forward = src.flow(_sequence(frames), 0, 1)
        backward = src.flow(_sequence(frames), 1, 2)
    finally:
        src.close()
    assert forward.grid_px == 4 and forward.flow_px.shape == (90, 160, 2)
    inner = (slice(10, -10), slice(10, -10))
    np.testing.assert_allclose(np.median(forward.flow_px[inner], axis=(0, 1)), [3, -2], atol=0.25)
    np.testing.assert_allclose(np.median(backward.flow_px[inner], axis=(0, 1)), [-3, 2], atol=0.25)
