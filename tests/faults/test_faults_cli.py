"""``roft-sim faults list`` and ``roft-sim faults show``."""

from __future__ import annotations

import json
import re

from roft_sim.cli import main
from roft_sim.faults import list_fault_presets


def test_list_prints_every_preset_with_its_description(capsys):
    assert main(["faults", "list"]) == 0
    out = capsys.readouterr().out.splitlines()
    presets = list_fault_presets()
    assert len(out) == len(presets)
    for line, (name, description) in zip(out, presets, strict=True):
        assert line.split()[0] == name and line.endswith(description)


def test_show_paper_prints_capture_to_arrival(capsys):
    assert main(["faults", "show", "paper", "--frames", "60"]) == 0
    out = capsys.readouterr().out
    assert "fault preset 'paper'" in out and "pose.faults[1]: delay 6 frames" in out
    assert "60 camera frames at 30 fps" in out
    rows = dict(re.findall(r"^(pose run|pose arrive|mask run|camera) +(\S+)$", out, re.M))
    assert rows["pose run"] == "C....." * 9 + ">....."
    assert rows["pose arrive"] == "1..........." + "1....." * 8
    assert rows["camera"] == "." * 60
    # one line per network run: id, capture, reported, arrival(s), delay
    runs = re.findall(r"^ +(\d+) +(\d+) +(\d+)  (\S+) +(\S+)", out, re.M)
    pose_runs = runs[:10]
    assert pose_runs[0] == ("0", "0", "0", "0", "+0")
    assert pose_runs[1] == ("1", "6", "6", "12", "+6")
    assert pose_runs[9][3] == "-" and "arrives after the end" in out


def test_show_marks_outliers_drops_and_duplicates(capsys):
    assert main(["faults", "show", "chaos", "--frames", "120", "--seed", "3"]) == 0
    out = capsys.readouterr().out
    for mark in ("OUTLIER", "DROPPED by", "DUPLICATED", "dropped camera frames:"):
        assert mark in out, mark


def test_show_file_json_ideal_and_width(capsys, tmp_path):
    f = tmp_path / "d3.toml"
    f.write_text('description = "three late"\n[pose]\nfaults = [{ kind = "delay", frames = 3 }]\n')
    assert main(["faults", "show", str(f), "--frames", "8", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["faults"]["name"] == "d3"
    assert [e["arrival_k"] for e in data["schedule"]["pose"]] == [3, 4, 5, 6, 7]
    assert main(["faults", "show", "paper", "--frames", "12", "--ideal"]) == 0
    out = capsys.readouterr().out
    assert "detector ideal" in out and re.search(r"^pose arrive +1{12}$", out, re.M)
    assert main(["faults", "show", "none", "--frames", "25", "--width", "10"]) == 0
    out = capsys.readouterr().out
    assert len(re.findall(r"^camera +\.+$", out, re.M)) == 3  # 10 + 10 + 5 frames


def test_show_errors_exit_with_usage_code(capsys, tmp_path):
    assert main(["faults", "show", "papr"]) == 2
    assert "did you mean 'paper'" in capsys.readouterr().err
    assert main(["faults", "show", "paper", "--frames", "0"]) == 2
    assert "--frames must be in 1..100000" in capsys.readouterr().err
    assert main(["faults", "show", "paper", "--frames", "100000001"]) == 2  # used to hang
    assert "--frames must be in 1..100000" in capsys.readouterr().err
    assert main(["faults", "show", "paper", "--width", "5"]) == 2  # used to become 10 silently
    assert "--width must be >= 10" in capsys.readouterr().err
    assert main(["faults", "show", "paper", "--fps", "24"]) == 2
    assert "does not divide the camera rate 24" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text('[pose]\nfaults = [{ kind = "delay", frames = "six" }]\n')
    assert main(["faults", "show", str(bad)]) == 2
    assert "bad.toml: pose.faults[0].frames: expected an integer" in capsys.readouterr().err
    assert main(["faults"]) == 2
