"""Real NVIDIA hardware optical flow (NVOFA) through the driver's NVOF API 1.0.

The flow the reference ROFT reads on Fast-YCB (``nvof_1_slow``) was computed by NVIDIA's optical
flow accelerator with the reference's dumper (``roft_reference.md`` section 10.1): NVOF API
1.0, performance level SLOW, a 4x4 output grid, temporal hints on, input = the grey frame
``k - 1``, reference = the grey frame ``k``, S10.5 int16 vectors. :class:`NvofHardwareFlowSource`
runs the same engine with the same settings on a sequence's rgb images, so a simulated dataset
can be read with real hardware flow wherever an NVIDIA GPU (Turing or newer) and its driver are
present (flow spec ``nvof-hw``; docs/sensors.md, ``nvof-hw``). The GPU's generation matters: the
engine changed after Turing (NVIDIA states 10-15 % better quality on Ada than on Ampere), and
ROFT's Fast-YCB flow came from a Turing engine.

The binding uses the driver's two C libraries alone, through ctypes: ``libcuda.so.1`` (context,
2-D copies) and ``libnvidia-opticalflow.so.1`` (the NVOF function table). Struct layouts follow
NVIDIA's public API 1.0 headers (``nvOpticalFlowCommon.h``, ``nvOpticalFlowCuda.h``,
github.com/NVIDIA/NVIDIAOpticalFlowSDK); each parameter struct is followed by zeroed reserved
space, which later API versions use for appended fields and version 1.0 ignores. Nothing here
runs on import: a machine without the libraries can import the module, and
:class:`NvofHardwareError` says what is missing when a flow is first asked for.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import Sequence
from roft_sim.errors import ConfigError
from roft_sim.records import FlowField
from roft_sim.sensors.flow_source_base import check_frame_pair, flow_px_from_s10_5

__all__ = [
    "NVOF_LIBRARY",
    "CUDA_LIBRARY",
    "NVOF_HW_GRID_PX",
    "NVOF_HW_PERF_LEVELS",
    "NvofHardwareError",
    "NvofHardwareSession",
    "NvofHardwareFlowSource",
]

NVOF_LIBRARY = "libnvidia-opticalflow.so.1"
"""The driver's optical flow library (Linux; part of the NVIDIA driver's video libraries)."""

CUDA_LIBRARY = "libcuda.so.1"
"""The CUDA driver API library."""

NVOF_HW_GRID_PX = 4
"""Output grid of NVOF API 1.0: one vector per 4x4 block (the reference's ``nvof_1_slow``)."""

NVOF_HW_PERF_LEVELS = {"slow": 5, "medium": 10, "fast": 20}
"""``NV_OF_PERF_LEVEL`` values by name; the reference's dumper uses SLOW."""

_API_VERSION_1_0 = (1 << 4) | 0
_MODE_OPTICAL_FLOW = 1
_USAGE_INPUT, _USAGE_OUTPUT = 1, 2
_FORMAT_GRAYSCALE8, _FORMAT_SHORT2 = 1, 5
_CUDA_BUFFER_DEVICE_PTR = 2
_MEMORY_HOST, _MEMORY_DEVICE = 1, 2

U8 = NDArray[np.uint8]
I16 = NDArray[np.int16]

_Ptr = ctypes.c_void_p
_U32 = ctypes.c_uint32


class NvofHardwareError(ConfigError):
    """No usable NVIDIA optical flow engine (library, GPU or driver call failed)."""


class _InitParams(ctypes.Structure):
    """``NV_OF_INIT_PARAMS`` (API 1.0), then reserved zeros."""

    _fields_ = [
        ("width", _U32),
        ("height", _U32),
        ("outGridSize", _U32),
        ("hintGridSize", _U32),
        ("mode", _U32),
        ("perfLevel", _U32),
        ("enableExternalHints", _U32),
        ("enableOutputCost", _U32),
        ("hPrivData", _Ptr),
        ("_reserved", _U32 * 32),
    ]


class _BufferDescriptor(ctypes.Structure):
    """``NV_OF_BUFFER_DESCRIPTOR``, then reserved zeros."""

    _fields_ = [
        ("width", _U32),
        ("height", _U32),
        ("bufferUsage", _U32),
        ("bufferFormat", _U32),
        ("_reserved", _U32 * 16),
    ]


class _ExecuteInput(ctypes.Structure):
    """``NV_OF_EXECUTE_INPUT_PARAMS`` (API 1.0), then reserved zeros."""

    _fields_ = [
        ("inputFrame", _Ptr),
        ("referenceFrame", _Ptr),
        ("externalHints", _Ptr),
        ("disableTemporalHints", _U32),
        ("padding", _U32),
        ("hPrivData", _Ptr),
        ("_reserved", _U32 * 32),
    ]


class _ExecuteOutput(ctypes.Structure):
    """``NV_OF_EXECUTE_OUTPUT_PARAMS`` (API 1.0), then reserved zeros."""

    _fields_ = [
        ("outputBuffer", _Ptr),
        ("outputCostBuffer", _Ptr),
        ("hPrivData", _Ptr),
        ("_reserved", _Ptr * 16),
    ]


class _StrideInfo(ctypes.Structure):
    """``NV_OF_CUDA_BUFFER_STRIDE_INFO``: (x, y) byte strides of up to three planes."""

    _fields_ = [("strides", _U32 * 6), ("numPlanes", _U32), ("_reserved", _U32 * 8)]


class _Memcpy2D(ctypes.Structure):
    """``CUDA_MEMCPY2D`` (cuda.h)."""

    _fields_ = [
        ("srcXInBytes", ctypes.c_size_t),
        ("srcY", ctypes.c_size_t),
        ("srcMemoryType", ctypes.c_uint),
        ("srcHost", _Ptr),
        ("srcDevice", ctypes.c_uint64),
        ("srcArray", _Ptr),
        ("srcPitch", ctypes.c_size_t),
        ("dstXInBytes", ctypes.c_size_t),
        ("dstY", ctypes.c_size_t),
        ("dstMemoryType", ctypes.c_uint),
        ("dstHost", _Ptr),
        ("dstDevice", ctypes.c_uint64),
        ("dstArray", _Ptr),
        ("dstPitch", ctypes.c_size_t),
        ("WidthInBytes", ctypes.c_size_t),
        ("Height", ctypes.c_size_t),
    ]


_FUNCTION_TABLE: tuple[tuple[str, Any], ...] = (
    # NV_OF_CUDA_API_FUNCTION_LIST, in its order
    ("create", ctypes.CFUNCTYPE(ctypes.c_int, _Ptr, ctypes.POINTER(_Ptr))),
    ("init", ctypes.CFUNCTYPE(ctypes.c_int, _Ptr, ctypes.POINTER(_InitParams))),
    (
        "create_buffer",
        ctypes.CFUNCTYPE(
            ctypes.c_int,
            _Ptr,
            ctypes.POINTER(_BufferDescriptor),
            ctypes.c_int,
            ctypes.POINTER(_Ptr),
        ),
    ),
    ("buffer_array", ctypes.CFUNCTYPE(_Ptr, _Ptr)),
    ("buffer_device_ptr", ctypes.CFUNCTYPE(ctypes.c_uint64, _Ptr)),
    ("buffer_strides", ctypes.CFUNCTYPE(ctypes.c_int, _Ptr, ctypes.POINTER(_StrideInfo))),
    ("set_streams", ctypes.CFUNCTYPE(ctypes.c_int, _Ptr, _Ptr, _Ptr)),
    (
        "execute",
        ctypes.CFUNCTYPE(
            ctypes.c_int, _Ptr, ctypes.POINTER(_ExecuteInput), ctypes.POINTER(_ExecuteOutput)
        ),
    ),
    ("destroy_buffer", ctypes.CFUNCTYPE(ctypes.c_int, _Ptr)),
    ("destroy", ctypes.CFUNCTYPE(ctypes.c_int, _Ptr)),
    ("last_error", ctypes.CFUNCTYPE(ctypes.c_int, _Ptr, ctypes.c_char_p, ctypes.POINTER(_U32))),
    (
        "get_caps",
        ctypes.CFUNCTYPE(
            ctypes.c_int, _Ptr, ctypes.c_int, ctypes.POINTER(_U32), ctypes.POINTER(_U32)
        ),
    ),
)


def _load(name: str, loader: Callable[[str], Any]) -> Any:
    try:
        return loader(name)
    except OSError as e:
        raise NvofHardwareError(
            f"the 'nvof-hw' flow needs an NVIDIA GPU (Turing or newer) and its driver's "
            f"{name}, which could not be loaded ({e}); on a machine without one, use the "
            "simulated NVOF-like flow ('nvof-model', fitted to this engine's errors, or "
            "'nvof-like:dis')"
        ) from e


class _CudaDriver:
    """The CUDA driver calls the session needs: the device's primary context and 2-D copies."""

    def __init__(self, lib: Any, gpu: int) -> None:
        self._lib = lib
        self._check(lib.cuInit(0), "cuInit")
        device = ctypes.c_int()
        self._check(lib.cuDeviceGet(ctypes.byref(device), int(gpu)), f"cuDeviceGet({gpu})")
        self._device = device
        self.context = _Ptr()
        self._check(
            lib.cuDevicePrimaryCtxRetain(ctypes.byref(self.context), device),
            "cuDevicePrimaryCtxRetain",
        )
        try:
            self._check(lib.cuCtxSetCurrent(self.context), "cuCtxSetCurrent")
        except NvofHardwareError:
            self.close()
            raise

    def _check(self, status: int, call: str) -> None:
        if status != 0:
            text = ctypes.c_char_p()
            self._lib.cuGetErrorString(int(status), ctypes.byref(text))
            detail = (text.value or b"").decode(errors="replace")
            raise NvofHardwareError(f"CUDA driver call {call} failed: error {status} {detail}")

    def copy_2d(
        self,
        *,
        src_host: int = 0,
        src_device: int = 0,
        src_pitch: int,
        dst_host: int = 0,
        dst_device: int = 0,
        dst_pitch: int,
        row_bytes: int,
        rows: int,
    ) -> None:
        """One synchronous 2-D copy between host memory and a pitched device buffer."""
        c = _Memcpy2D(
            srcMemoryType=_MEMORY_HOST if src_host else _MEMORY_DEVICE,
            srcHost=src_host or None,
            srcDevice=src_device,
            srcPitch=src_pitch,
            dstMemoryType=_MEMORY_HOST if dst_host else _MEMORY_DEVICE,
            dstHost=dst_host or None,
            dstDevice=dst_device,
            dstPitch=dst_pitch,
            WidthInBytes=row_bytes,
            Height=rows,
        )
        self._check(self._lib.cuMemcpy2D_v2(ctypes.byref(c)), "cuMemcpy2D")

    def synchronize(self) -> None:
        self._check(self._lib.cuCtxSynchronize(), "cuCtxSynchronize")

    def close(self) -> None:
        self._lib.cuDevicePrimaryCtxRelease_v2(self._device)


@dataclass(frozen=True, slots=True)
class _Buffer:
    handle: int
    device_ptr: int
    pitch_bytes: int


class _Engine(Protocol):
    """What :class:`NvofHardwareSession` asks of the hardware (a fake in the tests)."""

    def flow_s10_5(self, previous: U8, current: U8, *, temporal_hints: bool) -> I16: ...

    def close(self) -> None: ...


class _NvofEngine:
    """One NVOF API 1.0 session on the GPU for ``width`` x ``height`` grey images."""

    def __init__(
        self, width: int, height: int, perf_level: int, gpu: int, loader: Callable[[str], Any]
    ) -> None:
        cuda_lib = _load(CUDA_LIBRARY, loader)
        nvof_lib = _load(NVOF_LIBRARY, loader)
        self._fn: dict[str, Any] = {}
        self._handle = _Ptr()
        self._buffers: list[_Buffer] = []
        self.width, self.height = int(width), int(height)
        g = NVOF_HW_GRID_PX
        self.grid_shape = (-(-self.height // g), -(-self.width // g))
        self._cuda = _CudaDriver(cuda_lib, gpu)
        try:
            self._open(nvof_lib, perf_level)
        except BaseException:
            self.close()
            raise

    def _open(self, nvof_lib: Any, perf_level: int) -> None:
        table = (_Ptr * 64)()
        status = nvof_lib.NvOFAPICreateInstanceCuda(_API_VERSION_1_0, ctypes.byref(table))
        if status != 0:
            raise NvofHardwareError(
                f"NvOFAPICreateInstanceCuda(API 1.0) failed with status {status}: this driver "
                "or GPU has no optical flow engine"
            )
        self._fn = {name: kind(table[i]) for i, (name, kind) in enumerate(_FUNCTION_TABLE)}
        self._check(self._fn["create"](self._cuda.context, ctypes.byref(self._handle)), "create")
        init = _InitParams(
            width=self.width,
            height=self.height,
            outGridSize=NVOF_HW_GRID_PX,
            mode=_MODE_OPTICAL_FLOW,
            perfLevel=perf_level,
        )
        self._check(self._fn["init"](self._handle, ctypes.byref(init)), "init")
        self._input = self._buffer(self.width, self.height, _USAGE_INPUT, _FORMAT_GRAYSCALE8)
        self._reference = self._buffer(self.width, self.height, _USAGE_INPUT, _FORMAT_GRAYSCALE8)
        rows, cols = self.grid_shape
        self._output = self._buffer(cols, rows, _USAGE_OUTPUT, _FORMAT_SHORT2)

    def _check(self, status: int, call: str) -> None:
        if status != 0:
            text = ctypes.create_string_buffer(256)
            size = _U32(256)
            if self._handle:
                self._fn["last_error"](self._handle, text, ctypes.byref(size))
            detail = text.value.decode(errors="replace")
            raise NvofHardwareError(f"NVOF call {call} failed with status {status}: {detail}")

    def _buffer(self, width: int, height: int, usage: int, fmt: int) -> _Buffer:
        desc = _BufferDescriptor(width=width, height=height, bufferUsage=usage, bufferFormat=fmt)
        handle = _Ptr()
        self._check(
            self._fn["create_buffer"](
                self._handle, ctypes.byref(desc), _CUDA_BUFFER_DEVICE_PTR, ctypes.byref(handle)
            ),
            "create GPU buffer",
        )
        strides = _StrideInfo()
        self._check(self._fn["buffer_strides"](handle, ctypes.byref(strides)), "buffer strides")
        device_ptr = int(self._fn["buffer_device_ptr"](handle))
        buf = _Buffer(int(handle.value or 0), device_ptr, int(strides.strides[0]))
        self._buffers.append(buf)
        return buf

    def _upload(self, buf: _Buffer, grey: U8) -> None:
        img = np.ascontiguousarray(grey, dtype=np.uint8)
        self._cuda.copy_2d(
            src_host=img.ctypes.data,
            src_pitch=img.strides[0],
            dst_device=buf.device_ptr,
            dst_pitch=buf.pitch_bytes,
            row_bytes=img.shape[1],
            rows=img.shape[0],
        )

    def flow_s10_5(self, previous: U8, current: U8, *, temporal_hints: bool) -> I16:
        self._upload(self._input, previous)
        self._upload(self._reference, current)
        ins = _ExecuteInput(
            inputFrame=self._input.handle,
            referenceFrame=self._reference.handle,
            disableTemporalHints=0 if temporal_hints else 1,
        )
        outs = _ExecuteOutput(outputBuffer=self._output.handle)
        status = self._fn["execute"](self._handle, ctypes.byref(ins), ctypes.byref(outs))
        self._check(status, "execute")
        self._cuda.synchronize()
        rows, cols = self.grid_shape
        out = np.empty((rows, cols, 2), dtype=np.int16)
        self._cuda.copy_2d(
            src_device=self._output.device_ptr,
            src_pitch=self._output.pitch_bytes,
            dst_host=out.ctypes.data,
            dst_pitch=out.strides[0],
            row_bytes=cols * 4,  # two int16 per vector
            rows=rows,
        )
        return out

    def close(self) -> None:
        if self._fn:
            for buf in self._buffers:
                self._fn["destroy_buffer"](_Ptr(buf.handle))
            if self._handle:
                self._fn["destroy"](self._handle)
        self._buffers.clear()
        self._handle = _Ptr()
        self._cuda.close()


def grey_from_rgb(rgb: NDArray[np.uint8]) -> U8:
    """(H, W) uint8 luma of an (H, W, 3) RGB image, as the reference dumper's BGR-to-grey."""
    return np.asarray(cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY), np.uint8)


class NvofHardwareSession:
    """Hardware flow between grey frames of one size, with the reference dumper's hint policy.

    The engine's temporal hints reuse its previous result; the dumper runs consecutive pairs in
    order, with hints on. Here they are on for a pair that continues the previous one (its
    ``previous`` frame is the last pair's ``current``) and off for any other pair, so an
    out-of-order request is never hinted by an unrelated motion.

    Args:
        width, height: image size [px].
        perf_level: ``slow`` (the reference's), ``medium`` or ``fast``.
        gpu: CUDA device ordinal.
        engine: the hardware (tests pass a fake); None = the GPU's engine.
        loader: how the driver's libraries are opened (tests pass a failing one).
    """

    def __init__(
        self,
        width: int,
        height: int,
        *,
        perf_level: str = "slow",
        gpu: int = 0,
        engine: _Engine | None = None,
        loader: Callable[[str], Any] = ctypes.CDLL,
    ) -> None:
        if perf_level not in NVOF_HW_PERF_LEVELS:
            raise ConfigError(
                f"unknown NVOF performance level {perf_level!r}; expected one of "
                f"{', '.join(NVOF_HW_PERF_LEVELS)}"
            )
        if width < 32 or height < 32:
            raise ConfigError(f"NVOF needs images of at least 32x32 px, got {width}x{height}")
        self.size = (int(width), int(height))
        self._engine = engine or _NvofEngine(
            width, height, NVOF_HW_PERF_LEVELS[perf_level], gpu, loader
        )
        self._last: tuple[str, int] | None = None

    def flow_px(
        self, previous: U8, current: U8, *, pair_id: tuple[str, int, int]
    ) -> NDArray[np.float32]:
        """Flow from ``previous`` to ``current``.

        Args:
            previous, current: (H, W) uint8 grey images.
            pair_id: ``(sequence name, from_k, to_k)``; decides the temporal hints.

        Returns:
            (ceil(H/4), ceil(W/4), 2) float32 [px], the S10.5 vectors / 32, vector of pixel
            (u, v) at ``[v // 4, u // 4]``.
        """
        for img in (previous, current):
            if img.shape != (self.size[1], self.size[0]) or img.dtype != np.uint8:
                raise ValueError(
                    f"expected ({self.size[1]}, {self.size[0]}) uint8 grey images, got "
                    f"{img.shape} {img.dtype}"
                )
        name, from_k, to_k = pair_id
        hints = self._last == (name, from_k)
        q = self._engine.flow_s10_5(previous, current, temporal_hints=hints)
        self._last = (name, to_k)
        return flow_px_from_s10_5(q)

    def close(self) -> None:
        self._engine.close()


class NvofHardwareFlowSource:
    """Flow source ``nvof-hw[:<perf level>]``: the GPU's optical flow engine on the grey rgb
    images (module doc), one vector per 4x4 block, S10.5 like ``nvof_1_slow``.

    The session opens on the first request (so building the source needs no GPU) and is
    reopened for a sequence of another size.
    """

    def __init__(
        self,
        perf_level: str = "slow",
        *,
        gpu: int = 0,
        engine_factory: Callable[[int, int], _Engine] | None = None,
        loader: Callable[[str], Any] = ctypes.CDLL,
    ) -> None:
        if perf_level not in NVOF_HW_PERF_LEVELS:
            raise ConfigError(
                f"flow source 'nvof-hw:{perf_level}': unknown performance level; expected one "
                f"of {', '.join(NVOF_HW_PERF_LEVELS)}, e.g. 'nvof-hw:slow' (the reference's)"
            )
        self.perf_level = perf_level
        self._gpu = int(gpu)
        self._engine_factory = engine_factory
        self._loader = loader
        self._session: NvofHardwareSession | None = None

    @property
    def name(self) -> str:
        return "nvof-hw" if self.perf_level == "slow" else f"nvof-hw:{self.perf_level}"

    def _session_for(self, width: int, height: int) -> NvofHardwareSession:
        if self._session is not None and self._session.size == (width, height):
            return self._session
        if self._session is not None:
            self._session.close()
            self._session = None
        engine = self._engine_factory(width, height) if self._engine_factory else None
        self._session = NvofHardwareSession(
            width,
            height,
            perf_level=self.perf_level,
            gpu=self._gpu,
            engine=engine,
            loader=self._loader,
        )
        return self._session

    def flow(self, sequence: Sequence, from_k: int, to_k: int) -> FlowField:
        check_frame_pair(sequence, from_k, to_k)
        h, w = sequence.intrinsics.shape
        session = self._session_for(w, h)
        flow = session.flow_px(
            grey_from_rgb(sequence.rgb(from_k)),
            grey_from_rgb(sequence.rgb(to_k)),
            pair_id=(sequence.name, from_k, to_k),
        )
        return FlowField(flow_px=flow, from_k=from_k, to_k=to_k, grid_px=NVOF_HW_GRID_PX)

    def close(self) -> None:
        """Ends the GPU session (also done by the driver at process exit)."""
        if self._session is not None:
            self._session.close()
            self._session = None
