"""The roft_sim pytest plugin, exercised the way a user's project uses it: pytest runs in a
subprocess on a small test file in a temporary project."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest
from plugin_runs import PLUGIN_MODULE, plugin_installed, run_pytest

REPO = Path(__file__).resolve().parents[2]

USER_TESTS = """
from hypothesis import settings

from roft_sim.faults import load_faults
from roft_sim.testing import FaultedStream, check_determinism


def test_analytic_fixtures(analytic_sequence, analytic_sequence_factory):
    assert len(analytic_sequence) == 24 and analytic_sequence.intrinsics.width_px == 64
    assert analytic_sequence_factory() is analytic_sequence
    assert len(analytic_sequence_factory(n_frames=5, width_px=32, height_px=24)) == 5


def test_make_tracker(make_tracker, tracker_under_test, tracker_config, analytic_sequence):
    assert tracker_under_test.name == "detector-hold"
    assert tracker_config.velocity == "zero"
    stream = FaultedStream(sequence=analytic_sequence, faults=load_faults("paper"), seed=0)
    observations = stream.observations()
    check_determinism(lambda: make_tracker(analytic_sequence), observations).raise_if_failed()


def test_profile():
    assert settings.get_current_profile_name() == "roft-sim-ci"


def test_rendered(rendered_sequence):
    assert len(rendered_sequence) == 8
"""


@pytest.fixture
def project(tmp_path: Path) -> Path:
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    (tmp_path / "test_user.py").write_text(USER_TESTS)
    (tmp_path / "hold.toml").write_text('velocity = "zero"\n')
    return tmp_path


def test_the_entry_point_is_declared_in_pyproject():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    assert project["project"]["entry-points"]["pytest11"] == {"roft_sim": PLUGIN_MODULE}
    if not plugin_installed():
        pytest.skip("roft-sim is not pip-installed here; the other tests load the plugin with -p")


def test_importing_the_plugin_imports_nothing_heavy():
    code = (
        f"import sys, {PLUGIN_MODULE}; "
        "print(sorted(m for m in ('numpy', 'hypothesis', 'mujoco', 'scipy') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_fixtures_options_and_profiles_in_a_user_project(project):
    done = run_pytest(
        project,
        "--roft-sim-tracker",
        "detector-hold",
        "--roft-sim-tracker-config",
        "hold.toml",
        "--hypothesis-profile=roft-sim-ci",
        "-k",
        "not rendered",
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "3 passed" in done.stdout


def test_missing_tracker_and_missing_gl_backend_are_explained(project):
    (project / "pytest.ini").write_text("[pytest]\n")
    done = run_pytest(
        project,
        "-rs",
        "-k",
        "make_tracker or rendered",
        env={"MUJOCO_GL": "no-such-backend", "PYOPENGL_PLATFORM": "no-such-backend"},
    )
    out = done.stdout
    assert done.returncode == 1, out + done.stderr
    assert "1 skipped, 2 deselected, 1 error" in out  # the fixture fails at set-up
    assert "tracker_under_test: no tracker chosen; pass --roft-sim-tracker NAME" in out
    assert "no offscreen OpenGL backend to render with: no-such-backend" in out


def test_the_ini_option_names_the_tracker(project):
    (project / "pytest.ini").write_text("[pytest]\nroft_sim_tracker = detector-hold\n")
    (project / "test_ini.py").write_text(
        textwrap.dedent(
            """
            def test_spec(tracker_under_test, tracker_config):
                assert tracker_under_test.name == "detector-hold"
                assert tracker_config.velocity == "finite_difference"
            """
        )
    )
    done = run_pytest(project, "test_ini.py")
    assert done.returncode == 0 and "1 passed" in done.stdout, done.stdout + done.stderr


def test_help_lists_the_options_and_the_plugin_can_be_disabled(project):
    done = run_pytest(project, "--help")
    assert "--roft-sim-tracker=NAME" in done.stdout
    assert "--roft-sim-tracker-config=FILE" in done.stdout
    if plugin_installed():
        off = subprocess.run(
            [sys.executable, "-m", "pytest", "-p", "no:roft_sim", "--help"],
            cwd=project,
            capture_output=True,
            text=True,
        )
        assert "--roft-sim-tracker" not in off.stdout
