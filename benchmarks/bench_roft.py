"""Median ROFT step time at 640x480 and 1280x720, with flow given and with OpenCV DIS included.

Runs on ONE core (BLAS and OpenCV threads pinned to 1 before they load). The scene is the
analytic textured box of :mod:`roft_sim.testing.analytic_scene` in fast motion (peaks near
0.4 m/s and 4 rad/s), with the paper's schedule: a pose and a mask every 6 frames, each delivered
6 frames late (frame 0 undelayed), ground-truth flow, and the numpy analytic depth renderer for
the outlier test (its time is reported apart: a real renderer replaces it).

    python benchmarks/bench_roft.py                 # both resolutions, flow given and DIS
    python benchmarks/bench_roft.py --frames 24 --resolutions 1280x720 --dis-presets ultrafast

Prints, per resolution: the median / 90th percentile / mean step time over all frames, over the
frames without a pose (predict + velocity update) and over the frames with one (replay of 7
frames with the outlier test), the time spent in the depth renderer, and with DIS the median of
flow + step. Goal (issue 6): median <= 5 ms per step at 1280x720 on one core, flow given.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from roft_sim.records import FlowField, MaskDetection, Observation, PoseDetection  # noqa: E402
from roft_sim.testing.analytic_scene import (  # noqa: E402
    AnalyticBoxDepthRenderer,
    analytic_box_sequence,
    default_intrinsics,
)
from roft_sim.trackers.base import TrackerContext  # noqa: E402
from roft_sim.trackers.roft import RoftConfig, RoftTracker  # noqa: E402

DIS_PRESETS = {
    "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
    "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
}


class TimedRenderer:
    """Wraps a depth renderer and accumulates the time spent in it."""

    def __init__(self, inner: AnalyticBoxDepthRenderer):
        self.inner = inner
        self.seconds = 0.0

    def render_depth(self, T_cam_obj, intrinsics):
        t0 = time.perf_counter()
        out = self.inner.render_depth(T_cam_obj, intrinsics)
        self.seconds += time.perf_counter() - t0
        return out


def observations(seq, flows, period=6, delay=6):
    """The paper's schedule: captures every ``period`` frames delivered ``delay`` frames late
    (the first one, frame 0, undelayed)."""
    n = len(seq)
    captures = {0: 0} | {c + delay: c for c in range(period, n, period)}
    out = []
    for k in range(n):
        poses, masks = (), ()
        if k in captures:
            c = captures[k]
            T = seq.gt.T_cam_obj[c]
            poses = (PoseDetection(capture_k=c, arrival_k=k, T_cam_obj=T, detection_id=k),)
            m = seq.mask(c, "gt")
            masks = (MaskDetection(capture_k=c, arrival_k=k, mask=m, detection_id=k),)
        out.append(
            Observation(
                k=k,
                t_s=seq.time_s(k),
                rgb=seq.rgb(k),
                depth_m=seq.depth(k),
                flow=flows[k],
                poses=poses,
                masks=masks,
            )
        )
    return out


def run_once(seq, obs, renderer, flow_fn=None):
    ctx = TrackerContext(
        intrinsics=seq.intrinsics,
        fps=seq.fps,
        object_model=seq.object_model(),
        rng=np.random.default_rng(0),
        depth_renderer=renderer,
    )
    tracker = RoftTracker(RoftConfig(), ctx)
    tracker.reset(None)
    times, cpu, has_pose, render_s = [], [], [], []
    for o in obs:
        before = renderer.seconds
        t0, c0 = time.perf_counter(), time.thread_time()
        if flow_fn is not None:
            o = flow_fn(o)
        tracker.step(o)
        times.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
        render_s.append(renderer.seconds - before)
        has_pose.append(bool(o.poses))
    return np.array(times), np.array(cpu), np.array(has_pose), np.array(render_s)


def summarise(label, times, cpu, has_pose, render_s):
    ms = 1e3 * times
    cpu_ms = 1e3 * cpu
    pose = has_pose
    rend = 1e3 * render_s
    print(
        f"  {label:<22} wall median {np.median(ms):6.2f} ms (CPU {np.median(cpu_ms):6.2f})  "
        f"p90 {np.percentile(ms, 90):6.2f}  mean {ms.mean():6.2f} | no pose: median "
        f"{np.median(ms[~pose]):6.2f} | pose frames: median {np.median(ms[pose]):6.2f} "
        f"(renderer {np.median(rend[pose]):5.2f}) | median without renderer "
        f"{np.median(ms - rend):6.2f}"
    )


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=37)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--resolutions", nargs="+", default=["640x480", "1280x720"])
    parser.add_argument("--dis-presets", nargs="*", default=["ultrafast", "medium"])
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    print(f"python {sys.version.split()[0]}, numpy {np.__version__}, opencv {cv2.__version__}")
    for res in args.resolutions:
        w, h = (int(x) for x in res.split("x"))
        t0 = time.perf_counter()
        seq = analytic_box_sequence(n_frames=args.frames, intrinsics=default_intrinsics(w, h))
        flows = [seq.flow(k, "gt") for k in range(len(seq))]
        mask_px = np.mean([seq.mask(k, "gt").sum() for k in range(len(seq))])
        print(
            f"{res}: {args.frames} frames, object mask {mask_px:.0f} px "
            f"(scene built in {time.perf_counter() - t0:.1f} s)"
        )
        renderer = TimedRenderer(AnalyticBoxDepthRenderer())
        obs = observations(seq, flows)
        runs = [run_once(seq, obs, renderer) for _ in range(args.repeats)]
        summarise("flow given", *(np.concatenate(r) for r in zip(*runs, strict=True)))
        grey = [cv2.cvtColor(seq.rgb(k), cv2.COLOR_RGB2GRAY) for k in range(len(seq))]
        for preset in args.dis_presets:
            dis = cv2.DISOpticalFlow_create(DIS_PRESETS[preset])

            def with_dis(o, dis=dis, grey=grey):
                if o.k == 0:
                    return o
                f = dis.calc(grey[o.k - 1], grey[o.k], None)
                flow = FlowField(flow_px=f, from_k=o.k - 1, to_k=o.k)
                return Observation(
                    k=o.k,
                    t_s=o.t_s,
                    rgb=o.rgb,
                    depth_m=o.depth_m,
                    flow=flow,
                    poses=o.poses,
                    masks=o.masks,
                )

            runs = [run_once(seq, obs, renderer, with_dis) for _ in range(args.repeats)]
            summarise(f"DIS {preset} + step", *(np.concatenate(r) for r in zip(*runs, strict=True)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
