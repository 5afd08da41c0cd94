"""Frames over pipes: blocking I/O for the child, I/O with a deadline for the parent.

A frame is :data:`~roft_sim.trackers.process.codec.HEADER` (the payload length) and the
payload. The parent writes to a non-blocking pipe and polls with a deadline, so a child that stops
reading (or never replies) cannot block it past its timeout. Pipes are enlarged to the system's
maximum (``/proc/sys/fs/pipe-max-size``, 1 MiB by default on Linux) so that a 640x480 frame
crosses them in a few writes.
"""

from __future__ import annotations

import errno
import os
import select
import time

from roft_sim.trackers.process.codec import HEADER, MAX_MESSAGE_BYTES, ProtocolError

__all__ = [
    "Deadline",
    "EndOfStream",
    "enlarge_pipe",
    "read_frame",
    "write_frame",
    "receive_frame",
    "send_frame",
]

_F_SETPIPE_SZ = 1031  # fcntl.F_SETPIPE_SZ (Linux), not exported by Python 3.11's fcntl


class EndOfStream(Exception):
    """The other side closed the pipe (it exited, or closed its end)."""


class Deadline(Exception):
    """The deadline passed before a frame was fully sent or received."""


def enlarge_pipe(fd: int) -> None:
    """Sets the pipe buffer of ``fd`` to the system's maximum (no-op where not supported)."""
    try:
        import fcntl

        with open("/proc/sys/fs/pipe-max-size", encoding="ascii") as f:
            size = int(f.read())
        fcntl.fcntl(fd, _F_SETPIPE_SZ, size)
    except (OSError, ValueError, ImportError):
        pass


def _read_exact(fd: int, n: int) -> bytearray:
    buffer = bytearray(n)
    view = memoryview(buffer)
    got = 0
    while got < n:
        count = os.readv(fd, [view[got:]])
        if count == 0:
            raise EndOfStream(f"pipe closed after {got} of {n} bytes")
        got += count
    return buffer


def read_frame(fd: int) -> bytearray | None:
    """The payload of the next frame on blocking ``fd``; None at a clean end of stream."""
    try:
        header = _read_exact(fd, HEADER.size)
    except EndOfStream:
        return None
    (size,) = HEADER.unpack(header)
    if size > MAX_MESSAGE_BYTES:
        raise ProtocolError(
            f"frame header: received length {size}, expected <= {MAX_MESSAGE_BYTES}"
        )
    return _read_exact(fd, size)


def write_frame(fd: int, frame: bytes) -> None:
    """Writes a whole frame to blocking ``fd``."""
    view = memoryview(frame)
    while view:
        view = view[os.write(fd, view) :]


def _wait(fd: int, *, write: bool, deadline: float) -> None:
    left = deadline - time.monotonic()
    if left <= 0:
        raise Deadline()
    poller = select.poll()
    poller.register(fd, select.POLLOUT if write else select.POLLIN)
    if not poller.poll(left * 1000.0):
        raise Deadline()


def send_frame(fd: int, frame: bytes, deadline: float) -> None:
    """Writes ``frame`` to non-blocking ``fd`` before ``deadline`` (``time.monotonic``).

    Raises:
        Deadline: the reader did not take it all in time.
        EndOfStream: the reader closed the pipe.
    """
    view = memoryview(frame)
    while view:
        try:
            view = view[os.write(fd, view) :]
        except BlockingIOError:
            _wait(fd, write=True, deadline=deadline)
        except BrokenPipeError as e:
            raise EndOfStream("the reader closed the pipe") from e
        except OSError as e:
            if e.errno != errno.EPIPE:
                raise
            raise EndOfStream("the reader closed the pipe") from e


def _receive_exact(fd: int, n: int, deadline: float) -> bytearray:
    buffer = bytearray(n)
    view = memoryview(buffer)
    got = 0
    while got < n:
        _wait(fd, write=False, deadline=deadline)
        count = os.readv(fd, [view[got:]])
        if count == 0:
            raise EndOfStream(f"pipe closed after {got} of {n} bytes")
        got += count
    return buffer


def receive_frame(fd: int, deadline: float) -> bytearray:
    """The payload of the next frame on ``fd``, read before ``deadline``.

    Raises:
        Deadline: no whole frame in time.
        EndOfStream: the writer closed the pipe (the child exited).
        ProtocolError: the header announces an oversized payload.
    """
    (size,) = HEADER.unpack(_receive_exact(fd, HEADER.size, deadline))
    if size > MAX_MESSAGE_BYTES:
        raise ProtocolError(
            f"frame header: received length {size}, expected <= {MAX_MESSAGE_BYTES}"
        )
    return _receive_exact(fd, size, deadline)
