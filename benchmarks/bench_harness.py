"""Harness overhead per frame and tracker step times (median, p95).

    python benchmarks/bench_harness.py                          # analytic box, 320x240, in memory
    python benchmarks/bench_harness.py --dataset data/fy/003_cracker_box --frames 120
    python benchmarks/bench_harness.py --trackers roft,detector-hold --repeats 5

Prints, per configuration:

- harness overhead per frame: building the observation (reading rgb/depth, flow, masks,
  faults) and the rest of the loop, measured with a tracker that does nothing;
- per tracker: the median and 95th percentile of ``tracker.step`` (``time.perf_counter`` around
  ``step`` only), pooled over ``--repeats`` runs, and the median wall time per frame.

On the in-memory analytic scene ROFT renders its outlier-test depth with the analytic ray caster;
on a dataset path it uses MuJoCo (set ``MUJOCO_GL`` or let the script pick EGL/OSMesa).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np


def _noop_spec():
    from dataclasses import dataclass

    from roft_sim.records import Estimate
    from roft_sim.trackers import TrackerSpec

    @dataclass(frozen=True, slots=True, kw_only=True)
    class NoopConfig:
        pass

    class Noop:
        def __init__(self, config, context):
            self.T = np.eye(4)

        def reset(self, initial):
            pass

        def step(self, observation):
            return Estimate(
                k=observation.k, T_cam_obj=self.T, v_obj_mps=np.zeros(3), w_radps=np.zeros(3)
            )

    return TrackerSpec(
        name="noop", description="does nothing", config_type=NoopConfig, factory=Noop
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", help="a sequence path (default: analytic box in memory)")
    parser.add_argument("--frames", type=int, default=90, help="frames of the analytic scene")
    parser.add_argument("--resolution", default="320x240", help="analytic scene size WxH")
    parser.add_argument(
        "--trackers",
        default="detector-hold,naive-delay,pose-only-ukf,roft",
        help="comma-separated trackers",
    )
    parser.add_argument("--faults", default="paper")
    parser.add_argument(
        "--flow", help="flow source (default: stored:gt in memory, auto for a dataset)"
    )
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    import cv2

    cv2.setNumThreads(1)
    from roft_sim.faults import load_faults
    from roft_sim.harness import RunOptions, run_sequence

    if args.dataset:
        from roft_sim.render.gl_backend import select_gl_backend

        select_gl_backend(os.environ)
        from roft_sim.datasets import open_sequence

        sequence = open_sequence(args.dataset)
        renderer = None
        poses, masks = "auto", "auto"
        flow = args.flow or "auto"
        label = f"{args.dataset} ({len(sequence)} frames)"
    else:
        from roft_sim.testing.analytic_scene import (
            AnalyticBoxDepthRenderer,
            analytic_box_sequence,
            default_intrinsics,
        )

        w, h = (int(x) for x in args.resolution.split("x"))
        sequence = analytic_box_sequence(n_frames=args.frames, intrinsics=default_intrinsics(w, h))
        renderer = lambda model: AnalyticBoxDepthRenderer()  # noqa: E731
        poses, masks = "gt", "gt"
        flow = args.flow or "stored:gt"
        label = f"analytic box {w}x{h} in memory ({args.frames} frames)"
    base = RunOptions(
        tracker="noop", faults=load_faults(args.faults), flow=flow, poses=poses, masks=masks
    )
    print(f"{label}, faults {args.faults}, flow {flow}, {args.repeats} repeats")

    loads, rest = [], []
    for _ in range(args.repeats):
        t0 = time.perf_counter()
        run = run_sequence(sequence, base, spec=_noop_spec())
        wall = time.perf_counter() - t0
        loads.extend(run.load_times_s)
        rest.append((wall - run.load_times_s.sum() - run.step_times_s.sum()) / len(run))
    print(
        f"harness: observation median {1e3 * np.median(loads):.3f} ms, p95 "
        f"{1e3 * np.percentile(loads, 95):.3f} ms per frame; rest of the loop "
        f"{1e3 * statistics.median(rest):.3f} ms per frame (set-up included)"
    )
    print(f"{'tracker':<16}{'step median ms':>16}{'step p95 ms':>14}{'wall ms/frame':>15}")
    for name in args.trackers.split(","):
        steps, walls = [], []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            run = run_sequence(
                sequence,
                base.replace(tracker=name, tracker_config=None),
                depth_renderer_factory=renderer,
            )
            walls.append((time.perf_counter() - t0) / len(run))
            steps.extend(run.step_times_s)
        print(
            f"{name:<16}{1e3 * np.median(steps):>16.3f}{1e3 * np.percentile(steps, 95):>14.3f}"
            f"{1e3 * statistics.median(walls):>15.3f}"
        )


if __name__ == "__main__":
    main()
