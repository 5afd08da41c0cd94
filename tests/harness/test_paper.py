"""`roft-sim paper`: the rows, the findings check, the tables, and one full run (slow)."""

from __future__ import annotations

import json

import pytest
from harness_cases import write_box_dataset

from roft_sim.cli import main
from roft_sim.errors import ConfigError
from roft_sim.harness.paper import (
    PAPER_ROWS,
    REFERENCE_ROWS,
    attribution_table,
    check_findings,
    checked_configurations,
    paper_rows,
    plan_paper,
)
from roft_sim.report.paper_reference import ALL, paper_tables
from roft_sim.trackers.roft import RoftConfig


def _paper_results() -> dict:
    """The paper's own Table IV (and Table II) numbers, as simulated results."""
    paper = paper_tables()
    results = {}
    for row in PAPER_ROWS:
        ref = paper.table4[row.label]
        entry = dict(ref)
        if row.label in paper.table2:
            entry |= {m: v[ALL] for m, v in paper.table2[row.label].items()}
        results[row.key] = {ALL: entry}
    results["roft_no_mask_sync"][ALL] |= {
        m: v[ALL] for m, v in paper.table2["ROFT w/o segm. sync."].items()
    }
    return results


def test_rows_cover_every_table_iv_variant():
    paper = paper_tables()
    assert [r.label for r in PAPER_ROWS] == list(paper.table4)
    assert {r.key for r in PAPER_ROWS if "I" in r.tables} == {"roft", "detector"}
    assert {r.key for r in PAPER_ROWS if "II" in r.tables} == {"roft", "roft_no_mask_sync"}
    keys = [r.key for r in paper_rows()]
    assert "plugin:naive-delay" in keys and "plugin:pose-only-ukf" in keys
    assert "plugin:roft" not in keys
    with pytest.raises(ConfigError, match="unknown paper rows"):
        paper_rows(["roft", "dope"])


def test_the_paper_numbers_pass_the_findings_check():
    findings = check_findings(_paper_results())
    assert [f.holds for f in findings] == [True] * 5
    assert "roft: add_auc_pct 76.59" in findings[0].evidence


@pytest.mark.parametrize(
    ("key", "metric", "value", "broken"),
    [
        ("detector", "rmse_a_deg", 10.0, 0),  # the detector beats ROFT on e_a
        ("roft_no_outlier_rejection", "add_auc_pct", 40.0, 1),  # worse than w/o velocity
        ("roft_no_mask_sync", "rmse_w_dps", 20.0, 2),  # mask sync no longer helps e_w
        ("roft_no_pose_sync", "rmse_a_deg", 12.0, 3),  # pose sync no longer helps e_a
        ("roft_gt_mask", "rmse_t_cm", 3.5, 4),  # a GT row worse than ROFT on e_t
    ],
)
def test_each_finding_fails_when_its_numbers_say_so(key, metric, value, broken):
    results = _paper_results()
    results[key][ALL][metric] = value
    findings = check_findings(results)
    holds = [f.holds for f in findings]
    assert holds[broken] is False
    assert sum(h is False for h in holds) == 1
    assert f"on {metric}" in findings[broken].evidence.split("Fails: ")[1]


def _as_reference(results: dict) -> dict:
    """The ROFT rows of ``results`` under the reference configuration's keys, the others as
    they are."""
    return {
        (k.replace("roft", "roft_reference", 1) if k.startswith("roft") else k): v
        for k, v in results.items()
    }


def test_the_reference_configuration_is_checked_on_its_own_rows():
    results = _as_reference(_paper_results())
    assert checked_configurations(results) == ["roft", "roft_reference"]
    assert checked_configurations(_paper_results()) == ["roft"]
    reference = check_findings(results, configuration="roft_reference")
    assert [f.holds for f in reference] == [True] * 5
    assert {f.configuration for f in reference} == {"roft_reference"}
    assert "roft_reference: add_auc_pct 76.59" in reference[0].evidence
    # our default's rows are absent from these results: not checked
    assert [f.holds for f in check_findings(results)] == [None] * 5
    # a reference row that breaks a finding fails it, and names the reference's row
    results["roft_reference_no_outlier_rejection"][ALL]["add_auc_pct"] = 40.0
    broken = check_findings(results, configuration="roft_reference")
    assert [f.holds for f in broken] == [True, False, True, True, True]
    assert "roft_reference_no_outlier_rejection" in broken[1].evidence.split("Fails: ")[1]


def test_table2_shows_each_configuration_that_ran(tmp_path):
    from roft_sim.harness.paper import REFERENCE_ROWS, write_paper_tables

    both = {**_paper_results(), **_as_reference(_paper_results())}
    for results in (_paper_results(), both):
        for row in results.values():
            row["003_cracker_box"] = dict(row[ALL])
        rows = [r for r in (*PAPER_ROWS, *REFERENCE_ROWS) if r.key in results]
        write_paper_tables(tmp_path, rows, results)
        header = (tmp_path / "table2.csv").read_text().splitlines()[0]
        columns = header.split(",")
        assert "sim:roft:rmse_v_cmps" in columns and "paper:ROFT:rmse_v_cmps" in columns
        reference = "sim:roft_reference:rmse_v_cmps" in columns
        assert reference == (results is both)
        tables = (tmp_path / "tables.md").read_text()
        assert ("Configuration `roft_reference`:" in tables) == (results is both)


def test_missing_rows_are_not_checked():
    results = {k: v for k, v in _paper_results().items() if k in ("roft", "detector")}
    holds = [f.holds for f in check_findings(results)]
    assert holds == [True, None, None, None, None]


def test_plan_uses_the_ablation_configs_and_the_paper_faults(tmp_path):
    dataset = write_box_dataset(tmp_path, names=("box_a",))
    rows = paper_rows(["roft", "roft_no_pose_sync", "roft_gt_mask_pose", "detector"])
    cells = plan_paper(rows, [dataset / "box_a"], flow="stored:gt", seed=3)
    by_label = {c.label: c for c in cells}
    assert by_label["roft"].options.tracker_config == RoftConfig()
    assert by_label["roft_no_pose_sync"].options.tracker_config.use_pose_resync is False
    no_velocity = plan_paper(
        paper_rows(["roft_no_velocity"]), [dataset / "box_a"], flow="none", seed=0
    )[0].options.tracker_config
    assert not (no_velocity.use_velocity or no_velocity.use_pose_resync)
    assert not no_velocity.outlier_rejection.enable
    assert no_velocity.pose.sigma_angular == (0.01,) * 3
    assert no_velocity.pose.meas_cov_q == (0.01,) * 3
    gt = by_label["roft_gt_mask_pose"].options
    assert (gt.poses, gt.masks) == ("gt", "gt")
    hold = by_label["detector"].options
    assert hold.flow == "none" and hold.masks == "none" and hold.invalid == "hold"
    assert all(c.options.faults.name == "paper" and c.options.seed == 3 for c in cells)


def test_paper_cli_on_a_reused_dataset(tmp_path, capsys):
    dataset = write_box_dataset(tmp_path / "data")
    out = tmp_path / "paper"
    rows = "detector,detector_ideal,roft_no_velocity,roft_no_pose,roft,roft_no_mask_sync"
    args = ["paper", "--out", str(out), "--reuse", str(dataset), "--rows", rows, "--no-plugins"]
    assert main([*args, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    # checked where their rows ran: not the pose-sync and ground-truth findings
    assert [f["holds"] is None for f in summary["findings"]] == [False, False, False, True, True]
    tables = (out / "tables.md").read_text()
    assert "## Table I" in tables and "## Table IV" in tables
    assert "| DOPE | " in tables and "| ROFT w/o pose |" in tables
    for name in ("table1_add_auc.csv", "table2.csv", "table4.csv", "tables.tex", "paper.json"):
        assert (out / name).is_file(), name
    record = json.loads((out / "paper.json").read_text())
    assert set(record["results"]) == set(rows.split(","))
    assert record["results"]["detector"]["analytic_box"]["frames"] > 0
    # the per-object motion table: the box is not a paper object, so only ALL has ratios
    motion = record["per_object_motion"]["roft"]
    assert [r["entry"] for r in motion["rows"]] == ["analytic_box", ALL]
    assert motion["rows"][0]["add_gap"] is None and motion["rank_correlation"] is None
    assert motion["rows"][1]["stale_masks:rmse_v_cmps"] > 0
    assert (out / "per_object_motion_roft.csv").is_file()
    # resumable: a second call reuses every cell
    assert main([*args, "--resume", "--json"]) == 0
    capsys.readouterr()
    assert main([*args]) == 2
    assert "not empty" in capsys.readouterr().err
    assert (
        main(["paper", "--out", str(tmp_path / "x"), "--reuse", str(dataset), "--frames", "9"]) == 2
    )


@pytest.mark.slow
@pytest.mark.render
def test_full_paper_run_at_640x480_with_short_sequences(tmp_path, capsys):
    """The whole `roft-sim paper` path: generation of the six Fast-YCB-like sequences at 640x480
    (24 frames each), every Table I/II/IV row and the plugins, the tables and the findings.

    24 frames cover 3 pose arrivals per sequence, too few for the findings to be meaningful:
    this checks that everything runs and is written, not the numbers (docs/paper.md has those).
    """
    out = tmp_path / "paper"
    args = ["paper", "--out", str(out), "--resolution", "640x480", "--frames", "24"]
    assert main([*args, "--workers", "2", "--no-progress", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    # five findings for our default and five for the reference configuration, on its own rows
    configurations = [f["configuration"] for f in summary["findings"]]
    assert configurations == ["roft"] * 5 + ["roft_reference"] * 5
    assert all(f["holds"] in (True, False) for f in summary["findings"])
    record = json.loads((out / "paper.json").read_text())
    assert record["dataset"]["generated"] and record["dataset"]["frames_generated"] == 6 * 24
    results = record["results"]
    assert {r.key for r in paper_rows()} == set(results)
    for key, entries in results.items():
        # frames before a sequence's first detection are left out (invalid = hold)
        assert 0 < entries[ALL]["frames"] <= 6 * 24, key
        assert set(entries) == {*paper_tables().objects, ALL}
    table4 = (out / "table4.csv").read_text().splitlines()
    assert len(table4) == 1 + len([r for r in paper_rows() if "IV" in r.tables])
    assert (out / "attribution.csv").exists()
    # both configurations ran their plain and stale-mask rows: a motion table each, six objects
    motion = record["per_object_motion"]
    assert set(motion) == {"roft", "roft_reference"}
    assert all(isinstance(m["rank_correlation"], float) for m in motion.values())
    assert (out / "per_object_motion_roft_reference.csv").exists()


def test_paper_cli_checks_its_arguments_before_touching_the_output(tmp_path, capsys):
    dataset = write_box_dataset(tmp_path / "data", names=("box_a",), n_frames=12)
    out = tmp_path / "paper"
    out.mkdir()
    (out / "keep.txt").write_text("earlier results")
    base = ["paper", "--out", str(out), "--overwrite", "--no-plugins"]
    for bad, message in (
        (["--frames", "0"], "--frames must be >= 1"),
        (["--assets", str(tmp_path / "nowhere")], "is not a folder"),
        (["--resolution", "abc"], "expected WIDTHxHEIGHT"),
        (["--flow", "raft"], "unknown flow source"),
        (["--reuse", str(dataset), "--seed", "-1", "--rows", "detector"], "seed must be"),
        (["--reuse", str(dataset), "--flow", "raft", "--rows", "roft"], "unknown flow source"),
    ):
        assert main([*base, *bad]) == 2, bad
        assert message in capsys.readouterr().err
        assert (out / "keep.txt").exists(), bad


def test_reference_rows_mirror_the_roft_rows_and_the_attribution_chain_ends_at_the_default():
    from roft_sim.harness.paper import _tracker_config
    from roft_sim.trackers.roft import DEVIATIONS, ablation_config, reference_config

    ref_rows = [r for r in REFERENCE_ROWS if r.deviations is None]
    assert [r.paper_label for r in ref_rows] == [r.label for r in PAPER_ROWS if r.tracker == "roft"]
    assert {r.tracker for r in REFERENCE_ROWS} == {"roft-reference"}
    main_row = next(r for r in REFERENCE_ROWS if r.key == "roft_reference")
    assert main_row.tables == ("I", "II", "IV")
    no_mask_sync = next(r for r in REFERENCE_ROWS if r.key == "roft_reference_no_mask_sync")
    assert no_mask_sync.tables == ("II", "IV")
    no_pose = next(r for r in REFERENCE_ROWS if r.key == "roft_reference_no_pose")
    assert RoftConfig(**_fields(_tracker_config(no_pose))) == ablation_config(
        "no_pose", reference_config()
    )
    attr = [r for r in REFERENCE_ROWS if r.deviations is not None]
    assert [r.deviations for r in attr] == list(range(1, len(DEVIATIONS)))
    keys = {r.key for r in paper_rows()}
    assert "plugin:roft-reference" not in keys and "roft_reference" in keys


def _fields(config) -> dict:
    import dataclasses

    return {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}


def test_attribution_table_chains_the_changes():
    from roft_sim.trackers.roft import DEVIATIONS

    def entry(auc: float) -> dict:
        return {ALL: {"add_auc_pct": auc, "rmse_t_cm": 1.0, "rmse_a_deg": 2.0}}

    results = {"roft_reference": entry(50.0), "roft": entry(80.0)}
    for n in range(1, len(DEVIATIONS)):
        results[f"attr_{n:02d}_{DEVIATIONS[n - 1].name}"] = entry(50.0 + n)
    _, rows = attribution_table(results)
    assert [r["step"] for r in rows][0] == "reference" and rows[-1]["step"].endswith("default")
    assert len(rows) == len(DEVIATIONS) + 1
    assert rows[0]["d:add_auc_pct"] is None
    assert rows[1]["d:add_auc_pct"] == pytest.approx(1.0)
    assert rows[-1]["d:add_auc_pct"] == pytest.approx(80.0 - (50.0 + len(DEVIATIONS) - 1))
    assert sum(r["d:add_auc_pct"] for r in rows[1:]) == pytest.approx(30.0)
    assert attribution_table({"detector": entry(1.0)})[1] == []


def _per_object_results(paper, scale_v: dict[str, float], add_gap: dict[str, float]) -> dict:
    """Reference rows with the paper's per-object numbers: ROFT's ADD-AUC moved by
    ``add_gap[object]`` points and every velocity error divided by ``scale_v[object]`` (so the
    paper / sim ratio is ``scale_v``)."""
    objects = list(scale_v)
    reference: dict = {}
    stale: dict = {}
    for entry in [*objects, ALL]:
        k = scale_v.get(entry, 2.0)
        reference[entry] = {
            "add_auc_pct": paper.table1["ROFT"]["add_auc_pct"][entry] + add_gap.get(entry, 0.0),
            **{m: v[entry] / k for m, v in paper.table2["ROFT"].items()},
        }
        stale[entry] = {m: v[entry] / k for m, v in paper.table2["ROFT w/o segm. sync."].items()}
    return {"roft_reference": reference, "roft_reference_no_mask_sync": stale}


def test_per_object_motion_reads_paper_over_sim_velocity_errors_next_to_the_add_gap():
    from scipy.stats import spearmanr

    from roft_sim.harness.paper import per_object_motion

    paper = paper_tables()
    objects = paper.objects
    scale_v = dict(zip(objects, [0.5, 0.8, 1.5, 1.2, 2.5, 2.0], strict=True))
    add_gap = dict(zip(objects, [-1.0, 0.5, 9.0, 6.0, 7.0, 9.5], strict=True))
    results = _per_object_results(paper, scale_v, add_gap)
    motion = per_object_motion(results, paper, [*objects, ALL])
    assert motion is not None and motion.configuration == "roft_reference"
    by_entry = {r["entry"]: r for r in motion.rows}
    for o in objects:
        assert by_entry[o]["add_gap"] == pytest.approx(add_gap[o])
        for column in ("roft", "stale_masks"):
            for metric in ("rmse_v_cmps", "rmse_w_dps"):
                assert by_entry[o][f"{column}:{metric}"] == pytest.approx(scale_v[o])
    assert by_entry[ALL]["stale_masks:rmse_v_cmps"] == pytest.approx(2.0)
    expected = spearmanr([add_gap[o] for o in objects], [scale_v[o] for o in objects]).statistic
    assert motion.rank_correlation == pytest.approx(expected)
    assert motion.rank_correlation == pytest.approx(1 - 6 * (1 + 4 + 1) / (6 * 35))  # sum d^2 = 6
    # the gap falling as the motion ratio rises: a negative correlation
    reversed_gap = {o: -g for o, g in add_gap.items()}
    reversed_motion = per_object_motion(
        _per_object_results(paper, scale_v, reversed_gap), paper, [*objects, ALL]
    )
    assert reversed_motion is not None and reversed_motion.rank_correlation == pytest.approx(
        -expected
    )


def test_per_object_motion_needs_both_rows_and_three_objects(tmp_path):
    from roft_sim.harness.paper import per_object_motion, write_paper_tables

    paper = paper_tables()
    objects = paper.objects
    results = _per_object_results(paper, dict.fromkeys(objects, 1.0), {})
    assert per_object_motion(results, paper, [*objects, ALL], configuration="roft") is None
    constant = per_object_motion(results, paper, [*objects, ALL])  # every ratio 1: undefined
    assert constant is not None and constant.rank_correlation is None
    without_stale = {"roft_reference": results["roft_reference"]}
    assert per_object_motion(without_stale, paper, [*objects, ALL]) is None
    two = {k: {e: v[e] for e in (*objects[:2], ALL)} for k, v in results.items()}
    motion = per_object_motion(two, paper, [*objects[:2], ALL])
    assert motion is not None and motion.rank_correlation is None
    # tables.md and the CSV carry the section only when the rows ran
    rows = [r for r in REFERENCE_ROWS if r.key in results]
    write_paper_tables(tmp_path, rows, results)
    assert (
        "## Per object: does the difference follow the motion?"
        in (tmp_path / "tables.md").read_text()
    )
    csv = (tmp_path / "per_object_motion_roft_reference.csv").read_text().splitlines()
    assert csv[0].split(",")[:2] == ["entry", "add_gap"] and len(csv) == len(objects) + 2
    write_paper_tables(tmp_path / "none", rows[:1], without_stale)
    assert "does the difference follow" not in (tmp_path / "none" / "tables.md").read_text()


def test_docs_paper_md_names_every_option():
    """docs/paper.md's option table names every option of ``roft-sim paper``."""
    import argparse
    from pathlib import Path

    from roft_sim.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    text = (Path(__file__).resolve().parents[2] / "docs" / "paper.md").read_text()
    options = [s for a in sub.choices["paper"]._actions for s in a.option_strings]
    assert "--motion" in options
    for option in options:
        if option not in ("-h", "--help"):
            assert f"`{option}" in text, option
