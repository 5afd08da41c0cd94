"""Versions of the package to measure side by side: the working tree and git commits.

A benchmark that compares the current code with a baseline runs each measurement in a fresh
process per tree, with the tree's folder first on ``PYTHONPATH``, interleaved (baseline, ...,
now, baseline, ..., now) so that every tree sees the same machine load. A baseline is the
``roft_sim`` package as it was at a git commit, extracted with ``git archive``. Bytecode is
compiled first in every tree, as pip leaves an installed package.
"""

from __future__ import annotations

import compileall
import dataclasses
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
"""The repository this benchmark lives in."""


@dataclasses.dataclass(frozen=True)
class Tree:
    """A version of the package to measure: its label and the folder put on PYTHONPATH."""

    label: str
    pythonpath: Path
    cache: Path


def current_tree(scratch: Path) -> Tree:
    """The working tree of this repository (label ``now``)."""
    return Tree(label="now", pythonpath=REPO, cache=scratch / "cache_now")


def baseline_tree(ref: str, scratch: Path) -> Tree:
    """The package at git commit ``ref`` of this repository, extracted under ``scratch``."""
    folder = scratch / f"baseline_{ref}"
    folder.mkdir()
    archive = subprocess.run(
        ["git", "-C", str(REPO), "archive", ref, "roft_sim"], capture_output=True, check=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return Tree(label=ref[:9], pythonpath=folder, cache=scratch / f"cache_baseline_{ref}")


def compile_trees(trees: list[Tree]) -> None:
    """Compiles every tree's bytecode (a fresh process then reads it, as from an install)."""
    for tree in trees:
        compileall.compile_dir(tree.pythonpath / "roft_sim", quiet=1)
