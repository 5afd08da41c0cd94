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
