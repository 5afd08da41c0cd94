"""``roft-sim paper --seeds N``: rows over fault and detector seeds, intervals beside the paper's
numbers, Kendall's tau with its interval."""

from __future__ import annotations

import json

import numpy as np
import pytest
from harness_cases import write_box_dataset

from roft_sim.cli import main
from roft_sim.datasets import open_sequence
from roft_sim.harness.inputs import resolve_inputs
from roft_sim.harness.options import RunOptions
from roft_sim.harness.paper import PAPER_LAYOUT, paper_rows, plan_paper
from roft_sim.harness.paper_seeds import noise_tables, seed_poses, uncertainty_markdown
from roft_sim.report.paper_reference import ALL, paper_tables


def test_redrawn_detector_poses_are_a_fresh_draw_of_the_same_law(tmp_path) -> None:
    dataset = write_box_dataset(tmp_path, names=("box_a",), n_frames=40)
    sequence = open_sequence(dataset / "box_a")
    draws = []
    for k in (1, 1, 2):
        inputs = resolve_inputs(sequence, RunOptions(tracker="detector-hold", poses=f"redraw:{k}"))
        assert inputs.pose_set == f"redraw:{k}"
        draws.append(inputs.sequence.detector_poses(inputs.pose_set))
    assert np.array_equal(draws[0].T_cam_obj, draws[1].T_cam_obj)  # seeded
    assert not np.array_equal(draws[0].T_cam_obj, draws[2].T_cam_obj)
    gt = sequence.ground_truth().T_cam_obj
    error_m = np.linalg.norm(
        draws[2].T_cam_obj[draws[2].valid, :3, 3] - gt[draws[2].valid, :3, 3], axis=1
    )
    assert 0.0 < np.median(error_m) < 0.05  # the DOPE-like estimator's centimetres
    assert seed_poses("auto", 0, 0) == "auto" and seed_poses("auto", 3, 0) == "redraw:3"
    assert seed_poses("gt", 3, 0) == "gt"


def test_the_noise_section_says_which_differences_lie_inside() -> None:
    """Three seeds of the DOPE row around the paper's ALL ADD-AUC (inside), and of our default
    ROFT row far above it (outside); the tau interval needs the nine ROFT rows' ALL values."""
    paper = paper_tables()
    dope = paper.table1["DOPE"]["add_auc_pct"][ALL]
    roft = paper.table1["ROFT"]["add_auc_pct"][ALL]
    rows = ("roft", "roft_no_velocity", "roft_no_pose", "roft_no_pose_sync")
    by_seed = {}
    for i, s in enumerate((0, 1, 2)):
        results = {"detector": {ALL: {"add_auc_pct": dope + (i - 1) * 0.5}}}
        for j, row in enumerate(rows):
            results[row] = {ALL: {"add_auc_pct": roft + 10.0 - 5.0 * j + 0.1 * i}}
        by_seed[s] = results
    columns, table = noise_tables(by_seed, paper, [ALL], PAPER_LAYOUT)["ADD-AUC (%)"]
    row = table[0]
    assert row["detector:inside"] is True and row["detector:noise"] == "yes"
    assert row["roft:inside"] is False and row["roft:diff"] == pytest.approx(10.1)
    md = "\n".join(uncertainty_markdown(by_seed, paper, [ALL], ["roft"], PAPER_LAYOUT))
    assert "- DOPE (5 fps, held), ADD-AUC (%): inside the noise: ALL; outside: none" in md
    assert "- ROFT, our default, ADD-AUC (%): inside the noise: none; outside: ALL (+10.10)" in md
    assert "- `roft`, add_auc_pct: tau " in md


@pytest.mark.slow
def test_paper_over_three_seeds_gives_intervals_and_the_noise(tmp_path, capsys) -> None:
    dataset = write_box_dataset(tmp_path / "data", names=("box_a",), n_frames=30)
    rows = "detector,roft,roft_no_velocity,roft_no_pose"
    cells = plan_paper(
        paper_rows(rows.split(",")), [dataset / "box_a"], flow="stored:gt", seed=4, seeds=3
    )
    detector = [c.options for c in cells if c.label == "detector"]
    assert [(o.seed, o.poses) for o in detector] == [(4, "auto"), (5, "redraw:5"), (6, "redraw:6")]
    out = tmp_path / "paper"
    args = ["paper", "--out", str(out), "--reuse", str(dataset), "--rows", rows, "--no-plugins"]
    assert main([*args, "--flow", "stored:gt", "--seed", "4", "--seeds", "3", "--json"]) == 0
    capsys.readouterr()
    tables = (out / "tables.md").read_text()
    assert "## Over 3 seeds: which differences from the paper are inside the noise" in tables
    assert "sim mean [95 % CI]" in tables and "inside the noise" in tables
    assert "Kendall tau of the Table IV order, with its interval over the seeds" in tables
    record = json.loads((out / "paper.json").read_text())
    uncertainty = record["uncertainty"]
    assert record["seeds"] == 3 and uncertainty["seeds"] == [4, 5, 6]
    taus = uncertainty["kendall_tau"]
    assert {t["metric"] for t in taus} == {"add_auc_pct", "rmse_t_cm", "rmse_a_deg"}
    for t in taus:
        if t["low"] is not None:
            assert -1.0 <= t["low"] <= t["high"] <= 1.0
    all_row = next(r for r in uncertainty["noise"]["ADD-AUC (%)"] if r["entry"] == "ALL")
    assert all_row["detector:sim_lo"] <= all_row["detector:sim_mean"] <= all_row["detector:sim_hi"]
    assert all_row["detector:sim_lo"] < all_row["detector:sim_hi"]  # the draws differ


@pytest.mark.slow
def test_paper_cli_over_two_seeds_of_the_detector_row(tmp_path, capsys) -> None:
    dataset = write_box_dataset(tmp_path / "data", names=("box_a",), n_frames=24)
    out = tmp_path / "paper"
    args = ["paper", "--out", str(out), "--reuse", str(dataset), "--rows", "detector"]
    assert main([*args, "--no-plugins", "--seeds", "2", "--json"]) == 0
    capsys.readouterr()
    assert "## Over 2 seeds: which differences" in (out / "tables.md").read_text()
    assert json.loads((out / "paper.json").read_text())["uncertainty"]["seeds"] == [0, 1]


def test_paper_plans_every_row_over_the_seeds_and_refuses_zero(tmp_path, capsys) -> None:
    dataset = write_box_dataset(tmp_path / "data", names=("box_a",), n_frames=12)
    rows = paper_rows(["detector", "roft_gt_pose"])
    cells = plan_paper(rows, [dataset / "box_a"], flow="stored:gt", seed=4, seeds=3)
    by_row = {
        r.key: [(c.options.seed, c.options.poses) for c in cells if c.label == r.key] for r in rows
    }
    assert by_row["detector"] == [(4, "auto"), (5, "redraw:5"), (6, "redraw:6")]
    assert by_row["roft_gt_pose"] == [(4, "gt"), (5, "gt"), (6, "gt")]  # no detector to redraw
    assert len({c.cell_id for c in cells}) == 6
    single = plan_paper(rows, [dataset / "box_a"], flow="stored:gt", seed=4)
    assert [c.cell_id for c in single] == [c.cell_id for c in cells if c.options.seed == 4]
    out = tmp_path / "paper"
    args = ["paper", "--out", str(out), "--reuse", str(dataset), "--rows", "detector"]
    assert main([*args, "--seeds", "0"]) == 2
    assert "--seeds must be >= 1" in capsys.readouterr().err
    assert not out.exists()
