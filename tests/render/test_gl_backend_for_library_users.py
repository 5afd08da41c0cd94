"""A script that uses roft_sim.render without setting MUJOCO_GL: the backend is chosen for it;
when MuJoCo was imported first (too late to choose), the error says how to fix it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

SCRIPT = """
import os{pre}
from roft_sim.render import SceneRenderer
from roft_sim.scenario import load_scenario
from roft_sim.shipped_files import scenarios_dir
scenario = load_scenario(scenarios_dir() / "ci" / "cracker_box.toml")
with SceneRenderer(scenario) as renderer:
    frame = renderer.render_frame(0)
print("rendered", frame.rgb.shape, os.environ.get("MUJOCO_GL"))
"""


def _run(pre: str = "") -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("MUJOCO_GL", "PYOPENGL_PLATFORM")}
    return subprocess.run([sys.executable, "-c", SCRIPT.format(pre=pre)], env=env,
                          capture_output=True, text=True, timeout=300)  # fmt: skip


@pytest.mark.render
def test_a_script_without_mujoco_gl_renders_offscreen():
    done = _run()
    assert done.returncode == 0, done.stderr[-2000:]
    assert "rendered (240, 320, 3)" in done.stdout
    assert done.stdout.split()[-1] in ("egl", "osmesa")


@pytest.mark.render
@pytest.mark.slow  # a fresh interpreter importing MuJoCo
def test_mujoco_imported_first_gives_an_actionable_error():
    done = _run(pre="\nimport mujoco")
    assert done.returncode != 0
    assert "RenderBackendError" in done.stderr
    assert "MuJoCo was imported before an offscreen backend was chosen" in done.stderr
    assert "Set MUJOCO_GL=egl or MUJOCO_GL=osmesa before importing mujoco" in done.stderr
