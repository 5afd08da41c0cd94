"""Generation throughput of ``roft-sim generate`` per format, resolution and worker count, and
peak memory over a long sequence.

Workload: the Fast-YCB-like scenario ``scenarios/fast_ycb/003_cracker_box.toml`` (procedural
stand-in mesh, no asset cache) with the default networks (gt float flow, nvof-like DIS S10.5
flow, DOPE-like poses, Mask R-CNN-like masks) rendered at each resolution (intrinsics scaled).

Throughput, medians over ``--repeats`` fresh runs of N frames each:

- ``steady fr/s``: frames per second once every worker is producing, from the time stamps at
  which frames are reported written: (N - W) / (t_last - t_W), where t_W is when the W-th frame
  (W = workers) was written; start-up, object loading, worker spawning and finalize are left out;
- ``wall fr/s``: N / the whole run's wall time (start-up and finalize included: what a short run
  sees).

One unmeasured 2-frame run per configuration comes first (in-process caches: imports, the
object's procedural texture).

Memory: peak resident set size (``ru_maxrss``) of a fresh process generating a short and a long
sequence of the CI cracker-box scenario at 96x72, in-process; flat when frames stream to disk.

    python benchmarks/bench_generate.py                       # everything (~10 min on 2 cores)
    python benchmarks/bench_generate.py --resolutions 640x480 --formats fast-ycb --repeats 1
    python benchmarks/bench_generate.py --skip-throughput --long-frames 3000
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from roft_sim.render.gl_backend import require_gl_backend

BACKEND = require_gl_backend(os.environ)  # before MuJoCo is imported

from roft_sim.generation import (  # noqa: E402
    GenerationOptions,
    ScenarioOverrides,
    generate_dataset,
    parse_resolution,
    shipped_scenarios_dir,
)
from roft_sim.scenario import load_scenario  # noqa: E402

FORMATS = ("fast-ycb", "bop", "hdf5")


def timed_run(scenario, fmt: str, frames: int, workers: int, chunk: int, resolution):
    """(steady frames/s, wall frames/s) of one fresh run."""
    out = Path(tempfile.mkdtemp(prefix="bench_generate_"))
    stamps: list[float] = []

    def on_frames(n: int) -> None:
        stamps.extend([time.perf_counter()] * n)

    try:
        t0 = time.perf_counter()
        summary = generate_dataset(
            [scenario],
            out,
            GenerationOptions(
                format=fmt, workers=workers, chunk_frames=chunk, progress=False, gl_backend=BACKEND
            ),
            overrides=ScenarioOverrides(frames=frames, resolution=resolution),
            on_frames=on_frames,
        )
        wall = time.perf_counter() - t0
        assert summary.finished and summary.frames_generated == frames == len(stamps)
        steady = (frames - workers) / (stamps[-1] - stamps[workers - 1])
        return steady, frames / wall
    finally:
        shutil.rmtree(out, ignore_errors=True)


def throughput(args: argparse.Namespace) -> None:
    scenario = load_scenario(shipped_scenarios_dir() / "fast_ycb" / "003_cracker_box.toml")
    print(
        f"backend {BACKEND}, {os.cpu_count()} CPUs, scenario {scenario.name}, default networks, "
        f"medians over {args.repeats} repeats"
    )
    print(f"{'resolution':>10} {'format':>9} {'workers':>7} {'N':>3} {'steady fr/s':>12} "
          f"{'wall fr/s':>10}")  # fmt: skip
    for text in args.resolutions:
        resolution = parse_resolution(text)
        n = (
            args.frames
            if args.frames
            else (12 if resolution[0] * resolution[1] <= 640 * 480 else 8)
        )
        for fmt in args.formats:
            for workers in args.workers:
                chunk = max(1, -(-n // workers))  # one unit per worker
                timed_run(scenario, fmt, 2, 1, chunk, resolution)  # warm caches
                runs = [
                    timed_run(scenario, fmt, n, workers, chunk, resolution)
                    for _ in range(args.repeats)
                ]
                steady = statistics.median(r[0] for r in runs)
                wall = statistics.median(r[1] for r in runs)
                print(
                    f"{text:>10} {fmt:>9} {workers:>7} {n:>3} {steady:>12.2f} {wall:>10.2f}",
                    flush=True,
                )


def memory_child(frames: int) -> None:
    """Generates ``frames`` frames in this process and prints its peak RSS [MiB]."""
    scenario = load_scenario(shipped_scenarios_dir() / "ci" / "cracker_box.toml")
    duration = frames / scenario.fps + 1.0
    scenario = dataclasses.replace(
        scenario,
        trajectory=dataclasses.replace(scenario.trajectory, duration_s=duration),
    )
    out = Path(tempfile.mkdtemp(prefix="bench_generate_mem_"))
    try:
        t0 = time.perf_counter()
        summary = generate_dataset(
            [scenario],
            out,
            GenerationOptions(format="fast-ycb", progress=False, gl_backend=BACKEND),
            overrides=ScenarioOverrides(frames=frames, resolution=(96, 72)),
        )
        wall = time.perf_counter() - t0
        assert summary.finished
        peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{frames} {peak_mib:.1f} {wall:.1f}")
    finally:
        shutil.rmtree(out, ignore_errors=True)


def memory(args: argparse.Namespace) -> None:
    print(
        "\npeak RSS of a fresh process generating one sequence (ci cracker box, 96x72, fast-ycb, "
        "default networks, in-process):"
    )
    for frames in (args.short_frames, args.long_frames):
        res = subprocess.run(
            [sys.executable, __file__, "--memory-child", str(frames)],
            capture_output=True,
            text=True,
            check=True,
        )
        n, peak, wall = res.stdout.split()[-3:]
        print(
            f"  {int(n):>6} frames: peak RSS {float(peak):7.1f} MiB ({float(wall):.0f} s)",
            flush=True,
        )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--resolutions", nargs="+", default=["640x480", "1280x720"])
    p.add_argument("--formats", nargs="+", default=list(FORMATS), choices=FORMATS)
    p.add_argument("--workers", nargs="+", type=int, default=[1, 2])
    p.add_argument("--frames", type=int, help="N (default 12 at <= 640x480, else 8)")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--short-frames", type=int, default=150)
    p.add_argument("--long-frames", type=int, default=1500)
    p.add_argument("--skip-throughput", action="store_true")
    p.add_argument("--skip-memory", action="store_true")
    p.add_argument("--memory-child", type=int, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.memory_child is not None:
        memory_child(args.memory_child)
        return
    if not args.skip_throughput:
        throughput(args)
    if not args.skip_memory:
        memory(args)


if __name__ == "__main__":
    main()
