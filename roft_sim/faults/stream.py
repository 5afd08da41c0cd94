"""The observation stream: what a tracker sees, frame by frame.

:class:`ObservationStream` turns a :class:`~roft_sim.datasets.base.Sequence` (detector outputs on
every frame, as in Fast-YCB) and a :class:`~roft_sim.faults.config.FaultConfig` into one
:class:`~roft_sim.records.Observation` per camera frame: time stamp, rgb, depth, the flow from
the previous DELIVERED camera frame, and the pose and mask detections that ARRIVE at that frame.
Frames are materialised lazily (one image read at a time); the timing comes from
:func:`~roft_sim.faults.schedule.schedule_detections`.

Ground truth never enters an observation; the sequence is never modified (images are handed out
as read-only views, corrupted copies are new arrays). The :attr:`ObservationStream.ledger` says,
for the harness and the metrics, what happened to every detection.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.base import GT_MASK_SET, Sequence
from roft_sim.datasets.frames import GT_FULL_MASK_SET
from roft_sim.errors import ConfigError, RoftSimError
from roft_sim.faults.config import FaultConfig
from roft_sim.faults.content import CorruptionContext
from roft_sim.faults.events import Corruption, DeliveryEvent, DetectionRecord, StreamName
from roft_sim.faults.schedule import CameraSchedule, DetectionSchedule, schedule_detections
from roft_sim.records import FlowField, MaskDetection, Observation, PoseDetection
from roft_sim.sensors.flow_sources import FlowSource

I64 = NDArray[np.int64]
Bool = NDArray[np.bool_]

__all__ = ["FlowSource", "FaultLedger", "ObservationStream"]

_SOURCE = re.compile(r"^(pose|mask|camera|flow)\.faults\[(\d+)\]$")


@dataclass(frozen=True, slots=True, kw_only=True)
class FaultLedger:
    """What happened to every detection and camera frame of one stream (for harness/metrics).

    Holds ground truth about the faults (true capture frames, injected outliers): never hand it
    to a tracker.
    """

    pose: tuple[DetectionRecord, ...]
    """One record per pose-network run, indexed by ``detection_id``."""
    mask: tuple[DetectionRecord, ...]
    """One record per mask-network run, indexed by ``detection_id``."""
    camera: CameraSchedule
    """Dropped camera frames and depth / flow faults per frame."""

    def records(self, stream: StreamName) -> tuple[DetectionRecord, ...]:
        """Records of ``stream`` (``pose`` or ``mask``)."""
        return self.pose if stream == "pose" else self.mask

    def record(self, stream: StreamName, detection_id: int) -> DetectionRecord:
        """The record of one detection."""
        return self.records(stream)[detection_id]

    def outlier_ids(self) -> frozenset[int]:
        """``detection_id`` of every pose into which an outlier was injected (delivered or not)."""
        return frozenset(r.detection_id for r in self.pose if r.is_outlier)

    def corrupted_mask_ids(self) -> frozenset[int]:
        """``detection_id`` of every mask that was corrupted."""
        return frozenset(r.detection_id for r in self.mask if r.is_mask_corrupted)

    def summary(self) -> dict[str, Any]:
        """Counts per stream and fate, outliers, duplicates and camera faults (JSON-ready)."""
        out: dict[str, Any] = {}
        for stream in ("pose", "mask"):
            records = self.records(stream)
            fates: dict[str, int] = {}
            for r in records:
                fates[r.fate] = fates.get(r.fate, 0) + 1
            delays = [a - r.true_capture_k for r in records for a in r.arrivals]
            out[stream] = {
                "runs": len(records),
                "fates": fates,
                "deliveries": sum(len(r.arrivals) for r in records),
                "duplicates": sum(c == "duplicate" for r in records for c in r.copies),
                "stale": sum(c == "stale" for r in records for c in r.copies),
                "outliers": sum(r.is_outlier for r in records),
                "corrupted": sum(bool(r.corruptions) for r in records),
                "mean_delay_frames": float(np.mean(delays)) if delays else None,
                "max_delay_frames": int(max(delays)) if delays else None,
            }
        cam = self.camera
        out["camera"] = {
            "frames": cam.n_frames,
            "dropped": int(cam.dropped.sum()),
            "depth_faulted": sum(bool(c) for c in cam.depth),
            "flow_faulted": sum(bool(c) for c in cam.flow),
        }
        return out


def _read_only(a: np.ndarray) -> np.ndarray:
    view = a.view()
    view.flags.writeable = False
    return view


class ObservationStream:
    """Iterable of :class:`~roft_sim.records.Observation`, one per camera frame, lazily
    materialised from a sequence under a fault configuration.

    Args:
        sequence: the dataset sequence (any format).
        faults: the fault configuration (e.g. ``load_faults("paper")``).
        seed: the run's seed (int >= 0 or a ``SeedSequence``); ignored if ``faults.seed`` is set.
        flow_source: where flow comes from; None = no flow in the observations.
        pose_set: the sequence's detector pose set; None = no pose detections.
        mask_set: the sequence's mask set; ``"auto"`` = its first detector set (neither ``gt``
            nor ``gt_full``; an error if it has none); ``"gt"`` = ground-truth masks (an
            ablation); None = no mask detections.
        include_rgb: False leaves ``rgb`` None on every observation (saves reading images for
            trackers that do not use them).
        ideal_detections: the "detector ideal" baseline: every frame's detection arrives at its
            own frame (rate, delay and delivery faults ignored; loss and content faults kept).

    Raises:
        ConfigError: unknown pose or mask set (listing the available ones), or a rate that does
            not divide the sequence's fps.
    """

    def __init__(
        self,
        sequence: Sequence,
        faults: FaultConfig,
        *,
        seed: int | np.random.SeedSequence,
        flow_source: FlowSource | None,
        pose_set: str | None = "dope",
        mask_set: str | None = "auto",
        include_rgb: bool = True,
        ideal_detections: bool = False,
    ) -> None:
        self.sequence = sequence
        self.faults = faults
        self.seed = seed
        self.flow_source = flow_source
        self.include_rgb = include_rgb
        self.ideal_detections = ideal_detections
        self.pose_set = self._resolve_pose_set(pose_set)
        self.mask_set = self._resolve_mask_set(mask_set)
        faults.check_camera_rate(int(sequence.fps))
        self._schedule: DetectionSchedule | None = None
        self._detector_T: np.ndarray | None = None

    # ------------------------------------------------------------ set-up

    def _resolve_pose_set(self, pose_set: str | None) -> str | None:
        if pose_set is None:
            return None
        available = tuple(self.sequence.pose_sets())
        if pose_set not in available:
            raise ConfigError(
                f"sequence {self.sequence.name!r} has no pose set {pose_set!r}; available: "
                f"{list(available)} (or pose_set=None for no pose detections)"
            )
        return pose_set

    def _resolve_mask_set(self, mask_set: str | None) -> str | None:
        if mask_set is None:
            return None
        available = tuple(self.sequence.mask_sets())
        if mask_set == "auto":
            detectors = [s for s in available if s not in (GT_MASK_SET, GT_FULL_MASK_SET)]
            if not detectors:
                raise ConfigError(
                    f"sequence {self.sequence.name!r} has no detector mask set (only "
                    f"{list(available)}); pass mask_set='{GT_MASK_SET}' for ground-truth masks "
                    "or mask_set=None for no masks"
                )
            return detectors[0]
        if mask_set not in available:
            raise ConfigError(
                f"sequence {self.sequence.name!r} has no mask set {mask_set!r}; available: "
                f"{list(available)} (or mask_set=None for no masks)"
            )
        return mask_set

    def _read_mask(self, k: int) -> Bool | None:
        assert self.mask_set is not None
        return self.sequence.mask(int(k), self.mask_set)

    def _mask_valid(self, captures: I64) -> Bool:
        return np.array([self._read_mask(int(c)) is not None for c in captures], dtype=bool)

    @property
    def schedule(self) -> DetectionSchedule:
        """The timing of every stream (computed on first use; reads masks only on the frames
        the mask network runs on, to find the detector's misses)."""
        if self._schedule is None:
            n = len(self.sequence)
            pose_valid: Any
            if self.pose_set is None:
                pose_valid = np.zeros(n, dtype=bool)
            else:
                detector = self.sequence.detector_poses(self.pose_set)
                if len(detector) != n:
                    raise RoftSimError(
                        f"pose set {self.pose_set!r} of {self.sequence.name!r} has "
                        f"{len(detector)} rows for {n} frames"
                    )
                self._detector_T = detector.T_cam_obj
                pose_valid = np.asarray(detector.valid, dtype=bool)
            mask_valid: Any = np.zeros(n, dtype=bool) if self.mask_set is None else self._mask_valid
            self._schedule = schedule_detections(
                n,
                self.faults,
                self.seed,
                valid={"pose": pose_valid, "mask": mask_valid},
                fps=int(self.sequence.fps),
                ideal_detections=self.ideal_detections,
            )
        return self._schedule

    @property
    def ledger(self) -> FaultLedger:
        """Per-detection records (fates, true capture frames, injected outliers) and the camera
        schedule, for the harness and metrics. Never give it to a tracker."""
        s = self.schedule
        return FaultLedger(pose=s.pose_records, mask=s.mask_records, camera=s.camera)

    # ------------------------------------------------------------ materialisation

    def _fault(self, corruption: Corruption) -> Any:
        m = _SOURCE.match(corruption.source)
        if m is None:  # pragma: no cover - sources are written by the scheduler
            raise RoftSimError(f"bad fault source {corruption.source!r}")
        return getattr(self.faults, m.group(1)).faults[int(m.group(2))]

    def _context(self) -> CorruptionContext:
        return CorruptionContext(
            intrinsics=self.sequence.intrinsics,
            n_frames=len(self.sequence),
            read_mask=self._read_mask if self.mask_set is not None else (lambda k: None),
        )

    def _pose(self, event: DeliveryEvent, ctx: CorruptionContext) -> PoseDetection:
        assert self._detector_T is not None
        T = np.array(self._detector_T[event.true_capture_k], dtype=np.float64)
        for c in event.corruptions:
            T = self._fault(c).apply_pose(T, c.params, ctx)
        return PoseDetection(
            capture_k=event.reported_capture_k,
            arrival_k=event.arrival_k,
            T_cam_obj=T,
            detection_id=event.detection_id,
        )

    def _mask(self, event: DeliveryEvent, ctx: CorruptionContext) -> MaskDetection:
        mask = self._read_mask(event.true_capture_k)
        if mask is None:  # the schedule only delivers frames whose mask exists
            raise RoftSimError(
                f"mask set {self.mask_set!r} of {self.sequence.name!r} returned no mask for "
                f"frame {event.true_capture_k} although it had one when scheduled"
            )
        for c in event.corruptions:
            mask = self._fault(c).apply_mask(mask, c.params, ctx)
        return MaskDetection(
            capture_k=event.reported_capture_k,
            arrival_k=event.arrival_k,
            mask=_read_only(mask),
            detection_id=event.detection_id,
        )

    def flow_since(self, previous: int, k: int) -> FlowField | None:
        """The flow camera frame ``k`` carries when the last frame with images before it was
        ``previous`` (-1: none), with frame ``k``'s flow faults applied.

        :meth:`observation` passes the last frame the camera delivered; a harness that lets a
        busy tracker miss frames passes the last frame the tracker saw.
        """
        camera = self.schedule.camera
        if self.flow_source is None or previous < 0:
            return None
        backward = any(c.params.get("backward") for c in camera.flow[k])
        pair = (k, previous) if backward else (previous, k)
        flow = self.flow_source.flow(self.sequence, *pair)
        if flow is None:
            return None
        if (flow.from_k, flow.to_k) != pair:
            raise RoftSimError(
                f"flow source {self.flow_source.name!r} returned the flow {flow.from_k}->"
                f"{flow.to_k} when asked for {pair[0]}->{pair[1]}"
            )
        for c in camera.flow[k]:
            flow = self._fault(c).apply_flow(flow, c.params)
        return flow

    def observation(self, k: int) -> Observation:
        """The observation of camera frame ``k`` (random access; iteration calls this)."""
        n = len(self.sequence)
        if not 0 <= k < n:
            raise IndexError(f"frame {k} out of range for a sequence of {n} frames")
        schedule = self.schedule
        camera = schedule.camera
        rgb = depth = flow = None
        if not camera.dropped[k]:
            if self.include_rgb:
                rgb = _read_only(np.asarray(self.sequence.rgb(k)))
            depth = np.asarray(self.sequence.depth(k))
            for c in camera.depth[k]:
                depth = self._fault(c).apply_depth(depth, c.params)
            depth = _read_only(depth)
            flow = self.flow_since(int(camera.previous_delivered[k]), k)
        ctx = self._context()
        poses = tuple(self._pose(e, ctx) for e in schedule.arriving_at("pose", k))
        masks = tuple(self._mask(e, ctx) for e in schedule.arriving_at("mask", k))
        return Observation(
            k=k,
            t_s=float(self.sequence.time_s(k)),
            rgb=rgb,
            depth_m=depth,
            flow=flow,
            poses=poses,
            masks=masks,
        )

    def __len__(self) -> int:
        return len(self.sequence)

    def __iter__(self) -> Iterator[Observation]:
        for k in range(len(self.sequence)):
            yield self.observation(k)
