"""Fault presets and fault files: loading, strictness, errors that name the key and the fix."""

from __future__ import annotations

from pathlib import Path

import pytest

from roft_sim.errors import ConfigError
from roft_sim.faults import (
    BusyNetwork,
    FaultConfig,
    FixedDelay,
    LogNormalDelay,
    Rate,
    fault_presets_dir,
    list_fault_presets,
    load_faults,
    schedule_detections,
)
from roft_sim.shipped_files import scenarios_dir

EXPECTED_PRESETS = {
    "none",
    "paper",
    "paper-reference",
    "jitter",
    "bursts",
    "outliers-10pct",
    "reorder",
    "camera-drops",
    "mask-corruption",
    "blackout",
    "chaos",
}


def test_every_preset_loads_describes_itself_and_schedules():
    presets = dict(list_fault_presets())
    assert set(presets) >= EXPECTED_PRESETS
    for name, description in presets.items():
        assert description and "\n" not in description
        faults = load_faults(name)
        assert faults.name == name and faults.description == description
        schedule_detections(300, faults, 0)  # valid at 30 fps
        assert faults.describe_lines()


def test_paper_preset_content():
    paper = load_faults("paper")
    for stream in (paper.pose, paper.mask):
        assert stream.first_result == "undelayed"
        assert stream.faults == (Rate(rate_hz=5), FixedDelay(frames=6))
    assert paper.camera.faults == () and paper.flow.faults == ()
    assert load_faults("none") == FaultConfig(
        name="none", description=load_faults("none").description
    )


def test_nested_processing_model_loads():
    jitter = load_faults("jitter")
    busy = jitter.pose.faults[0]
    assert isinstance(busy, BusyNetwork) and isinstance(busy.processing, LogNormalDelay)


def test_load_by_path_names_the_config_after_the_file(tmp_path):
    f = tmp_path / "my-faults.toml"
    f.write_text('[pose]\nfaults = [{ kind = "delay", frames = 3 }]\n')
    faults = load_faults(f)
    assert faults.name == "my-faults" and faults.pose.faults == (FixedDelay(frames=3),)
    assert load_faults(str(f)) == faults
    assert load_faults(fault_presets_dir() / "paper.toml") == load_faults("paper")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ('[pose]\nfaults = [{ kind = "delya", frames = 3 }]', r"did you mean 'delay'"),
        (
            '[pose]\nfaults = [{ kind = "delay", frame = 3 }]',
            r"bad\.toml: pose\.faults\[0\]: unknown key 'frame' for FixedDelay; did you mean "
            r"'frames'",
        ),
        ('[pose]\nfaults = [{ kind = "delay", frames = -2 }]', r"pose\.faults\[0\].*>= 0"),
        ('[pose]\nfaults = [{ kind = "delay", frames = 2.5 }]', "expected an integer"),
        ('[pose]\nfaults = [{ kind = "rate" }]', "exactly one of period_frames or rate_hz"),
        (
            '[pose]\nfaults = [{ kind = "rate", rate_hz = 5 }, { kind = "rate", rate_hz = 10 }]',
            r"at most one sampling fault .*faults\[0\] \(rate\), faults\[1\] \(rate\); keep one",
        ),
        ('[pose]\nfaults = [{ kind = "dropout", p = 1.5 }]', r"p must be a probability"),
        ('[pose]\nfirst_result = "early"', r"expected one of 'delayed', 'undelayed'"),
        ("[poses]\nfaults = []", r"unknown key 'poses' for FaultConfig; did you mean 'pose'"),
        (
            '[camera]\nfaults = [{ kind = "mask_shift" }]',
            r"camera\.faults\[0\]: kind = 'mask_shift' is not known",
        ),
        (
            '[pose]\nfaults = [{ kind = "blackout", windows = [[5, 3]] }]',
            r"windows\[0\] = \[5, 3\] is not a frame window",
        ),
        (
            '[pose]\nfaults = [{ kind = "blackout", windows = [[1, 3]], mode = "hold" }]',
            'needs on = "arrival"',
        ),
        (
            '[camera]\nfaults = [{ kind = "blackout", windows = [[1, 3]], on = "arrival", '
            'mode = "hold" }]',
            "a camera frame cannot be held back",
        ),
        (
            '[pose]\nfaults = [{ kind = "burst_dropout", p_bad_to_good = 0.0 }]',
            "a burst never ends",
        ),
        (
            '[pose]\nfaults = [{ kind = "busy", processing = { kind = "rate", rate_hz = 5 } }]',
            r"processing: kind = 'rate' is not known",
        ),
        ("seed = -1", "seed must be >= 0"),
        ("pose = 3", "expected a table of PoseStreamFaults settings"),
    ],
)
def test_bad_fault_files_name_the_key_and_the_fix(tmp_path, text, match):
    f = tmp_path / "bad.toml"
    f.write_text(text + "\n")
    with pytest.raises(ConfigError, match=match):
        load_faults(f)


def test_rate_that_does_not_divide_the_camera_rate(tmp_path):
    f = tmp_path / "seven.toml"
    f.write_text('[mask]\nfaults = [{ kind = "rate", rate_hz = 7 }]\n')
    faults = load_faults(f)  # valid on its own: the camera rate is known only later
    with pytest.raises(
        ConfigError,
        match=r"'seven' mask\.faults\[0\]: rate_hz = 7 does not divide the camera rate 30 fps; "
        r"use one of \[1, 2, 3, 5, 6, 10, 15, 30\] or give period_frames",
    ):
        schedule_detections(10, faults, 0, fps=30)
    schedule_detections(10, faults, 0, fps=14)


def test_unknown_preset_and_missing_file():
    with pytest.raises(ConfigError, match=r"unknown fault preset 'papr'; did you mean 'paper'"):
        load_faults("papr")
    with pytest.raises(ConfigError, match="does not exist"):
        load_faults("no/such/file.toml")


def test_presets_live_in_scenarios_faults():
    # scenarios/faults in the repository, installed as the package data roft_sim.scenarios
    assert fault_presets_dir() == scenarios_dir() / "faults"
    repo_view = Path(__file__).resolve().parents[2] / "scenarios" / "faults"
    assert repo_view.resolve() == fault_presets_dir()
