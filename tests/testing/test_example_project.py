"""examples/testing_my_tracker, the project docs/testing.md walks through, runs its own tests
(pytest in a subprocess on a copy of the folder, with the reproducible CI profile)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from plugin_runs import run_pytest

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "testing_my_tracker"


@pytest.mark.slow  # runs the example project's own pytest
def test_the_example_project_passes_its_property_tests(tmp_path):
    copy = tmp_path / "testing_my_tracker"
    shutil.copytree(
        EXAMPLE, copy, ignore=shutil.ignore_patterns("__pycache__", ".hypothesis", ".benchmarks")
    )
    done = run_pytest(copy, "--hypothesis-profile=roft-sim-ci")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "4 passed" in done.stdout
