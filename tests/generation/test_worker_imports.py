"""A generation worker does not import scipy.signal (with scipy.stats, 1-2 s of every spawned
worker's start-up), nor trimesh (0.1-0.5 s; a stand-in object needs no mesh file) nor the download
modules of ``roft_sim.assets.install``: it imports the generation modules, loads the object and
generates frames without them."""

from __future__ import annotations

import subprocess
import sys

import pytest

pytestmark = pytest.mark.render

_SCRIPT = """
import sys
from roft_sim.generation import runner, sequence_generator
from roft_sim.datasets import fast_ycb
from roft_sim.generation import ScenarioOverrides, shipped_scenarios_dir
from roft_sim.scenario import load_scenario
scenario = load_scenario(shipped_scenarios_dir() / "ci" / "cracker_box.toml")
scenario = ScenarioOverrides(frames=3, resolution=(64, 48)).apply(scenario)
with sequence_generator.SequenceGenerator(scenario) as generator:
    frames = list(generator.frames(0, 3))
assert len(frames) == 3 and frames[2].detector_poses is not None
unwanted = ("scipy.signal", "scipy.stats", "trimesh", "http.client", "urllib.request", "tarfile")
print(sorted(m for m in sys.modules if m in unwanted))
"""


@pytest.mark.slow  # a fresh interpreter generating frames
def test_generating_frames_does_not_import_scipy_signal_trimesh_or_the_network():
    res = subprocess.run(
        [sys.executable, "-c", _SCRIPT], capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().splitlines()[-1] == "[]"
