"""Hand occluder geometry: capsules touch the object's faces without entering it."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.errors import ConfigError
from roft_sim.scene.config import HandConfig
from roft_sim.scene.hand import hand_capsules


def _segment_box_distance(a, b, half, samples=200):
    """Smallest distance from points of segment ab to the box |x_i| <= half_i (0 inside)."""
    p = a + np.linspace(0, 1, samples)[:, None] * (b - a)
    outside = np.maximum(np.abs(p) - half, 0.0)
    return np.linalg.norm(outside, axis=1).min()


@pytest.mark.parametrize(
    "palm_side,wrap_axis", [("-x", "z"), ("+y", "x"), ("-z", "y"), ("+x", "y")]
)
def test_capsules_rest_on_the_faces(palm_side, wrap_axis):
    half = np.array([0.04, 0.09, 0.03])
    config = HandConfig(enabled=True, palm_side=palm_side, wrap_axis=wrap_axis)
    capsules = hand_capsules(config, half)
    assert [c.name for c in capsules] == [
        "palm",
        "finger0",
        "finger1",
        "finger2",
        "finger3",
        "thumb",
    ]
    for c in capsules:
        gap = _segment_box_distance(c.start_m, c.end_m, half) - c.radius_m
        assert -1e-9 <= gap < 0.2 * c.radius_m + 1e-9, f"{c.name}: gap {gap}"
    palm = capsules[0]
    axis = "xyz".index(palm_side[1])
    sign = 1.0 if palm_side[0] == "+" else -1.0
    assert sign * palm.start_m[axis] > half[axis]
    fingers_c = [c.start_m["xyz".index(wrap_axis)] for c in capsules[1:-1]]
    assert all(v > half["xyz".index(wrap_axis)] for v in fingers_c)
    assert capsules[-1].start_m["xyz".index(wrap_axis)] < -half["xyz".index(wrap_axis)]


def test_bad_hand_configs_are_errors():
    with pytest.raises(ConfigError, match="wrap_axis .* must differ from the palm axis"):
        HandConfig(palm_side="-z", wrap_axis="z")
    with pytest.raises(ConfigError, match="finger_count must be 1 to 4"):
        HandConfig(finger_count=5)
    with pytest.raises(ConfigError, match="finger_radius_m must be a positive number"):
        HandConfig(finger_radius_m=0.0)


def test_hand_and_light_configs_built_in_code_check_their_choices():
    """The TOML loader checks Literal fields; configs built in Python must too (a bad palm side
    was a KeyError when the scene was built; an unknown light kind silently became a spot)."""
    from roft_sim.scene.config import LightConfig

    with pytest.raises(ConfigError, match=r"hand.palm_side must be one of .*got '\+w'"):
        HandConfig(palm_side="+w")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="hand.wrap_axis must be one of .*got 'q'"):
        HandConfig(wrap_axis="q")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="light kind must be one of .*got 'point'"):
        LightConfig(kind="point")  # type: ignore[arg-type]
