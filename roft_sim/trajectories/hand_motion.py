"""Hand-object manipulation motion: captured when the captures are there, fitted otherwise.

``kind = "hand-motion"`` (the ``fast-ycb`` preset's motion) picks, by ``source``:

- ``auto``: the ``captured`` file when it exists under the trajectories folder, else the
  ``continuous`` profile (fitted to captured hand motion);
- ``captured``: the file, an error when it is missing;
- ``continuous``: the fitted continuous profile;
- ``bursty``: the earlier minimum-jerk generator with rests (``bursty``), unchanged.

The trajectories folder is ``trajectories_dir`` when given, else ``../shared/trajectories``
beside the repository (the project's shared data, DESIGN.md); which source a build used is
logged and available from :func:`resolve_hand_motion`.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from roft_sim.errors import ConfigError
from roft_sim.trajectories.captured import CapturedMotionConfig
from roft_sim.trajectories.continuous import ContinuousMotionConfig
from roft_sim.trajectories.synthetic import SyntheticMotionConfig

__all__ = [
    "HandMotionConfig",
    "HandMotionSource",
    "default_trajectories_dir",
    "resolve_hand_motion",
]

_log = logging.getLogger(__name__)

HandMotionSource = Literal["auto", "captured", "continuous", "bursty"]


def default_trajectories_dir() -> Path:
    """``../shared/trajectories`` beside the repository (may not exist, e.g. once installed)."""
    return Path(__file__).resolve().parents[2].parent / "shared" / "trajectories"


@dataclass(frozen=True, slots=True, kw_only=True)
class HandMotionConfig:
    """Captured hand-object motion when available, the fitted continuous profile otherwise."""

    kind: Literal["hand-motion"] = "hand-motion"
    """Tells trajectory configs apart in scenario files."""
    source: HandMotionSource = "auto"
    """``auto`` (captured when present, else continuous), ``captured``, ``continuous`` or
    ``bursty`` (the earlier generator with rests between bursts)."""
    captured: CapturedMotionConfig | None = None
    """The captured motion; a relative ``path`` is relative to the trajectories folder. None =
    no capture (``auto`` then uses the continuous profile)."""
    trajectories_dir: Path | None = None
    """Folder of captured motion (relative paths resolve against the scenario file's folder);
    None = ``../shared/trajectories`` beside the repository."""
    continuous: ContinuousMotionConfig = field(default_factory=ContinuousMotionConfig)
    """The fitted continuous profile."""
    bursty: SyntheticMotionConfig = field(default_factory=SyntheticMotionConfig)
    """The bursty minimum-jerk profile."""

    def __post_init__(self) -> None:
        if self.source not in ("auto", "captured", "continuous", "bursty"):
            raise ConfigError(
                f"source = {self.source!r} is not known; expected auto, captured, continuous "
                "or bursty"
            )
        if self.source == "captured" and self.captured is None:
            raise ConfigError(
                "source = 'captured' needs a [trajectory.captured] table (path, format, ...)"
            )

    def with_base_dir(self, base_dir: Path) -> HandMotionConfig:
        """The config with a relative ``trajectories_dir`` made absolute against ``base_dir``
        (the scenario file's folder)."""
        if self.trajectories_dir is None or self.trajectories_dir.is_absolute():
            return self
        return dataclasses.replace(self, trajectories_dir=base_dir / self.trajectories_dir)

    def captured_path(self) -> Path | None:
        """Where the captured file is looked for (None without a capture)."""
        if self.captured is None:
            return None
        folder = self.trajectories_dir or default_trajectories_dir()
        path = Path(self.captured.path)
        return path if path.is_absolute() else folder / path


def resolve_hand_motion(
    config: HandMotionConfig,
) -> tuple[CapturedMotionConfig | ContinuousMotionConfig | SyntheticMotionConfig, str]:
    """The concrete trajectory config ``config`` stands for, and why it was chosen.

    Raises:
        ConfigError: ``source = "captured"`` and the file is missing.
    """
    if config.source == "bursty":
        return config.bursty, "source = bursty"
    if config.source == "continuous":
        return config.continuous, "source = continuous"
    path = config.captured_path()
    if config.captured is not None and path is not None and path.is_file():
        return dataclasses.replace(config.captured, path=path), f"captured motion {path}"
    if config.source == "captured":
        raise ConfigError(
            f"captured motion {str(path)!r} is missing; set trajectories_dir to the folder of "
            "the shared captures (with tum/ and bvh/), or use source = 'auto' to fall back to "
            "the fitted continuous profile"
        )
    reason = "no capture configured" if path is None else f"{path} is absent"
    return config.continuous, f"fitted continuous profile ({reason})"
