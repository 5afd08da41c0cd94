"""The tracker plugin interface and the entry-point registry.

A tracker is any object with ``reset`` and ``step`` (the :class:`Tracker` protocol; no base class
needed). A plugin makes it available by exposing a :class:`TrackerSpec` under the entry-point
group ``roft_sim.trackers``, e.g. in its ``pyproject.toml``::

    [project.entry-points."roft_sim.trackers"]
    my-tracker = "my_package.tracker:SPEC"

The harness creates a tracker with ``spec.factory(config, context)`` where ``config`` is an
instance of ``spec.config_type`` (a frozen dataclass, loadable from TOML) and ``context`` a
:class:`TrackerContext`. Trackers never see ground truth and never import MuJoCo: what they need
from the simulator (a depth renderer) is injected through the context.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any, Literal, Protocol, runtime_checkable

import numpy as np

from roft_sim.config_files import dataclass_from_mapping, load_toml
from roft_sim.errors import ConfigError, PluginError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import DepthRenderer, Estimate, ObjectModel, Observation

ENTRY_POINT_GROUP = "roft_sim.trackers"

__all__ = [
    "ENTRY_POINT_GROUP",
    "Tracker",
    "TrackerContext",
    "TrackerSpec",
    "discover_trackers",
    "get_tracker_spec",
    "load_tracker_config",
    "create_tracker",
    "close_tracker",
    "checked_step",
]


def checked_step(tracker: Tracker, observation: Observation) -> Estimate:
    """``tracker.step(observation)``, checked: a :class:`PluginError` unless it returned an
    :class:`Estimate` for the observation's frame."""
    estimate = tracker.step(observation)
    if not isinstance(estimate, Estimate) or estimate.k != observation.k:
        got = getattr(estimate, "k", type(estimate).__name__)
        raise PluginError(
            f"{type(tracker).__name__}.step(k={observation.k}) returned {got!r}; a tracker must "
            "return an Estimate with the observation's k"
        )
    return estimate


@runtime_checkable
class Tracker(Protocol):
    """A 6D pose and velocity tracker, stepped once per camera frame."""

    def reset(self, initial: Estimate | None) -> None:
        """Starts a new sequence.

        Args:
            initial: the pose and velocity AT frame ``initial.k`` (the harness gives the ground
                truth of the first frame, with that frame's ``k``, or nothing); None means
                "initialise from the first pose that arrives".
        """
        ...

    def step(self, observation: Observation) -> Estimate:
        """Consumes camera frame ``observation.k`` and returns the estimate for that frame.

        Frames come in increasing ``k`` without gaps; a dropped camera frame still comes as an
        observation with ``rgb``/``depth_m`` None.
        """
        ...

    # Optional: ``close()``, called once when the harness is done with the tracker
    # (:func:`close_tracker`); not part of the protocol, so plain trackers need none.


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackerContext:
    """What the harness tells a tracker about the sequence it will track."""

    intrinsics: CameraIntrinsics
    """Camera intrinsics of the observations."""
    fps: int
    """Camera frame rate [Hz]; frame k is taken at k / fps seconds."""
    object_model: ObjectModel
    """Mesh and model points of the tracked object, in the frame of its poses."""
    rng: np.random.Generator
    """Random generator reserved for this tracker (seeded by the harness)."""
    depth_renderer: DepthRenderer | None = None
    """Renders the object's depth at given poses; given when ``spec.needs_depth_renderer``."""


@dataclass(frozen=True, slots=True, kw_only=True)
class TrackerSpec:
    """How to build one kind of tracker; registered under :data:`ENTRY_POINT_GROUP`."""

    name: str
    """Registry name used on the command line (``--tracker NAME``)."""
    description: str
    """One line for ``roft-sim trackers``."""
    config_type: type
    """Frozen dataclass of the tracker's settings; every field has a default."""
    factory: Callable[[Any, TrackerContext], Tracker]
    """``factory(config, context) -> Tracker``."""
    needs_depth_renderer: bool = False
    """The harness must inject a depth renderer into the context."""
    detection_mode: Literal["stream", "ideal"] = "stream"
    """``stream``: detections go through the fault/delay stream. ``ideal``: the harness delivers
    every frame's detection at its own frame, whatever the fault preset (the "ideal detector")."""

    def __post_init__(self) -> None:
        if not dataclasses.is_dataclass(self.config_type):
            raise PluginError(f"tracker {self.name!r}: config_type must be a dataclass type")


def discover_trackers(group: str = ENTRY_POINT_GROUP) -> dict[str, TrackerSpec]:
    """Loads every :class:`TrackerSpec` registered under the entry-point ``group``.

    Raises:
        PluginError: an entry point fails to import, is not a TrackerSpec, or reuses a name.
    """
    specs: dict[str, TrackerSpec] = {}
    for ep in sorted(entry_points(group=group), key=lambda e: e.name):
        try:
            spec = ep.load()
        except Exception as e:  # a broken plugin must say which one it is
            raise PluginError(
                f"tracker entry point {ep.name!r} ({ep.value}) failed to load: {e}"
            ) from e
        if not isinstance(spec, TrackerSpec):
            raise PluginError(
                f"tracker entry point {ep.name!r} ({ep.value}) is a {type(spec).__name__}, "
                "expected roft_sim.trackers.TrackerSpec"
            )
        if spec.name in specs:
            raise PluginError(
                f"tracker name {spec.name!r} is registered twice (entry point {ep.name!r}, "
                f"{ep.value}); uninstall one of the plugins or rename it"
            )
        specs[spec.name] = spec
    return specs


def get_tracker_spec(name: str, group: str = ENTRY_POINT_GROUP) -> TrackerSpec:
    """The spec registered as ``name``.

    Raises:
        PluginError: no tracker of that name (the message lists the installed ones).
    """
    specs = discover_trackers(group)
    if name not in specs:
        known = ", ".join(sorted(specs)) or "none"
        raise PluginError(
            f"no tracker named {name!r}; installed trackers: {known}. A plugin registers one under "
            f"the entry-point group {group!r} (see docs/plugins.md); reinstall the package after "
            "adding it"
        )
    return specs[name]


def load_tracker_config(spec: TrackerSpec, source: str | Path | Mapping[str, Any] | None) -> Any:
    """Builds ``spec.config_type`` from a TOML file, a mapping, or defaults (None).

    A TOML file may hold the settings at top level or in a ``[tracker]`` table.
    """
    if source is None:
        return spec.config_type()
    if isinstance(source, Mapping):
        return dataclass_from_mapping(spec.config_type, source, where=f"tracker {spec.name} config")
    data = load_toml(source)
    if set(data) == {"tracker"}:
        data = data["tracker"]
    if not isinstance(data, Mapping):
        raise ConfigError(f"{source}: expected a table of {spec.name} settings")
    return dataclass_from_mapping(spec.config_type, data, where=str(source))


def create_tracker(spec: TrackerSpec, context: TrackerContext, config: Any = None) -> Tracker:
    """Builds a tracker from its spec, checking that what it needs is in the context."""
    if config is None:
        config = spec.config_type()
    if not isinstance(config, spec.config_type):
        raise ConfigError(
            f"tracker {spec.name!r} expects a {spec.config_type.__name__} config, got "
            f"{type(config).__name__}"
        )
    if spec.needs_depth_renderer and context.depth_renderer is None:
        raise PluginError(f"tracker {spec.name!r} needs a depth renderer and none was injected")
    tracker = spec.factory(config, context)
    if not isinstance(tracker, Tracker):
        raise PluginError(
            f"tracker {spec.name!r}: factory returned {type(tracker).__name__}, "
            "which has no reset()/step()"
        )
    return tracker


def close_tracker(tracker: Tracker) -> None:
    """Calls ``tracker.close()`` when the tracker has one (optional: a tracker that holds a
    child process or other resources releases them there). The harness calls it once a run of
    the tracker has ended, normally or not."""
    close = getattr(tracker, "close", None)
    if callable(close):
        close()
