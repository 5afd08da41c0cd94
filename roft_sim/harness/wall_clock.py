"""Running a tracker against a real clock: ``roft-sim run --clock wall`` (docs/wall_clock.md).

Three threads share the run:

- the **loader** builds each frame's :class:`~roft_sim.records.Observation` (images, flow, the
  detections that arrive at that frame, as in ``--clock sim``) ahead of its release, into a
  buffer of :attr:`WallClock.prefetch_mib`; the clock starts once the buffer is full (or holds
  the whole sequence), so reading and decoding files competes as little as possible with the
  tracker for the CPU and the GIL;
- the **clock** (the calling thread) releases frame k at ``k / fps`` on the run's clock, i.e.
  ``time_scale * k / fps`` wall seconds after frame 0; a detection scheduled to arrive at frame
  ``arrival_k`` is released with that frame, at ``arrival_k / fps``;
- the **worker** steps the tracker whenever it is free. Under ``drop`` it takes every frame
  released since its last step: the newest with its images, the older ones (which the camera
  driver dropped while the tracker was busy) as frames without images that still carry the
  detections that arrived with them, so steps keep increasing ``k`` without gaps and no detection
  is lost; the flow of the newest then spans from the last frame the tracker saw. Under
  ``queue`` it takes the oldest waiting frame: the tracker gets exactly the observations of
  ``--clock sim``, late.

Each estimate's delivery time is taken when ``step`` returns. The run's estimates are the ones a
consumer holds at each frame's deadline (:func:`~roft_sim.metrics.deadlines.held_at_deadlines`);
the tracker's own are kept in :attr:`WallClockTimeline.tracker_estimates`. Wall mode is not
deterministic: the timing, so the scores, depend on the machine and its load.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal, get_args

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.faults import ObservationStream
from roft_sim.harness.robust_start import RobustStartGate
from roft_sim.metrics.deadlines import (
    DeadlineStats,
    deadline_stats,
    frame_deadlines_s,
    held_at_deadlines,
)
from roft_sim.records import Estimate, Observation
from roft_sim.trackers import Tracker

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
Bool = NDArray[np.bool_]

__all__ = [
    "CLOCK_MODES",
    "WHEN_BUSY",
    "WallClock",
    "WallClockTimeline",
    "WhenBusy",
    "clock_record",
    "held_estimates",
    "step_against_clock",
]

WhenBusy = Literal["drop", "queue"]
WHEN_BUSY: tuple[str, ...] = get_args(WhenBusy)
"""``drop``: a camera driver that keeps only the newest frame; ``queue``: one that keeps all."""
CLOCK_MODES = ("sim", "wall")
"""``--clock`` choices: lockstep simulated time (deterministic) or a real clock."""


@dataclass(frozen=True, slots=True, kw_only=True)
class WallClock:
    """How a wall-clock run releases frames and what it does while the tracker is busy."""

    time_scale: float = 1.0
    """Wall seconds per second of the run's clock: 2 gives the tracker twice the wall time per
    frame (a machine twice as fast), 0.5 half (a machine twice as slow, or a camera twice as
    fast). Every time reported is on the run's clock."""
    when_busy: WhenBusy = "drop"
    """What happens to frames released while the tracker is still busy (see :data:`WHEN_BUSY`)."""
    prefetch_mib: int = 1024
    """Memory for observations built ahead of their release [MiB] (at least one is)."""

    def __post_init__(self) -> None:
        scale = self.time_scale
        if isinstance(scale, bool) or not isinstance(scale, int | float):
            raise ConfigError(f"time scale must be a number, got {scale!r}")
        if not (math.isfinite(scale) and scale > 0):
            raise ConfigError(
                f"time scale must be finite and > 0, got {scale!r}; e.g. --time-scale 2 runs the "
                "clock twice slower, 0.5 twice faster"
            )
        if self.when_busy not in WHEN_BUSY:
            raise ConfigError(
                f"unknown when-busy policy {self.when_busy!r}; expected one of {WHEN_BUSY}"
            )
        if isinstance(self.prefetch_mib, bool) or self.prefetch_mib < 0:
            raise ConfigError(f"prefetch_mib must be an integer >= 0, got {self.prefetch_mib!r}")

    def describe(self) -> dict[str, Any]:
        """JSON-ready record for ``run.json`` and ``metrics.json``."""
        return {"mode": "wall", "time_scale": float(self.time_scale), "when_busy": self.when_busy}


@dataclass(frozen=True, slots=True, kw_only=True)
class WallClockTimeline:
    """When each frame was released, stepped and answered, on the run's clock [s]."""

    clock: WallClock
    """The clock's settings."""
    fps: int
    """Camera rate [Hz]: frame k is due at ``k / fps``."""
    release_s: F64
    """(N,) when frame k was released (``k / fps`` plus the harness's own lag)."""
    started_s: F64
    """(N,) when the tracker's step for frame k began."""
    delivered_s: F64
    """(N,) when the tracker's estimate for frame k was delivered (``step`` returned)."""
    seen: Bool
    """(N,) True where the tracker got frame k's images."""
    dropped_busy: Bool
    """(N,) True where the tracker was busy and frame k's images were dropped (``drop``)."""
    queue_max: int | None
    """Under ``queue``, the most frames still waiting for the tracker when the next one was
    released (0: it always kept up); None under ``drop``."""
    tracker_estimates: tuple[Estimate, ...]
    """The tracker's own estimate for each frame, ``tracker_estimates[k].k == k``."""

    def held_index(self) -> I64:
        """(N,) frame whose estimate a consumer holds at frame k's deadline; -1 for none."""
        return held_at_deadlines(self.delivered_s, frame_deadlines_s(len(self.release_s), self.fps))

    def stats(self) -> DeadlineStats:
        """Latency, deadline misses, dropped frames and queue length (docs/wall_clock.md)."""
        return deadline_stats(
            release_s=self.release_s,
            delivered_s=self.delivered_s,
            seen=self.seen,
            dropped_busy=self.dropped_busy,
            fps=self.fps,
            queue_max=self.queue_max,
        )


def held_estimates(
    tracker_estimates: tuple[Estimate, ...], held_index: NDArray[np.integer]
) -> tuple[Estimate, ...]:
    """The estimate scored at each frame: the tracker's estimate of frame ``held_index[k]``
    relabelled as frame k (pose and velocity unchanged, pose ids cleared so that a held estimate
    does not count its fused poses twice, ``diagnostics["held_from_k"]`` saying which frame it
    was computed for); an invalid estimate where ``held_index[k] < 0``."""
    out = []
    for k, j in enumerate(int(x) for x in held_index):
        if j < 0:
            out.append(Estimate.invalid(k, diagnostics={"held_from_k": -1}))
            continue
        e = tracker_estimates[j]
        diagnostics = {**e.diagnostics, "held_from_k": j}
        if j == k:
            out.append(dataclasses.replace(e, diagnostics=diagnostics))
        else:
            out.append(
                dataclasses.replace(
                    e,
                    k=k,
                    accepted_pose_ids=(),
                    rejected_pose_ids=(),
                    dropped_pose_ids=(),
                    diagnostics=diagnostics,
                )
            )
    return tuple(out)


def clock_record(clock: WallClock | None) -> dict[str, Any]:
    """What ``run.json`` and ``metrics.json`` record of a run's clock (None: ``--clock sim``)."""
    return {"mode": "sim"} if clock is None else clock.describe()


class _Stopped(Exception):
    """Another thread failed; the clock stops releasing frames."""


def _nbytes(observation: Observation) -> int:
    """Bytes of the arrays of an observation (images, flow, masks)."""
    arrays = [observation.rgb, observation.depth_m, *(m.mask for m in observation.masks)]
    if observation.flow is not None:
        arrays += [observation.flow.flow_px, observation.flow.valid]
    return sum(a.nbytes for a in arrays if a is not None)


class _Prefetched:
    """Observations built ahead of their release, within a memory budget (thread-safe)."""

    def __init__(self, budget_bytes: int, stop: threading.Event) -> None:
        self._budget = budget_bytes
        self._stop = stop
        self._changed = threading.Condition()
        self._items: deque[tuple[Observation, int]] = deque()
        self._bytes = 0
        self.full = False
        """True once the loader has waited for room or built every frame."""

    def put(self, observation: Observation) -> bool:
        """Adds one (waiting for room); False when the run stopped meanwhile."""
        size = _nbytes(observation)
        with self._changed:
            while self._items and self._bytes + size > self._budget:
                self.full = True
                if self._stop.is_set():
                    return False
                self._changed.wait(0.05)
            self._items.append((observation, size))
            self._bytes += size
            self._changed.notify_all()
            return True

    def finish(self) -> None:
        """The loader has built every frame."""
        with self._changed:
            self.full = True
            self._changed.notify_all()

    def get(self) -> Observation:
        """The next observation (waiting for the loader)."""
        with self._changed:
            while not self._items:
                if self._stop.is_set():
                    raise _Stopped
                self._changed.wait(0.05)
            observation, size = self._items.popleft()
            self._bytes -= size
            self._changed.notify_all()
            return observation


class _Inbox:
    """Frames released to the tracker and not yet taken (thread-safe)."""

    def __init__(self, when_busy: WhenBusy, stop: threading.Event) -> None:
        self._when_busy = when_busy
        self._stop = stop
        self._ready = threading.Condition()
        self._waiting: deque[tuple[Observation, bool]] = deque()
        self._closed = False
        self.backlog_max = 0
        """Most frames still waiting when the next one was released (0: the tracker kept up)."""

    def put(self, observation: Observation) -> None:
        """Releases a frame; under ``drop`` the frames still waiting lose their images."""
        with self._ready:
            self.backlog_max = max(self.backlog_max, len(self._waiting))
            if self._when_busy == "drop":
                self._waiting = deque((o, True) for o, _ in self._waiting)
            self._waiting.append((observation, False))
            self._ready.notify()

    def close(self) -> None:
        """No more frames: :meth:`take` returns None once the waiting ones are taken."""
        with self._ready:
            self._closed = True
            self._ready.notify()

    def take(self) -> list[tuple[Observation, bool]] | None:
        """Waits for frames; returns ``(observation, dropped)`` pairs to step in order (under
        ``drop`` every waiting frame, under ``queue`` the oldest), or None at the end."""
        with self._ready:
            while not self._waiting and not self._closed and not self._stop.is_set():
                self._ready.wait(0.1)
            if self._stop.is_set() or not self._waiting:
                return None
            if self._when_busy == "drop":
                batch = list(self._waiting)
                self._waiting.clear()
                return batch
            return [self._waiting.popleft()]


class _Run:
    """The shared state of one wall-clock run (see the module docstring)."""

    def __init__(
        self,
        stream: ObservationStream,
        tracker: Tracker,
        n_frames: int,
        fps: int,
        clock: WallClock,
        check: Callable[[object, int], Estimate],
        gate: RobustStartGate | None,
        progress: Callable[[int], object] | None,
        warm_up: Callable[[], object] | None,
    ) -> None:
        self.stream = stream
        self.warm_up = warm_up
        self.worker_ready = threading.Event()
        self.tracker = tracker
        self.n = n_frames
        self.fps = fps
        self.clock = clock
        self.check = check
        self.gate = gate
        self.progress = progress
        self.stop = threading.Event()
        self.errors: list[BaseException] = []
        self.stream_lock = threading.Lock()  # flow sources and readers are not thread-safe
        self.loaded = _Prefetched(clock.prefetch_mib << 20, self.stop)
        self.inbox = _Inbox(clock.when_busy, self.stop)
        self.t0 = 0.0
        nan = np.full(n_frames, np.nan)
        self.release_s, self.started_s, self.delivered_s = nan.copy(), nan.copy(), nan.copy()
        self.step_times_s, self.load_times_s = nan.copy(), nan.copy()
        self.seen = np.zeros(n_frames, dtype=bool)
        self.dropped = np.zeros(n_frames, dtype=bool)
        self.estimates: list[Estimate | None] = [None] * n_frames

    def now_s(self) -> float:
        """Seconds on the run's clock since frame 0 was released."""
        return (time.perf_counter() - self.t0) / self.clock.time_scale

    def fail(self, error: BaseException) -> None:
        self.errors.append(error)
        self.stop.set()

    # ------------------------------------------------------------------ loader thread
    def load(self) -> None:
        try:
            for k in range(self.n):
                a = time.perf_counter()
                with self.stream_lock:
                    observation = self.stream.observation(k)
                self.load_times_s[k] = time.perf_counter() - a
                if not self.loaded.put(observation):
                    return
            self.loaded.finish()
        except BaseException as e:  # handed to the clock thread, which raises it
            self.fail(e)

    # ------------------------------------------------------------------ worker thread
    def work(self) -> None:
        previous = self.stream.schedule.camera.previous_delivered
        last_seen = -1
        try:
            if self.warm_up is not None:
                self.warm_up()
            self.worker_ready.set()
            while (batch := self.inbox.take()) is not None:
                for observation, dropped in batch:
                    k = observation.k
                    if self.gate is not None:  # it keeps the depth of every captured frame
                        observation = self.gate.filter(observation)
                    if dropped:
                        observation = dataclasses.replace(
                            observation, rgb=None, depth_m=None, flow=None
                        )
                    elif observation.depth_m is not None and int(previous[k]) != last_seen:
                        with self.stream_lock:  # the flow must start at the last frame seen
                            flow = self.stream.flow_since(last_seen, k)
                        observation = dataclasses.replace(observation, flow=flow)
                    self.started_s[k] = self.now_s()
                    a = time.perf_counter()
                    estimate = self.tracker.step(observation)
                    b = time.perf_counter()
                    self.delivered_s[k] = self.now_s()
                    self.estimates[k] = self.check(estimate, k)
                    self.step_times_s[k] = b - a
                    self.dropped[k] = dropped
                    self.seen[k] = observation.depth_m is not None
                    if self.seen[k]:
                        last_seen = k
                    if self.progress is not None:
                        self.progress(1)
        except BaseException as e:  # handed to the clock thread, which raises it
            self.fail(e)

    # ------------------------------------------------------------------ clock (calling thread)
    def release_all(self) -> None:
        period_wall_s = self.clock.time_scale / self.fps
        # the clock starts once the tracker has set itself up and the prefetch buffer is full
        while not (self.worker_ready.is_set() and self.loaded.full):
            if self.stop.wait(0.005):
                raise _Stopped
        for k in range(self.n):
            observation = self.loaded.get()
            if k == 0:
                self.t0 = time.perf_counter()
            wait_s = self.t0 + k * period_wall_s - time.perf_counter()
            if wait_s > 0 and self.stop.wait(wait_s):
                raise _Stopped
            self.release_s[k] = self.now_s()
            self.inbox.put(observation)

    def run(self) -> None:
        self.stream.schedule  # noqa: B018  # computed here, before the threads share the stream
        threads = [
            threading.Thread(target=self.load, name="roft-sim-loader", daemon=True),
            threading.Thread(target=self.work, name="roft-sim-tracker", daemon=True),
        ]
        for thread in threads:
            thread.start()
        try:
            self.release_all()
            self.inbox.close()
            threads[1].join()
        except _Stopped:
            pass
        finally:
            self.stop.set()
            self.inbox.close()
        threads[0].join()
        if self.errors:
            raise self.errors[0]


def step_against_clock(
    stream: ObservationStream,
    tracker: Tracker,
    n_frames: int,
    *,
    fps: int,
    clock: WallClock,
    check: Callable[[object, int], Estimate],
    gate: RobustStartGate | None = None,
    progress: Callable[[int], object] | None = None,
    warm_up: Callable[[], object] | None = None,
) -> tuple[WallClockTimeline, F64, F64]:
    """Runs an already reset ``tracker`` over frames ``0 .. n_frames - 1`` of ``stream`` against a
    real clock (module docstring).

    Args:
        stream: the observation stream (faults, delays, flow).
        tracker: any :class:`~roft_sim.trackers.Tracker`, stepped in a worker thread.
        n_frames: frames to release.
        fps: camera rate [Hz].
        clock: time scale and when-busy policy.
        check: validates the tracker's return value for frame k (raises on a protocol error).
        gate: the robust-start gate (``--init robust``), applied in the worker thread, where the
            tracker renders too (an OpenGL context belongs to one thread).
        progress: called with 1 after every step (from the worker thread).
        warm_up: called once in the worker thread before the clock starts (e.g. building the
            depth renderer, whose OpenGL context must belong to the thread that renders), as a
            tracker sets itself up before its camera runs.

    Returns:
        ``(timeline, step_times_s, load_times_s)``: the :class:`WallClockTimeline`, and per frame
        the wall time of ``tracker.step`` and of building the observation [s].

    Raises:
        Whatever the tracker, the stream or ``check`` raised, in this thread.
    """
    run = _Run(stream, tracker, n_frames, fps, clock, check, gate, progress, warm_up)
    run.run()
    estimates = tuple(e for e in run.estimates if e is not None)
    if len(estimates) != n_frames:  # pragma: no cover - every frame is stepped unless one failed
        raise RuntimeError(f"the tracker was stepped on {len(estimates)} of {n_frames} frames")
    timeline = WallClockTimeline(
        clock=clock,
        fps=fps,
        release_s=run.release_s,
        started_s=run.started_s,
        delivered_s=run.delivered_s,
        seen=run.seen,
        dropped_busy=run.dropped,
        queue_max=run.inbox.backlog_max if clock.when_busy == "queue" else None,
        tracker_estimates=estimates,
    )
    return timeline, run.step_times_s, run.load_times_s
