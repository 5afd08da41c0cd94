"""Shipped scenario files and the named presets of ``roft-sim generate --preset``.

Every lookup of a shipped scenario file goes through :func:`shipped_scenarios_dir`, which asks
:func:`roft_sim.shipped_files.scenarios_dir` (``scenarios/`` in the repository, installed as
the package data ``roft_sim.scenarios``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from roft_sim.errors import ConfigError
from roft_sim.shipped_files import scenarios_dir

__all__ = ["Preset", "PRESETS", "shipped_scenarios_dir", "preset_scenario_paths"]


def shipped_scenarios_dir() -> Path:
    """The folder of the scenario files shipped with roft_sim (``ci/``, ``fast_ycb/``, ...).

    Raises:
        ConfigError: the folder is missing (a broken installation).
    """
    return scenarios_dir()


@dataclass(frozen=True, slots=True, kw_only=True)
class Preset:
    """A named set of shipped scenarios."""

    name: str
    """Preset name, as given to ``--preset``."""
    folder: str
    """Sub-folder of :func:`shipped_scenarios_dir` holding its ``*.toml`` files."""
    sequence_names: Literal["scenario", "object"]
    """How its sequences are named on disk: after the scenario's ``name`` or after its object
    (``003_cracker_box``, like the reference Fast-YCB layout)."""
    description: str
    """One line for ``--help``."""


PRESETS: dict[str, Preset] = {
    "fast-ycb": Preset(
        name="fast-ycb",
        folder="fast_ycb",
        sequence_names="object",
        description="the six Fast-YCB-like sequences (1280x720, 30 fps, 880 frames each), "
        "one folder per object",
    ),
    "ci": Preset(
        name="ci",
        folder="ci",
        sequence_names="scenario",
        description="the small CI scenarios (320x240): static camera, hand occluder with a "
        "moving camera, off-centre camera with motion blur",
    ),
}
"""The presets by name."""


def preset_scenario_paths(name: str) -> list[Path]:
    """The scenario files of preset ``name``, sorted by file name.

    Raises:
        ConfigError: unknown preset, or its folder holds no scenario file.
    """
    if name not in PRESETS:
        raise ConfigError(f"unknown preset {name!r}; expected one of {', '.join(PRESETS)}")
    folder = shipped_scenarios_dir() / PRESETS[name].folder
    paths = sorted(folder.glob("*.toml"))
    if not paths:
        raise ConfigError(f"preset {name!r}: no scenario file (*.toml) in {str(folder)!r}")
    return paths
