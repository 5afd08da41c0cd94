"""Atomic file writes: a temp file in the target folder, then ``os.replace``.

A reader (or a resumed writer) therefore sees each file either complete or absent, never half
written, even when the writing process is killed. Temp files are hidden (``.name.<pid>.tmp``) and
removed by :func:`remove_temp_files` when a sequence is finalized. Atomicity holds against process
crashes and interrupts; files are not fsync'ed, so a power loss may still lose recent frames.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["atomic_write_bytes", "atomic_write_text", "remove_temp_files", "temp_path_for"]

_TEMP_SUFFIX = ".tmp"


def temp_path_for(path: Path) -> Path:
    """The hidden temp path used while ``path`` is being written (unique per process)."""
    return path.with_name(f".{path.name}.{os.getpid()}{_TEMP_SUFFIX}")


def atomic_write_bytes(path: Path, data: bytes | memoryview) -> None:
    """Writes ``data`` to ``path`` atomically, creating parent folders."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = temp_path_for(path)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def atomic_write_text(path: Path, text: str) -> None:
    """Writes UTF-8 ``text`` to ``path`` atomically, with ``\\n`` line ends on every platform."""
    atomic_write_bytes(path, text.encode("utf-8"))


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
