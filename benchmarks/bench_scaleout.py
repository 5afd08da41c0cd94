"""Scale-out of ``roft-sim generate``: throughput per executor, per-frame cost at 1280x720, and
a paper estimate of the time and disk to generate 1 000 Fast-YCB-like sequences on N machines.

1. Throughput on a small scenario (the Fast-YCB-like cracker box at 640x360, default networks,
   fast-ycb), per executor: in-process (1 worker), 2 local ``spawn`` processes, and 2 Ray actors
   on a private local Ray instance when ``ray`` is installed. Fresh runs of N = f x W frames (W
   workers, one unit of f = ``--frames`` frames each); medians over ``--repeats`` runs of:

   - ``steady fr/s``: frames written per second while every worker was producing (from the
     write times of the atomically written rgb files; worker and Ray start-up, object loading
     and finalize left out);
   - ``wall fr/s``: N / the run's wall time, what a run of that length sees;
   - ``start-up s``: wall time - N / steady, the fixed cost of a run;
   - ``CPU s/frame``: CPU time of the whole run (this process and the local worker processes,
     start-up included; not measured for Ray actors) per frame; ``cores busy``: that CPU time
     over the wall time (how many of the machine's cores the run actually got).

2. Per-frame cost at 1280x720 (the Fast-YCB-like 003_cracker_box scenario, procedural stand-in,
   default networks, fast-ycb), in-process with OpenCV on one thread (as in a worker): the steady
   wall time per frame and the process CPU time per frame (all threads, Mesa llvmpipe's
   included) over frames 2..N, and the disk per frame of the finished sequence. Medians over
   ``--repeats`` runs. CPU time is the cost basis of the estimate: it is what a core spends,
   and less disturbed than wall time by other jobs on a shared machine.

3. The estimate: F = sequences x frames (default 1 000 x 880) at the measured CPU s per frame,
   on N machines of ``--cores`` cores, one worker per core, ``--efficiency`` (default 1) of their
   CPU time spent on frames: frames are independent, so the work divides by the cores as long
   as every core has a worker (part 1 shows what a second worker adds on THIS machine, whose two
   cores other jobs share). Not modelled: network and storage
   bandwidth (every frame is written to a shared filesystem), scheduling and start-up (10-20 s
   per worker, small next to hours), stragglers (a machine's last unit; at most one unit of
   ``--chunk-frames`` frames per worker).

    python benchmarks/bench_scaleout.py                  # everything (~5 min on 2 cores)
    python benchmarks/bench_scaleout.py --repeats 1 --skip-720p
    python benchmarks/bench_scaleout.py --machines 1 10 50 100 --cores 16
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import resource
import shutil
import statistics
import tempfile
import time
from pathlib import Path

from roft_sim.render.gl_backend import require_gl_backend

BACKEND = require_gl_backend(os.environ)  # before MuJoCo is imported

from roft_sim.executors import LocalProcessExecutor, RayExecutor, SerialExecutor  # noqa: E402
from roft_sim.generation import (  # noqa: E402
    GenerationOptions,
    ScenarioOverrides,
    generate_dataset,
    shipped_scenarios_dir,
)
from roft_sim.scenario import load_scenario  # noqa: E402


def _executor(kind: str, workers: int):
    if kind == "local" and workers == 1:
        return SerialExecutor()
    if kind == "local":
        return LocalProcessExecutor(workers)
    env = {k: os.environ[k] for k in ("MUJOCO_GL", "PYOPENGL_PLATFORM") if os.environ.get(k)}
    return RayExecutor(
        workers,
        worker_env=env,
        init_options={"log_to_driver": False, "num_cpus": os.cpu_count()},
    )


def _cpu_s() -> float:
    """CPU time [s] of this process and of its reaped children (local worker processes)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def timed_run(scenario, per_worker: int, kind: str, workers: int, resolution):
    """One fresh run of ``per_worker`` x ``workers`` frames, one unit per worker.

    Returns:
        (steady frames/s, wall time [s], frames, CPU time [s] of this process and its finished
        child processes: not the Ray actors'). ``steady``: frames written per second while
        EVERY worker was producing: from the write times of the rgb files (each written
        atomically, so its mtime is when the frame was written), the window from the latest
        worker's first frame to the earliest worker's last frame.
    """
    frames = per_worker * workers
    out = Path(tempfile.mkdtemp(prefix="bench_scaleout_"))
    try:
        cpu0 = _cpu_s()
        t0 = time.perf_counter()
        summary = generate_dataset(
            [scenario],
            out,
            GenerationOptions(chunk_frames=per_worker, progress=False, gl_backend=BACKEND),
            overrides=ScenarioOverrides(frames=frames, resolution=resolution),
            executor=_executor(kind, workers),
        )
        wall = time.perf_counter() - t0
        cpu = _cpu_s() - cpu0
        assert summary.finished and summary.frames_generated == frames
        rgb = Path(summary.sequences[0].path) / "rgb"
        mtime = [(rgb / f"{k}.png").stat().st_mtime_ns / 1e9 for k in range(frames)]
        units = [mtime[w * per_worker : (w + 1) * per_worker] for w in range(workers)]
        start, stop = max(min(u) for u in units), min(max(u) for u in units)
        inside = sum(start <= t <= stop for t in mtime)
        steady = (inside - workers) / (stop - start) if stop > start else float("nan")
        return steady, wall, frames, cpu
    finally:
        shutil.rmtree(out, ignore_errors=True)


def throughput(args: argparse.Namespace) -> dict[tuple[str, int], float]:
    scenario = load_scenario(shipped_scenarios_dir() / "fast_ycb" / "003_cracker_box.toml")
    resolution = (640, 360)
    configs = [("local", 1), ("local", 2)]
    if args.ray and importlib.util.find_spec("ray") is not None:
        configs.append(("ray", 2))
    elif args.ray:
        print("(ray is not installed: the Ray rows are left out; pip install 'roft-sim[ray]')")
    print(
        f"\n1. throughput: {scenario.name} at {resolution[0]}x{resolution[1]}, fast-ycb, default "
        f"networks; {args.frames} frames per worker (one unit each); medians over "
        f"{args.repeats} runs (backend {BACKEND}, {os.cpu_count()} CPUs, load average "
        f"{os.getloadavg()[0]:.1f} at start)"
    )
    print(
        f"{'executor':>9} {'W':>2} {'N':>4} {'steady fr/s':>12} {'wall fr/s':>10} "
        f"{'start-up s':>11} {'CPU s/frame':>12} {'cores busy':>11}"
    )
    timed_run(scenario, 2, "local", 1, resolution)  # warm in-process caches (imports, textures)
    steady_of: dict[tuple[str, int], float] = {}
    for kind, workers in configs:
        runs = [
            timed_run(scenario, args.frames, kind, workers, resolution) for _ in range(args.repeats)
        ]
        n = runs[0][2]
        steady = statistics.median(r[0] for r in runs)
        wall = statistics.median(n / r[1] for r in runs)
        startup = statistics.median(r[1] - n / r[0] for r in runs)
        cpu, busy = "n/a", "n/a"
        if kind != "ray":
            cpu = f"{statistics.median(r[3] for r in runs) / n:.3f}"
            busy = f"{statistics.median(r[3] / r[1] for r in runs):.2f}"
        steady_of[(kind, workers)] = steady
        print(
            f"{kind:>9} {workers:>2} {n:>4} {steady:>12.2f} {wall:>10.2f} {startup:>11.1f} "
            f"{cpu:>12} {busy:>11}",
            flush=True,
        )
    return steady_of


def cost_720p(args: argparse.Namespace) -> tuple[float, float, float]:
    """(median steady wall s/frame, median CPU s/frame, bytes/frame) at 1280x720."""
    import cv2

    cv2.setNumThreads(1)  # as in a worker process: the cost of one worker on one core
    scenario = load_scenario(shipped_scenarios_dir() / "fast_ycb" / "003_cracker_box.toml")
    n = args.frames_720p
    walls, cpus, sizes = [], [], []
    for _ in range(args.repeats):
        out = Path(tempfile.mkdtemp(prefix="bench_scaleout_720p_"))
        marks: list[tuple[float, float]] = []

        def on_frames(k: int, marks=marks) -> None:
            usage = resource.getrusage(resource.RUSAGE_SELF)
            marks.extend([(time.perf_counter(), usage.ru_utime + usage.ru_stime)] * k)

        try:
            summary = generate_dataset(
                [scenario],
                out,
                GenerationOptions(progress=False, gl_backend=BACKEND),
                overrides=ScenarioOverrides(frames=n, resolution=(1280, 720)),
                on_frames=on_frames,
            )
            assert summary.finished and len(marks) == n
            walls.append((marks[-1][0] - marks[1][0]) / (n - 2))
            cpus.append((marks[-1][1] - marks[1][1]) / (n - 2))
            sizes.append(sum(p.stat().st_size for p in out.rglob("*") if p.is_file()) / n)
        finally:
            shutil.rmtree(out, ignore_errors=True)
    wall, cpu, size = statistics.median(walls), statistics.median(cpus), statistics.median(sizes)
    print(
        f"\n2. per-frame cost at 1280x720 ({scenario.name}, fast-ycb, default networks, "
        f"in-process, frames 2..{n - 1} of {n}, medians over {args.repeats} runs): "
        f"{wall:.3f} s wall/frame, {cpu:.3f} s CPU/frame; {size / 1e6:.2f} MB on disk per frame "
        f"(rgb, depth, 2 flow sets, 3 mask sets, text files)",
        flush=True,
    )
    return wall, cpu, size


def estimate(args: argparse.Namespace, cost_s: float, bytes_per_frame: float, eff: float) -> None:
    frames = args.sequences * args.sequence_frames
    cpu_h = frames * cost_s / 3600
    print(
        f"\n3. estimate: {args.sequences} sequences x {args.sequence_frames} frames at 1280x720 "
        f"= {frames:,} frames x {cost_s:.3f} s/frame = {cpu_h:,.0f} core-hours; "
        f"{frames * bytes_per_frame / 1e12:.2f} TB on disk "
        f"({args.sequence_frames * bytes_per_frame / 1e9:.1f} GB per sequence)"
    )
    print(
        f"   N machines x {args.cores} cores, one worker per core, efficiency {eff:.2f} "
        "(--efficiency); network and storage not modelled"
    )
    print(f"{'machines':>9} {'workers':>8} {'hours':>9} {'days':>7} {'write MB/s':>11}")
    for machines in args.machines:
        workers = machines * args.cores
        hours = cpu_h / (workers * eff)
        rate = frames * bytes_per_frame / (hours * 3600) / 1e6
        print(f"{machines:>9} {workers:>8} {hours:>9.1f} {hours / 24:>7.2f} {rate:>11.0f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--frames", type=int, default=24, help="f: frames per worker and run")
    p.add_argument("--frames-720p", type=int, default=8, help="frames per 1280x720 run")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--no-ray", dest="ray", action="store_false", help="leave Ray out")
    p.add_argument("--skip-720p", action="store_true")
    p.add_argument("--sequences", type=int, default=1000)
    p.add_argument("--sequence-frames", type=int, default=880)
    p.add_argument("--cores", type=int, default=os.cpu_count() or 1, help="cores per machine")
    p.add_argument("--machines", type=int, nargs="+", default=[1, 10, 100])
    p.add_argument(
        "--efficiency",
        type=float,
        default=1.0,
        help="fraction of the cores' CPU time that goes into frames (default 1: frames are "
        "independent and a worker's start-up is seconds against hours)",
    )
    args = p.parse_args()
    steady = throughput(args)
    measured = steady[("local", 2)] / (2 * steady[("local", 1)])
    print(f"   2 workers / (2 x 1 worker), steady: {measured:.2f} on this machine")
    if not args.skip_720p:
        _, cpu, size = cost_720p(args)
        estimate(args, cpu, size, args.efficiency)


if __name__ == "__main__":
    main()
