"""``roft-sim run|sweep --tracker "process:<command>"``: the same metrics as in process, and a
sweep that goes on when a tracker process crashes."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("msgpack", reason="the process extra (msgpack) is not installed")

from harness_cases import write_box_dataset  # noqa: E402

from roft_sim.cli import main  # noqa: E402
from roft_sim.faults import load_faults  # noqa: E402
from roft_sim.harness import RunOptions, open_sequences, run_sequences  # noqa: E402
from roft_sim.harness.cells import ERROR_SUFFIX, CellsFailedError  # noqa: E402
from roft_sim.harness.sweep import SweepConfig, run_sweep  # noqa: E402
from roft_sim.trackers import TrackerSpec  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
CV_TRACKER = REPO / "examples" / "process_tracker_cpp" / "cv_tracker.py"
CRASHING_CHILD = REPO / "tests" / "trackers" / "process_child.py"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_box_dataset(tmp_path_factory.mktemp("data"), names=("box_a",), n_frames=18)


def _twin_spec() -> TrackerSpec:
    import importlib.util

    spec = importlib.util.spec_from_file_location("cv_tracker_example", CV_TRACKER)
    assert spec is not None and spec.loader is not None
    cv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cv)
    return TrackerSpec(
        name="cv-twin",
        description="in-process twin",
        config_type=cv.ConstantVelocityConfig,
        factory=lambda config, context: cv.ConstantVelocityTracker(context),
    )


def _without_timing(value):
    if isinstance(value, dict):
        return {k: _without_timing(v) for k, v in value.items() if not k.startswith("time_")}
    return value


def _assert_close(a, b, path="metrics"):
    if isinstance(b, dict):
        assert a.keys() == b.keys(), path
        for key in b:
            _assert_close(a[key], b[key], f"{path}.{key}")
    elif isinstance(b, list):
        assert isinstance(a, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _assert_close(x, y, f"{path}[{i}]")
    elif isinstance(b, float) and isinstance(a, float):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-300, err_msg=path)
    else:
        assert a == b, path


def test_a_cli_run_through_a_process_gives_the_in_process_metrics(dataset, tmp_path):
    command = f"process:{sys.executable} {CV_TRACKER}"
    out = tmp_path / "process"
    argv = ["run", str(dataset), "--tracker", command, "--tracker-name", "cv-process"]
    argv += ["--faults", "chaos", "--flow", "none", "--out", str(out), "--no-progress", "--json"]
    assert main(argv) == 0
    run_json = json.loads((out / "run.json").read_text())
    assert run_json["options"]["tracker"] == command
    options = RunOptions(tracker="cv-twin", faults=load_faults("chaos"), flow="none")
    run_sequences(open_sequences([dataset]), options, tmp_path / "twin", spec=_twin_spec())
    got, expected = (
        _without_timing(json.loads((d / "metrics.json").read_text()))
        for d in (out, tmp_path / "twin")
    )
    assert got["box_a"]["frames"] == 18
    _assert_close(got, expected)


def test_a_sweep_goes_on_after_a_crashed_tracker_process(dataset, tmp_path):
    crash = f"process:{sys.executable} {CRASHING_CHILD} crash"
    config = SweepConfig(
        name="t",
        datasets=(dataset,),
        trackers=(crash, f"process:{sys.executable} {CV_TRACKER}"),
        faults=("paper",),
        flow="none",
        include_rgb=False,
    )
    with pytest.raises(CellsFailedError, match=r"(?s)1 cell\(s\) failed.*native code") as failed:
        run_sweep(config, tmp_path / "sweep", plots=False)
    cells = tmp_path / "sweep" / "cells"
    (crashed,) = failed.value.failures
    assert crashed.startswith("process-process_child.py-crash__paper__box_a")
    assert "status 3" in (cells / f"{crashed}{ERROR_SUFFIX}").read_text()
    finished = [p.name for p in cells.iterdir() if (p / "cell.json").is_file()]
    assert len(finished) == 1 and finished[0].startswith("process-cv_tracker.py__paper")
