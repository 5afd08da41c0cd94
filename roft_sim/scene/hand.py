"""Geometry of the simple hand occluder: capsules for the palm, fingers and thumb.

The hand holds the object with a fixed grasp, so its capsules are given in the OBJECT frame and
move rigidly with the object; see :class:`roft_sim.scene.config.HandConfig` for the layout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.scene.config import HandConfig

F64 = NDArray[np.float64]

__all__ = ["Capsule", "hand_capsules"]

_AXIS = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True, slots=True)
class Capsule:
    """A capsule between two points, object frame."""

    name: str
    """``palm``, ``finger0`` ... ``finger3`` or ``thumb``."""
    start_m: F64
    """(3,) first end point [m]."""
    end_m: F64
    """(3,) second end point [m]."""
    radius_m: float
    """Radius [m]."""


def hand_capsules(config: HandConfig, half_extents_m: ArrayLike) -> list[Capsule]:
    """Capsules of a hand grasping a box-like object.

    Args:
        config: hand layout.
        half_extents_m: (3,) half extents of the object's axis-aligned bounding box about the
            object origin, object frame [m] (``max(|min|, |max|)`` per axis).

    Returns:
        The palm first, then the fingers, then the thumb (if any).
    """
    e = np.asarray(half_extents_m, dtype=np.float64)
    a = _AXIS[config.palm_side[1]]
    s = 1.0 if config.palm_side[0] == "+" else -1.0
    c = _AXIS[config.wrap_axis]
    b = 3 - a - c
    rp, rf = config.palm_radius_m, config.finger_radius_m

    def point(along_a: float, along_b: float, along_c: float) -> F64:
        p = np.zeros(3)
        p[a], p[b], p[c] = along_a, along_b, along_c
        return p

    palm_a = s * (e[a] + rp)
    palm_half = min(e[b], 0.045)
    capsules = [Capsule("palm", point(palm_a, -palm_half, 0.0), point(palm_a, palm_half, 0.0), rp)]
    root_a = s * (e[a] + 0.5 * rp)
    tip_a = root_a - s * config.finger_length_m
    n = config.finger_count
    spacing = 2 * palm_half / n
    for i in range(n):
        along_b = -palm_half + spacing * (i + 0.5)
        along_c = e[c] + rf
        capsules.append(
            Capsule(
                f"finger{i}", point(root_a, along_b, along_c), point(tip_a, along_b, along_c), rf
            )
        )
    if config.thumb:
        thumb_tip_a = root_a - s * 0.8 * config.finger_length_m
        along_c = -(e[c] + 1.2 * rf)
        capsules.append(
            Capsule(
                "thumb", point(root_a, 0.0, along_c), point(thumb_tip_a, 0.0, along_c), 1.2 * rf
            )
        )
    return capsules
