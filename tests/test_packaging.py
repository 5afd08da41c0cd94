"""The package list in pyproject.toml: every roft_sim package, and the two top-level data folders
(scenarios/, assets/ycb/) mapped into the installed package; and ``pip install .`` without a
setuptools warning."""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from setuptools import find_packages

from roft_sim.assets import list_objects
from roft_sim.shipped_files import scenarios_dir

REPO = Path(__file__).resolve().parent.parent
DATA_PACKAGES = {"roft_sim.scenarios": "scenarios", "roft_sim.assets.ycb": "assets/ycb"}


def _pyproject() -> dict:
    with (REPO / "pyproject.toml").open("rb") as f:
        return tomllib.load(f)


def _setuptools_table() -> dict:
    return _pyproject()["tool"]["setuptools"]


def _scenario_data_packages() -> set[str]:
    """Each folder of scenarios/ (presets, scenario files): a package of data files, which
    setuptools warns about ("Package would be ignored") unless it is listed."""
    return {
        f"roft_sim.scenarios.{d.name}"
        for d in (REPO / "scenarios").iterdir()
        if d.is_dir() and not d.name.startswith(("_", "."))
    }


def test_pyproject_lists_every_package_and_maps_the_data_folders():
    table = _setuptools_table()
    code_packages = set(find_packages(where=str(REPO), include=["roft_sim*"]))
    assert _scenario_data_packages() >= {"roft_sim.scenarios.faults", "roft_sim.scenarios.ci"}
    assert set(table["packages"]) == code_packages | set(DATA_PACKAGES) | _scenario_data_packages()
    assert table["package-dir"] == DATA_PACKAGES
    for folder in DATA_PACKAGES.values():
        assert (REPO / folder / "__init__.py").is_file()
        assert not (REPO / folder).is_symlink()


def test_the_package_finds_the_top_level_folders_from_a_checkout():
    assert scenarios_dir().resolve() == (REPO / "scenarios").resolve()
    assert {p.name for p in scenarios_dir().iterdir() if p.is_dir()} >= {"ci", "fast_ycb", "faults"}
    assert "003_cracker_box" in {o.name for o in list_objects()}


def test_the_build_configuration_is_the_one_setuptools_accepts_without_a_warning():
    """The licence is an SPDX expression (a TOML table is deprecated), which needs setuptools 77;
    the folder test above keeps the scenario data folders listed."""
    project = _pyproject()
    assert project["project"]["license"] == "BSD-3-Clause"
    requires = project["build-system"]["requires"]
    assert "setuptools>=77" in requires, requires


@pytest.mark.slow
def test_pip_install_prints_no_setuptools_warning(tmp_path):
    """``pip install . --no-deps`` (isolated build, verbose so that setuptools' output shows) of a
    copy of the sources into a throwaway folder: no warning from the build, and the scenario files
    are installed."""
    source = tmp_path / "source"
    skip = shutil.ignore_patterns("__pycache__", "*.egg-info", "build")
    for name in ("roft_sim", "scenarios", "assets"):
        shutil.copytree(REPO / name, source / name, ignore=skip)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(REPO / name, source / name)
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "install", str(source), "--no-deps", "--no-cache-dir", "-v",
         "--disable-pip-version-check", "--target", str(tmp_path / "target")],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    lines = (proc.stdout + proc.stderr).splitlines()
    warnings = [
        line
        for line in lines
        if re.search(r"warning|deprecat", line, re.IGNORECASE)
        # pip's own notes about this machine's package index, and byte-compiling left off
        and "Location 'file:" not in line
        and "byte-compiling is disabled" not in line
    ]
    assert not warnings, "\n".join(warnings)
    installed = tmp_path / "target" / "roft_sim" / "scenarios"
    assert (installed / "faults" / "paper.toml").is_file()
    assert (installed / "fast_ycb" / "003_cracker_box.toml").is_file()
