"""Shipped scenario files and the named presets of ``roft-sim generate --preset``.

Every lookup of a shipped scenario file goes through :func:`shipped_scenarios_dir`, which asks
:func:`roft_sim.shipped_files.scenarios_dir` (``scenarios/`` in the repository, installed as
the package data ``roft_sim.scenarios``).
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from roft_sim.errors import ConfigError
from roft_sim.scenario import Scenario
from roft_sim.shipped_files import scenarios_dir
from roft_sim.trajectories import CapturedMotionConfig, read_fast_ycb_poses

__all__ = [
    "Preset",
    "PRESETS",
    "shipped_scenarios_dir",
    "preset_scenario_paths",
    "with_fast_ycb_motion",
]

_log = logging.getLogger(__name__)


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


def with_fast_ycb_motion(scenario: Scenario, motion_dir: str | Path) -> Scenario:
    """``scenario`` with its object moving along the captured motion of the real Fast-YCB
    sequence of the same object, for reproducing the paper on the paper's own motion
    (``roft-sim paper --motion``).

    The poses of ``<motion_dir>/<object>/gt/poses.txt`` (the Fast-YCB layout, ``T_cam_obj`` in the
    camera frame, one row per frame) are replayed as they are: ``kind = "file"``, ``format =
    "fast-ycb"`` at the scenario's frame rate, no filtering, drift removal or re-placement, so frame
    k shows the object where Fast-YCB's frame k does (with the scenario's intrinsics: a
    ``--resolution`` keeps the field of view). The scenario's frames are cut to the file's poses
    when it has fewer (Fast-YCB's sequences end where their captures do; the preset asks for
    880); everything else (scene, hand, networks, seeds) stays the scenario's.

    Args:
        scenario: a loaded scenario whose object is named (a ``fast-ycb`` preset scenario).
        motion_dir: the root of a Fast-YCB dataset (one folder per object).

    Returns:
        The scenario with the replayed trajectory.

    Raises:
        ConfigError: the scenario's object is a mesh file, not a name, or the object's sequence
            folder is missing under ``motion_dir``.
        DatasetFormatError: the poses file is malformed (:func:`read_fast_ycb_poses`).
    """
    name = scenario.object.name_or_path
    if isinstance(name, Path):
        raise ConfigError(
            f"scenario {scenario.name!r}: its object is the mesh file {str(name)!r}; a Fast-YCB "
            "motion is looked up by object name (e.g. 003_cracker_box)"
        )
    folder = Path(motion_dir) / name
    if not (folder / "gt" / "poses.txt").is_file():
        raise ConfigError(
            f"no Fast-YCB motion for {name}: {str(folder / 'gt' / 'poses.txt')!r} does not exist; "
            "give the root of a Fast-YCB dataset (one folder per object, each with gt/poses.txt; "
            "the real one comes from hsp-iit/fast-ycb's tools/download/download_dataset.sh)"
        )
    poses = read_fast_ycb_poses(folder, rate_hz=scenario.fps)
    frames = min(scenario.n_frames, len(poses))
    if frames < scenario.n_frames:
        _log.info(
            "%s: the Fast-YCB motion of %s has %d poses: %d frames instead of %d",
            scenario.name, name, len(poses), frames, scenario.n_frames,
        )  # fmt: skip
    trajectory = CapturedMotionConfig(
        path=folder.resolve(), format="fast-ycb", sample_rate_hz=float(scenario.fps)
    )
    return dataclasses.replace(scenario, trajectory=trajectory, frames=frames, duration_s=None)
