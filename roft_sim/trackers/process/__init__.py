"""Trackers in other processes (any language): the tracker process protocol (docs/process.md).

- :func:`process_tracker_spec` / :class:`ProcessTracker`: the parent side, behind
  ``--tracker "process:<command line>"``.
- :func:`serve`: runs any Python tracker as such a process; ``python -m roft_sim.trackers.process
  NAME`` serves an installed plugin (one that needs a depth renderer is served by
  ``python -m roft_sim.harness.process_server NAME``, which may import MuJoCo).
- :mod:`roft_sim.trackers.process.codec`: the messages and their checks.
"""

from __future__ import annotations

from roft_sim.trackers.process.client import (
    PROCESS_PREFIX,
    ProcessTracker,
    ProcessTrackerConfig,
    process_tracker_spec,
    tracker_name_from_command,
)
from roft_sim.trackers.process.codec import PROTOCOL_VERSION, ProtocolError, TrackerProcessError
from roft_sim.trackers.process.server import TrackerFactory, serve, serve_main

__all__ = [
    "PROCESS_PREFIX",
    "PROTOCOL_VERSION",
    "ProcessTracker",
    "ProcessTrackerConfig",
    "ProtocolError",
    "TrackerFactory",
    "TrackerProcessError",
    "process_tracker_spec",
    "serve",
    "serve_main",
    "tracker_name_from_command",
]
