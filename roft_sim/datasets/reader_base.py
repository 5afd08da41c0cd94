"""What the lazy readers of every format share: the Sequence properties and flow files.

A reader sets ``path``, ``_name``, ``_object_name``, ``_intrinsics``, ``_fps`` and ``_t_s``
(``(N,)`` time stamps [s]) in its constructor; the rest of :class:`roft_sim.datasets.Sequence`
is format-specific.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.fast_ycb_codec import decode_flow_float, flow_grid_px
from roft_sim.datasets.image_files import decode_png_mask, read_file_bytes
from roft_sim.errors import DatasetFormatError, located
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import FlowField

__all__ = ["SequenceReaderBase", "check_time_stamps", "read_flow_field", "subfolder_names"]


class SequenceReaderBase:
    """The format-independent part of a lazy :class:`roft_sim.datasets.Sequence` reader."""

    path: Path
    _name: str
    _object_name: str
    _intrinsics: CameraIntrinsics
    _fps: int
    _t_s: NDArray[np.float64]

    @property
    def name(self) -> str:
        return self._name

    @property
    def object_name(self) -> str:
        return self._object_name

    @property
    def intrinsics(self) -> CameraIntrinsics:
        return self._intrinsics

    @property
    def fps(self) -> int:
        return self._fps

    def __len__(self) -> int:
        return len(self._t_s)

    def time_s(self, k: int) -> float:
        return float(self._t_s[self._check_k(k)])

    def _check_k(self, k: int) -> int:
        if not 0 <= k < len(self):
            raise IndexError(f"frame {k} is outside 0..{len(self) - 1} of {located(self.path)}")
        return int(k)

    def _cached_sets(self, kind: str, find: Callable[[], tuple[str, ...]]) -> tuple[str, ...]:
        """Set names, listed once (a dataset does not change while it is read)."""
        cache: dict[str, tuple[str, ...]] = self.__dict__.setdefault("_set_cache", {})
        if kind not in cache:
            cache[kind] = find()
        return cache[kind]


def check_time_stamps(
    t_s: NDArray[np.float64], path: Path, frame_label: Callable[[int], str]
) -> None:
    """Raises :class:`DatasetFormatError` unless the ``(N,)`` time stamps [s] are finite and
    strictly increasing (what every writer guarantees and every tracker relies on);
    ``frame_label(k)`` names frame ``k`` in the message (a line, an image id)."""
    bad = np.flatnonzero(~np.isfinite(t_s))
    if bad.size:
        k = int(bad[0])
        raise DatasetFormatError(f"{located(path)}: {frame_label(k)}: time stamp {t_s[k]} s")
    steps = np.flatnonzero(np.diff(t_s) <= 0)
    if steps.size:
        k = int(steps[0]) + 1
        raise DatasetFormatError(
            f"{located(path)}: {frame_label(k)}: time stamp {t_s[k]} s does not increase (the "
            f"frame before has {t_s[k - 1]} s); time stamps must increase frame by frame"
        )


def subfolder_names(folder: Path) -> tuple[str, ...]:
    """Sorted names of the sub-folders of ``folder`` (empty when it does not exist)."""
    if not folder.is_dir():
        return ()
    return tuple(sorted(p.name for p in folder.iterdir() if p.is_dir()))


def read_flow_field(
    flow_path: str, valid_path: str, k: int, image_shape: tuple[int, int]
) -> FlowField:
    """The flow F_k (frame k-1 -> k) stored in a ``.float`` file, with its optional validity PNG.

    Raises:
        DatasetFormatError: a missing or malformed file (named in the message).
    """
    flow_px, _ = decode_flow_float(read_file_bytes(flow_path, "optical flow"), flow_path)
    grid = flow_grid_px(flow_px.shape[0], flow_px.shape[1], image_shape, flow_path)
    valid = None
    if os.path.isfile(valid_path):
        valid = decode_png_mask(
            read_file_bytes(valid_path, "flow validity"), valid_path, shape=flow_px.shape[:2]
        )
    return FlowField(flow_px=flow_px, from_k=k - 1, to_k=k, grid_px=grid, valid=valid)
