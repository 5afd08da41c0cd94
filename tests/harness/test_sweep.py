"""Sweeps: the grid, swept fault parameters, executors, resumability, summary and plots."""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import pytest
from harness_cases import write_box_dataset

from roft_sim.cli import main
from roft_sim.errors import ConfigError
from roft_sim.executors import (
    LocalProcessExecutor,
    SerialExecutor,
    WorkUnitError,
    make_executor,
)
from roft_sim.faults import BernoulliDropout, FixedDelay, Rate, load_faults
from roft_sim.harness.cells import CELL_FILE, CELLS_DIR, finished_cells
from roft_sim.harness.sweep import (
    SweepConfig,
    SweptParameter,
    apply_parameter,
    load_sweep_config,
    parse_parameter,
    plan_sweep,
    run_sweep,
)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_box_dataset(tmp_path_factory.mktemp("data"), n_frames=18)


def _config(dataset: Path, **kw) -> SweepConfig:
    base = {
        "name": "t",
        "datasets": (dataset,),
        "trackers": ("detector-hold", "naive-delay"),
        "faults": ("paper",),
        "parameter": SweptParameter(name="delay", values=(0.0, 3.0, 6.0)),
        "flow": "none",
        "include_rgb": False,
    }
    return SweepConfig(**(base | kw))


def test_parse_parameter():
    p = parse_parameter("delay=0:20:2")
    assert p.name == "delay" and p.values == tuple(float(v) for v in range(0, 21, 2))
    p = parse_parameter("dropout=0,0.1,0.35", streams=["pose"])
    assert p.values == (0.0, 0.1, 0.35) and p.streams == ("pose",)
    for bad in ("delay", "delay=", "delay=3:1:1", "delay=a,b", "delay=0:4:0"):
        with pytest.raises(ConfigError, match="--param"):
            parse_parameter(bad)
    with pytest.raises(ConfigError, match="unknown swept parameter 'jitter'"):
        parse_parameter("jitter=1,2")
    with pytest.raises(ConfigError, match="whole frames"):
        parse_parameter("delay=0.5,1")
    with pytest.raises(ConfigError, match=r"probabilities in \[0, 1\]"):
        parse_parameter("dropout=0.5,1.5")


def test_apply_parameter_replaces_delays_and_adds_dropout():
    paper = load_faults("paper")
    delayed = apply_parameter(paper, SweptParameter(name="delay", values=(9.0,)), 9.0)
    for stream in (delayed.pose, delayed.mask):
        assert [type(f) for f in stream.faults] == [Rate, FixedDelay]
        assert stream.faults[1].frames == 9
    assert delayed.pose.first_result == "undelayed"
    assert delayed.name == "paper+delay=9"
    only_pose = SweptParameter(name="dropout", values=(0.3,), streams=("pose",))
    lossy = apply_parameter(paper, only_pose, 0.3)
    assert isinstance(lossy.pose.faults[-1], BernoulliDropout) and lossy.pose.faults[-1].p == 0.3
    assert lossy.mask == paper.mask


def test_plan_is_the_full_grid_with_unique_ids(dataset):
    cells = plan_sweep(_config(dataset, seeds=(0, 1)))
    assert len(cells) == 2 * 3 * 2 * 2
    assert len({c.cell_id for c in cells}) == len(cells)
    first = cells[0]
    assert first.cell_id.startswith("detector-hold__paper__delay=0__box_a__s0__")
    # ids change with any setting
    other = plan_sweep(_config(dataset, seeds=(0, 1), flow="stored:gt"))
    assert not {c.cell_id for c in cells} & {c.cell_id for c in other}


class _Interrupting:
    """An executor that runs ``limit`` units, then raises as if the sweep were killed."""

    workers = 1

    def __init__(self, limit: int) -> None:
        self.limit = limit

    def map_unordered(self, fn, units):
        for i, unit in enumerate(units):
            if i == self.limit:
                raise KeyboardInterrupt
            yield unit, fn(unit)


def test_sweep_resumes_after_an_interruption_with_an_identical_summary(dataset, tmp_path):
    config = _config(dataset)
    full = run_sweep(config, tmp_path / "full", plots=False)
    assert len(full.cells) == 12

    out = tmp_path / "resumed"
    with pytest.raises(KeyboardInterrupt):
        run_sweep(config, out, executor=_Interrupting(5), plots=False)
    done = finished_cells(out / CELLS_DIR)
    assert len(done) == 5
    # leftovers of a cell that was killed half-way: a temporary folder, a folder without cell.json
    half = out / CELLS_DIR / f".{full.cells[7].cell_id}.999.tmp"
    half.mkdir()
    (half / "pose_estimate.txt").write_text("0 0\n")
    broken = out / CELLS_DIR / full.cells[8].cell_id
    broken.mkdir()
    (broken / "pose_estimate.txt").write_text("garbage\n")
    stamps = {i: os.stat(out / CELLS_DIR / i / CELL_FILE).st_mtime_ns for i in done}

    resumed = run_sweep(config, out, executor=SerialExecutor(), plots=False)
    assert len(resumed.records) == 12
    # finished cells were not redone, leftovers are gone
    assert {i: os.stat(out / CELLS_DIR / i / CELL_FILE).st_mtime_ns for i in done} == stamps
    assert not half.exists()
    assert (broken / CELL_FILE).is_file()
    for name in ("summary.csv", "summary.md", "summary.tex", "cells.csv"):
        assert (out / name).read_text() == (tmp_path / "full" / name).read_text(), name


def test_summary_pools_sequences_and_writes_plots(dataset, tmp_path):
    result = run_sweep(_config(dataset), tmp_path, plots=True)
    rows = result.summary_rows
    assert [(r["tracker"], r["value"]) for r in rows] == [
        (t, v) for t in ("detector-hold", "naive-delay") for v in (0.0, 3.0, 6.0)
    ]
    assert all(r["sequences"] == 2 and r["frames"] == 36 for r in rows)
    # the delay hurts the detector
    hold = [r["rmse_t_cm"] for r in rows if r["tracker"] == "detector-hold"]
    assert hold[0] < hold[2]
    names = sorted(p.name for p in result.plots)
    assert names[0] == "error_vs_delay.png" and len(names) == 4
    image = cv2.imread(str(tmp_path / "plots" / "error_vs_delay.png"))
    assert image is not None and image.shape[0] > 300
    csv = (tmp_path / "summary.csv").read_text().splitlines()
    assert csv[0].split(",")[:3] == ["tracker", "faults", "value"]
    assert len(csv) == 1 + 6
    tex = (tmp_path / "summary.tex").read_text()
    assert r"\begin{tabular}" in tex and "detector-hold" in tex
    timing = (tmp_path / "timing.csv").read_text().splitlines()
    assert timing[0].startswith("tracker,faults,value,steps,time_median_ms")


def test_sweep_file_paths_are_relative_to_the_file(dataset, tmp_path):
    (tmp_path / "hold.toml").write_text('velocity = "zero"\n')
    path = tmp_path / "sweep.toml"
    path.write_text(
        f'name = "file"\ndatasets = ["{os.path.relpath(dataset, tmp_path)}"]\n'
        'trackers = ["detector-hold"]\nfaults = ["paper"]\nflow = "none"\n'
        '[parameter]\nname = "dropout"\nvalues = [0.0, 0.5]\n'
        '[[variants]]\nlabel = "hold zero"\nname = "detector-hold"\nconfig = "hold.toml"\n'
    )
    config = load_sweep_config(path)
    assert config.datasets == (dataset,) or config.datasets[0].resolve() == dataset.resolve()
    cells = plan_sweep(config)
    assert {c.label for c in cells} == {"detector-hold", "hold zero"}
    zero = next(c for c in cells if c.label == "hold zero")
    assert zero.options.tracker_config.velocity == "zero"
    path.write_text('datasets = ["x"]\ntrackers = ["roft"]\nfault = ["paper"]\n')
    with pytest.raises(ConfigError, match="unknown key 'fault'"):
        load_sweep_config(path)


def test_the_sweep_file_shown_in_docs_running_md_loads(tmp_path):
    """The documented example stays a valid sweep file (the help's examples point there)."""
    import re

    docs = Path(__file__).resolve().parents[2] / "docs" / "running.md"
    block = re.search(r"A sweep file \(strict TOML.*?```toml\n(.*?)```", docs.read_text(), re.S)
    assert block is not None, "docs/running.md lost its sweep-file example"
    path = tmp_path / "sweep.toml"
    path.write_text(block.group(1))
    config = load_sweep_config(path)
    assert config.parameter is not None and config.parameter.name == "delay"
    assert config.variants[0].config == tmp_path / "roft_no_sync.toml"


def test_serial_executor_wraps_errors():
    with pytest.raises(WorkUnitError, match=r"work unit 'x' failed: ValueError"):
        list(SerialExecutor().map_unordered(int, ["1", "x"]))
    assert isinstance(make_executor(1), SerialExecutor)
    assert isinstance(make_executor(2), LocalProcessExecutor)
    with pytest.raises(ConfigError, match="--workers must be >= 1"):
        make_executor(0)


@pytest.mark.slow
def test_local_process_executor_runs_units_in_parallel_processes():
    executor = LocalProcessExecutor(2)
    results = dict(executor.map_unordered(abs, [-1, -2, -3, 4]))
    assert results == {-1: 1, -2: 2, -3: 3, 4: 4}
    with pytest.raises(WorkUnitError, match="failed: ValueError"):
        list(executor.map_unordered(int, ["1", "x", "2"]))


def test_sweep_cli_and_its_errors(dataset, tmp_path, capsys):
    out = tmp_path / "s"
    args = ["sweep", str(dataset), "--trackers", "detector-hold", "--flow", "none"]
    assert main([*args, "--param", "delay=0:6:6", "--out", str(out), "--no-plots"]) == 0
    assert "| detector-hold | paper | 0 |" in capsys.readouterr().out
    record = json.loads(next((out / CELLS_DIR).glob("*/cell.json")).read_text())
    assert record["tracker"] == "detector-hold" and record["parameter"] == "delay"
    # non-empty --out without --resume
    assert main([*args, "--out", str(out)]) == 2
    assert "not empty" in capsys.readouterr().err
    assert main([*args, "--param", "delay=0:6:6", "--out", str(out), "--resume", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["cells"] == 4
    # --config with grid flags
    config = tmp_path / "c.toml"
    config.write_text(f'datasets = ["{dataset}"]\ntrackers = ["detector-hold"]\n')
    assert main(["sweep", "--config", str(config), "--trackers", "roft", "--out", str(out)]) == 2
    assert "drop --trackers" in capsys.readouterr().err
    assert main(["sweep", str(dataset), "--trackers", "nope", "--out", str(tmp_path / "n")]) == 2
    assert "no tracker named 'nope'" in capsys.readouterr().err


def test_a_grid_value_listed_twice_is_a_config_error(dataset):
    for repeated in (
        {"faults": ("paper", "paper")},
        {"seeds": (0, 0)},
        {"datasets": (dataset, dataset / "box_a")},
    ):
        with pytest.raises(ConfigError, match="more than once"):
            plan_sweep(_config(dataset, **repeated))


def test_sweep_cli_checks_inputs_and_repeats_before_writing(dataset, tmp_path, capsys):
    out = tmp_path / "s"
    args = ["sweep", str(dataset), "--trackers", "detector-hold", "--out", str(out)]
    assert main([*args, "--poses", "posecnn"]) == 2
    assert "no pose set 'posecnn'" in capsys.readouterr().err
    assert main([*args, "--flow", "raft"]) == 2
    assert "unknown flow source 'raft'" in capsys.readouterr().err
    assert main([*args, "--flow", "stored:nvof_1_slow"]) == 2
    assert "no stored flow set 'nvof_1_slow'" in capsys.readouterr().err
    assert main([*args, "--faults", "paper,paper"]) == 2
    assert "more than once" in capsys.readouterr().err
    assert not out.exists()


def test_flows_are_a_grid_dimension_with_their_own_summary_rows(
    dataset: Path, tmp_path: Path
) -> None:
    config = _config(
        dataset,
        trackers=("detector-hold",),
        parameter=None,
        flows=("stored:gt", "gt+noise:1"),
        include_rgb=True,
    )
    cells = plan_sweep(config)
    assert sorted({c.options.flow for c in cells}) == ["gt+noise:1", "stored:gt"]
    assert len(cells) == 2 * 2  # two flows x two sequences
    result = run_sweep(config, tmp_path / "s", plots=False)
    assert sorted(r["flow"] for r in result.summary_rows) == ["gt+noise:1", "stored:gt"]
    table_head = (tmp_path / "s" / "summary.md").read_text().split("|---")[0]
    assert "flow" in table_head
    with pytest.raises(ConfigError, match="flows lists a source twice"):
        _config(dataset, flows=("dis", "dis"))


def test_a_sweep_scores_with_the_hold_policy_and_its_summary_names_the_policy(dataset, tmp_path):
    failure = run_sweep(_config(dataset, trackers=("detector-hold",)), tmp_path / "f", plots=False)
    hold = run_sweep(
        _config(dataset, trackers=("detector-hold",), invalid="hold"), tmp_path / "h", plots=False
    )
    assert "invalid estimates: failure (" in (tmp_path / "f" / "summary.md").read_text()
    assert "invalid estimates: hold (" in (tmp_path / "h" / "summary.md").read_text()
    # every cell is scored under the sweep's policy (metrics/sequence.py's tests check the policy)
    cells = sorted((tmp_path / "h" / CELLS_DIR).glob(f"*/{CELL_FILE}"))
    assert cells and all('"invalid": "hold"' in c.read_text() for c in cells)
    assert len(failure.summary_rows) == len(hold.summary_rows)
