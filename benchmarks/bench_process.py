"""The tracker process protocol's overhead per frame, side by side with the same tracker in process.

The tracker is the constant-velocity example (examples/process_tracker_cpp): in process (the
Python twin), in a Python child served by ``serve`` (large arrays through the shared file, and
again with everything through the pipe) and, with ``--cpp PATH``, the C++ program (which takes
the shared file and reads no image).
Every frame sends what a real run sends at the given resolution: rgb (uint8), depth (float32),
flow (float32 on a ``--flow-grid`` grid, with its validity), one pose and one mask detection; the
estimate comes back. The trackers alternate block by block (in process, child, C++, in process,
...) so that all see the same machine load. Printed: the step time [ms] (median, p95) of each and
the overhead, the median step of the child minus the median in process, and the CPU time per
frame of parent and child together minus the in-process tracker's (on a busy machine the wall
time also holds the waits for a core); also the parent's time to encode and pack one
observation either way.

    python benchmarks/bench_process.py
    python benchmarks/bench_process.py --frames 300 --flow-grid 4 --cpp build/cv_tracker/cv_tracker

Goal: overhead <= 1.5 ms per frame at 640x480 with full-resolution flow.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time
from pathlib import Path

import numpy as np

from roft_sim.geometry.se3 import transform_from_pq
from roft_sim.records import FlowField, MaskDetection, Observation, PoseDetection
from roft_sim.testing.analytic_scene import AnalyticBox, default_intrinsics
from roft_sim.trackers import Tracker, TrackerContext
from roft_sim.trackers.process import ProcessTracker, ProcessTrackerConfig, codec
from roft_sim.trackers.process.shared import SharedWriter

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "process_tracker_cpp"


def observations(width: int, height: int, frames: int, grid: int) -> list[Observation]:
    """``frames`` observations with random images, flow and one pose and mask each."""
    rng = np.random.default_rng(0)
    hg, wg = -(-height // grid), -(-width // grid)
    out = []
    for k in range(frames):
        q = np.array([1.0, 0.01 * k, 0.0, 0.0])
        T = transform_from_pq([0.0, 0.0, 0.6 + 0.001 * k], q / np.linalg.norm(q))
        out.append(
            Observation(
                k=k,
                t_s=k / 30,
                rgb=rng.integers(0, 256, (height, width, 3), dtype=np.uint8),
                depth_m=rng.random((height, width), dtype=np.float32),
                flow=FlowField(
                    flow_px=rng.normal(size=(hg, wg, 2)).astype(np.float32),
                    from_k=k - 1,
                    to_k=k,
                    grid_px=grid,
                    valid=rng.random((hg, wg)) > 0.1,
                ),
                poses=(PoseDetection(capture_k=k, arrival_k=k, T_cam_obj=T, detection_id=k),),
                masks=(
                    MaskDetection(
                        capture_k=k,
                        arrival_k=k,
                        mask=rng.random((height, width)) > 0.5,
                        detection_id=k,
                    ),
                ),
            )
        )
    return out


def child_cpu_s(tracker: Tracker) -> float:
    """CPU time the tracker's child process has used [s] (0 in process; Linux /proc)."""
    if not isinstance(tracker, ProcessTracker):
        return 0.0
    fields = Path(f"/proc/{tracker.pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def step_times_ms(tracker: Tracker, block: list[Observation]) -> list[float]:
    times = []
    for observation in block:
        t0 = time.perf_counter()
        tracker.step(observation)
        times.append((time.perf_counter() - t0) * 1e3)
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolution", default="640x480", help="WIDTHxHEIGHT (default 640x480)")
    parser.add_argument("--frames", type=int, default=200, help="frames per tracker (default 200)")
    parser.add_argument("--block", type=int, default=20, help="frames per alternation block")
    parser.add_argument("--flow-grid", type=int, default=1, help="pixels per flow cell (1: full)")
    parser.add_argument("--cpp", type=Path, help="the built C++ example, measured too")
    args = parser.parse_args()
    width, height = (int(v) for v in args.resolution.split("x"))
    spec = importlib.util.spec_from_file_location("cv_tracker", EXAMPLE / "cv_tracker.py")
    assert spec is not None and spec.loader is not None
    cv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(cv)
    context = TrackerContext(
        intrinsics=default_intrinsics(width, height),
        fps=30,
        object_model=AnalyticBox().object_model(),
        rng=np.random.default_rng(0),
    )
    frames = observations(width, height, args.block, args.flow_grid)
    child = [sys.executable, str(EXAMPLE / "cv_tracker.py")]
    trackers: dict[str, Tracker] = {
        "in process": cv.ConstantVelocityTracker(context),
        "python child": ProcessTracker(child, context),
        "python, pipe": ProcessTracker(
            child, context, config=ProcessTrackerConfig(shared_memory=False)
        ),
    }
    if args.cpp is not None:
        trackers["c++ child"] = ProcessTracker([str(args.cpp)], context)
    times: dict[str, list[float]] = {name: [] for name in trackers}
    cpu_s = dict.fromkeys(trackers, 0.0)
    for tracker in trackers.values():
        tracker.reset(None)
        step_times_ms(tracker, frames[:2])  # warm up
    for _ in range(max(1, args.frames // args.block)):
        for name, tracker in trackers.items():
            tracker.reset(None)
            parent, child = time.process_time(), child_cpu_s(tracker)
            times[name] += step_times_ms(tracker, frames)
            cpu_s[name] += time.process_time() - parent + child_cpu_s(tracker) - child
    shared = SharedWriter(width * height * 18 + 1024)
    encode: dict[str, list[float]] = {"shared file": [], "pipe": []}
    for observation in frames:
        for way, writer in (("shared file", shared), ("pipe", None)):
            t0 = time.perf_counter()
            codec.pack(codec.observation_message(observation, writer))
            encode[way].append((time.perf_counter() - t0) * 1e3)
    shared.close()
    for tracker in trackers.values():
        getattr(tracker, "close", lambda: None)()
    size_mb = len(codec.pack(codec.observation_message(frames[0]))) / 1e6
    print(f"{width}x{height}, flow grid {args.flow_grid}: {size_mb:.2f} MB per observation")
    base = float(np.median(times["in process"]))
    base_cpu = cpu_s["in process"] / len(times["in process"]) * 1e3
    print(f"{'tracker':<14} {'median ms':>10} {'p95 ms':>8} {'overhead ms':>12} {'cpu ms':>7} ")
    for name, values in times.items():
        median = float(np.median(values))
        p95 = float(np.percentile(values, 95))
        cpu_ms = cpu_s[name] / len(values) * 1e3 - base_cpu
        print(f"{name:<14} {median:>10.3f} {p95:>8.3f} {median - base:>12.3f} {cpu_ms:>7.3f}")
    print("cpu ms: CPU time per frame of parent and child together, minus the in-process tracker's")
    for way, values in encode.items():
        print(f"parent encode + pack, {way}: median {np.median(values):.3f} ms")


if __name__ == "__main__":
    main()
