"""Replicates in sweep summaries: seeds that change nothing count once, intervals per metric,
the paired table."""

from __future__ import annotations

import csv
import math

import pytest
from harness_cases import write_box_dataset

from roft_sim.harness.replicates import distinct_replicates, paired_set, replicate_intervals
from roft_sim.harness.sweep import SweepConfig, run_sweep


def test_a_sequence_whose_seeds_change_nothing_counts_once() -> None:
    same = {"add_auc_pct": 70.0, "rmse_t_cm": 2.0}
    keyed = {
        ("a", 0): same,
        ("a", 1): dict(same),
        ("b", 0): {"add_auc_pct": 60.0},
        ("b", 1): {"add_auc_pct": 60.0},  # coincides with seed 0 ...
        ("b", 2): {"add_auc_pct": 65.0},  # ... but b's seeds do differ: all kept
    }
    assert list(distinct_replicates(keyed)) == [("a", 0), ("b", 0), ("b", 1), ("b", 2)]
    pairs = paired_set("x", "y", keyed, keyed, key="k")
    assert pairs.pairs == 4 and pairs.comparisons["add_auc_pct"].difference.estimate == 0.0


def test_seeds_count_once_per_sequence_and_flow_when_they_change_nothing() -> None:
    """Stress keys (sequence, flow, seed): the stored flow's seeds are copies, the noisy
    flow's seeds differ; only the copies collapse."""
    keyed = {
        ("s", "stored", 0): {"add_auc_pct": 70.0},
        ("s", "stored", 1): {"add_auc_pct": 70.0},
        ("s", "noisy", 0): {"add_auc_pct": 60.0},
        ("s", "noisy", 1): {"add_auc_pct": 62.0},
    }
    assert list(distinct_replicates(keyed)) == [
        ("s", "stored", 0),
        ("s", "noisy", 0),
        ("s", "noisy", 1),
    ]


def test_metric_intervals_stay_inside_the_metrics_range() -> None:
    """Two replicates: Student's t (1 degree of freedom) reaches far past 0 and 100."""
    got = replicate_intervals(
        [{"add_auc_pct": 98.0, "rmse_t_cm": 0.1}, {"add_auc_pct": 60.0, "rmse_t_cm": 3.0}], "k"
    )
    assert (got["add_auc_pct"].low, got["add_auc_pct"].high) == (0.0, 100.0)
    assert got["rmse_t_cm"].low == 0.0 and got["rmse_t_cm"].high > 3.0


def test_sweep_summary_gives_means_with_intervals_and_a_paired_table(tmp_path) -> None:
    dataset = write_box_dataset(tmp_path / "data", n_frames=18)
    config = SweepConfig(
        name="r",
        datasets=(dataset,),
        trackers=("detector-hold", "naive-delay"),
        faults=("paper", "chaos"),
        seeds=(0, 1, 2),
        flow="none",
        include_rgb=False,
    )
    result = run_sweep(config, tmp_path / "s", plots=False)
    rows = {(r["tracker"], r["faults"]): r for r in result.summary_rows}
    # paper has no randomness: each sequence counts once; chaos draws differ per seed
    assert rows[("detector-hold", "paper")]["replicates"] == 2
    assert rows[("detector-hold", "chaos")]["replicates"] == 6
    for r in rows.values():
        assert r["add_auc_pct_lo"] <= r["add_auc_pct_mean"] <= r["add_auc_pct_hi"]
        assert r["add_auc_pct_ci"].startswith(f"{r['add_auc_pct_mean']:.2f} [")
    md = (tmp_path / "s" / "summary.md").read_text()
    assert "| ADD-AUC % mean [95 % CI] |" in md and "## Paired: each tracker against" in md
    with (tmp_path / "s" / "paired.csv").open() as f:
        paired = list(csv.DictReader(f))
    assert {(p["tracker"], p["versus"]) for p in paired} == {("naive-delay", "detector-hold")}
    chaos = next(p for p in paired if p["faults"] == "chaos")
    assert chaos["pairs"] == "6" and chaos["rmse_t_cm_verdict"] in (
        "better",
        "worse",
        "no detectable difference",
    )
    assert math.isfinite(float(chaos["add_auc_pct_diff"]))
    header = (tmp_path / "s" / "summary.csv").read_text().splitlines()[0].split(",")
    assert {"replicates", "add_auc_pct", "add_auc_pct_mean", "add_auc_pct_lo"} <= set(header)
    assert (
        pytest.approx(float(rows[("detector-hold", "paper")]["add_auc_pct_mean"]))
        == sum(
            result.records[c.cell_id]["metrics"]["add_auc_pct"]
            for c in result.cells
            if c.label == "detector-hold" and c.fault_label == "paper" and c.options.seed == 0
        )
        / 2
    )


def test_a_series_band_is_drawn_around_its_line() -> None:
    """The sweep's parameter plot: each line gets a shaded band over its intervals."""
    from roft_sim.report.plotting import Panel, Series, line_figure

    banded = Series(
        x=[0, 1, 2],
        y=[1.0, 2.0, 3.0],
        label="a",
        band_low=[0.5, 1.5, 2.5],
        band_high=[1.5, 2.5, 3.5],
    )
    figure = line_figure([Panel(title="t", y_label="y [cm]", series=(banded,))], x_label="x")
    (axes,) = figure.axes
    assert len(axes.collections) == 1  # the band
    (path,) = axes.collections[0].get_paths()
    assert path.vertices[:, 1].min() == 0.5 and path.vertices[:, 1].max() == 3.5
    with pytest.raises(ValueError, match="both band_low and band_high"):
        Series(x=[0, 1], y=[1.0, 2.0], band_low=[0.0, 1.0])
