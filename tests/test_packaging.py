"""The package list in pyproject.toml: every roft_sim package, and the two top-level data folders
(scenarios/, assets/ycb/) mapped into the installed package."""

from __future__ import annotations

import tomllib
from pathlib import Path

from setuptools import find_packages

from roft_sim.assets import list_objects
from roft_sim.shipped_files import scenarios_dir

REPO = Path(__file__).resolve().parent.parent
DATA_PACKAGES = {"roft_sim.scenarios": "scenarios", "roft_sim.assets.ycb": "assets/ycb"}


def _setuptools_table() -> dict:
    with (REPO / "pyproject.toml").open("rb") as f:
        return tomllib.load(f)["tool"]["setuptools"]


def test_pyproject_lists_every_package_and_maps_the_data_folders():
    table = _setuptools_table()
    code_packages = set(find_packages(where=str(REPO), include=["roft_sim*"]))
    assert set(table["packages"]) == code_packages | set(DATA_PACKAGES)
    assert table["package-dir"] == DATA_PACKAGES
    for folder in DATA_PACKAGES.values():
        assert (REPO / folder / "__init__.py").is_file()
        assert not (REPO / folder).is_symlink()


def test_the_package_finds_the_top_level_folders_from_a_checkout():
    assert scenarios_dir().resolve() == (REPO / "scenarios").resolve()
    assert {p.name for p in scenarios_dir().iterdir() if p.is_dir()} >= {"ci", "fast_ycb", "faults"}
    assert "003_cracker_box" in {o.name for o in list_objects()}
