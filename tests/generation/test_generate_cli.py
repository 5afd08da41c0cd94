"""``roft-sim generate``: help and argument errors (exit 2, clear messages, nothing written)."""

from __future__ import annotations

import argparse
import re
import shutil
from pathlib import Path

import pytest

from roft_sim.assets.registry import FAST_YCB_OBJECTS
from roft_sim.cli import build_parser, main
from roft_sim.generation import shipped_scenarios_dir


def _generate_parser() -> argparse.ArgumentParser:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["generate"]


def test_help_documents_every_option(capsys):
    assert main(["generate", "--help"]) == 0
    text = capsys.readouterr().out
    options = [s for a in _generate_parser()._actions for s in a.option_strings]
    assert len(options) >= 14
    for option in options:
        assert option in text, option
    for action in _generate_parser()._actions:
        assert action.help, f"{action.option_strings or action.dest} has no help"
    for word in ("fast-ycb", "bop", "hdf5", "--resume", "exit codes", "byte-identical"):
        assert word in text


def _ci(name="cracker_box"):
    return str(shipped_scenarios_dir() / "ci" / f"{name}.toml")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["missing.toml"], "scenario file 'missing.toml' does not exist"),
        ([_ci(), "--format", "png"], "unknown --format 'png'; expected one of fast-ycb, bop, hdf5"),
        ([], "no scenario given"),
        ([_ci(), "--preset", "fast-ycb"], "scenario files or --preset, not both"),
        (["--preset", "fast_ycb"], "unknown preset 'fast_ycb'"),
        ([_ci(), "--resolution", "640by480"], "WIDTHxHEIGHT"),
        ([_ci(), "--frames", "0"], "--frames must be >= 1"),
        ([_ci(), "--workers", "0"], "--workers must be >= 1"),
        ([_ci(), "--assets", "/nonexistent/ycb"], "--assets '/nonexistent/ycb' is not a folder"),
        ([_ci(), "--frames", "1000"], r"needs 1000 frames .* use at most --frames 76"),
        ([_ci(), "--overwrite", "--resume"], "contradict each other"),
    ],
)
def test_bad_arguments_exit_2_with_a_clear_message(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    code = main(["generate", *args, "--out", str(out), "--no-progress"])
    assert code == 2
    err = capsys.readouterr().err
    assert "roft-sim generate: error:" in err
    assert re.search(message, err), err
    assert not out.exists() or not any(out.iterdir())


def test_an_invalid_scenario_file_names_the_file_and_key(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    text = (shipped_scenarios_dir() / "ci" / "cracker_box.toml").read_text()
    bad.write_text(text + "\n[networks]\nflows = 1\n")
    assert main(["generate", str(bad), "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "bad.toml" in err and "unknown key 'flows'" in err


def test_overwrite_keeps_the_output_when_a_later_check_fails(tmp_path, capsys):
    """--overwrite empties the output only after every scenario passed its checks."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    args = ["generate", _ci(), "--out", str(out), "--frames", "1000", "--overwrite"]
    assert main(args) == 2
    assert (out / "keep.txt").exists()
    shutil.rmtree(out)
    capsys.readouterr()


def test_docs_describe_every_option_and_every_networks_key():
    """docs/generate.md names every CLI option and every key of the [networks] table."""
    import dataclasses

    from roft_sim.sensors.flow_sources import FlowNoiseConfig
    from roft_sim.sensors.networks import (
        FlowSetConfig,
        MaskSetConfig,
        NetworksConfig,
        PoseSetConfig,
    )
    from roft_sim.sensors.pose_estimator import PoseEstimatorConfig
    from roft_sim.sensors.segmenter import SegmenterConfig

    text = (Path(__file__).resolve().parents[2] / "docs" / "generate.md").read_text()
    for action in _generate_parser()._actions:
        for option in action.option_strings:
            if option not in ("-h", "--help"):
                assert f"`{option}" in text, option
    for cls in (
        NetworksConfig,
        PoseSetConfig,
        MaskSetConfig,
        FlowSetConfig,
        PoseEstimatorConfig,
        SegmenterConfig,
        FlowNoiseConfig,
    ):
        for f in dataclasses.fields(cls):
            # as `key`, [networks.key], `key = ...`, or a `key` in a list of keys
            assert re.search(rf"[`.\[]{f.name}[`\]\s=,]", text), (cls.__name__, f.name)


@pytest.mark.slow
@pytest.mark.render
def test_fast_ycb_preset_writes_six_object_folders_that_pass_the_checker(tmp_path, capsys):
    from roft_sim.datasets import check_fast_ycb_sequence, open_sequence

    out = tmp_path / "fast_ycb"
    args = ["generate", "--preset", "fast-ycb", "--out", str(out), "--frames", "12",
            "--resolution", "160x90", "--no-progress"]  # fmt: skip
    assert main(args) == 0
    names = sorted(p.name for p in out.iterdir())
    assert names == list(FAST_YCB_OBJECTS)
    for name in names:
        assert check_fast_ycb_sequence(out / name) == [], name
        seq = open_sequence(out / name)
        assert seq.object_name == name and len(seq) == 12
        assert seq.intrinsics.shape == (90, 160)
        assert seq.metadata()["generator"]["preset"] == "fast-ycb"
    capsys.readouterr()
