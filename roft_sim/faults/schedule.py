"""Fault schedules: the pure timing of every stream, without touching an image.

:func:`schedule_detections` turns a :class:`~roft_sim.faults.config.FaultConfig` into, for each
detection stream, the list of deliveries (which network run, true and reported capture frame,
arrival frame, content faults drawn) and one :class:`DetectionRecord` per network run, plus the
camera schedule (dropped frames, depth and flow faults per frame). It is cheap (no images), so
property tests can run it thousands of times, and it is what :class:`ObservationStream`
materialises.

Composition order of a detection stream (by stage, whatever the order of the list; within a
stage, in the listed order):

1. sampling: ``rate`` or ``busy`` (at most one) chooses the network runs (capture frames).
   Runs are numbered 0, 1, 2, ... in capture order: the ``detection_id``.
2. misses: runs on frames where the dataset's detector found nothing produce no detection.
3. loss: ``dropout``, ``burst_dropout``, ``blackout`` (on capture) -- union of drop masks,
   so they commute.
4. corruption: pose outliers / mask corruption, in listed order (it matters: a wrong-object
   pose or wrong-frame mask REPLACES what earlier faults did).
5. stamp: ``clock_skew`` -- time-stamp errors add up, then round once (they commute).
6. delay: processing time of ``busy`` + every delay fault -- delays add up (they commute).
   Then ``first_result`` may deliver run 0 at its capture frame.
7. delivery: ``duplicate``, ``stale``, ``reorder``, ``blackout`` (on arrival), in listed
   order (it matters).
8. deliveries arriving at or after ``n_frames`` are cut (fate ``after_end``).

Randomness: every fault draws from its own generator, a child of the run's
``SeedSequence`` keyed by (stream, fault kind, occurrence of that kind in the stream), so adding,
removing or reordering other faults never changes a fault's draws; each fault draws one value per
network run (or per camera frame), so its decision for run i never depends on other runs.
"""

from __future__ import annotations

import bisect
import dataclasses
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.errors import ConfigError
from roft_sim.faults.config import FaultConfig, FirstResult, MaskStreamFaults, PoseStreamFaults
from roft_sim.faults.delivery import apply_blackout_on_arrival
from roft_sim.faults.events import (
    Corruption,
    DeliveryEvent,
    DetectionRecord,
    StreamName,
)
from roft_sim.faults.loss import Blackout

I64 = NDArray[np.int64]
Bool = NDArray[np.bool_]
ValidSpec = ArrayLike | Callable[[I64], ArrayLike] | None

__all__ = [
    "CameraSchedule",
    "DetectionSchedule",
    "schedule_detections",
    "fault_rng",
    "root_seed_sequence",
]

_STREAM_KEYS = {"pose": 1, "mask": 2, "camera": 3, "flow": 4}


def root_seed_sequence(
    rng_seed: int | np.random.SeedSequence, faults: FaultConfig
) -> np.random.SeedSequence:
    """The seed sequence all faults derive from: ``faults.seed`` if set, else ``rng_seed``."""
    if faults.seed is not None:
        return np.random.SeedSequence(faults.seed)
    if isinstance(rng_seed, np.random.SeedSequence):
        return rng_seed
    if isinstance(rng_seed, bool) or not isinstance(rng_seed, int | np.integer) or rng_seed < 0:
        raise ConfigError(f"seed must be an integer >= 0 or a SeedSequence, got {rng_seed!r}")
    return np.random.SeedSequence(int(rng_seed))


def fault_rng(
    root: np.random.SeedSequence, stream: str, kind: str, occurrence: int
) -> np.random.Generator:
    """The generator of the ``occurrence``-th fault of ``kind`` in ``stream``.

    A child of ``root`` keyed by (stream, kind, occurrence), independent of the other faults.
    """
    key = (*root.spawn_key, _STREAM_KEYS[stream], zlib.crc32(kind.encode()), occurrence)
    return np.random.default_rng(np.random.SeedSequence(root.entropy, spawn_key=key))


def _fault_rngs(
    root: np.random.SeedSequence, stream: str, faults: tuple[Any, ...]
) -> list[np.random.Generator]:
    seen: dict[str, int] = {}
    rngs = []
    for f in faults:
        occurrence = seen.get(f.kind, 0)
        seen[f.kind] = occurrence + 1
        rngs.append(fault_rng(root, stream, f.kind, occurrence))
    return rngs


@dataclass(frozen=True, slots=True, kw_only=True)
class CameraSchedule:
    """What happens to each camera frame."""

    n_frames: int
    """Number of camera frames."""
    dropped: Bool
    """(N,) bool: True for camera frames that never reach the tracker (no rgb, depth, flow)."""
    dropped_by: tuple[str | None, ...]
    """(N,) the fault that dropped each frame (``camera.faults[i] (kind)``), or None."""
    depth: tuple[tuple[Corruption, ...], ...]
    """(N,) the depth faults applied to each frame, in order."""
    flow: tuple[tuple[Corruption, ...], ...]
    """(N,) the flow faults applied to the flow delivered with each frame, in order."""
    previous_delivered: I64
    """(N,) the last delivered camera frame before k (-1: none): the flow of frame k starts
    there, so after one dropped frame the stride is 2."""


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectionSchedule:
    """The complete timing of one run: deliveries and records per detection stream, and the
    camera schedule. Built by :func:`schedule_detections`; immutable."""

    n_frames: int
    """Number of camera frames."""
    fps: int
    """Camera rate [Hz]."""
    pose: tuple[DeliveryEvent, ...]
    """Pose deliveries in delivery order (non-decreasing ``arrival_k``)."""
    mask: tuple[DeliveryEvent, ...]
    """Mask deliveries in delivery order."""
    pose_records: tuple[DetectionRecord, ...]
    """One record per pose-network run, indexed by ``detection_id``."""
    mask_records: tuple[DetectionRecord, ...]
    """One record per mask-network run, indexed by ``detection_id``."""
    camera: CameraSchedule
    """Dropped camera frames and depth / flow faults."""

    def deliveries(self, stream: StreamName) -> tuple[DeliveryEvent, ...]:
        """All deliveries of ``stream`` in delivery order."""
        return self.pose if stream == "pose" else self.mask

    def records(self, stream: StreamName) -> tuple[DetectionRecord, ...]:
        """One record per network run of ``stream``, indexed by ``detection_id``."""
        return self.pose_records if stream == "pose" else self.mask_records

    def arriving_at(self, stream: StreamName, k: int) -> tuple[DeliveryEvent, ...]:
        """Deliveries of ``stream`` that arrive at camera frame ``k``, in delivery order."""
        events = self.deliveries(stream)
        arrivals = [e.arrival_k for e in events]
        lo = bisect.bisect_left(arrivals, k)
        hi = bisect.bisect_right(arrivals, k)
        return events[lo:hi]


def _valid_for(spec: ValidSpec, captures: I64, n_frames: int, stream: str) -> Bool:
    if spec is None:
        return np.ones(captures.shape[0], dtype=bool)
    if callable(spec):
        out = np.asarray(spec(captures), dtype=bool)
        if out.shape != captures.shape:
            raise ConfigError(
                f"{stream} validity function returned shape {out.shape} for "
                f"{captures.shape[0]} capture frames; it must return one bool per frame"
            )
        return out
    arr = np.asarray(spec)
    if arr.dtype != np.bool_ or arr.shape != (n_frames,):
        raise ConfigError(
            f"{stream} validity must be a ({n_frames},) bool array (one per camera frame), got "
            f"{arr.dtype} {arr.shape}"
        )
    return arr[captures]


def _fault_label(stream: StreamName, faults: Sequence[Any], i: int) -> str:
    """``pose.faults[2] (bursts)``: where a fault sits, for the records' causes."""
    return f"{stream}.faults[{i}] ({faults[i].kind})"


def _sample_runs(
    faults: Sequence[Any], rngs: Sequence[np.random.Generator], n_frames: int, fps: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Stage 1, sampling: the capture frame of every network run and its processing delay
    [frames] (every frame, no delay, without a sampling fault)."""
    captures = np.arange(n_frames, dtype=np.int64)
    delay = np.zeros(n_frames, dtype=np.int64)
    for f, rng in zip(faults, rngs, strict=True):
        if f.stage == "sampling":
            captures, delay = f.sample(n_frames, fps, rng)
    return captures, delay


def _lost_runs(
    stream: StreamName,
    faults: Sequence[Any],
    rngs: Sequence[np.random.Generator],
    captures: NDArray[np.int64],
) -> list[str | None]:
    """Stage 3, loss: per run, the label of the first loss fault that drops it, or None."""
    dropped_by: list[str | None] = [None] * captures.shape[0]
    for i, (f, rng) in enumerate(zip(faults, rngs, strict=True)):
        if f.stage == "loss":
            for r in np.flatnonzero(f.dropped(captures, rng)):
                dropped_by[r] = dropped_by[r] or _fault_label(stream, faults, i)
    return dropped_by


def _corrupted_runs(
    stream: StreamName,
    faults: Sequence[Any],
    rngs: Sequence[np.random.Generator],
    captures: NDArray[np.int64],
    n_frames: int,
) -> list[tuple[Corruption, ...]]:
    """Stage 4, corruption: per run, the corruptions drawn for it, in fault order."""
    corruptions: list[list[Corruption]] = [[] for _ in range(captures.shape[0])]
    for i, (f, rng) in enumerate(zip(faults, rngs, strict=True)):
        if f.stage == "corruption":
            source = f"{stream}.faults[{i}]"
            for r, params in enumerate(f.draw(captures, rng, n_frames)):
                if params is not None:
                    corruptions[r].append(Corruption(source=source, kind=f.kind, params=params))
    return [tuple(c) for c in corruptions]


def _stamped_and_delayed(
    faults: Sequence[Any],
    rngs: Sequence[np.random.Generator],
    captures: NDArray[np.int64],
    delay: NDArray[np.int64],
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Stages 5 and 6, stamp and delay: the capture frame each run reports and its arrival
    frame (the sampling delay plus every delay fault's)."""
    offset = np.zeros(captures.shape[0])
    for f, rng in zip(faults, rngs, strict=True):
        if f.stage == "stamp":
            offset += f.offsets(captures, rng)
        elif f.stage == "delay":
            delay = delay + f.delays(rng, captures.shape[0])
    reported = np.maximum(np.rint(captures + offset), 0).astype(np.int64)
    return reported, captures + delay


def _first_deliveries(
    stream: StreamName,
    first_result: FirstResult,
    capture_l: list[int],
    reported_l: list[int],
    arrival_l: list[int],
    kept: list[bool],
    corruptions: list[tuple[Corruption, ...]],
) -> list[DeliveryEvent]:
    """One delivery per kept run, in arrival order; the first run's as ``first_result`` says
    (at its capture frame, and again after the delay for ``undelayed_and_delayed``)."""
    events: list[DeliveryEvent] = []
    for r, keep in enumerate(kept):
        if not keep:
            continue
        base = DeliveryEvent(
            stream=stream,
            detection_id=r,
            true_capture_k=capture_l[r],
            reported_capture_k=reported_l[r],
            arrival_k=arrival_l[r],
            corruptions=corruptions[r],
        )
        if r == 0 and first_result != "delayed":
            events.append(dataclasses.replace(base, arrival_k=capture_l[0]))
            if first_result == "undelayed_and_delayed" and arrival_l[0] > capture_l[0]:
                events.append(dataclasses.replace(base, copy="repeat"))
        else:
            events.append(base)
    events.sort(key=lambda e: (e.arrival_k, e.true_capture_k))  # stable: repeat after original
    return events


def _delivered(
    stream: StreamName,
    faults: Sequence[Any],
    rngs: Sequence[np.random.Generator],
    events: list[DeliveryEvent],
    n_runs: int,
) -> tuple[list[DeliveryEvent], dict[int, tuple[str, str]]]:
    """Stage 7, delivery: the deliveries after the delivery faults, and per run they removed
    ``(fate, fault label)``."""
    removed_by: dict[int, tuple[str, str]] = {}
    for i, (f, rng) in enumerate(zip(faults, rngs, strict=True)):
        if f.stage != "delivery":
            continue
        if isinstance(f, Blackout):
            events, removed = apply_blackout_on_arrival(f, events)
        else:
            events, removed = f.deliver(events, rng, n_runs)
        for r, reason in removed.items():
            removed_by.setdefault(r, (reason, _fault_label(stream, faults, i)))
    return events, removed_by


def _detection_records(
    stream: StreamName,
    in_time: list[DeliveryEvent],
    late: set[int],
    valid_l: list[bool],
    dropped_by: list[str | None],
    removed_by: dict[int, tuple[str, str]],
    capture_l: list[int],
    reported_l: list[int],
    corruptions: list[tuple[Corruption, ...]],
) -> list[DetectionRecord]:
    """Stage 8: the fate of every run (missed, dropped, removed by a delivery fault, delivered,
    or arriving after the sequence's end) with its deliveries."""
    by_id: dict[int, list[DeliveryEvent]] = {}
    for e in in_time:
        by_id.setdefault(e.detection_id, []).append(e)
    records = []
    for r in range(len(valid_l)):
        fate, cause = "delivered", None
        if not valid_l[r]:
            fate = "missed"
        elif dropped_by[r] is not None:
            fate, cause = "dropped", dropped_by[r]
        elif r in by_id:
            fate = "delivered"
        elif r in removed_by:
            fate, cause = removed_by[r]
        elif r in late:
            fate = "after_end"
        else:  # pragma: no cover - every run lands in one branch above
            raise RuntimeError(f"{stream} run {r} has no fate")
        deliveries = by_id.get(r, [])
        records.append(
            DetectionRecord(
                stream=stream,
                detection_id=r,
                true_capture_k=capture_l[r],
                reported_capture_k=reported_l[r],
                fate=fate,  # type: ignore[arg-type]
                cause=cause,
                arrivals=tuple(e.arrival_k for e in deliveries),
                copies=tuple(e.copy for e in deliveries),
                corruptions=corruptions[r],
            )
        )
    return records


def _schedule_stream(
    stream: StreamName,
    cfg: PoseStreamFaults | MaskStreamFaults,
    n_frames: int,
    fps: int,
    root: np.random.SeedSequence,
    valid_spec: ValidSpec,
    ideal: bool,
) -> tuple[tuple[DeliveryEvent, ...], tuple[DetectionRecord, ...]]:
    """The deliveries and per-run records of one detection stream, stage by stage
    (docs/faults.md). ``ideal`` ("detector ideal"): every frame, at its own frame, no stamp,
    delay or delivery faults."""
    faults = cfg.faults
    rngs = _fault_rngs(root, stream, faults)
    if ideal:
        captures = np.arange(n_frames, dtype=np.int64)
        delay = np.zeros(n_frames, dtype=np.int64)
    else:
        captures, delay = _sample_runs(faults, rngs, n_frames, fps)  # 1. sampling
    n_runs = captures.shape[0]
    valid = _valid_for(valid_spec, captures, n_frames, stream)  # 2. misses
    dropped_by = _lost_runs(stream, faults, rngs, captures)  # 3. loss
    corruptions = _corrupted_runs(stream, faults, rngs, captures, n_frames)  # 4. corruption
    if ideal:
        reported, arrival = captures.copy(), captures + delay
    else:
        reported, arrival = _stamped_and_delayed(faults, rngs, captures, delay)  # 5., 6.
    # plain Python values from here on (per-run loops over numpy scalars are slow)
    capture_l, reported_l, arrival_l = captures.tolist(), reported.tolist(), arrival.tolist()
    valid_l = valid.tolist()
    kept = [v and d is None for v, d in zip(valid_l, dropped_by, strict=True)]
    events = _first_deliveries(
        stream,
        "delayed" if ideal else cfg.first_result,
        capture_l,
        reported_l,
        arrival_l,
        kept,
        corruptions,
    )
    removed_by: dict[int, tuple[str, str]] = {}
    if not ideal:
        events, removed_by = _delivered(stream, faults, rngs, events, n_runs)  # 7. delivery
    # 8. the end of the sequence
    in_time = [e for e in events if e.arrival_k < n_frames]
    late = {e.detection_id for e in events if e.arrival_k >= n_frames}
    records = _detection_records(
        stream,
        in_time,
        late,
        valid_l,
        dropped_by,
        removed_by,
        capture_l,
        reported_l,
        corruptions,
    )
    return tuple(in_time), tuple(records)


def _schedule_camera(
    faults: FaultConfig, n_frames: int, root: np.random.SeedSequence
) -> CameraSchedule:
    frames = np.arange(n_frames, dtype=np.int64)
    dropped_by: list[str | None] = [None] * n_frames
    depth: list[list[Corruption]] = [[] for _ in range(n_frames)]
    flow: list[list[Corruption]] = [[] for _ in range(n_frames)]
    for stream, per_frame in (("camera", depth), ("flow", flow)):
        stream_faults = getattr(faults, stream).faults
        for i, (f, rng) in enumerate(
            zip(stream_faults, _fault_rngs(root, stream, stream_faults), strict=True)
        ):
            if f.stage == "loss":
                for frame in np.flatnonzero(f.dropped(frames, rng)):
                    dropped_by[frame] = dropped_by[frame] or f"{stream}.faults[{i}] ({f.kind})"
            else:
                source = f"{stream}.faults[{i}]"
                for k, params in enumerate(f.draw_frames(n_frames, rng)):
                    if params is not None:
                        per_frame[k].append(Corruption(source=source, kind=f.kind, params=params))
    dropped = np.array([d is not None for d in dropped_by], dtype=bool)
    # previous delivered frame: running maximum of the delivered indices, shifted by one
    delivered_index = np.where(dropped, -1, np.arange(n_frames))
    previous = np.full(n_frames, -1, dtype=np.int64)
    if n_frames > 1:
        previous[1:] = np.maximum.accumulate(delivered_index)[:-1]
    return CameraSchedule(
        n_frames=n_frames,
        dropped=dropped,
        dropped_by=tuple(dropped_by),
        depth=tuple(tuple(c) for c in depth),
        flow=tuple(tuple(c) for c in flow),
        previous_delivered=previous,
    )


def schedule_detections(
    n_frames: int,
    faults: FaultConfig,
    rng_seed: int | np.random.SeedSequence,
    *,
    valid: ValidSpec | Mapping[str, ValidSpec] = None,
    fps: int = 30,
    ideal_detections: bool = False,
) -> DetectionSchedule:
    """The timing of every stream over ``n_frames`` camera frames (pure, no images).

    Args:
        n_frames: number of camera frames, >= 0.
        faults: the fault configuration.
        rng_seed: the run's seed (an int >= 0 or a ``SeedSequence``); ignored when
            ``faults.seed`` is set.
        valid: which frames the dataset's detectors found something on: None (all), one
            ``(n_frames,)`` bool array for both streams, or ``{"pose": ..., "mask": ...}`` where
            each entry is a ``(n_frames,)`` bool array or a function from capture frames ``(R,)``
            int to ``(R,)`` bool (so a lazy reader checks only the frames the network runs on).
        fps: camera rate [Hz]; every ``rate_hz`` must divide it.
        ideal_detections: the "detector ideal" baseline: every frame's detection arrives at its
            own frame (sampling, stamp, delay and delivery faults are ignored; loss and content
            faults still apply).

    Returns:
        The :class:`DetectionSchedule`.

    Raises:
        ConfigError: bad ``n_frames``, ``fps``, seed or validity, or a rate that does not divide
            ``fps``.
    """
    if isinstance(n_frames, bool) or not isinstance(n_frames, int | np.integer) or n_frames < 0:
        raise ConfigError(f"n_frames must be an integer >= 0, got {n_frames!r}")
    n_frames = int(n_frames)
    faults.check_camera_rate(fps)
    root = root_seed_sequence(rng_seed, faults)
    if isinstance(valid, Mapping):
        unknown = set(valid) - {"pose", "mask"}
        if unknown:
            raise ConfigError(f"valid has unknown streams {sorted(unknown)}; use 'pose', 'mask'")
        valid_by_stream = {s: valid.get(s) for s in ("pose", "mask")}
    else:
        valid_by_stream = {"pose": valid, "mask": valid}
    pose, pose_records = _schedule_stream(
        "pose", faults.pose, n_frames, fps, root, valid_by_stream["pose"], ideal_detections
    )
    mask, mask_records = _schedule_stream(
        "mask", faults.mask, n_frames, fps, root, valid_by_stream["mask"], ideal_detections
    )
    return DetectionSchedule(
        n_frames=n_frames,
        fps=fps,
        pose=pose,
        mask=mask,
        pose_records=pose_records,
        mask_records=mask_records,
        camera=_schedule_camera(faults, n_frames, root),
    )
