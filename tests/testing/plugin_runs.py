"""Runs pytest in a subprocess with the roft_sim plugin (for the plugin and example tests)."""

from __future__ import annotations

import os
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

PLUGIN_MODULE = "roft_sim.testing.pytest_plugin"


def plugin_installed() -> bool:
    """True when the ``pytest11`` entry point of roft-sim is installed (pip install -e .)."""
    return any(ep.value == PLUGIN_MODULE for ep in entry_points(group="pytest11"))


def run_pytest(
    folder: Path, *args: str, env: dict[str, str] | None = None, timeout_s: float = 300
) -> subprocess.CompletedProcess[str]:
    """``python -m pytest -q -p no:cacheprovider *args`` in ``folder``; loads the plugin with
    ``-p`` when its entry point is not installed (a source checkout without ``pip install``)."""
    load = [] if plugin_installed() else ["-p", PLUGIN_MODULE]
    return subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *load, *args],
        cwd=folder,
        env={**os.environ, **(env or {})},
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
