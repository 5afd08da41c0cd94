"""Where the files shipped with roft_sim live: the one place that knows.

Scenario files (``ci/``, ``fast_ycb/``), fault presets (``faults/``) and the stress benchmark's
sweep file (``sweeps/stress.toml``) are package data in
``roft_sim/scenarios/``; the repository also shows them at ``scenarios/`` (a symbolic link), so
paths like ``scenarios/ci/cracker_box.toml`` work from a checkout.
"""

from __future__ import annotations

from pathlib import Path

from roft_sim.errors import ConfigError

__all__ = ["scenarios_dir"]


def scenarios_dir() -> Path:
    """The folder of the shipped scenario and fault-preset files.

    Raises:
        ConfigError: the folder is missing (a broken installation).
    """
    path = Path(__file__).resolve().parent / "scenarios"
    if not path.is_dir():
        raise ConfigError(
            f"the shipped scenario folder {str(path)!r} is missing; reinstall roft-sim "
            "(pip install --force-reinstall roft-sim) or pass scenario files explicitly"
        )
    return path
