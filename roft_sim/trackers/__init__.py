"""Tracker plugins: the interface, the registry, ROFT and the baselines.

Registered trackers (entry-point group ``roft_sim.trackers``; ``roft-sim trackers`` lists them):
``roft`` (:mod:`roft_sim.trackers.roft`), ``detector-hold``, ``detector-ideal``, ``naive-delay``
and ``pose-only-ukf`` (:mod:`roft_sim.trackers.baselines`). Writing a plugin: docs/plugins.md.
A name ``process:<command line>`` is a tracker in a child process, any language
(:mod:`roft_sim.trackers.process`, docs/process.md).
"""

from __future__ import annotations

from collections.abc import Iterable

from roft_sim.records import Estimate, Observation
from roft_sim.trackers import base
from roft_sim.trackers.base import (
    ENTRY_POINT_GROUP,
    Tracker,
    TrackerContext,
    TrackerSpec,
    checked_step,
    close_tracker,
    create_tracker,
    discover_trackers,
    load_tracker_config,
)
from roft_sim.trackers.process.client import PROCESS_PREFIX, process_tracker_spec

__all__ = [
    "ENTRY_POINT_GROUP",
    "PROCESS_PREFIX",
    "Tracker",
    "TrackerContext",
    "TrackerSpec",
    "checked_step",
    "close_tracker",
    "create_tracker",
    "discover_trackers",
    "get_tracker_spec",
    "load_tracker_config",
    "run_tracker",
]


def get_tracker_spec(name: str, group: str = ENTRY_POINT_GROUP) -> TrackerSpec:
    """The spec registered as ``name``, or for ``process:<command line>`` the spec of a tracker
    process running that command (:func:`roft_sim.trackers.process.process_tracker_spec`).

    Raises:
        PluginError: no tracker of that name (the message lists the installed ones).
        ConfigError: an empty or unbalanced ``process:`` command line.
    """
    if name.startswith(PROCESS_PREFIX):
        return process_tracker_spec(name[len(PROCESS_PREFIX) :])
    return base.get_tracker_spec(name, group)


def run_tracker(
    tracker: Tracker, observations: Iterable[Observation], initial: Estimate | None = None
) -> list[Estimate]:
    """Resets ``tracker`` and steps it through ``observations`` (e.g. an ``ObservationStream``).

    Args:
        tracker: any :class:`Tracker`.
        observations: one observation per camera frame, in increasing ``k``.
        initial: passed to ``reset`` (None: the tracker starts from the first pose it receives).

    Returns:
        The estimate of every frame, in order.

    Raises:
        PluginError: the tracker returned something that is not an :class:`Estimate` for the
            frame it was given.
    """
    tracker.reset(initial)
    estimates = []
    for observation in observations:
        estimates.append(checked_step(tracker, observation))
    return estimates
