"""Generation throughput of ``roft-sim generate`` next to the renderer's, and peak memory.

The one source of the README's generation numbers (docs/generate.md, "Performance"). Workload:
the Fast-YCB-like scenario ``scenarios/fast_ycb/003_cracker_box.toml`` (procedural stand-in mesh)
with the default networks (gt float flow, nvof-like DIS S10.5 flow, DOPE-like poses, Mask
R-CNN-like masks) at each resolution (intrinsics scaled), written as fast-ycb by default, with an
asset cache that the first (unmeasured) run fills, as ``roft-sim generate``'s default cache is
after its first run.

Every measurement runs in a fresh process, with the package's bytecode compiled beforehand (as
pip leaves an installed package; with ``PYTHONDONTWRITEBYTECODE`` set, every fresh process would
otherwise compile the modules it imports: 0.07-0.1 s of a short run's start-up). With
``--baseline-ref REF [REF ...]`` the same measurement also runs on the package as it was at each
git commit REF (extracted with ``git archive``), interleaved with the current one (baseline, ...,
now, baseline, ..., now), so that all see the same machine load; the table prints medians and
the ratio now / each baseline. Rows:

- ``render+seg+flow``: :class:`SceneRenderer` with segmentation plus exact ground-truth flow from
  the previous frame, frames/s over N frames (what ``bench_render.py``'s ``+seg+flow`` mode
  measures, on this scenario): the renderer's bare rate that generation is compared with;
- ``generate W=w steady``: frames/s once every worker is producing, from the time stamps at which
  frames are reported written: (N - W) / (t_last - t_W), t_W when the W-th frame was written
  (start-up, spawning and finalize left out; one unit of N/W frames per worker);
- ``generate W=w wall``: N / the whole run's wall time (start-up and finalize included);
- ``generate W=1 CPU ms/frame``: CPU time (user + system, every thread of the process: the
  render, networks and writer threads and llvmpipe's) per frame over the same steady frames,
  from ``getrusage``; a shared machine's load changes it far less than the rates (W=1 only: it
  generates in the measuring process);
- ``short W=2 wall``: ``--short-frames`` frames (default 24) with 2 workers and the default
  ``--chunk-frames`` (32), wall frames/s: what ``roft-sim generate --frames 24 --workers 2``
  sees (at most one unit of frames is generated in-process: spawning workers would cost more than
  it saves); printed as a fraction of the 2-worker steady rate too;
- ``short W=2 wall, unit per worker``: the same run cut into one unit per worker, so both workers
  are spawned (``--chunk-frames 12``): the cost of spawning on a short run;
- ``start-up floor [s]``: seconds, on the short run's clock, from the call to the first rgb+depth
  frame read back from the package's renderer on a one-box model (MuJoCo's import, one OpenGL
  context, one ``MjrContext`` without textures or multisampling, the first draw): what any fresh
  process pays before its first frame, whatever it renders;
- ``8 x short W=2 wall``: ``--batch-sequences`` (default 8) sequences of ``--short-frames``
  frames (other trajectory seeds) in one run with 2 workers and the default chunking, wall
  frames/s: short sequences generated together, as a sweep or a dataset of short clips would.

Then the ratios of the goals (issue 17): 1-worker steady / render+seg+flow, and short / steady;
the start-up a short run may take for that goal (it is generated in-process: start-up, then its
frames at the 1-worker steady rate), next to the floor; and the batch's ratio to the steady rate.
The 1-minute load average is printed with every row (the machine may be shared).

Memory: peak resident set size (``ru_maxrss``) of a fresh process generating a short and a long
sequence of the CI cracker-box scenario at 96x72 in-process; flat when frames stream to disk.

    python benchmarks/bench_generate.py --baseline-ref main       # everything
    python benchmarks/bench_generate.py --baseline-ref 33cdec7 c52c313 --skip-memory
    python benchmarks/bench_generate.py --resolutions 640x480 --repeats 1 --skip-memory
    python benchmarks/bench_generate.py --skip-throughput --long-frames 3000
    python benchmarks/bench_generate.py --resolutions 640x480 --nvof-source nvof-like:dis:medium4

``--nvof-source SPEC`` and ``--msaa N`` change the workload (the ``nvof_1_slow`` set's source, the
colour pass's samples) for what-if measurements; every tree runs the changed workload, so a
baseline must know the spec.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from baseline_trees import Tree, baseline_tree, compile_trees, current_tree


# ------------------------------------------------------------------------ child measurements
def _scenario(
    resolution: tuple[int, int], nvof_source: str | None = None, msaa: int | None = None
) -> Any:
    """The workload at ``resolution``; ``nvof_source`` replaces the ``nvof_1_slow`` set's
    source and ``msaa`` the colour pass's ``msaa_samples`` (None = the scenario's)."""
    from roft_sim.generation import ScenarioOverrides, shipped_scenarios_dir
    from roft_sim.scenario import load_scenario

    scenario = load_scenario(shipped_scenarios_dir() / "fast_ycb" / "003_cracker_box.toml")
    scenario = ScenarioOverrides(resolution=resolution).apply(scenario)
    if msaa is not None:
        render = dataclasses.replace(scenario.render, msaa_samples=msaa)
        scenario = dataclasses.replace(scenario, render=render)
    if nvof_source is not None:
        sets = tuple(
            dataclasses.replace(s, source=nvof_source) if s.set_name == "nvof_1_slow" else s
            for s in scenario.networks.flow_sets
        )
        networks = dataclasses.replace(scenario.networks, flow_sets=sets)
        scenario = dataclasses.replace(scenario, networks=networks)
    return scenario


def child_render(
    resolution: tuple[int, int], frames: int, cache: Path, msaa: int | None = None
) -> float:
    """render+seg+flow frames/s over ``frames`` frames after one warm-up frame."""
    from roft_sim.render import SceneRenderer, ground_truth_flow

    scenario = _scenario(resolution, msaa=msaa)
    with SceneRenderer(scenario, cache_dir=cache, segmentation=True) as renderer:
        previous = renderer.render_frame(0)
        start = time.perf_counter()
        for k in range(1, frames + 1):
            frame = renderer.render_frame(k)
            ground_truth_flow(previous, frame, renderer.intrinsics)
            previous = frame
        return frames / (time.perf_counter() - start)


_FLOOR_MODEL = """<mujoco><visual><global offwidth="{w}" offheight="{h}"/></visual>
<worldbody><light pos="0 0 2"/><camera name="c" pos="0 0 1"/>
<geom type="box" size="0.1 0.1 0.1" pos="0 0 -0.5"/></worldbody></mujoco>"""


def child_floor(resolution: tuple[int, int]) -> float:
    """Seconds from the same point as a generate run's clock (the package's generation module and
    the GL backend's choice already imported) to the first rgb+depth frame read back from the
    package's own renderer on a one-box model: MuJoCo's import, one OpenGL context, one
    ``MjrContext`` without textures or multisampling, and the first draw. What any fresh process
    pays before its first frame, whatever the scene."""
    from roft_sim.generation import GenerationOptions  # noqa: F401  (imported before t0, as there)
    from roft_sim.render.gl_backend import require_gl_backend

    require_gl_backend(os.environ)
    t0 = time.perf_counter()
    import mujoco

    from roft_sim.render.offscreen import OffscreenRenderer

    w, h = resolution
    model = mujoco.MjModel.from_xml_string(_FLOOR_MODEL.format(w=w, h=h))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    with OffscreenRenderer(model, w, h) as renderer:
        renderer.update(data, 0)
        buffers = renderer.render(rgb=True, depth=True)
        assert buffers.depth_m is not None and float(buffers.depth_m.max()) > 0.0
        return time.perf_counter() - t0


def child_generate(
    resolution: tuple[int, int],
    frames: int,
    workers: int,
    fmt: str,
    cache: Path,
    nvof_source: str | None = None,
    msaa: int | None = None,
    default_chunks: bool = False,
    sequences: int = 1,
) -> tuple[float, float, float]:
    """(steady, wall) frames/s and CPU ms per steady frame (W=1) of one run (module doc): one
    unit of frames per worker, or ``GenerationOptions``' default chunking with
    ``default_chunks``. ``sequences`` > 1 generates that many sequences of ``frames`` frames in
    the one run (the workload's scenario with trajectory seeds 0, 1, ...: other motions, the same
    cached textures), and the rates count the frames of all of them."""
    from roft_sim.generation import GenerationOptions, ScenarioOverrides, generate_dataset
    from roft_sim.render.gl_backend import require_gl_backend

    backend = require_gl_backend(os.environ)
    out = Path(tempfile.mkdtemp(prefix="bench_generate_"))
    stamps: list[float] = []
    cpu_s: list[float] = []

    def on_frames(n: int) -> None:
        usage = resource.getrusage(resource.RUSAGE_SELF)
        stamps.extend([time.perf_counter()] * n)
        cpu_s.extend([usage.ru_utime + usage.ru_stime] * n)

    known = {f.name for f in dataclasses.fields(GenerationOptions)}
    options = {
        "format": fmt,
        "workers": workers,
        **({} if default_chunks else {"chunk_frames": max(1, -(-frames // workers))}),
        "progress": False,
        "gl_backend": backend,
        "cache_dir": cache,
    }
    try:
        t0 = time.perf_counter()
        scenario = _scenario(resolution, nvof_source, msaa)
        scenarios = (
            [scenario]
            if sequences == 1
            else [
                dataclasses.replace(
                    scenario,
                    name=f"{scenario.name}_{i:02d}",
                    trajectory=dataclasses.replace(scenario.trajectory, seed=i),
                )
                for i in range(sequences)
            ]
        )
        summary = generate_dataset(
            scenarios,
            out,
            GenerationOptions(**{k: v for k, v in options.items() if k in known}),
            overrides=ScenarioOverrides(frames=frames),
            on_frames=on_frames,
        )
        wall = time.perf_counter() - t0
        total = frames * sequences
        assert summary.finished and summary.frames_generated == total == len(stamps)
        steady = (total - workers) / max(1e-9, stamps[-1] - stamps[workers - 1])
        cpu_ms = 1000 * (cpu_s[-1] - cpu_s[workers - 1]) / max(1, total - workers)
        return steady, total / wall, cpu_ms
    finally:
        shutil.rmtree(out, ignore_errors=True)


def memory_child(frames: int) -> None:
    """Generates ``frames`` frames in this process and prints its peak RSS [MiB]."""
    from roft_sim.generation import (
        GenerationOptions,
        ScenarioOverrides,
        generate_dataset,
        shipped_scenarios_dir,
    )
    from roft_sim.render.gl_backend import require_gl_backend
    from roft_sim.scenario import load_scenario

    backend = require_gl_backend(os.environ)
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
            GenerationOptions(format="fast-ycb", progress=False, gl_backend=backend),
            overrides=ScenarioOverrides(frames=frames, resolution=(96, 72)),
        )
        wall = time.perf_counter() - t0
        assert summary.finished
        peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"{frames} {peak_mib:.1f} {wall:.1f}")
    finally:
        shutil.rmtree(out, ignore_errors=True)


def child_main(spec: dict[str, Any]) -> None:
    resolution = tuple(spec["resolution"])
    cache = Path(spec["cache"])
    variant = {k: spec[k] for k in ("nvof_source", "msaa") if spec.get(k) is not None}
    if spec["kind"] == "render":
        result: Any = child_render(resolution, spec["frames"], cache, variant.get("msaa"))
    elif spec["kind"] == "floor":
        result = child_floor(resolution)
    else:
        result = child_generate(
            resolution,
            spec["frames"],
            spec["workers"],
            spec["format"],
            cache,
            **variant,
            default_chunks=bool(spec.get("default_chunks", False)),
            sequences=int(spec.get("sequences", 1)),
        )
    print("RESULT " + json.dumps(result))


# ----------------------------------------------------------------------------- the driver
def run_child(tree: Tree, spec: dict[str, Any]) -> Any:
    env = dict(os.environ, PYTHONPATH=str(tree.pythonpath))
    res = subprocess.run(
        [sys.executable, __file__, "--child", json.dumps({**spec, "cache": str(tree.cache)})],
        capture_output=True,
        text=True,
        env=env,
        cwd=tempfile.gettempdir(),  # the tree on PYTHONPATH, not the current folder, is imported
    )
    if res.returncode != 0:
        raise RuntimeError(f"{tree.label} child {spec} failed:\n{res.stderr[-3000:]}")
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT ") :])


def load1() -> float:
    return os.getloadavg()[0]


def measure(
    trees: list[Tree], spec: dict[str, Any], repeats: int, pick: int | None
) -> dict[str, float]:
    """Median per tree of ``repeats`` interleaved runs (``pick`` = index into a tuple result)."""
    values: dict[str, list[float]] = {t.label: [] for t in trees}
    for _ in range(repeats):
        for tree in trees:
            result = run_child(tree, spec)
            values[tree.label].append(result if pick is None else result[pick])
    return {label: statistics.median(v) for label, v in values.items()}


def print_row(name: str, medians: dict[str, float], trees: list[Tree]) -> None:
    """Medians of every tree, then now / each baseline (the last tree is now)."""
    cells = " ".join(f"{medians[t.label]:>9.2f}" for t in trees)
    now = medians[trees[-1].label]
    ratios = " ".join(f"{now / medians[t.label]:>7.2f}x" for t in trees[:-1])
    print(f"{name:<30} {cells} {ratios} {load1():>6.2f}", flush=True)


def workload(args: argparse.Namespace) -> str:
    """The networks and rendering of the workload, as the table's header names them."""
    if args.nvof_source is None and args.msaa is None:
        return "default networks"
    parts = [f"nvof_1_slow = {args.nvof_source or 'default'}"]
    if args.msaa is not None:
        parts.append(f"msaa_samples = {args.msaa}")
    return ", ".join(parts)


def throughput(args: argparse.Namespace, trees: list[Tree]) -> None:
    now = trees[-1].label
    heads = " ".join(f"{t.label:>9}" for t in trees)
    print(
        f"{os.cpu_count()} CPUs, load average (1, 5, 15 min) at start "
        f"{', '.join(f'{x:.2f}' for x in os.getloadavg())}; fast_ycb 003_cracker_box, "
        f"{workload(args)}, {args.format}; medians over {args.repeats} interleaved runs "
        "[frames/s]"
    )
    ratios = " ".join(f"{'/' + t.label:>8}" for t in trees[:-1])
    print(f"{'':<30} {heads} {ratios} {'load1':>6}")
    for text in args.resolutions:
        w, h = (int(v) for v in text.lower().split("x"))
        n = args.frames or (48 if w * h <= 640 * 480 else 24)
        base = {
            "resolution": [w, h],
            "format": args.format,
            "nvof_source": args.nvof_source,
            "msaa": args.msaa,
        }
        print(f"-- {text}, N = {n}")
        for tree in trees:  # fill each tree's cache (object and scene textures): unmeasured
            run_child(tree, {**base, "kind": "generate", "frames": 2, "workers": 1})
        render = measure(trees, {**base, "kind": "render", "frames": n}, args.repeats, None)
        print_row("render+seg+flow", render, trees)
        steady: dict[int, dict[str, float]] = {}
        for workers in args.workers:
            spec = {**base, "kind": "generate", "frames": n, "workers": workers}
            values: dict[str, list[tuple[float, float, float]]] = {t.label: [] for t in trees}
            for _ in range(args.repeats):
                for tree in trees:
                    values[tree.label].append(tuple(run_child(tree, spec)))
            steady[workers] = {k: statistics.median(r[0] for r in v) for k, v in values.items()}
            wall = {k: statistics.median(r[1] for r in v) for k, v in values.items()}
            print_row(f"generate W={workers} steady", steady[workers], trees)
            print_row(f"generate W={workers} wall", wall, trees)
            if workers == 1:
                cpu = {k: statistics.median(r[2] for r in v) for k, v in values.items()}
                print_row("generate W=1 CPU ms/frame", cpu, trees)
        short = None
        if 2 in steady and args.short_frames:
            spec = {**base, "kind": "generate", "frames": args.short_frames, "workers": 2}
            short = measure(trees, {**spec, "default_chunks": True}, args.repeats, 1)
            print_row(f"short N={args.short_frames} W=2 wall", short, trees)
            spawned = measure(trees, spec, args.repeats, 1)
            print_row(f"short N={args.short_frames} W=2 wall, unit per worker", spawned, trees)
            floor = measure(trees, {**base, "kind": "floor"}, args.repeats, None)
            print_row("start-up floor [s]", floor, trees)
        batch = None
        if 2 in steady and args.short_frames and args.batch_sequences > 1:
            spec = {
                **base,
                "kind": "generate",
                "frames": args.short_frames,
                "workers": 2,
                "default_chunks": True,
                "sequences": args.batch_sequences,
            }
            batch = measure(trees, spec, args.repeats, 1)
            name = f"{args.batch_sequences} x short W=2 wall"
            print_row(name, batch, trees)
        if 1 in steady:
            print(f"   W=1 steady / render+seg+flow ({now}): {steady[1][now] / render[now]:.2f}")
        if short is not None:
            print(f"   short / W=2 steady ({now}): {short[now] / steady[2][now]:.2f}")
            ratio = spawned[now] / steady[2][now]
            print(f"   short, unit per worker / W=2 steady ({now}): {ratio:.2f}")
            if 1 in steady:
                # a short run is generated in-process: start-up, then its frames at one worker's
                # steady rate; the goal (0.6 x the 2-worker steady rate) leaves this much start-up
                n_short = args.short_frames
                allowed = n_short / (0.6 * steady[2][now]) - (n_short - 1) / steady[1][now]
                print(
                    f"   start-up a {n_short}-frame run may take for 0.6 x W=2 steady ({now}): "
                    f"{allowed:.2f} s; the floor of any fresh process: {floor[now]:.2f} s"
                )
        if batch is not None:
            ratio = batch[now] / steady[2][now]
            print(f"   {args.batch_sequences} x short / W=2 steady ({now}): {ratio:.2f}")


def memory(args: argparse.Namespace, tree: Tree) -> None:
    print(
        "\npeak RSS of a fresh process generating one sequence (ci cracker box, 96x72, fast-ycb, "
        "default networks, in-process):"
    )
    for frames in (args.short_frames_memory, args.long_frames):
        res = subprocess.run(
            [sys.executable, __file__, "--memory-child", str(frames)],
            capture_output=True,
            text=True,
            check=True,
            env=dict(os.environ, PYTHONPATH=str(tree.pythonpath)),
        )
        n, peak, wall = res.stdout.split()[-3:]
        print(
            f"  {int(n):>6} frames: peak RSS {float(peak):7.1f} MiB ({float(wall):.0f} s, "
            f"load1 {load1():.2f})",
            flush=True,
        )


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--resolutions", nargs="+", default=["640x480", "1280x720"])
    p.add_argument("--format", default="fast-ycb", choices=("fast-ycb", "bop", "hdf5"))
    p.add_argument("--workers", nargs="+", type=int, default=[1, 2])
    p.add_argument("--frames", type=int, help="N (default 48 at <= 640x480, else 24)")
    p.add_argument("--short-frames", type=int, default=24, help="frames of the short run")
    p.add_argument(
        "--batch-sequences",
        type=int,
        default=8,
        help="sequences of --short-frames frames generated in one run (0: skip that row)",
    )
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument(
        "--baseline-ref", nargs="+", default=[], help="git commits to measure side by side"
    )
    p.add_argument(
        "--nvof-source",
        help="what-if: source of the nvof_1_slow set (e.g. nvof-like:dis:medium4); every tree "
        "runs it, so a baseline must know it",
    )
    p.add_argument(
        "--msaa", type=int, choices=(0, 2, 4, 8, 16), help="what-if: the colour pass's samples"
    )
    p.add_argument("--short-frames-memory", type=int, default=150)
    p.add_argument("--long-frames", type=int, default=3000)
    p.add_argument("--skip-throughput", action="store_true")
    p.add_argument("--skip-memory", action="store_true")
    p.add_argument("--child", help=argparse.SUPPRESS)
    p.add_argument("--memory-child", type=int, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child is not None:
        child_main(json.loads(args.child))
        return
    if args.memory_child is not None:
        memory_child(args.memory_child)
        return
    scratch = Path(tempfile.mkdtemp(prefix="bench_generate_trees_"))
    try:
        now = current_tree(scratch)
        trees = [*(baseline_tree(ref, scratch) for ref in args.baseline_ref), now]
        compile_trees(trees)  # as an installed package is: a fresh process reads bytecode
        if not args.skip_throughput:
            throughput(args, trees)
        if not args.skip_memory:
            memory(args, now)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    main()
