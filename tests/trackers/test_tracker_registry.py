"""The registered trackers, ``roft-sim trackers``, and config round trips through TOML."""

from __future__ import annotations

import dataclasses
import json
import tomllib

import pytest

from roft_sim.cli import main
from roft_sim.cli.trackers import toml_from_dataclass
from roft_sim.errors import PluginError
from roft_sim.trackers import (
    ENTRY_POINT_GROUP,
    discover_trackers,
    get_tracker_spec,
    load_tracker_config,
    run_tracker,
)
from roft_sim.trackers.roft import RoftConfig, ablation_config

OURS = {"roft", "detector-hold", "detector-ideal", "naive-delay", "pose-only-ukf"}


def test_all_our_trackers_are_registered_under_the_entry_point_group():
    specs = discover_trackers(ENTRY_POINT_GROUP)
    assert set(specs) >= OURS
    assert specs["roft"].needs_depth_renderer and specs["roft"].config_type is RoftConfig
    assert specs["detector-ideal"].detection_mode == "ideal"
    assert all(specs[name].description for name in OURS)


def test_cli_lists_the_trackers(capsys):
    assert main(["trackers"]) == 0
    out = capsys.readouterr().out
    for name in OURS:
        assert name in out
    assert "[depth renderer]" in out and "[ideal detections]" in out


def test_cli_json(capsys):
    assert main(["trackers", "--json"]) == 0
    rows = {row["name"]: row for row in json.loads(capsys.readouterr().out)}
    assert rows["roft"]["entry_point"] == "roft_sim.trackers.roft:SPEC"
    assert rows["roft"]["config_type"] == "roft_sim.trackers.roft.config.RoftConfig"
    assert rows["detector-ideal"]["detection_mode"] == "ideal"


@pytest.mark.parametrize("name", sorted(OURS))
def test_cli_defaults_are_valid_toml_that_loads_back(capsys, tmp_path, name):
    assert main(["trackers", "--defaults", name]) == 0
    text = capsys.readouterr().out
    tomllib.loads(text)
    path = tmp_path / "cfg.toml"
    path.write_text(text)
    spec = get_tracker_spec(name)
    assert load_tracker_config(spec, path) == spec.config_type()


@pytest.mark.parametrize("ablation", ["no_velocity", "no_pose", "no_mask_sync"])
def test_ablation_configs_round_trip_through_toml(tmp_path, ablation):
    cfg = ablation_config(ablation)
    path = tmp_path / "a.toml"
    path.write_text("[tracker]\n" + toml_from_dataclass(cfg).replace("\n[", "\n[tracker."))
    assert load_tracker_config(get_tracker_spec("roft"), path) == cfg


def test_unknown_tracker_is_a_usage_error_naming_the_installed_ones(capsys):
    assert main(["trackers", "--defaults", "kalman-magic"]) == 2  # as in run, demo and sweep
    err = capsys.readouterr().err
    assert "no tracker named 'kalman-magic'" in err and "detector-hold" in err


def test_run_tracker_checks_what_the_tracker_returns():
    class Broken:
        def reset(self, initial):
            pass

        def step(self, observation):
            return "pose"

    from roft_sim.records import Observation

    obs = [Observation(k=0, t_s=0.0, rgb=None, depth_m=None, flow=None)]
    with pytest.raises(PluginError, match=r"Broken.step\(k=0\) returned 'str'"):
        run_tracker(Broken(), obs)


def test_reference_config_plus_every_deviation_is_the_default():
    """The attribution table's chain ends at the default, and the roft-reference tracker's
    defaults are reference_config()."""
    from roft_sim.trackers.roft import DEVIATIONS, apply_deviations, reference_config

    assert apply_deviations(reference_config()) == RoftConfig()
    assert reference_config() != RoftConfig()
    names = [d.name for d in DEVIATIONS]
    assert len(set(names)) == len(names)
    for i, deviation in enumerate(DEVIATIONS):  # each one changes something
        before = apply_deviations(reference_config(), i)
        assert deviation.apply(before) != before, deviation.name
    spec = get_tracker_spec("roft-reference")
    loaded = load_tracker_config(spec, None)
    assert dataclasses.asdict(loaded) == dataclasses.asdict(reference_config())
