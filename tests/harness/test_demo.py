"""``roft-sim demo``: the main job generates, tracks and compares; errors come before rendering."""

from __future__ import annotations

import json

import pytest

from roft_sim.cli import main


@pytest.mark.render
def test_demo_generates_a_sequence_tracks_it_and_prints_the_comparison(tmp_path, capsys):
    out = tmp_path / "demo"
    argv = ["demo", "--out", str(out), "--frames", "18", "--resolution", "160x90",
            "--trackers", "roft,detector-hold", "--no-progress"]  # fmt: skip
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "paper faults (pose and mask networks at 5 fps, results 6 frames late)" in printed
    assert "roft " in printed and "detector-hold " in printed and "ADD-AUC %" in printed
    assert "invalid estimates: hold (" in printed  # the table names the policy (paper faults)
    sequence = out / "dataset" / "003_cracker_box"
    assert len(list((sequence / "rgb").glob("*.png"))) == 18
    assert (sequence / "dope" / "poses.txt").is_file()
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["metrics"]) == {"roft", "detector-hold"}
    for name in ("roft", "detector-hold"):
        run = out / "runs" / name
        metrics = json.loads((run / "metrics.json").read_text())
        assert metrics["003_cracker_box"]["frames"] == 18
        assert summary["metrics"][name]["add_auc_pct"] == metrics["003_cracker_box"]["add_auc_pct"]
        assert len((run / "003_cracker_box" / "pose_estimate.txt").read_text().splitlines()) == 18
        assert json.loads((run / "run.json").read_text())["options"]["invalid"] == "hold"
    # a second run into the same folder needs --overwrite, and the message does not offer --resume
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "--overwrite" in err and "--resume" not in err


def test_demo_refuses_bad_arguments_before_rendering(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--trackers", "roft,nope"]) == 2
    assert "no tracker named 'nope'" in capsys.readouterr().err
    assert main(["demo", "--out", str(out), "--frames", "12"]) == 2  # one delivery only
    assert "at least 13 (two pose deliveries" in capsys.readouterr().err
    assert main(["demo", "--out", str(out), "--resolution", "big"]) == 2
    assert "WIDTHxHEIGHT" in capsys.readouterr().err
    assert main(["demo", "--out", str(out), "--faults", "papr"]) == 2
    assert "did you mean 'paper'" in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.render
def test_demo_checks_the_trajectory_length_before_touching_the_output(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--out", str(out), "--frames", "100000", "--no-progress"]) == 2
    assert "use at most --frames" in capsys.readouterr().err
    assert not out.exists()  # used to be created, empty
    out.mkdir()
    (out / "keep.txt").write_text("earlier results")
    argv = ["demo", "--out", str(out), "--frames", "100000", "--overwrite", "--no-progress"]
    assert main(argv) == 2
    assert (out / "keep.txt").read_text() == "earlier results"  # --overwrite emptied it first
