"""ROFT's step time, stage by stage, and its accuracy, side by side with baseline commits.

One process per tree and run, on ONE core (BLAS and OpenCV threads pinned to 1 before they
load). The scene is the analytic textured box of :mod:`roft_sim.testing.analytic_scene` in fast
motion (peaks near 0.4 m/s and 4 rad/s), with the paper's schedule: a pose and a mask every 6
frames, each delivered 6 frames late (frame 0 undelayed), ground-truth flow (or OpenCV DIS
computed in the step's clock with ``--dis-presets``), and the numpy analytic depth renderer for
the outlier test (its time is reported apart: a real renderer replaces it). The sequence is
rendered once per resolution and kept as ``.npy`` files that every process maps (``--cache``
keeps them between runs).

With ``--baseline-ref REF [REF ...]`` every measurement also runs on the package as it was at
each git commit (``git archive``), interleaved with the working tree's (baseline, ..., now,
baseline, ..., now), so that every tree sees the same machine load: a speed-up is a ratio
measured in one run. The same run scores every tree's estimates against the exact ground truth
(ADD-AUC, position / rotation / velocity RMSE) and prints the largest per-frame difference
between the working tree's estimates and each baseline's, so a speed-up that moves accuracy
shows in the same table. ``--config default reference`` measures the default configuration and
the paper's (``reference_config()``) the same way, interleaved, each tree under each (labels
``now:default``, ``now:reference``; the working tree under the first configuration is the one
the others are compared with): the step time a user gives up for the default's accuracy.

Printed per resolution and input (flow given, or DIS + step): the step's wall time [ms], median,
p95, p99, max and mean over all frames, over the frames without an arriving pose and over the
frames where one arrives (the replay of the delayed pose); then, for trees whose tracker reports
them (``RoftTracker.stage_times_s``), the same for each stage: ``mask_sync`` (propagating the
mask, warping an arrived one), ``velocity`` (the flow measurement with its depth rows and
residual fits, and the velocity KF), ``remeasure`` (the velocity KF re-run over the flows a
freshly arrived mask reads again), ``pose`` (the pose UKF's predict and correct of this frame),
``replay`` (the pose UKF re-run from an arrived pose's capture frame, outlier test included)
and ``render`` (the outlier test's depth renders, inside ``replay`` and ``pose``).

    python benchmarks/bench_roft.py --frames 150 --repeats 2 --baseline-ref HEAD~1
    python benchmarks/bench_roft.py --resolutions 640x480 --dis-presets ultrafast
    python benchmarks/bench_roft.py --config default reference --repeats 2
    python benchmarks/bench_roft.py --resolutions 1280x720 --repeats 1 --cache /tmp/bench_roft

Profiles of one run (how the hot spots are found; pyinstrument is in the dev extra):

    python -m pyinstrument -r text benchmarks/bench_roft.py --profile 1280x720
    python -m pyinstrument -r text benchmarks/bench_roft.py --profile 640x480 --frames 60

Goals: at 1280x720, median <= 4 ms, p95 <= 12, p99 <= 20, max <= 33 (a 30 fps camera's period,
pose arrivals included) and mean <= 5 ms; at 640x480 median <= 2 ms, p95 <= 6, and DIS
ultrafast + step p95 <= 33 ms.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import json  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402
from baseline_trees import Tree, baseline_tree, compile_trees, current_tree  # noqa: E402

PERIOD = 6
"""Frames between two captures of the pose and mask networks (the paper's 5 fps at 30 fps)."""
DELAY = 6
"""Frames a capture takes to arrive (the paper's 200 ms)."""
CONFIGS = ("default", "reference")
"""``RoftConfig()`` and the paper's configuration (``reference_config()``)."""
STAGES = ("mask_sync", "velocity", "remeasure", "pose", "replay", "render")
"""The stages a tracker may report in ``stage_times_s``, in pipeline order."""


# ----------------------------------------------------------------------------- the sequence
def sequence_folder(cache: Path, width: int, height: int, frames: int) -> Path:
    """Renders the analytic sequence into ``cache`` once; returns its folder."""
    folder = cache / f"analytic_{width}x{height}_{frames}"
    if (folder / "meta.json").exists():
        return folder
    import cv2

    from roft_sim.testing.analytic_scene import analytic_box_sequence, default_intrinsics

    t0 = time.perf_counter()
    seq = analytic_box_sequence(n_frames=frames, intrinsics=default_intrinsics(width, height))
    tmp = folder.with_name(folder.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    shape = (frames, height, width)
    depth = np.lib.format.open_memmap(tmp / "depth.npy", "w+", np.float32, shape)
    grey = np.lib.format.open_memmap(tmp / "grey.npy", "w+", np.uint8, shape)
    flow = np.lib.format.open_memmap(tmp / "flow.npy", "w+", np.float32, shape + (2,))
    valid = np.lib.format.open_memmap(tmp / "valid.npy", "w+", np.bool_, shape)
    for k in range(frames):
        depth[k] = seq.depth(k)
        grey[k] = cv2.cvtColor(seq.rgb(k), cv2.COLOR_RGB2GRAY)
        f = seq.flow(k, "gt")
        if f is not None:
            flow[k] = f.flow_px
            valid[k] = f.valid if f.valid is not None else True
    for arr in (depth, grey, flow, valid):
        arr.flush()
    captures = [0, *range(PERIOD, frames, PERIOD)]
    np.save(tmp / "masks.npy", np.stack([seq.mask(c, "gt") for c in captures]))
    np.savez(
        tmp / "gt.npz",
        T_cam_obj=seq.gt.T_cam_obj,
        v_obj_mps=seq.gt.v_obj_mps,
        w_radps=seq.gt.w_radps,
        model_points_m=seq.object_model().model_points_m,
    )
    meta = {
        "frames": frames,
        "fps": seq.fps,
        "width": width,
        "height": height,
        "captures": captures,
        "times_s": [seq.time_s(k) for k in range(frames)],
        "mask_px": float(np.mean([seq.mask(k, "gt").sum() for k in range(frames)])),
        "render_s": time.perf_counter() - t0,
    }
    (tmp / "meta.json").write_text(json.dumps(meta))
    tmp.rename(folder)
    return folder


# ----------------------------------------------------------------------------- the child
class Observations:
    """The paper's schedule: captures every PERIOD frames delivered DELAY frames late (the
    first one, frame 0, undelayed); each frame's observation is read from the mapped files
    when asked for (outside the timed step)."""

    def __init__(self, folder: Path):
        self.meta = json.loads((folder / "meta.json").read_text())
        self.depth = np.load(folder / "depth.npy", mmap_mode="r")
        self.flow = np.load(folder / "flow.npy", mmap_mode="r")
        self.valid = np.load(folder / "valid.npy", mmap_mode="r")
        self.masks = np.load(folder / "masks.npy")
        self.T = np.load(folder / "gt.npz")["T_cam_obj"]
        captures = self.meta["captures"]
        self.arrivals = {(c + DELAY if c else 0): (i, c) for i, c in enumerate(captures)}

    def __len__(self) -> int:
        return int(self.meta["frames"])

    def __getitem__(self, k: int) -> Any:
        from roft_sim.records import FlowField, MaskDetection, Observation, PoseDetection

        poses: tuple[Any, ...] = ()
        masks: tuple[Any, ...] = ()
        if k in self.arrivals:
            i, c = self.arrivals[k]
            T = self.T[c]
            poses = (PoseDetection(capture_k=c, arrival_k=k, T_cam_obj=T, detection_id=k),)
            masks = (MaskDetection(capture_k=c, arrival_k=k, mask=self.masks[i], detection_id=k),)
        flow = None
        if k:
            flow = FlowField(
                flow_px=np.array(self.flow[k]),
                from_k=k - 1,
                to_k=k,
                valid=np.array(self.valid[k]),
            )
        return Observation(
            k=k,
            t_s=self.meta["times_s"][k],
            rgb=None,
            depth_m=np.array(self.depth[k]),
            flow=flow,
            poses=poses,
            masks=masks,
        )


class TimedRenderer:
    """Wraps a depth renderer and accumulates the time spent in it."""

    def __init__(self, inner: Any):
        self.inner = inner
        self.seconds = 0.0

    def render_depth(self, T_cam_obj: Any, intrinsics: Any) -> Any:
        t0 = time.perf_counter()
        out = self.inner.render_depth(T_cam_obj, intrinsics)
        self.seconds += time.perf_counter() - t0
        return out


def make_tracker(meta: dict[str, Any], renderer: TimedRenderer, config: str) -> Any:
    from roft_sim.testing.analytic_scene import AnalyticBox, default_intrinsics
    from roft_sim.trackers.base import TrackerContext
    from roft_sim.trackers.roft import RoftConfig, RoftTracker

    cfg = RoftConfig()
    if config == "reference":
        from roft_sim.trackers.roft.reference import reference_config

        cfg = reference_config()
    ctx = TrackerContext(
        intrinsics=default_intrinsics(meta["width"], meta["height"]),
        fps=meta["fps"],
        object_model=AnalyticBox().object_model(),
        rng=np.random.default_rng(0),
        depth_renderer=renderer,
    )
    tracker = RoftTracker(cfg, ctx)
    tracker.reset(None)
    return tracker


def child_main(spec: dict[str, Any]) -> None:
    """Runs the tracker once over the sequence; writes the times and estimates to an npz."""
    import cv2

    from roft_sim.records import FlowField
    from roft_sim.testing.analytic_scene import AnalyticBoxDepthRenderer

    cv2.setNumThreads(1)
    folder = Path(spec["folder"])
    meta = json.loads((folder / "meta.json").read_text())
    obs = Observations(folder)
    grey = np.load(folder / "grey.npy", mmap_mode="r") if spec["dis"] else None
    dis = None
    if spec["dis"]:
        preset = getattr(cv2, f"DISOPTICAL_FLOW_PRESET_{spec['dis'].upper()}")
        dis = cv2.DISOpticalFlow_create(preset)
        grey = np.array(grey)
    renderer = TimedRenderer(AnalyticBoxDepthRenderer())
    tracker = make_tracker(meta, renderer, spec["config"])
    n = len(obs)
    wall, cpu, render = np.zeros(n), np.zeros(n), np.zeros(n)
    stages = np.full((n, len(STAGES)), np.nan)
    T = np.full((n, 4, 4), np.nan)
    twist = np.full((n, 6), np.nan)  # the pose filter's (v_obj, w)
    spatial = np.full((n, 6), np.nan)  # the reported spatial twist (v_o, w)
    for k in range(n):
        o = obs[k]
        before = renderer.seconds
        t0, c0 = time.perf_counter(), time.thread_time()
        if dis is not None and k:
            f = dis.calc(grey[k - 1], grey[k], None)
            o = dataclasses.replace(o, flow=FlowField(flow_px=f, from_k=k - 1, to_k=k))
        est = tracker.step(o)
        wall[k] = time.perf_counter() - t0
        cpu[k] = time.thread_time() - c0
        render[k] = renderer.seconds - before
        times = getattr(tracker, "stage_times_s", None)
        if times is not None:
            stages[k] = [times.get(s, 0.0) for s in STAGES]
        if est.valid:
            T[k] = est.T_cam_obj
            twist[k] = np.concatenate([est.v_obj_mps, est.w_radps])
        if est.spatial_twist is not None:
            spatial[k] = est.spatial_twist
    np.savez(
        spec["out"],
        wall=wall,
        cpu=cpu,
        render=render,
        stages=stages,
        has_pose=np.array([k in obs.arrivals for k in range(n)]),
        T=T,
        twist=twist,
        spatial=spatial,
    )


# ----------------------------------------------------------------------------- the parent
def run_child(tree: Tree, spec: dict[str, Any]) -> dict[str, np.ndarray]:
    env = dict(os.environ, PYTHONPATH=str(tree.pythonpath))
    res = subprocess.run(
        [sys.executable, __file__, "--child", json.dumps(spec)],
        capture_output=True,
        text=True,
        env=env,
    )
    if res.returncode != 0:
        raise RuntimeError(f"{tree.label} child failed:\n{res.stderr[-3000:]}")
    with np.load(spec["out"]) as data:
        return {k: data[k] for k in data.files}


def percentiles_ms(seconds: np.ndarray) -> str:
    ms = 1e3 * seconds[np.isfinite(seconds)]
    if ms.size == 0:
        return f"{'n/a':>47}"
    p = np.percentile(ms, [50, 95, 99])
    return f"{p[0]:7.2f} {p[1]:7.2f} {p[2]:7.2f} {ms.max():7.2f} {ms.mean():7.2f}"


def accuracy(run: dict[str, np.ndarray], gt: Any) -> str:
    """ADD-AUC [%], position and rotation RMSE [cm, deg] and the reported velocity's RMSE [cm/s,
    deg/s], scored as ``roft-sim run`` scores them (``evaluate_sequence``, frames without an
    estimate holding the last one)."""
    from roft_sim.metrics.sequence import evaluate_sequence

    T = run["T"]
    valid = np.isfinite(T).all(axis=(1, 2))
    spatial = run.get("spatial")
    has_spatial = spatial is not None and np.isfinite(spatial).all(axis=1).any()
    m = evaluate_sequence(
        np.where(valid[:, None, None], T, np.eye(4)),
        gt["T_cam_obj"],
        gt["model_points_m"],
        v_obj_gt=gt["v_obj_mps"],
        w_gt=gt["w_radps"],
        v_obj_est=run["twist"][:, :3],
        w_est=run["twist"][:, 3:],
        spatial_twist_est=spatial if has_spatial else None,
        valid=valid,
        invalid="hold",
    )
    return (
        f"ADD-AUC {m.add_auc_pct:6.2f} %  e_t {m.rmse_t_cm:6.3f} cm  e_a {m.rmse_a_deg:6.3f} deg  "
        f"e_v {m.rmse_v_cmps:6.3f} cm/s  e_w {m.rmse_w_dps:7.3f} deg/s"
    )


def difference(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> str:
    """Largest per-frame difference between two runs' estimates."""
    from roft_sim.metrics.pose_errors import rotation_errors_rad

    Ta, Tb = a["T"], b["T"]
    both = np.isfinite(Ta).all(axis=(1, 2)) & np.isfinite(Tb).all(axis=(1, 2))
    mismatch = int((np.isfinite(Ta).all(axis=(1, 2)) != np.isfinite(Tb).all(axis=(1, 2))).sum())
    if not both.any():
        return f"no frame estimated by both; {mismatch} validity mismatches"
    dp = np.linalg.norm(Ta[both, :3, 3] - Tb[both, :3, 3], axis=1).max()
    da = rotation_errors_rad(Ta[both], Tb[both]).max()
    dv = np.abs(a["twist"][both] - b["twist"][both]).max(axis=0)
    text = (
        f"max |diff| position {1e3 * dp:.2e} mm, rotation {np.degrees(da):.2e} deg, "
        f"v {dv[:3].max():.2e} m/s, w {dv[3:].max():.2e} rad/s"
    )
    if "spatial" in a and "spatial" in b:
        ds = np.nanmax(np.abs(a["spatial"] - b["spatial"]), axis=0)
        text += f", reported twist v_o {ds[:3].max():.2e} m/s, w {ds[3:].max():.2e} rad/s"
    return text + f"; {mismatch} validity mismatches"


@dataclasses.dataclass(frozen=True)
class Variant:
    """One measured combination: a tree and a configuration of ROFT."""

    tree: Tree
    config: str
    label: str
    """``tree.label``, with ``:config`` when several configurations are measured."""


def variants_of(trees: list[Tree], configs: list[str]) -> list[Variant]:
    """Every tree under every configuration, grouped by configuration (the working tree last in
    each group)."""
    return [
        Variant(tree, config, tree.label if len(configs) == 1 else f"{tree.label}:{config}")
        for config in configs
        for tree in trees
    ]


def comparisons(variants: list[Variant]) -> list[tuple[Variant, Variant]]:
    """``(now, other)`` pairs: the working tree against each baseline commit under the same
    configuration, then the working tree under each further configuration against the first."""
    now = {v.config: v for v in variants if v.tree.label == "now"}
    pairs = [(now[v.config], v) for v in variants if v.tree.label != "now"]
    first = next(iter(now.values()))
    return pairs + [(v, first) for v in now.values() if v is not first]


def label_width(variants: list[Variant]) -> int:
    """The width of the label column (10 or the longest label)."""
    return max(10, *(len(v.label) for v in variants))


def report(
    label: str, variants: list[Variant], runs: dict[str, list[dict[str, np.ndarray]]]
) -> None:
    width = label_width(variants)
    pad = " " * (width - 10)
    print(f"  {label}: step wall time [ms]{pad}      median     p95     p99     max    mean")
    for variant in variants:
        rs = runs[variant.label]
        wall = np.concatenate([r["wall"] for r in rs])
        pose = np.concatenate([r["has_pose"] for r in rs])
        for name, sel in (("all", slice(None)), ("no pose", ~pose), ("pose arrives", pose)):
            print(f"    {variant.label:<{width}} {name:<18} {percentiles_ms(wall[sel])}")
    medians = {
        v.label: np.median(np.concatenate([r["wall"] for r in runs[v.label]])) for v in variants
    }
    for a, b in comparisons(variants):
        print(f"    {a.label} / {b.label}: median step {medians[a.label] / medians[b.label]:.3f}x")
    for variant in variants:
        stages = np.concatenate([r["stages"] for r in runs[variant.label]])
        if np.isnan(stages).all():
            continue
        pose = np.concatenate([r["has_pose"] for r in runs[variant.label]])
        print(f"    stages of {variant.label} [ms]     median     p95     p99     max    mean")
        for i, stage in enumerate(STAGES):
            for name, sel in (("", ~pose), (" (pose)", pose)):
                print(f"      {stage + name:<22} {percentiles_ms(stages[sel, i])}")


def measure(
    variants: list[Variant], folder: Path, scratch: Path, repeats: int, dis: str | None
) -> dict[str, list[dict[str, np.ndarray]]]:
    """Every variant ``repeats`` times, interleaved (so that all see the same machine load)."""
    runs: dict[str, list[dict[str, np.ndarray]]] = {v.label: [] for v in variants}
    for r in range(repeats):
        for v in variants:
            out = scratch / f"{v.label.replace(':', '_')}_{folder.name}_{dis}_{r}.npz"
            spec = {"folder": str(folder), "dis": dis, "config": v.config, "out": str(out)}
            runs[v.label].append(run_child(v.tree, spec))
    return runs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--resolutions", nargs="+", default=["640x480", "1280x720"])
    parser.add_argument("--dis-presets", nargs="*", default=[], help="e.g. ultrafast medium")
    parser.add_argument("--baseline-ref", nargs="*", default=[], help="git commits to compare")
    parser.add_argument(
        "--config",
        nargs="+",
        choices=CONFIGS,
        default=["default"],
        help="ROFT configurations to measure side by side (the first is the one compared with)",
    )
    parser.add_argument("--cache", type=Path, help="keep the rendered sequences here")
    parser.add_argument("--profile", metavar="WxH", help="one in-process run, for a profiler")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child is not None:
        child_main(json.loads(args.child))
        return 0
    configs = list(dict.fromkeys(args.config))
    scratch = Path(tempfile.mkdtemp(prefix="bench_roft_"))
    cache = args.cache or scratch
    try:
        if args.profile:
            w, h = (int(x) for x in args.profile.split("x"))
            folder = sequence_folder(cache, w, h, args.frames)
            spec = {"folder": str(folder), "dis": None, "config": configs[0]}
            child_main({**spec, "out": str(scratch / "profile.npz")})
            return 0
        trees = [*(baseline_tree(ref, scratch) for ref in args.baseline_ref), current_tree(scratch)]
        compile_trees(trees)
        variants = variants_of(trees, configs)
        print(
            f"python {sys.version.split()[0]}, numpy {np.__version__}; {os.cpu_count()} CPUs, "
            f"load average {', '.join(f'{x:.2f}' for x in os.getloadavg())}; "
            f"config {', '.join(configs)}; {args.repeats} interleaved runs per tree"
        )
        for res in args.resolutions:
            w, h = (int(x) for x in res.split("x"))
            folder = sequence_folder(cache, w, h, args.frames)
            meta = json.loads((folder / "meta.json").read_text())
            gt = dict(np.load(folder / "gt.npz"))
            print(f"{res}: {args.frames} frames, object mask {meta['mask_px']:.0f} px")
            for dis in [None, *args.dis_presets]:
                runs = measure(variants, folder, scratch, args.repeats, dis)
                label = "flow given" if dis is None else f"DIS {dis} + step"
                report(label, variants, runs)
                width = label_width(variants)
                for v in variants:
                    print(f"    accuracy {v.label:<{width}} {accuracy(runs[v.label][0], gt)}")
                for a, b in comparisons(variants):
                    if a.config == b.config:
                        diff = difference(runs[a.label][0], runs[b.label][0])
                        print(f"    {a.label} vs {b.label}: {diff}")
            print(f"  load average after: {os.getloadavg()[0]:.2f}", flush=True)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
