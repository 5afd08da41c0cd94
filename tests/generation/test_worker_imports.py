"""A generation worker does not import scipy.signal (with scipy.stats, 1-2 s of every spawned
worker's start-up): it imports the generation modules and generates frames without it."""

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
print(sorted(m for m in sys.modules if m in ("scipy.signal", "scipy.stats")))
"""


def test_generating_frames_does_not_import_scipy_signal():
    res = subprocess.run(
        [sys.executable, "-c", _SCRIPT], capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr[-2000:]
    assert res.stdout.strip().splitlines()[-1] == "[]"
