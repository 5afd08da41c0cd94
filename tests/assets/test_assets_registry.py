"""The object registry (manifest.toml): completeness, validation and error messages."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from roft_sim.assets import (
    UnknownObjectError,
    get_object_info,
    list_objects,
    object_registry,
)
from roft_sim.assets.registry import FAST_YCB_OBJECTS, load_manifest
from roft_sim.errors import AssetNotFoundError, ConfigError

FAST_YCB = FAST_YCB_OBJECTS  # checked against the shipped manifest below


def test_registry_holds_the_six_fast_ycb_objects_in_order():
    names = [info.name for info in list_objects()]
    assert names[:6] == list(FAST_YCB)
    assert list(object_registry()) == names


@pytest.mark.parametrize("name", FAST_YCB)
def test_every_entry_is_complete(name):
    info = get_object_info(name)
    dims = np.asarray(info.dimensions_m)
    assert dims.shape == (3,) and (dims > 0.02).all() and (dims < 0.25).all()
    assert info.shape in ("box", "cylinder", "bottle")
    assert len(info.colors_rgb) >= 2
    assert np.isclose(sum(info.color_weights), 1.0, atol=0.01)
    assert info.nvdu_alignment is not None
    T = info.nvdu_alignment.T_nvdu_orig
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(T[:3, :3], np.asarray(info.nvdu_alignment.R), atol=2e-6)
    assert info.model_point_count == 2620


def test_shape_classes_match_the_objects():
    shapes = {name: get_object_info(name).shape for name in FAST_YCB}
    assert shapes == {
        "003_cracker_box": "box",
        "004_sugar_box": "box",
        "005_tomato_soup_can": "cylinder",
        "006_mustard_bottle": "bottle",
        "009_gelatin_box": "box",
        "010_potted_meat_can": "cylinder",
    }
    # a round can: equal extents across its axis (y)
    x, _, z = get_object_info("005_tomato_soup_can").dimensions_m
    assert x == pytest.approx(z, abs=0.5e-3)


def _reference_alignment_table(path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    table = {}
    pattern = re.compile(r"^(\d{3}) R=(\[\[.*\]\])\s+t=(\[.*\])\s*$")
    for line in path.read_text().splitlines():
        m = pattern.match(line.strip())
        if m:
            table[m.group(1)] = (np.array(json.loads(m.group(2))), np.array(json.loads(m.group(3))))
    return table


def test_alignment_equals_the_reference_table(shared_ycb_dir):
    reference = shared_ycb_dir.parent / "reference" / "fast_ycb_format.md"
    if not reference.is_file():
        pytest.skip(f"{reference} is absent")
    table = _reference_alignment_table(reference)
    assert len(table) == 6
    for name in FAST_YCB:
        R, t = table[name[:3]]
        alignment = get_object_info(name).nvdu_alignment
        np.testing.assert_array_equal(np.asarray(alignment.R), R)
        np.testing.assert_array_equal(np.asarray(alignment.t_m), t)


def test_unknown_name_suggests_the_closest(tmp_path):
    with pytest.raises(UnknownObjectError, match=r"did you mean '003_cracker_box'"):
        get_object_info("003_craker_box")
    # usable both as "asset missing" and as a configuration (usage) error
    assert issubclass(UnknownObjectError, AssetNotFoundError)
    assert issubclass(UnknownObjectError, ConfigError)


_GOOD_ENTRY = """
format_version = 1
[[object]]
name = "x_box"
description = "test"
shape = "box"
dimensions_m = [0.1, 0.2, 0.05]
colors_rgb = [[10, 20, 30], [200, 200, 200]]
color_weights = [0.5, 0.5]
"""


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "manifest.toml"
    path.write_text(text)
    return path


def test_a_minimal_manifest_loads(tmp_path):
    (info,) = load_manifest(_write(tmp_path, _GOOD_ENTRY))
    assert info.name == "x_box" and info.nvdu_alignment is None


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (('shape = "box"', 'shape = "box"\ncolour = 3'), r"unknown key 'colour'"),
        (('shape = "box"', 'shape = "sphere"'), r"shape: got 'sphere', expected one of"),
        (("[0.1, 0.2, 0.05]", "[0.1, -0.2, 0.05]"), r"dimensions_m must be three positive"),
        (("[0.5, 0.5]", "[0.5]"), r"one color_weights entry per colour"),
        (("format_version = 1", "format_version = 2"), r"format_version 2 is not supported"),
    ],
)
def test_bad_manifests_name_the_problem(tmp_path, edit, match):
    with pytest.raises(ConfigError, match=match):
        load_manifest(_write(tmp_path, _GOOD_ENTRY.replace(*edit)))


def test_duplicate_names_are_refused(tmp_path):
    text = _GOOD_ENTRY + _GOOD_ENTRY.split("format_version = 1")[1]
    with pytest.raises(ConfigError, match=r"objects listed twice: x_box"):
        load_manifest(_write(tmp_path, text))


def test_a_reflection_is_not_an_alignment(tmp_path):
    text = _GOOD_ENTRY + (
        "[object.nvdu_alignment]\nR = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]\n"
        "t_m = [0.0, 0.0, 0.0]\n"
    )
    with pytest.raises(ConfigError, match=r"reflection"):
        load_manifest(_write(tmp_path, text))


def test_a_bottle_profile_must_agree_with_the_dimensions(tmp_path):
    text = _GOOD_ENTRY.replace('shape = "box"', 'shape = "bottle"') + (
        "profile = [[-0.1, 0.05, 0.025, 2.0], [0.1, 0.05, 0.025, 2.0]]\n"
    )
    load_manifest(_write(tmp_path, text))  # spans (0.1, 0.2, 0.05): consistent
    with pytest.raises(ConfigError, match=r"the profile spans \[0.1, 0.2, 0.06\] m"):
        load_manifest(_write(tmp_path, text.replace("0.025, 2.0]", "0.03, 2.0]")))


def test_missing_manifest_file(tmp_path):
    with pytest.raises(ConfigError, match=r"does not exist"):
        load_manifest(tmp_path / "nope.toml")


def test_an_entry_instead_of_a_name_is_refused_with_what_was_expected():
    from roft_sim.assets import list_objects

    entry = list_objects()[0]
    with pytest.raises(TypeError, match=r"takes an object's name .* got ObjectInfo"):
        get_object_info(entry)  # type: ignore[arg-type]
    assert get_object_info(entry.name) == entry
