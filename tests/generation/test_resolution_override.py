"""--resolution keeps the field of view; a changed aspect ratio is allowed but warned about."""

from __future__ import annotations

import logging

import pytest

from roft_sim.generation.jobs import ScenarioOverrides
from roft_sim.generation.presets import preset_scenario_paths
from roft_sim.scenario import load_scenario


@pytest.fixture(scope="module")
def fast_ycb_scenario():
    return load_scenario(preset_scenario_paths("fast-ycb")[0])


def test_same_aspect_ratio_keeps_square_pixels_quietly(fast_ycb_scenario, caplog):
    with caplog.at_level(logging.WARNING, logger="roft_sim.generation"):
        k = ScenarioOverrides(resolution=(640, 360)).apply(fast_ycb_scenario).intrinsics
    assert k.fx_px == pytest.approx(k.fy_px) == pytest.approx(1229.4285612615463 / 2)
    assert not caplog.records


def test_another_aspect_ratio_warns_and_names_the_square_alternative(fast_ycb_scenario, caplog):
    with caplog.at_level(logging.WARNING, logger="roft_sim.generation"):
        k = ScenarioOverrides(resolution=(640, 480)).apply(fast_ycb_scenario).intrinsics
    assert k.fy_px == pytest.approx(k.fx_px * 4 / 3)  # the field of view is kept
    assert len(caplog.records) == 1
    assert "pixels are no longer square" in caplog.text and "use 640x360" in caplog.text


def test_a_width_the_4px_flow_grid_does_not_divide_is_warned_about(fast_ycb_scenario, caplog):
    """Review regression: the reference ROFT reads the grid as image_width // flow_cols, so a
    98-px-wide nvof-like set (25 columns) would be read with a 3-px grid."""
    from roft_sim.generation.jobs import _warn_about_grid_width

    with caplog.at_level(logging.WARNING, logger="roft_sim.generation"):
        _warn_about_grid_width(ScenarioOverrides(resolution=(640, 360)).apply(fast_ycb_scenario))
        assert not caplog.records
        _warn_about_grid_width(ScenarioOverrides(resolution=(98, 55)).apply(fast_ycb_scenario))
    assert sum("grid columns" in r.getMessage() for r in caplog.records) == 1
    assert "['nvof_1_slow'] have 25 grid columns" in caplog.text
    assert "98 // 25 = 3 px instead of 4" in caplog.text and "(e.g. 96)" in caplog.text
