"""Atomic file writes: a temp file in the target folder, then ``os.replace``.

A reader (or a resumed writer) therefore sees each file either complete or absent, never half
written, even when the writing process is killed. Temp files are hidden (``.name.<pid>.tmp``) and
removed by :func:`remove_temp_files` when a sequence is finalized. Atomicity holds against process
crashes and interrupts; files are not fsync'ed, so a power loss may still lose recent frames.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import TextIO

__all__ = [
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "remove_temp_files",
    "temp_path_for",
    "AtomicTextFiles",
    "remove_file",
]

_TEMP_SUFFIX = ".tmp"


def temp_path_for(path: str | os.PathLike[str]) -> str:
    """The hidden temp path used while ``path`` is being written (unique per process).

    Per-frame paths are plain strings on purpose: Python 3.11's pathlib interns every new file
    name for the life of the process, which grows memory with the number of frames.
    """
    folder, name = os.path.split(os.fspath(path))
    return os.path.join(folder, f".{name}.{os.getpid()}{_TEMP_SUFFIX}")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[str]:
    """The temp path (:func:`temp_path_for`) to write ``path``'s content to: renamed to ``path``
    when the ``with`` block ends normally, removed when it raises (``path`` is then left as it
    was). Creates the parent folders (a bare file name is written in the current folder).
    Close the file before the block ends."""
    path = os.fspath(path)
    folder = os.path.dirname(path)
    if folder:
        os.makedirs(folder, exist_ok=True)
    tmp = temp_path_for(path)
    try:
        yield tmp
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.remove(tmp)
        raise


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes | memoryview) -> None:
    """Writes ``data`` to ``path`` atomically (:func:`atomic_path`)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        f.write(data)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Writes UTF-8 ``text`` to ``path`` atomically, with ``\\n`` line ends on every platform."""
    atomic_write_bytes(path, text.encode("utf-8"))


def remove_file(path: str | os.PathLike[str]) -> None:
    """Deletes a file if it exists (a detector miss after a retried frame leaves no stale file)."""
    with contextlib.suppress(FileNotFoundError):
        os.remove(path)


def remove_temp_files(root: Path) -> list[Path]:
    """Deletes temp files left under ``root`` by interrupted writers; returns what was removed.

    Call it only when no writer is active on ``root`` (at finalize).
    """
    removed = []
    for p in root.rglob(f".*{_TEMP_SUFFIX}"):
        if p.is_file():
            p.unlink(missing_ok=True)
            removed.append(p)
    return removed


class AtomicTextFiles:
    """Several text files written piece by piece, then renamed into place together.

    Use as a context manager: on a clean exit every file is closed and renamed to its final
    name; on an exception the temp files are deleted and no final file is touched. Lets a
    finalize step stream records into many files with flat memory.
    """

    def __init__(self) -> None:
        self._open: dict[Path, tuple[str, TextIO]] = {}

    def write(self, path: Path, text: str) -> None:
        """Appends ``text`` to the file that will become ``path``."""
        entry = self._open.get(path)
        if entry is None:
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = temp_path_for(path)
            entry = (tmp, open(tmp, "w", encoding="utf-8", newline="\n"))  # noqa: SIM115
            self._open[path] = entry
        entry[1].write(text)

    def __enter__(self) -> AtomicTextFiles:
        return self

    def __exit__(self, exc_type: type | None, exc: BaseException | None, tb: object) -> None:
        for _, f in self._open.values():
            f.close()
        for path, (tmp, _) in self._open.items():
            if exc is None:
                os.replace(tmp, path)
            else:
                remove_file(tmp)
