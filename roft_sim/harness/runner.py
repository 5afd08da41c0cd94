"""The run loop: one tracker over one sequence under one fault configuration.

:func:`run_sequence` builds the observation stream (faults, delays, flow source), creates the
tracker with its context (intrinsics, fps, object model, its own random generator, a lazily
built depth renderer when the tracker asks for one), steps it once per camera frame and
returns a :class:`SequenceRun`: the per-frame estimates, step times (``time.perf_counter``
around ``step`` only), observation load times, and the fault ledger.

Seeds: each sequence gets ``SeedSequence(seed, spawn_key=(crc32(name),))``, whose three spawned
children seed the tracker's generator, the fault stream and the flow source, so one stream
never shifts another, and adding a sequence to a run leaves the others unchanged.

Ground truth never reaches the tracker: it gets only :class:`~roft_sim.records.Observation`
objects and a :class:`~roft_sim.trackers.TrackerContext`. The exceptions are explicit options:
``init = "gt"`` (the initial estimate is frame 0's ground truth) and the ground-truth input
ablations (``poses = "gt"``, ``masks = "gt"``, flow ``gt``), which enter through the detection and
flow channels, delayed and faulted like any detector output.
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import Sequence
from roft_sim.errors import ConfigError, PluginError
from roft_sim.faults import FaultLedger, ObservationStream
from roft_sim.faults.events import DeliveryEvent
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.harness.inputs import (
    DepthRendererFactory,
    LazyDepthRenderer,
    ResolvedInputs,
    mujoco_depth_renderer,
    resolve_inputs,
    resolve_object_model,
)
from roft_sim.harness.options import RunOptions
from roft_sim.harness.robust_start import RobustStartGate
from roft_sim.harness.wall_clock import (
    WallClock,
    WallClockTimeline,
    held_estimates,
    step_against_clock,
)
from roft_sim.records import Estimate, ObjectModel, PoseTrack
from roft_sim.sensors.flow_sources import make_flow_source
from roft_sim.trackers import (
    Tracker,
    TrackerContext,
    TrackerSpec,
    close_tracker,
    create_tracker,
    get_tracker_spec,
)

F64 = NDArray[np.float64]

__all__ = [
    "SequenceRun",
    "SeedPlan",
    "seed_plan",
    "run_sequence",
    "make_observation_stream",
    "initial_estimate_from_ground_truth",
]

_CHILDREN = ("tracker", "stream", "flow")


@dataclass(frozen=True, slots=True, kw_only=True)
class SeedPlan:
    """The seeds of one sequence's run (recorded in ``run.json``)."""

    seed: int
    """The run's seed."""
    spawn_key: tuple[int, ...]
    """``(crc32(sequence name),)``: the sequence's key under the run seed."""
    tracker: np.random.SeedSequence
    """Seeds the tracker's ``rng`` (context)."""
    stream: np.random.SeedSequence
    """Seeds the fault stream (every fault draws from its own child of it)."""
    flow: np.random.SeedSequence
    """Seeds a stochastic flow source."""

    @property
    def flow_seed(self) -> int:
        """The integer seed handed to :func:`~roft_sim.sensors.flow_sources.make_flow_source`."""
        return int(self.flow.generate_state(1, np.uint32)[0])

    def describe(self) -> dict[str, Any]:
        """JSON-ready: the seed, the spawn key and the order of the children."""
        return {
            "seed": self.seed,
            "spawn_key": list(self.spawn_key),
            "children": list(_CHILDREN),
            "flow_seed": self.flow_seed,
        }


def seed_plan(seed: int, sequence_name: str) -> SeedPlan:
    """The :class:`SeedPlan` of sequence ``sequence_name`` in a run with ``seed``."""
    key = (zlib.crc32(sequence_name.encode("utf-8")),)
    tracker, stream, flow = np.random.SeedSequence(seed, spawn_key=key).spawn(len(_CHILDREN))
    return SeedPlan(seed=seed, spawn_key=key, tracker=tracker, stream=stream, flow=flow)


@dataclass(frozen=True, slots=True, kw_only=True)
class SequenceRun:
    """Everything one tracker produced on one sequence, and what the harness knows about it.

    Holds ground truth and the fault ledger for scoring: never hand it to a tracker.
    """

    sequence_name: str
    """Name of the sequence."""
    object_name: str
    """Registry name of the tracked object."""
    tracker: str
    """Registry name of the tracker."""
    intrinsics: CameraIntrinsics
    """Camera of the sequence."""
    fps: int
    """Camera rate [Hz]."""
    estimates: tuple[Estimate, ...]
    """One estimate per camera frame, ``estimates[k].k == k``: the tracker's own (``--clock
    sim``), or the one a consumer held at frame k's deadline (``--clock wall``, see
    :mod:`roft_sim.harness.wall_clock`)."""
    step_times_s: F64
    """(N,) wall time of each ``tracker.step`` call [s] (of the step for frame k)."""
    load_times_s: F64
    """(N,) wall time of building each observation (reading images, flow, faults) [s]."""
    ledger: FaultLedger
    """What happened to every detection and camera frame (true capture frames, outliers)."""
    pose_deliveries: tuple[DeliveryEvent, ...]
    """Every pose delivery, in delivery order."""
    mask_deliveries: tuple[DeliveryEvent, ...]
    """Every mask delivery, in delivery order."""
    inputs: dict[str, str | None]
    """The resolved pose set, mask set and flow source (and, with ``init = "robust"``, under
    ``init``, when the tracker could start and why it waited)."""
    seeds: SeedPlan
    """The seeds used."""
    ground_truth: PoseTrack | None
    """The sequence's ground truth (None for real data without it)."""
    object_model: ObjectModel
    """The object model the tracker got (its model points score ADD)."""
    depth_renderer_built: bool
    """Whether a depth renderer was actually built (False: the run never touched MuJoCo)."""
    wall_s: float
    """Wall time of the whole run loop [s]."""
    wall_clock: WallClockTimeline | None = None
    """With ``--clock wall``: when each frame was released, stepped and answered, and the
    tracker's own estimates; None in simulated time."""

    @property
    def tracker_estimates(self) -> tuple[Estimate, ...]:
        """The tracker's own estimate for each frame (``estimates`` unless the clock was wall)."""
        return self.estimates if self.wall_clock is None else self.wall_clock.tracker_estimates

    def __len__(self) -> int:
        return len(self.estimates)

    def pose_arrival_frames(self) -> NDArray[np.int64]:
        """(A,) sorted distinct frames at which at least one pose arrived."""
        return np.unique(np.array([e.arrival_k for e in self.pose_deliveries], dtype=np.int64))


def initial_estimate_from_ground_truth(ground_truth: PoseTrack) -> Estimate:
    """The ``init = "gt"`` initial estimate: frame 0's true pose and velocity (no covariance)."""
    return Estimate(
        k=0,
        T_cam_obj=np.array(ground_truth.T_cam_obj[0], dtype=np.float64),
        v_obj_mps=np.array(ground_truth.v_obj_mps[0], dtype=np.float64),
        w_radps=np.array(ground_truth.w_radps[0], dtype=np.float64),
    )


def _checked(estimate: object, k: int, tracker: str) -> Estimate:
    if not isinstance(estimate, Estimate):
        raise PluginError(
            f"tracker {tracker!r} returned a {type(estimate).__name__} at frame {k}; step() must "
            "return a roft_sim.records.Estimate"
        )
    if estimate.k != k:
        raise PluginError(
            f"tracker {tracker!r} returned an estimate for frame {estimate.k} when stepped with "
            f"frame {k}; set Estimate.k to observation.k"
        )
    return estimate


def make_observation_stream(
    sequence: Sequence,
    options: RunOptions,
    *,
    detection_mode: str = "stream",
    with_flow: bool = True,
) -> tuple[ObservationStream, ResolvedInputs, SeedPlan]:
    """The observation stream a run of ``options`` feeds its tracker, with its seeds.

    The same options, sequence and detection mode give the same detections (the fault schedule
    depends on neither the flow source nor the tracker), so a report can rebuild what a tracker
    received; ``with_flow=False`` skips computing the flow.
    """
    inputs = resolve_inputs(sequence, options)
    seeds = seed_plan(options.seed, sequence.name)
    flow_source = None
    if with_flow and inputs.flow is not None:
        flow_source = make_flow_source(inputs.flow, seed=seeds.flow_seed)
    stream = ObservationStream(
        inputs.sequence,
        options.faults,
        seed=seeds.stream,
        flow_source=flow_source,
        pose_set=inputs.pose_set,
        mask_set=inputs.mask_set,
        include_rgb=options.include_rgb,
        ideal_detections=detection_mode == "ideal",
    )
    return stream, inputs, seeds


def _initial_estimate(
    options: RunOptions, sequence_name: str, ground_truth: PoseTrack | None
) -> Estimate | None:
    """What the tracker is reset with: the ground truth of frame 0 for ``--init gt``, else None
    (the tracker starts from its first detection)."""
    if options.init != "gt":
        return None
    if ground_truth is None:
        raise ConfigError(
            f"--init gt needs ground truth, and sequence {sequence_name!r} has none; use "
            "--init first-detection"
        )
    return initial_estimate_from_ground_truth(ground_truth)


def _step_through(
    stream: ObservationStream,
    tracker: Tracker,
    n_frames: int,
    tracker_name: str,
    progress: Callable[[int], object] | None,
    gate: RobustStartGate | None,
) -> tuple[list[Estimate], F64, F64]:
    """Feeds frames 0 .. n_frames - 1 to the tracker (through the robust-start ``gate`` when
    there is one); returns the checked estimates and, per frame, the tracker's step time and
    the observation's load time [s]."""
    estimates: list[Estimate] = []
    step_times = np.empty(n_frames)
    load_times = np.empty(n_frames)
    for k in range(n_frames):
        a = time.perf_counter()
        observation = stream.observation(k)
        if gate is not None:
            observation = gate.filter(observation)
        b = time.perf_counter()
        estimate = tracker.step(observation)
        c = time.perf_counter()
        estimates.append(_checked(estimate, k, tracker_name))
        load_times[k] = b - a
        step_times[k] = c - b
        if progress is not None:
            progress(1)
    return estimates, step_times, load_times


def _warm_up(renderer: LazyDepthRenderer, intrinsics: CameraIntrinsics) -> None:
    """Builds the depth renderer and draws once (the object half a metre ahead), so that a
    wall-clock run does not count the one-time set-up of MuJoCo and OpenGL as a step."""
    T_cam_obj = np.eye(4)
    T_cam_obj[2, 3] = 0.5
    renderer.render_depth(T_cam_obj[None], intrinsics)


def run_sequence(
    sequence: Sequence,
    options: RunOptions,
    *,
    spec: TrackerSpec | None = None,
    object_model: ObjectModel | None = None,
    depth_renderer_factory: DepthRendererFactory | None = None,
    progress: Callable[[int], object] | None = None,
    clock: WallClock | None = None,
) -> SequenceRun:
    """Runs ``options.tracker`` over ``sequence`` under ``options.faults``.

    Args:
        sequence: any :class:`~roft_sim.datasets.base.Sequence` (on disk or in memory).
        options: the run's configuration.
        spec: the tracker spec (default: looked up by ``options.tracker``; pass one to run a
            tracker that is not registered, e.g. in tests).
        object_model: the model handed to the tracker and used for scoring (default: the
            sequence's, else the registry's, :func:`resolve_object_model`).
        depth_renderer_factory: builds the depth renderer for trackers that need one (default:
            MuJoCo's, built lazily on the first render).
        progress: called with 1 after every frame (e.g. ``tqdm.update``).
        clock: None steps the tracker in lockstep with simulated time (deterministic); a
            :class:`~roft_sim.harness.wall_clock.WallClock` runs it against a real clock.

    Returns:
        The :class:`SequenceRun`.

    Raises:
        ConfigError: bad inputs (unknown pose/mask set, flow source, tracker config).
        PluginError: unknown tracker, or the tracker broke the protocol.
    """
    t0 = time.perf_counter()
    spec = spec if spec is not None else get_tracker_spec(options.tracker)
    model = object_model if object_model is not None else resolve_object_model(sequence)
    stream, inputs, seeds = make_observation_stream(
        sequence, options, detection_mode=spec.detection_mode
    )
    renderer = None
    if spec.needs_depth_renderer or options.init == "robust":
        renderer = LazyDepthRenderer(depth_renderer_factory or mujoco_depth_renderer, model)
    gate = None
    if options.init == "robust" and renderer is not None:
        gate = RobustStartGate(
            config=options.robust_start,
            renderer=renderer,
            intrinsics=sequence.intrinsics,
            fps=int(sequence.fps),
        )
    context = TrackerContext(
        intrinsics=sequence.intrinsics,
        fps=int(sequence.fps),
        object_model=model,
        rng=np.random.default_rng(seeds.tracker),
        depth_renderer=renderer if spec.needs_depth_renderer else None,
    )
    tracker = create_tracker(spec, context, options.tracker_config)
    try:
        ground_truth = sequence.ground_truth()
        tracker.reset(_initial_estimate(options, sequence.name, ground_truth))
        timeline = None
        if clock is None:
            estimates, step_times, load_times = _step_through(
                stream, tracker, len(sequence), spec.name, progress, gate
            )
        else:
            tracker_name = spec.name
            timeline, step_times, load_times = step_against_clock(
                stream,
                tracker,
                len(sequence),
                fps=int(sequence.fps),
                clock=clock,
                check=lambda estimate, k: _checked(estimate, k, tracker_name),
                gate=gate,
                progress=progress,
                warm_up=None
                if renderer is None
                else partial(_warm_up, renderer, sequence.intrinsics),
            )
            estimates = list(held_estimates(timeline.tracker_estimates, timeline.held_index()))
    finally:
        close_tracker(tracker)  # a tracker process exits (or is killed) and is reaped
    schedule = stream.schedule
    return SequenceRun(
        sequence_name=sequence.name,
        object_name=sequence.object_name,
        tracker=spec.name,
        intrinsics=sequence.intrinsics,
        fps=int(sequence.fps),
        estimates=tuple(estimates),
        step_times_s=step_times,
        load_times_s=load_times,
        ledger=stream.ledger,
        pose_deliveries=schedule.deliveries("pose"),
        mask_deliveries=schedule.deliveries("mask"),
        inputs=inputs.describe() | ({"init": gate.summary()} if gate is not None else {}),
        seeds=seeds,
        ground_truth=ground_truth,
        object_model=model,
        depth_renderer_built=renderer is not None and renderer.built,
        wall_s=time.perf_counter() - t0,
        wall_clock=timeline,
    )
