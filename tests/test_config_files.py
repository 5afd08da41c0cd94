"""Strict TOML -> dataclass loading: unknown keys, types, nested tables, tagged unions."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest

from roft_sim.config_files import dataclass_from_mapping, jsonable, load_dataclass_toml
from roft_sim.errors import ConfigError


@dataclass(frozen=True, slots=True, kw_only=True)
class Inner:
    rate_hz: int = 30
    scale: float = 1.0

    def __post_init__(self) -> None:
        if self.rate_hz <= 0:
            raise ConfigError(f"rate_hz must be positive, got {self.rate_hz}")


@dataclass(frozen=True, slots=True, kw_only=True)
class Delay:
    kind: Literal["delay"] = "delay"
    frames: int = 0


@dataclass(frozen=True, slots=True, kw_only=True)
class Drop:
    kind: Literal["drop"] = "drop"
    p: float = 0.1


@dataclass(frozen=True, slots=True, kw_only=True)
class Outer:
    name: str
    inner: Inner = field(default_factory=Inner)
    mode: Literal["a", "b"] = "a"
    size: tuple[int, int] = (1, 2)
    path: Path | None = None
    faults: tuple[Delay | Drop, ...] = ()


def test_builds_nested_and_coerces_int_to_float():
    cfg = dataclass_from_mapping(
        Outer,
        {
            "name": "x",
            "inner": {"scale": 2},
            "size": [3, 4],
            "path": "a/b",
            "faults": [{"kind": "drop", "p": 0.5}],
        },
    )
    assert cfg.inner == Inner(scale=2.0) and cfg.size == (3, 4) and cfg.path == Path("a/b")
    assert cfg.faults == (Drop(p=0.5),)


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"name": "x", "inne": {}}, r"unknown key 'inne' for Outer; did you mean 'inner'"),
        ({}, "missing required key 'name'"),
        ({"name": 3}, r"config\.name: expected a string"),
        ({"name": "x", "mode": "c"}, r"expected one of 'a', 'b'"),
        ({"name": "x", "inner": {"rate_hz": 0}}, r"config\.inner: rate_hz must be positive"),
        ({"name": "x", "inner": {"rate_hz": 2.5}}, "expected an integer"),
        ({"name": "x", "size": [1]}, "expected 2 values"),
        ({"name": "x", "faults": [{"kind": "delya"}]}, r"did you mean 'delay'"),
        (
            {"name": "x", "faults": [{"frames": 2}]},
            r"config\.faults\[0\]: missing key 'kind'; add kind = one of 'delay', 'drop'",
        ),
        (
            {"name": "x", "faults": [{"kind": "delay", "frames": "2"}]},
            r"config\.faults\[0\]\.frames: expected an integer",
        ),
        ({"name": "x", "inner": {"rate_hz": True}}, "expected an integer"),
    ],
)
def test_errors_name_the_key_and_the_fix(data, match):
    with pytest.raises(ConfigError, match=match):
        dataclass_from_mapping(Outer, data)


def test_load_from_toml_file_with_table(tmp_path):
    f = tmp_path / "c.toml"
    f.write_text('[outer]\nname = "n"\n[outer.inner]\nrate_hz = 5\n')
    assert load_dataclass_toml(Outer, f, table="outer").inner.rate_hz == 5
    with pytest.raises(ConfigError, match=r"has no \[other\] table"):
        load_dataclass_toml(Outer, f, table="other")
    bad = tmp_path / "bad.toml"
    bad.write_text("name = \n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_dataclass_toml(Outer, bad)
    with pytest.raises(ConfigError, match="does not exist"):
        load_dataclass_toml(Outer, tmp_path / "missing.toml")


def test_jsonable_roundtrip_of_config():
    cfg = dataclass_from_mapping(Outer, {"name": "x", "path": "p", "faults": [{"kind": "delay"}]})
    data = jsonable(cfg)
    assert data["path"] == "p" and data["size"] == [1, 2]
    assert dataclass_from_mapping(Outer, data) == cfg


@dataclass(frozen=True, slots=True, kw_only=True)
class WithOptionalTuple:
    window_s: tuple[float, float] | None = None


def test_an_optional_value_of_the_wrong_shape_says_what_was_expected():
    """An optional key keeps the specific message of its type (review regression): not just
    "matches none of tuple | NoneType"."""
    with pytest.raises(ConfigError, match=r"config\.window_s: expected 2 values, got 1"):
        dataclass_from_mapping(WithOptionalTuple, {"window_s": [1.0]})


@dataclass(frozen=True, slots=True, kw_only=True)
class _Gate:
    enable: bool = False
    probability: float = 0.999
    prior_m: float = 0.05


@dataclass(frozen=True, slots=True, kw_only=True)
class _Tracker:
    gate: _Gate = field(default_factory=lambda: _Gate(enable=True, prior_m=0.1))
    name: str = "t"


@dataclass(frozen=True, slots=True, kw_only=True)
class _Outer:
    tracker: _Tracker = field(default_factory=lambda: _Tracker(gate=_Gate(prior_m=0.2)))


def test_a_partial_nested_table_overrides_single_keys_of_the_enclosing_default():
    """``[gate] probability = 0.99`` keeps what the enclosing class's default gate holds
    (enable = true), not the nested class's own defaults; at any depth."""
    built = dataclass_from_mapping(_Tracker, {"gate": {"probability": 0.99}})
    assert built.gate == _Gate(enable=True, probability=0.99, prior_m=0.1)
    outer = dataclass_from_mapping(_Outer, {"tracker": {"gate": {"enable": True}}})
    assert outer.tracker.gate == _Gate(enable=True, probability=0.999, prior_m=0.2)
    assert dataclass_from_mapping(_Tracker, {}).gate == _Tracker().gate


def test_a_partial_table_of_roft_keeps_the_default_gate_and_of_the_reference_its_values():
    from roft_sim.trackers import get_tracker_spec, load_tracker_config
    from roft_sim.trackers.roft import RoftConfig
    from roft_sim.trackers.roft.reference import reference_config

    roft = load_tracker_config(get_tracker_spec("roft"), {"gate": {"probability": 0.99}})
    assert roft.gate.enable and roft.gate.adaptive and roft.gate.probability == 0.99
    assert roft.mask == RoftConfig().mask
    ref = load_tracker_config(get_tracker_spec("roft-reference"), {"mask": {"rounding": "nearest"}})
    expected = reference_config().mask
    assert ref.mask.cleanup == expected.cleanup and ref.mask.subpixel == expected.subpixel
    assert ref.mask.rounding == "nearest"


@dataclass(frozen=True, slots=True, kw_only=True)
class WithOptionals:
    band_m: float | None = 0.15
    label: str | None = "x"
    where: Path | None = None
    mode: Literal["a", "b"] | None = "a"
    named: Literal["a", "none"] | None = "a"


def test_the_string_none_sets_an_optional_value_to_none_where_it_is_not_a_value_itself():
    """TOML has no null: ``"none"`` switches an optional setting off (ROFT's
    ``velocity.depth_band_m``, ``occluder_depth_jump_m``), but stays a string, a path or a
    literal where the field can hold it."""
    cfg = dataclass_from_mapping(
        WithOptionals,
        {"band_m": "none", "label": "none", "where": "none", "mode": "none", "named": "none"},
    )
    assert cfg.band_m is None and cfg.mode is None
    assert cfg.label == "none" and cfg.where == Path("none") and cfg.named == "none"
    with pytest.raises(ConfigError, match="band_m"):
        dataclass_from_mapping(WithOptionals, {"band_m": "off"})


def test_a_roft_deviation_can_be_switched_off_from_a_tracker_toml(tmp_path):
    from roft_sim.trackers import get_tracker_spec, load_tracker_config

    path = tmp_path / "roft.toml"
    path.write_text('[velocity]\noccluder_depth_jump_m = "none"\ndepth_band_m = "none"\n')
    cfg = load_tracker_config(get_tracker_spec("roft"), path)
    assert cfg.velocity.occluder_depth_jump_m is None and cfg.velocity.depth_band_m is None
    assert cfg.velocity.mask_erosion_m == 0.005  # the rest keeps the default
