"""``roft-sim compare``: two runs paired frame by frame, the table, the plot, the errors."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from harness_cases import write_box_dataset

from roft_sim.cli import main
from roft_sim.errors import ConfigError
from roft_sim.harness.compare import compare_runs, format_compare
from roft_sim.metrics.statistics import BETTER


def _run(dataset: Path, tracker: str, out: Path, *extra: str) -> Path:
    args = ["run", str(dataset), "--tracker", tracker, "--flow", "none", "--no-rgb"]
    assert main([*args, "--faults", "paper", "--out", str(out), *extra]) == 0
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("compare")
    dataset = write_box_dataset(root / "data", names=("box_a",), n_frames=30)
    other = write_box_dataset(root / "other", names=("box_a",), n_frames=24)
    copy = root / "copy"
    shutil.copytree(dataset, copy)
    return {
        "hold": _run(dataset, "detector-hold", root / "hold"),
        "delay": _run(dataset, "naive-delay", root / "delay"),
        "copy": _run(copy, "naive-delay", root / "copy_delay"),
        "other": _run(other, "naive-delay", root / "other_delay"),
    }


def test_compare_pairs_frames_and_writes_table_and_plot(runs, tmp_path) -> None:
    result = compare_runs(runs["hold"], runs["hold"], n_resamples=300)
    # a run against itself: every difference is exactly 0
    assert all(m.difference.estimate == 0.0 for m in result.metrics)
    assert all(m.verdict == "no detectable difference" for m in result.metrics)

    result = compare_runs(runs["delay"], runs["hold"], tmp_path, n_resamples=300)
    assert result.pose_period == 6  # the paper preset: poses at 5 fps on a 30 fps camera
    assert [m.metric for m in result.metrics][:3] == ["add_auc_pct", "rmse_t_cm", "rmse_a_deg"]
    for m in result.metrics:
        assert m.block >= 6  # never shorter than a pose period
        assert m.difference.estimate == pytest.approx(m.a - m.b)
        if m.difference.has_interval:
            assert m.difference.low <= m.difference.estimate <= m.difference.high
    where = {w.category: w for w in result.where}
    assert {"all frames", "after a pose arrival", "rest of the pose period"} <= set(where)
    assert "fast motion" in where  # the box sequence has ground truth
    parts = ("after a pose arrival", "rest of the pose period", "no-detection stretch")
    assert sum(where[c].frames for c in parts) == where["all frames"].frames == result.frames
    assert sum(where[c].t_share for c in parts) == pytest.approx(1.0)
    image = cv2.imread(str(result.plots[0]))
    assert result.plots[0].name == "difference_box_a.png" and image.shape[0] > 300
    text = format_compare(result)
    assert "| e_t [cm] |" in text and "## Where the difference is" in text
    assert "| after a pose arrival |" in text and "![difference_box_a]" in text


def test_a_verdict_is_named_exactly_when_the_interval_excludes_0(runs) -> None:
    result = compare_runs(runs["delay"], runs["hold"], n_resamples=300)
    for m in result.metrics:
        if m.difference.excludes(0.0):
            assert m.verdict != "no detectable difference"
    assert result.plots == []  # no --out: no plot


def test_compare_cli_and_its_errors(runs, tmp_path, capsys) -> None:
    out = tmp_path / "cmp"
    assert main(["compare", str(runs["delay"]), str(runs["hold"]), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith("# naive-delay (A, ") and "| ADD-AUC [%] |" in printed
    summary = json.loads((out / "compare.json").read_text())
    assert summary["frames"] > 0 and len(summary["metrics"]) == 5
    assert (out / "compare.md").is_file() and (out / "difference_box_a.png").is_file()
    # the same sequence copied elsewhere is the same data
    assert compare_runs(runs["copy"], runs["hold"], n_resamples=100).frames > 0
    # another sequence of the same name
    code = main(["compare", str(runs["other"]), str(runs["hold"]), "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err
    assert "ran on different data: sequence 'box_a' has frames 24 and 30" in err
    assert not (tmp_path / "o").exists()  # nothing written
    code = main(["compare", str(tmp_path), str(runs["hold"]), "--out", str(tmp_path / "n")])
    assert code == 2 and "is not a run folder (no run.json)" in capsys.readouterr().err


def test_different_content_under_the_same_name_is_refused(runs, tmp_path) -> None:
    """Same name and length, other ground truth: the check opens both and compares."""
    moved = tmp_path / "moved"
    shutil.copytree(runs["hold"], moved)
    record = json.loads((moved / "run.json").read_text())
    record["sequences"][0]["path"] = str(tmp_path / "nowhere" / "box_a")
    (moved / "run.json").write_text(json.dumps(record))
    with pytest.raises(ConfigError, match="whose ground truth differs"):
        compare_runs(moved, runs["hold"])


def test_the_verdict_is_read_from_run_a(runs) -> None:
    """Swapping A and B flips every difference and turns better into worse."""
    result = compare_runs(runs["hold"], runs["delay"], n_resamples=300)
    flipped = compare_runs(runs["delay"], runs["hold"], n_resamples=300)
    for m, f in zip(result.metrics, flipped.metrics, strict=True):
        assert m.difference.estimate == pytest.approx(-f.difference.estimate)
        if m.verdict == BETTER:
            assert f.verdict == "worse"
    assert np.isfinite([m.a for m in result.metrics[:3]]).all()


def test_two_cells_of_a_sweep_compare_like_runs(tmp_path) -> None:
    from roft_sim.harness.sweep import SweepConfig, run_sweep

    dataset = write_box_dataset(tmp_path / "data", names=("box_a",), n_frames=24)
    config = SweepConfig(
        datasets=(dataset,),
        trackers=("detector-hold", "naive-delay"),
        faults=("chaos",),
        flow="none",
        include_rgb=False,
    )
    cells = run_sweep(config, tmp_path / "sweep", plots=False).cells
    folders = [tmp_path / "sweep" / "cells" / c.cell_id for c in cells]
    result = compare_runs(folders[1], folders[0], n_resamples=200)
    assert (result.run_a.tracker, result.run_b.tracker) == ("naive-delay", "detector-hold")
    assert result.frames > 0 and result.run_a.faults == "chaos"
