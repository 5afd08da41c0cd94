"""atomic_path / atomic_write_bytes / atomic_write_text: the file appears whole, parents are
created, a bare file name is written in the current folder (`roft-sim faults random --out
mix-7.toml`), and a write that fails leaves the target as it was and no temp file."""

from __future__ import annotations

from pathlib import Path

import pytest

from roft_sim.datasets.atomic_files import atomic_path, atomic_write_text


def test_a_bare_file_name_is_written_in_the_current_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    atomic_write_text("mix-7.toml", "seed = 7\n")
    assert (tmp_path / "mix-7.toml").read_text() == "seed = 7\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mix-7.toml"]


def test_parent_folders_are_created(tmp_path: Path) -> None:
    atomic_write_text(tmp_path / "a" / "b" / "c.txt", "x")
    assert (tmp_path / "a" / "b" / "c.txt").read_text() == "x"


def test_a_failed_write_leaves_the_target_as_it_was_and_no_temp_file(tmp_path: Path) -> None:
    target = tmp_path / "run.mcap"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError, match="interrupted"), atomic_path(target) as tmp:
        Path(tmp).write_bytes(b"half")
        assert target.read_bytes() == b"old"
        raise RuntimeError("interrupted")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap"]
    assert target.read_bytes() == b"old"
    with atomic_path(target) as tmp:
        Path(tmp).write_bytes(b"new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.mcap"]
    assert target.read_bytes() == b"new"
