"""`roft-sim run` end to end, and its error paths."""

from __future__ import annotations

import json

import pytest
from harness_cases import write_box_dataset

from roft_sim.cli import main
from roft_sim.datasets import open_sequence
from roft_sim.metrics.interval_velocity import interval_velocity_errors


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_box_dataset(tmp_path_factory.mktemp("data"))


def test_run_prints_a_table_and_writes_results(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(
        ["run", str(dataset), "--tracker", "detector-hold", "--flow", "none", "--out", str(out)]
    )
    assert code == 0
    lines = capsys.readouterr().out.splitlines()
    policy = next(i for i, line in enumerate(lines) if line.startswith("invalid estimates"))
    table, interval = lines[:policy], lines[policy + 1 :]
    assert table[0].split()[:3] == ["sequence", "ADD-AUC", "%"]
    assert [line.split()[0] for line in table[2:]] == ["box_a", "box_b", "ALL", "MEAN"]
    # the paper faults (the default) score with the reference's policy, and the table says so
    assert lines[policy].startswith("invalid estimates: hold (frames before the first tracker")
    # then what the exact interval motion gives as the velocity, per sequence
    assert interval[0].startswith("velocity from the exact interval motion")
    assert interval[1].split()[:3] == ["sequence", "e_v", "held"]
    for line, name in zip(interval[3:], ("box_a", "box_b"), strict=True):
        truth = open_sequence(dataset / name).ground_truth()
        held_w = interval_velocity_errors(truth).held_w_dps
        assert line.split()[0] == name and float(line.split()[4]) == pytest.approx(held_w, abs=0.01)
    assert (out / "box_a" / "pose_estimate.txt").is_file()
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) == {"ALL", "MEAN", "box_a", "box_b"}
    assert json.loads((out / "run.json").read_text())["options"]["invalid"] == "hold"


def test_run_json_and_single_sequence(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    args = ["run", str(dataset / "box_b"), "--tracker", "pose-only-ukf", "--faults", "bursts"]
    code = main([*args, "--seed", "4", "--out", str(out), "--json"])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["out"] == str(out)
    assert summary["invalid"] == "failure"  # auto: our policy outside the paper faults
    assert list(summary["metrics"]) == ["ALL", "MEAN", "box_b"]
    truth = open_sequence(dataset / "box_b").ground_truth()
    assert summary["interval_velocity"] == {"box_b": interval_velocity_errors(truth).summary()}
    run = json.loads((out / "run.json").read_text())
    assert run["options"]["seed"] == 4 and run["options"]["faults"]["name"] == "bursts"
    assert "--seed=4" in run["command"]


def test_tracker_config_file(dataset, tmp_path):
    config = tmp_path / "hold.toml"
    config.write_text('velocity = "zero"\n')
    out = tmp_path / "out"
    args = ["run", str(dataset), "--tracker", "detector-hold", "--tracker-config", str(config)]
    assert main([*args, "--flow", "none", "--out", str(out)]) == 0
    run = json.loads((out / "run.json").read_text())
    assert run["options"]["tracker_config"] == {"velocity": "zero"}


def test_bad_dataset_path_is_a_usage_error(tmp_path, capsys):
    code = main(
        ["run", str(tmp_path / "nothing"), "--tracker", "roft", "--out", str(tmp_path / "o")]
    )
    assert code == 2
    assert "does not exist" in capsys.readouterr().err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["run", str(empty), "--tracker", "roft", "--out", str(tmp_path / "o")]) == 2
    assert "no sequence found" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_unknown_tracker_lists_the_known_ones(dataset, tmp_path, capsys):
    code = main(["run", str(dataset), "--tracker", "roftt", "--out", str(tmp_path / "o")])
    assert code == 2
    err = capsys.readouterr().err
    assert "no tracker named 'roftt'" in err
    for name in ("detector-hold", "detector-ideal", "naive-delay", "pose-only-ukf", "roft"):
        assert name in err


def test_non_empty_out_needs_overwrite(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    args = ["run", str(dataset), "--tracker", "detector-hold", "--flow", "none", "--out", str(out)]
    assert main(args) == 2
    assert "is not empty; pass --overwrite" in capsys.readouterr().err
    assert (out / "keep.txt").exists()
    assert main([*args, "--overwrite"]) == 0
    assert not (out / "keep.txt").exists()


def test_out_dot_overwrite_is_refused_not_obeyed(dataset, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "precious.txt").write_text("x")
    args = ["run", str(dataset), "--tracker", "detector-hold", "--flow", "none", "--out", "."]
    assert main([*args, "--overwrite"]) == 2
    assert "--overwrite would empty" in capsys.readouterr().err
    assert (tmp_path / "precious.txt").exists()


def test_bad_inputs_are_usage_errors_before_writing(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    base = ["run", str(dataset), "--tracker", "detector-hold", "--out", str(out)]
    assert main([*base, "--poses", "posecnn"]) == 2
    assert "no pose set 'posecnn'" in capsys.readouterr().err
    assert main([*base, "--flow", "raft"]) == 2
    assert "unknown flow source 'raft'" in capsys.readouterr().err
    assert main([*base, "--faults", "papper"]) == 2
    assert "did you mean 'paper'" in capsys.readouterr().err
    assert not out.exists()


def test_repeated_sequences_and_missing_stored_flow_are_usage_errors_before_writing(
    dataset, tmp_path, capsys
):
    out = tmp_path / "out"
    base = ["run", str(dataset), "--tracker", "detector-hold", "--out", str(out)]
    twice = ["run", str(dataset), str(dataset / "box_a"), *base[2:]]
    assert main(twice) == 2
    assert "sequence names must be unique" in capsys.readouterr().err
    assert main([*base, "--flow", "stored:nvof_1_slow"]) == 2
    assert "no stored flow set 'nvof_1_slow'" in capsys.readouterr().err
    assert main([*base, "--flow", "nvof-like:stored:nvof_1_slow"]) == 2
    assert "no stored flow set 'nvof_1_slow'" in capsys.readouterr().err
    assert not out.exists()
    # --overwrite must not empty the folder of an earlier run before such an error
    out.mkdir()
    (out / "keep.txt").write_text("earlier results")
    assert main([*twice, "--overwrite"]) == 2
    assert (out / "keep.txt").exists()
