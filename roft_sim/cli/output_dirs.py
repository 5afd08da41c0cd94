"""Output-directory handling shared by the verbs that write results."""

from __future__ import annotations

import shutil
from pathlib import Path

from roft_sim.errors import ConfigError

__all__ = ["check_output_dir", "prepare_output_dir"]


def prepare_output_dir(
    path: str | Path, *, overwrite: bool = False, resume: bool = False, can_resume: bool = True
) -> Path:
    """Creates ``path`` or checks that it may be written.

    A non-empty directory is refused unless ``overwrite`` (it is emptied) or ``resume`` (kept as
    is, so finished work is not redone). ``can_resume`` False: the verb has no ``--resume``, so
    the message does not suggest it.

    ``overwrite`` never empties the file-system root, the home folder, the current folder or
    a folder that contains it (``--out . --overwrite`` is refused, not obeyed).

    Raises:
        ConfigError: the path is a file, a non-empty directory without overwrite/resume, or a
            folder ``overwrite`` must not empty.
    """
    path = check_output_dir(path, overwrite=overwrite, resume=resume, can_resume=can_resume)
    if overwrite and path.is_dir() and any(path.iterdir()):
        shutil.rmtree(path)
    path.mkdir(parents=True, exist_ok=True)
    return path


def check_output_dir(
    path: str | Path, *, overwrite: bool = False, resume: bool = False, can_resume: bool = True
) -> Path:
    """Checks, changing nothing, that :func:`prepare_output_dir` may write ``path`` (same
    arguments); returns it as a Path. For a verb that works before it writes: a bad ``--out``
    fails first.

    Raises:
        ConfigError: as :func:`prepare_output_dir`.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ConfigError(f"output {str(path)!r} is a file; give a directory path")
    if path.is_dir() and any(path.iterdir()):
        if overwrite and resume:
            raise ConfigError("--overwrite and --resume contradict each other; pick one")
        if overwrite:
            _refuse_to_empty_a_working_folder(path)
        elif not resume:
            hint = " or --resume to continue an interrupted run" if can_resume else ""
            raise ConfigError(
                f"output directory {str(path)!r} is not empty; pass --overwrite to replace it{hint}"
            )
    return path


def _refuse_to_empty_a_working_folder(path: Path) -> None:
    """Raises ConfigError when ``path`` is the root, the home folder, or the current folder or
    one of its ancestors: emptying one of those would delete far more than a previous output."""
    target = path.resolve()
    cwd = Path.cwd().resolve()
    home = Path.home().resolve()
    if target == Path(target.anchor) or target in (home, cwd) or target in cwd.parents:
        raise ConfigError(
            f"--overwrite would empty {str(target)!r} (the root, home or current folder, or one "
            "that contains it); give --out a dedicated folder, e.g. out/run1"
        )
