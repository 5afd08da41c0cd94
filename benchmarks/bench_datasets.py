"""Dataset writer and reader throughput per format, and peak memory over a long sequence.

Frames are synthetic but image-like (smooth texture, a moving textured rectangle, mild noise),
with what a generator writes: rgb, depth, a ground-truth mask, a full-resolution float32 flow
set with validity, an NVOF-like S10.5 flow on a 4x4 grid, a detector mask and a detector pose.
OpenCV runs on one thread. Medians over ``--repeats``.

    python benchmarks/bench_datasets.py                        # 640x480 and 1280x720, 3 formats
    python benchmarks/bench_datasets.py --frames 10 --repeats 2 --long-frames 200
    python benchmarks/bench_datasets.py --workers 2            # write with 2 processes

Prints, per format and resolution: write frames/s (write_frame + finalize; wall clock, and per
CPU second of this process, which is steadier on a shared machine), read frames/s (rgb, depth,
both flows, both masks; wall and per CPU second), MB on disk per frame; then the peak Python
heap allocated (tracemalloc, numpy arrays included; the two source frames excluded) while
writing a short and a long sequence at 640x480, which stays flat when frames stream to disk.
"""

from __future__ import annotations

import argparse
import dataclasses
import multiprocessing
import shutil
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import cv2
import numpy as np

from roft_sim.datasets import DatasetFrame, open_sequence, open_writer
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import FlowField

FORMATS = ("fast-ycb", "hdf5", "bop")
ENCODINGS = {"nvof_1_slow": "s10.5"}


def camera(width: int, height: int) -> CameraIntrinsics:
    f = width / (2 * np.tan(np.radians(55) / 2))
    return CameraIntrinsics(
        fx_px=f, fy_px=f, cx_px=width / 2, cy_px=height / 2, width_px=width, height_px=height
    )


def make_frame(cam: CameraIntrinsics, k: int, rng: np.random.Generator) -> DatasetFrame:
    """One image-like frame k (content moves with k)."""
    h, w = cam.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float32)
    x0, y0 = w * 0.3 + 3 * k, h * 0.3 + 2 * k
    obj = (u > x0) & (u < x0 + w * 0.3) & (v > y0) & (v < y0 + h * 0.3)
    base = 100 + 60 * np.sin(u / 37.0) * np.cos(v / 23.0)
    tex = 128 + 100 * np.sign(np.sin((u - x0) / 6.0) * np.sin((v - y0) / 6.0))
    grey = np.where(obj, tex, base) + rng.normal(0, 2, (h, w))
    rgb = np.clip(np.stack([grey, grey * 0.8 + 20, 255 - grey], axis=-1), 0, 255).astype(np.uint8)
    depth = np.where(obj, 0.6 + 0.0001 * u, 1.4 + 0.0002 * v).astype(np.float32)
    depth[rng.random((h, w)) < 0.01] = 0.0
    flows = {}
    if k > 0:
        dense = np.zeros((h, w, 2), np.float32)
        dense[obj] = (3.0, 2.0)
        dense[obj] += rng.normal(0, 0.1, (int(obj.sum()), 2)).astype(np.float32)
        flows["gt"] = FlowField(flow_px=dense, from_k=k - 1, to_k=k, valid=obj | (depth > 0))
        coarse = (np.round(dense[::4, ::4].astype(np.float64) * 32) / 32 + 0.0).astype(np.float32)
        flows["nvof_1_slow"] = FlowField(flow_px=coarse, from_k=k - 1, to_k=k, grid_px=4)
    T = np.eye(4)
    T[:3, 3] = (0.01 * k, 0.0, 0.6)
    return DatasetFrame(
        k=k,
        t_s=k / 30,
        rgb=rgb,
        depth_m=depth,
        T_world_cam=np.eye(4),
        gt_T_cam_obj=T,
        gt_v_obj_mps=np.array([0.3, 0.0, 0.0]),
        gt_w_radps=np.zeros(3),
        gt_mask=obj,
        flows=flows,
        detector_masks={"mrcnn": obj if k % 7 else None},
        detector_poses={"dope": T if k % 5 else None},
    )


def frames_for(cam: CameraIntrinsics, n: int) -> list[DatasetFrame]:
    """Two distinct frames reused (re-indexed) for n frames: content generation is not timed."""
    rng = np.random.default_rng(0)
    f0, f1 = make_frame(cam, 0, rng), make_frame(cam, 1, rng)
    out = [f0]
    for k in range(1, n):
        flows = {name: dataclasses.replace(f, from_k=k - 1, to_k=k) for name, f in f1.flows.items()}
        out.append(dataclasses.replace(f1, k=k, t_s=k / 30, flows=flows))
    return out


def new_writer(fmt: str, root: Path, cam: CameraIntrinsics, n: int):
    return open_writer(
        fmt, root, sequence_name="bench", object_name="003_cracker_box", intrinsics=cam,
        fps=30, n_frames=n, metadata={"benchmark": True}, object_model=None,
        flow_encodings=ENCODINGS,
    )  # fmt: skip


def _worker(args: tuple) -> None:
    writer, width, height, ks, n = args  # the writer arrives pickled
    cv2.setNumThreads(1)
    frames = frames_for(camera(width, height), n)
    for k in ks:
        writer.write_frame(frames[k])


def time_write(fmt: str, cam: CameraIntrinsics, n: int, workers: int, tmp: Path) -> tuple:
    root = tmp / f"w_{fmt}"
    shutil.rmtree(root, ignore_errors=True)
    frames = frames_for(cam, n)
    writer = new_writer(fmt, root, cam, n)
    t0 = time.perf_counter()
    c0 = time.process_time()
    if workers == 1:
        for f in frames:
            writer.write_frame(f)
    else:
        jobs = [
            (writer, cam.width_px, cam.height_px, list(range(i, n, workers)), n)
            for i in range(workers)
        ]
        with multiprocessing.get_context("fork").Pool(workers) as pool:
            pool.map(_worker, jobs)
    t1 = time.perf_counter()
    path = writer.finalize()
    t2 = time.perf_counter()
    cpu = time.process_time() - c0  # this process only (workers > 1: finalize only)
    size = sum(p.stat().st_size for p in path.rglob("*")) if path.is_dir() else path.stat().st_size
    return n / (t2 - t0), n / (t1 - t0), n / cpu, size / n / 1e6, path


def time_read(path: Path, n: int) -> tuple[float, float]:
    t0, c0 = time.perf_counter(), time.process_time()
    seq = open_sequence(path)
    for k in range(n):
        seq.rgb(k)
        seq.depth(k)
        for name in seq.flow_sets():
            seq.flow(k, name)
        for name in seq.mask_sets():
            seq.mask(k, name)
    if hasattr(seq, "close"):
        seq.close()
    return n / (time.perf_counter() - t0), n / (time.process_time() - c0)


def peak_memory_mb(fmt: str, cam: CameraIntrinsics, n: int, tmp: Path) -> float:
    """Peak traced heap [MB] while writing and finalizing n frames (frames made on the fly)."""
    root = tmp / f"m_{fmt}_{n}"
    shutil.rmtree(root, ignore_errors=True)
    base = frames_for(cam, 2)
    writer = new_writer(fmt, root, cam, n)
    tracemalloc.start()
    for k in range(n):
        src = base[min(k, 1)]
        flows = {
            name: dataclasses.replace(f, from_k=k - 1, to_k=k) for name, f in src.flows.items()
        }
        writer.write_frame(dataclasses.replace(src, k=k, t_s=k / 30, flows=flows))
    writer.finalize()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    shutil.rmtree(root, ignore_errors=True)
    return peak / 1e6


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=20, help="frames per timed run")
    parser.add_argument("--repeats", type=int, default=3, help="runs per measurement (median)")
    parser.add_argument("--resolutions", nargs="+", default=["640x480", "1280x720"])
    parser.add_argument("--formats", nargs="+", default=list(FORMATS), choices=FORMATS)
    parser.add_argument("--workers", type=int, default=1, help="writer processes")
    parser.add_argument("--long-frames", type=int, default=300, help="long sequence for memory")
    parser.add_argument("--no-memory", action="store_true", help="skip the memory measurement")
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    tmp = Path(tempfile.mkdtemp(prefix="bench_datasets_"))
    try:
        print(
            f"{args.frames} frames x {args.repeats} repeats, {args.workers} writer process(es), "
            "OpenCV 1 thread; medians"
        )
        print(
            f"{'format':9} {'resolution':>10} {'write fps':>10} {'(frames only)':>13} "
            f"{'write fps/CPU':>13} {'read fps':>9} {'read fps/CPU':>12} {'MB/frame':>9}"
        )
        for res in args.resolutions:
            width, height = (int(x) for x in res.split("x"))
            cam = camera(width, height)
            for fmt in args.formats:
                runs = []
                for _ in range(args.repeats):
                    total, only_frames, per_cpu, mb, path = time_write(
                        fmt, cam, args.frames, args.workers, tmp
                    )
                    read_wall, read_cpu = time_read(path, args.frames)
                    runs.append((total, only_frames, per_cpu, read_wall, read_cpu, mb))
                med = [statistics.median(col) for col in zip(*runs, strict=True)]
                cpu_text = f"{med[2]:13.1f}" if args.workers == 1 else f"{'-':>13}"
                print(
                    f"{fmt:9} {res:>10} {med[0]:10.1f} {med[1]:13.1f} {cpu_text} "
                    f"{med[3]:9.1f} {med[4]:12.1f} {med[5]:9.2f}"
                )
                sys.stdout.flush()
        if not args.no_memory:
            cam = camera(640, 480)
            short = max(2, args.long_frames // 6)
            print("\npeak traced Python heap while writing at 640x480 [MB]:")
            print(f"{'format':9} {short:>8} frames {args.long_frames:>8} frames")
            for fmt in args.formats:
                a = peak_memory_mb(fmt, cam, short, tmp)
                b = peak_memory_mb(fmt, cam, args.long_frames, tmp)
                print(f"{fmt:9} {a:15.1f} {b:15.1f}")
                sys.stdout.flush()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
