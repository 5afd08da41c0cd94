"""Observation streams for property tests: a sequence under a fault configuration, re-timed
detections, and trackers built for a sequence.

- :class:`FaultedStream`: a sequence x a :class:`~roft_sim.faults.FaultConfig` x a seed. Its
  ``repr`` is the fault list and the capture -> arrival timeline
  (:func:`roft_sim.faults.format_timeline`), so a hypothesis counterexample prints as a readable
  schedule.
- :func:`reschedule_poses`, :func:`poses_at_capture`, :func:`settled_frames`: the same pose
  detections delivered at other frames (e.g. each at its capture frame: the zero-delay run
  that a delay-correct tracker must reproduce).
- :func:`tracker_for`: a tracker built from its spec (or registry name) with the
  :class:`~roft_sim.trackers.TrackerContext` of a sequence (the analytic box's depth renderer for
  renderer-free sequences, MuJoCo's, built lazily, otherwise).

Nothing here imports hypothesis or MuJoCo.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import Sequence as DatasetSequence
from roft_sim.errors import ConfigError
from roft_sim.faults import DetectionSchedule, FaultConfig, ObservationStream, format_timeline
from roft_sim.records import DepthRenderer, Observation, PoseDetection
from roft_sim.trackers import Tracker, TrackerContext, TrackerSpec, create_tracker, get_tracker_spec

__all__ = [
    "FaultedStream",
    "reschedule_poses",
    "permute_pose_arrivals",
    "poses_at_capture",
    "settled_frames",
    "pose_delays",
    "tracker_for",
    "is_analytic_sequence",
]


@dataclass(frozen=True, slots=True, kw_only=True, repr=False)
class FaultedStream:
    """One sequence under one fault configuration and seed: what a tracker would receive.

    Build the observations with :meth:`observations` (materialised, so a property can re-time
    them); :attr:`schedule` is the pure timing. ``repr`` prints the faults and the timeline.
    """

    sequence: DatasetSequence
    """The dataset sequence (e.g. :func:`roft_sim.testing.analytic_scene.analytic_box_sequence`)."""
    faults: FaultConfig
    """The fault configuration."""
    seed: int
    """The stream's seed (>= 0); every fault draws from its own child of it."""
    flow: str | None = "gt"
    """Flow source spec (:func:`roft_sim.sensors.flow_sources.make_flow_source`), None = no flow.
    ``gt`` serves any stride, so the frame after a dropped one still gets its flow."""
    pose_set: str | None = "gt"
    """The sequence's detector pose set fed as detections (None: no poses)."""
    mask_set: str | None = "gt"
    """The sequence's mask set fed as detections (None: no masks)."""
    include_rgb: bool = True
    """Hand rgb images to the tracker."""

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError(f"FaultedStream seed must be an integer >= 0, got {self.seed!r}")

    def stream(self) -> ObservationStream:
        """The lazy :class:`~roft_sim.faults.ObservationStream` (flow source seeded by ``seed``)."""
        flow_source = None
        if self.flow is not None:
            from roft_sim.sensors.flow_sources import make_flow_source

            flow_source = make_flow_source(self.flow, seed=self.seed)
        return ObservationStream(
            self.sequence,
            self.faults,
            seed=self.seed,
            flow_source=flow_source,
            pose_set=self.pose_set,
            mask_set=self.mask_set,
            include_rgb=self.include_rgb,
        )

    @property
    def schedule(self) -> DetectionSchedule:
        """The timing of every stream (no images)."""
        return self.stream().schedule

    def observations(self) -> list[Observation]:
        """One :class:`~roft_sim.records.Observation` per camera frame, in order."""
        return list(self.stream())

    def timeline(self, *, width: int = 60) -> str:
        """The capture -> arrival timeline of the schedule (``roft-sim faults show`` format)."""
        header = (f"sequence {self.sequence.name!r}, seed {self.seed}",)
        return format_timeline(self.schedule, header=header, width=width)

    def _repr_pretty_(self, printer: Any, cycle: bool) -> None:
        """Hypothesis (and IPython) print a drawn stream as its timeline, not as its fields."""
        printer.text(repr(self))

    def __repr__(self) -> str:
        faults = "\n".join(f"  {line}" for line in self.faults.describe_lines())
        return (
            f"FaultedStream(sequence={self.sequence.name!r} ({len(self.sequence)} frames), "
            f"seed={self.seed}, flow={self.flow!r}, faults:\n{faults}\n" + self.timeline() + ")"
        )


def _check_frames(observations: Sequence[Observation]) -> None:
    for k, obs in enumerate(observations):
        if obs.k != k:
            raise ValueError(
                f"observations must be frames 0..{len(observations) - 1} in order; position {k} "
                f"holds frame {obs.k}"
            )


def reschedule_poses(
    observations: Sequence[Observation], arrival: Callable[[PoseDetection], int | None]
) -> list[Observation]:
    """The same observations with every pose detection moved to frame ``arrival(detection)``.

    Args:
        observations: one observation per camera frame, ``observations[k].k == k``.
        arrival: new arrival frame of a detection, or None to remove it. Detections that land on
            one frame keep their original delivery order.

    Returns:
        New observations (the inputs are not modified); ``arrival_k`` of each moved detection
        is updated.

    Raises:
        ValueError: the observations are not frames 0..N-1 in order, or an arrival lies outside
            them.
    """
    _check_frames(observations)
    n = len(observations)
    moved: list[list[PoseDetection]] = [[] for _ in range(n)]
    for obs in observations:
        for det in obs.poses:
            new = arrival(det)
            if new is None:
                continue
            new = int(new)
            if not 0 <= new < n:
                raise ValueError(
                    f"pose {det.detection_id} (capture {det.capture_k}) moved to frame {new}, "
                    f"outside the {n} observed frames"
                )
            moved[new].append(dataclasses.replace(det, arrival_k=new))
    return [dataclasses.replace(obs, poses=tuple(moved[k])) for k, obs in enumerate(observations)]


def poses_at_capture(
    observations: Sequence[Observation], *, max_delay_frames: int | None = None
) -> list[Observation]:
    """Every usable pose detection delivered at its (reported) capture frame: the zero-delay
    run a delay-correct tracker must reproduce once the delayed poses have arrived.

    Args:
        observations: frames 0..N-1 in order.
        max_delay_frames: drop poses that arrived more than this many frames after their
            capture (a tracker's buffer horizon: it must ignore them); None keeps all.

    Poses reported as captured after they arrived (clock skew) are dropped too: no tracker can
    use a pose from the future.
    """

    def at_capture(det: PoseDetection) -> int | None:
        delay = det.arrival_k - det.capture_k
        if delay < 0 or (max_delay_frames is not None and delay > max_delay_frames):
            return None
        return det.capture_k

    return reschedule_poses(observations, at_capture)


def permute_pose_arrivals(
    observations: Sequence[Observation],
    order: Sequence[int],
    *,
    max_delay_frames: int | None = None,
) -> list[Observation]:
    """The same pose detections in another arrival order, within the buffer horizon.

    Delivery j (in delivery order) takes the arrival slot of delivery ``order[j]``: its arrival
    frame, clipped to ``[capture_k, capture_k + max_delay_frames]`` (and to the observed frames),
    so every pose stays usable, and its place among the deliveries of that frame; a delivery
    whose window is empty (clock skew) keeps its arrival frame.

    Args:
        observations: frames 0..N-1 in order.
        order: a permutation of ``range(D)``, D = number of pose deliveries.
        max_delay_frames: the tracker's buffer horizon; None = the last frame.

    Raises:
        ValueError: ``order`` is not a permutation of the deliveries.
    """
    _check_frames(observations)
    deliveries = [(obs.k, i) for obs in observations for i in range(len(obs.poses))]
    if sorted(order) != list(range(len(deliveries))):
        raise ValueError(
            f"order must be a permutation of range({len(deliveries)}) (one entry per pose "
            f"delivery), got {list(order)}"
        )
    arrivals = [k for k, _ in deliveries]
    last = len(observations) - 1
    moved: list[list[PoseDetection]] = [[] for _ in observations]
    for j in sorted(range(len(deliveries)), key=lambda j: order[j]):  # in the order of the slots
        k, i = deliveries[j]
        det = observations[k].poses[i]
        lo = max(det.capture_k, 0)
        hi = last if max_delay_frames is None else min(det.capture_k + max_delay_frames, last)
        new = min(max(arrivals[order[j]], lo), hi) if lo <= hi else k
        moved[new].append(dataclasses.replace(det, arrival_k=new))
    return [dataclasses.replace(o, poses=tuple(moved[k])) for k, o in enumerate(observations)]


def settled_frames(
    observations: Sequence[Observation], *, max_delay_frames: int | None = None
) -> NDArray[np.bool_]:
    """``(N,)`` bool: True at frame k when every usable pose captured at or before k has arrived
    by k (and at least one has), so a delay-correct tracker's estimate at k must equal the
    zero-delay one.

    ``max_delay_frames`` and the clock-skew rule are those of :func:`poses_at_capture`.
    """
    n = len(observations)
    last_needed = np.full(n, -1, dtype=np.int64)  # latest arrival among captures <= k
    any_pose = np.zeros(n, dtype=bool)
    for obs in observations:
        for det in obs.poses:
            delay = det.arrival_k - det.capture_k
            if delay < 0 or (max_delay_frames is not None and delay > max_delay_frames):
                continue
            c = min(max(det.capture_k, 0), n - 1)
            last_needed[c] = max(last_needed[c], det.arrival_k)
            any_pose[c] = True
    latest = np.maximum.accumulate(last_needed)
    seen = np.logical_or.accumulate(any_pose)
    return seen & (latest <= np.arange(n))


def pose_delays(observations: Iterable[Observation]) -> list[int]:
    """``arrival_k - capture_k`` [frames] of every pose delivery, in delivery order."""
    return [det.arrival_k - det.capture_k for obs in observations for det in obs.poses]


def is_analytic_sequence(sequence: DatasetSequence) -> bool:
    """True for sequences made by :func:`roft_sim.testing.analytic_scene.analytic_box_sequence`."""
    meta: Any = sequence.metadata()
    return bool(meta.get("generator") == "roft_sim.testing.analytic_scene")


def _default_depth_renderer(sequence: DatasetSequence) -> DepthRenderer:
    if is_analytic_sequence(sequence):
        from roft_sim.testing.analytic_scene import AnalyticBox, AnalyticBoxDepthRenderer

        box = sequence.metadata()["box"]
        return AnalyticBoxDepthRenderer(
            AnalyticBox(size_m=tuple(box["size_m"]), texture_seed=box["texture_seed"])
        )
    from roft_sim.harness.inputs import (
        LazyDepthRenderer,
        mujoco_depth_renderer,
        resolve_object_model,
    )

    return LazyDepthRenderer(mujoco_depth_renderer, resolve_object_model(sequence))


@functools.lru_cache(maxsize=64)
def _registered_spec(name: str) -> TrackerSpec:
    """The spec registered as ``name``, looked up once per process (reading every installed
    distribution's entry points takes about 10 ms: a property test builds thousands of
    trackers)."""
    return get_tracker_spec(name)


def tracker_for(
    spec: TrackerSpec | str,
    sequence: DatasetSequence,
    config: Any = None,
    *,
    seed: int = 0,
    depth_renderer: DepthRenderer | None = None,
) -> Tracker:
    """A tracker built for ``sequence`` (its intrinsics, fps and object model).

    Args:
        spec: the tracker's :class:`~roft_sim.trackers.TrackerSpec`, or a registered name.
        sequence: the sequence it will track.
        config: an instance of ``spec.config_type`` (None: its defaults).
        seed: seeds the tracker's ``context.rng``.
        depth_renderer: injected when the spec needs one; default: the analytic box's exact
            renderer for analytic sequences, else MuJoCo's (built on first use, so a
            configuration that never renders never imports MuJoCo).

    Raises:
        PluginError: unknown tracker name, or the tracker broke the protocol.
        ConfigError: ``config`` is not a ``spec.config_type``.
    """
    if isinstance(spec, str):
        spec = _registered_spec(spec)
    model = sequence.object_model()
    if model is None:
        from roft_sim.harness.inputs import resolve_object_model

        model = resolve_object_model(sequence)
    if spec.needs_depth_renderer and depth_renderer is None:
        depth_renderer = _default_depth_renderer(sequence)
    context = TrackerContext(
        intrinsics=sequence.intrinsics,
        fps=int(sequence.fps),
        object_model=model,
        rng=np.random.default_rng(seed),
        depth_renderer=depth_renderer,
    )
    return create_tracker(spec, context, config)
