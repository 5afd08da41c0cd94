"""Tracker plugins: the interface, the registry, ROFT and the baselines.

Registered trackers (entry-point group ``roft_sim.trackers``; ``roft-sim trackers`` lists them):
``roft`` (:mod:`roft_sim.trackers.roft`), ``detector-hold``, ``detector-ideal``, ``naive-delay``
and ``pose-only-ukf`` (:mod:`roft_sim.trackers.baselines`). Writing a plugin: docs/plugins.md.
"""

from __future__ import annotations

from collections.abc import Iterable

from roft_sim.errors import PluginError
from roft_sim.records import Estimate, Observation
from roft_sim.trackers.base import (
    ENTRY_POINT_GROUP,
    Tracker,
    TrackerContext,
    TrackerSpec,
    create_tracker,
    discover_trackers,
    get_tracker_spec,
    load_tracker_config,
)

__all__ = [
    "ENTRY_POINT_GROUP",
    "Tracker",
    "TrackerContext",
    "TrackerSpec",
    "create_tracker",
    "discover_trackers",
    "get_tracker_spec",
    "load_tracker_config",
    "run_tracker",
]


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
        estimate = tracker.step(observation)
        if not isinstance(estimate, Estimate) or estimate.k != observation.k:
            got = getattr(estimate, "k", type(estimate).__name__)
            raise PluginError(
                f"{type(tracker).__name__}.step(k={observation.k}) returned {got!r}; a tracker "
                "must return an Estimate with the observation's k"
            )
        estimates.append(estimate)
    return estimates
