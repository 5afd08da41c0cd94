"""examples/process_tracker_cpp: the C++ constant-velocity tracker, the same tracker in Python
served over the protocol, and its in-process twin give the same estimates and metrics.

The C++ program is built once per session with cmake and g++ into a temporary folder (skipped,
with the reason, where either is missing); those tests are slow (the build), the Python process
test is fast. The C++ estimates equal the twin's bit for bit (the
same scalar operations, the same libm); the Python process receives poses as position and
quaternion and rebuilds the matrix, so its estimates agree to 1e-15.
"""

from __future__ import annotations

import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("msgpack", reason="the process extra (msgpack) is not installed")

from roft_sim.faults import load_faults  # noqa: E402
from roft_sim.harness import RunOptions  # noqa: E402
from roft_sim.harness.evaluation import evaluate_run  # noqa: E402
from roft_sim.harness.runner import run_sequence  # noqa: E402
from roft_sim.testing.analytic_scene import analytic_box_sequence, default_intrinsics  # noqa: E402
from roft_sim.trackers import TrackerSpec  # noqa: E402

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "process_tracker_cpp"
ATOL = 1e-12


def load_cv_module():
    """The example's cv_tracker.py as a module (examples are not installed)."""
    spec = importlib.util.spec_from_file_location("cv_tracker_example", EXAMPLE / "cv_tracker.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def twin_spec() -> TrackerSpec:
    cv = load_cv_module()
    return TrackerSpec(
        name="cv-twin",
        description="the in-process twin of the C++ example",
        config_type=cv.ConstantVelocityConfig,
        factory=lambda config, context: cv.ConstantVelocityTracker(context),
    )


@pytest.fixture(scope="session")
def cpp_tracker(tmp_path_factory) -> Path:
    missing = [tool for tool in ("cmake", "g++") if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not found: cannot build the C++ example")
    build = tmp_path_factory.mktemp("cv_tracker_build")
    for command in (
        ["cmake", "-S", str(EXAMPLE), "-B", str(build), "-DCMAKE_BUILD_TYPE=Release"],
        ["cmake", "--build", str(build)],
    ):
        done = subprocess.run(command, capture_output=True, text=True, check=False)
        assert done.returncode == 0, f"{' '.join(command)} failed:\n{done.stdout}\n{done.stderr}"
    return build / "cv_tracker"


@pytest.fixture(scope="module")
def sequence():
    return analytic_box_sequence(n_frames=60, intrinsics=default_intrinsics(32, 24))


def _run(sequence, tracker: str, faults: str, spec: TrackerSpec | None = None):
    options = RunOptions(
        tracker=tracker, faults=load_faults(faults), poses="gt", masks="none", flow="none", seed=4
    )
    run = run_sequence(sequence, options, spec=spec)
    metrics = evaluate_run(run, invalid=options.invalid).metrics.summary()
    return run, {k: v for k, v in metrics.items() if not k.startswith("time_")}


def _assert_same(got, expected, *, exact: bool) -> None:
    (run_a, metrics_a), (run_b, metrics_b) = got, expected
    assert sum(e.valid for e in run_b.estimates) > 30  # the tracker did track
    for a, b in zip(run_a.estimates, run_b.estimates, strict=True):
        assert (a.k, a.valid) == (b.k, b.valid)
        assert (a.accepted_pose_ids, a.dropped_pose_ids) == (
            b.accepted_pose_ids,
            b.dropped_pose_ids,
        )
        for name in ("T_cam_obj", "v_obj_mps", "w_radps"):
            x, y = getattr(a, name), getattr(b, name)
            assert np.array_equal(x, y) if exact else np.allclose(x, y, rtol=0, atol=ATOL), name
    assert metrics_a.keys() == metrics_b.keys()
    for key, value in metrics_b.items():
        if value is None or metrics_a[key] is None:
            assert metrics_a[key] is value, key
        else:
            assert np.allclose(metrics_a[key], value, rtol=ATOL, atol=0, equal_nan=True), key


@pytest.mark.parametrize("faults", ["chaos"])
def test_the_python_process_matches_the_in_process_twin(sequence, faults):
    """Fast: the served Python tracker against the twin under late, lost, duplicated and
    reordered detections."""
    twin = _run(sequence, "cv-twin", faults, twin_spec())
    served = _run(sequence, f"process:{sys.executable} {EXAMPLE / 'cv_tracker.py'}", faults)
    assert served[0].tracker == "process-cv_tracker.py"
    assert any(e.dropped_pose_ids for e in twin[0].estimates)  # reordering was exercised
    _assert_same(served, twin, exact=False)


@pytest.mark.slow  # building the C++ program takes 5-15 s on 2 busy cores
@pytest.mark.parametrize("faults", ["paper", "chaos"])
def test_the_cpp_tracker_matches_the_twin_bit_for_bit(sequence, cpp_tracker, faults):
    twin = _run(sequence, "cv-twin", faults, twin_spec())
    _assert_same(_run(sequence, f"process:{cpp_tracker}", faults), twin, exact=True)
