"""Where the files shipped with roft_sim live: the one place that knows.

Scenario files (``ci/``, ``fast_ycb/``), fault presets (``faults/``) and the stress benchmark's
sweep file (``sweeps/stress.toml``) live in ``scenarios/`` at
the repository's top level, so paths like ``scenarios/ci/cracker_box.toml`` work from a checkout;
they are installed as the data package ``roft_sim.scenarios`` (``package-dir`` in
pyproject.toml), which is how the installed package finds them.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

from roft_sim.errors import ConfigError

__all__ = ["scenarios_dir"]


def scenarios_dir() -> Path:
    """The folder of the shipped scenario and fault-preset files.

    Raises:
        ConfigError: the folder is missing (a broken installation).
    """
    try:
        path = Path(str(importlib.resources.files("roft_sim.scenarios")))
    except ModuleNotFoundError:
        path = Path(__file__).resolve().parent / "scenarios"  # named in the error below
    if not path.is_dir():
        raise ConfigError(
            f"the shipped scenario folder {str(path)!r} is missing; reinstall roft-sim "
            "(pip install --force-reinstall roft-sim) or pass scenario files explicitly"
        )
    return path
