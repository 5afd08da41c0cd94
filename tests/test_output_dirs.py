"""``prepare_output_dir``: what --out, --overwrite and --resume may do to a folder;
``check_output_dir``: the same refusals, changing nothing."""

from __future__ import annotations

from pathlib import Path

import pytest

from roft_sim.cli.output_dirs import check_output_dir, prepare_output_dir
from roft_sim.errors import ConfigError


def test_overwrite_empties_a_previous_output_and_resume_keeps_it(tmp_path: Path):
    out = tmp_path / "out"
    assert prepare_output_dir(out) == out and out.is_dir()
    (out / "old.txt").write_text("x")
    with pytest.raises(ConfigError, match="is not empty; pass --overwrite"):
        prepare_output_dir(out)
    assert prepare_output_dir(out, resume=True) == out and (out / "old.txt").exists()
    prepare_output_dir(out, overwrite=True)
    assert out.is_dir() and not any(out.iterdir())
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="is a file"):
        prepare_output_dir(tmp_path / "file")


def test_check_output_dir_refuses_as_prepare_does_and_changes_nothing(tmp_path: Path):
    out = tmp_path / "out"
    assert check_output_dir(out) == out and not out.exists()
    out.mkdir()
    (out / "old.txt").write_text("x")
    with pytest.raises(ConfigError, match="is not empty; pass --overwrite to replace it$"):
        check_output_dir(out, can_resume=False)
    with pytest.raises(ConfigError, match="contradict"):
        check_output_dir(out, overwrite=True, resume=True)
    assert check_output_dir(out, overwrite=True) == out and (out / "old.txt").exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="is a file"):
        check_output_dir(tmp_path / "file")


@pytest.mark.parametrize("which", ["cwd", "parent_of_cwd", "home"])
def test_overwrite_never_empties_the_current_home_or_an_enclosing_folder(
    which, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    work = tmp_path / "project" / "work"
    work.mkdir(parents=True)
    (work / "precious.txt").write_text("keep me")
    monkeypatch.chdir(work)
    monkeypatch.setenv("HOME", str(tmp_path / "project"))
    target = {"cwd": Path("."), "parent_of_cwd": Path(".."), "home": tmp_path / "project"}[which]
    with pytest.raises(ConfigError, match="--overwrite would empty"):
        prepare_output_dir(target, overwrite=True)
    assert (work / "precious.txt").read_text() == "keep me"
