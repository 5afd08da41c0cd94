"""Tracker plugins: the interface, the registry, ROFT and the baselines."""

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
]
