"""Large arrays through a shared file instead of the pipe (optional, negotiated in hello/ready).

The parent creates one file in ``/dev/shm`` (else the temporary folder), offers its path in
``hello`` and removes the name once the child has replied (the child keeps it open). When the
child accepted it, each observation's large arrays (:data:`SHM_MIN_BYTES` or more) are copied into
the file and their array maps carry ``shm_offset`` instead of ``data``; what does not fit goes
inline. The file is rewritten by the next observation, so the child copies what it keeps before
it replies (:class:`SharedReader` always copies).
"""

from __future__ import annotations

import mmap
import os
import tempfile
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["SHM_MIN_BYTES", "SHM_ALIGN_BYTES", "SharedWriter", "SharedReader", "shared_folder"]

SHM_MIN_BYTES = 1 << 16
"""Arrays of at least this many bytes go through the shared file (when accepted)."""
SHM_ALIGN_BYTES = 64
"""Every array in the shared file starts at a multiple of this offset."""


def shared_folder() -> str:
    """``/dev/shm`` where it is a writable folder (memory-backed), else the temporary folder."""
    return "/dev/shm" if os.access("/dev/shm", os.W_OK) else tempfile.gettempdir()


class SharedWriter:
    """The parent's side: a file of ``size_bytes`` mapped read-write; arrays of at least
    ``min_bytes`` go into it."""

    def __init__(self, size_bytes: int, *, min_bytes: int = SHM_MIN_BYTES) -> None:
        fd, self.path = tempfile.mkstemp(prefix="roft_sim-tracker-", dir=shared_folder())
        try:
            os.ftruncate(fd, size_bytes)
            self._map = mmap.mmap(fd, size_bytes)
        finally:
            os.close(fd)
        self.size_bytes = size_bytes
        self.min_bytes = min_bytes
        self._used = 0
        self._linked = True

    def unlink(self) -> None:
        """Removes the file's name (the mappings stay valid)."""
        if self._linked:
            self._linked = False
            os.unlink(self.path)

    def start(self) -> None:
        """Starts a new message: the whole file is free again."""
        self._used = 0

    def place(self, array: NDArray[Any]) -> int | None:
        """Copies ``array`` (C order) into the file; its offset, or None when it is small or
        does not fit (it then goes inline)."""
        n = array.nbytes
        offset = -(-self._used // SHM_ALIGN_BYTES) * SHM_ALIGN_BYTES
        if n < self.min_bytes or offset + n > self.size_bytes:
            return None
        target = np.frombuffer(self._map, dtype=array.dtype, count=array.size, offset=offset)
        np.copyto(target.reshape(array.shape), array)
        self._used = offset + n
        return offset

    def close(self) -> None:
        """Unmaps the file and removes its name."""
        self.unlink()
        self._map.close()


class SharedReader:
    """The child's side: the parent's file, mapped read-only."""

    def __init__(self, path: str, size_bytes: int) -> None:
        fd = os.open(path, os.O_RDONLY)
        try:
            self._map = mmap.mmap(fd, size_bytes, prot=mmap.PROT_READ)
        finally:
            os.close(fd)
        self.size_bytes = size_bytes

    def copy(self, offset: int, dtype: np.dtype[Any], shape: tuple[int, ...]) -> NDArray[Any]:
        """A copy of the array at ``offset`` (raises ValueError outside the file)."""
        count = int(np.prod(shape))
        if offset < 0 or offset + count * dtype.itemsize > self.size_bytes:
            raise ValueError(
                f"bytes {offset}..{offset + count * dtype.itemsize} of {self.size_bytes}"
            )
        return (
            np.frombuffer(self._map, dtype=dtype, count=count, offset=offset).reshape(shape).copy()
        )

    def close(self) -> None:
        self._map.close()
