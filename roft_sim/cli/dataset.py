"""``roft-sim dataset check|info|convert``: inspect, validate and convert datasets on disk.

- ``check PATH``: every sequence under PATH (a sequence or a dataset root). Fast-YCB folders go
  through the independent format checker (headers, sizes, counts, axis-angle rows, velocities
  against finite differences of the poses, flow direction against the ground-truth motion);
  BOP and HDF5 sequences are read completely, frame by frame. Exit code 1 when a problem is
  found.
- ``info PATH``: format, frames, camera, rate, flow/mask/pose sets, ground truth, model.
- ``convert PATH --to FORMAT --out DIR``: rewrites every sequence in another format.
"""

from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

import numpy as np

from roft_sim.cli.output_dirs import prepare_output_dir
from roft_sim.datasets import (
    DATASET_FORMATS,
    detect_format,
    open_sequence,
    write_sequence,
)
from roft_sim.datasets.fast_ycb_check import run_fast_ycb_check
from roft_sim.errors import ConfigError, DatasetFormatError

__all__ = ["register", "read_every_frame", "sequence_info"]


_log = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``dataset check``, ``dataset info`` and ``dataset convert``."""
    parser = subparsers.add_parser(
        "dataset",
        help="check, describe or convert datasets (fast-ycb, bop, hdf5)",
        description=__doc__.split("\n\n")[0] if __doc__ else None,
    )
    verbs = parser.add_subparsers(dest="dataset_verb", metavar="ACTION", required=True)

    check = verbs.add_parser("check", help="validate every sequence under PATH")
    check.add_argument("path", type=Path, help="a sequence, or a dataset root")
    check.add_argument("--format", choices=DATASET_FORMATS, help="skip format detection")
    check.add_argument(
        "--max-flow-frames",
        type=int,
        default=20,
        help="fast-ycb: frames per flow set used for the flow-direction check, >= 1 (default 20)",
    )
    check.add_argument("--json", action="store_true", help="print a JSON summary on stdout")
    check.set_defaults(func=_run_check)

    info = verbs.add_parser("info", help="describe every sequence under PATH")
    info.add_argument("path", type=Path, help="a sequence, or a dataset root")
    info.add_argument("--json", action="store_true", help="print JSON on stdout")
    info.set_defaults(func=_run_info)

    convert = verbs.add_parser("convert", help="rewrite every sequence under PATH in a format")
    convert.add_argument("path", type=Path, help="a sequence, or a dataset root")
    convert.add_argument("--to", required=True, choices=DATASET_FORMATS, help="target format")
    convert.add_argument("--out", required=True, type=Path, help="output dataset root")
    convert.add_argument("--overwrite", action="store_true", help="empty a non-empty --out")
    convert.set_defaults(func=_run_convert)


def _sequences(path: Path) -> list[Path]:
    """The sequences under PATH; a missing PATH or one without sequences is a usage error (exit
    2), worded as ``roft-sim run`` and ``sweep`` word it."""
    from roft_sim.harness.run_dataset import find_sequences

    try:
        return find_sequences([path])
    except DatasetFormatError as e:
        raise ConfigError(str(e)) from None


def read_every_frame(path: Path, fmt: str | None = None) -> list[str]:
    """Reads every array of a sequence through its reader; returns the problems met."""
    problems: list[str] = []
    try:
        seq = open_sequence(path, fmt)
        for getter in (seq.ground_truth, seq.camera_poses, seq.object_model):
            getter()
        for name in seq.pose_sets():
            seq.detector_poses(name)
    except DatasetFormatError as e:
        return [str(e)]
    for k in range(len(seq)):
        for what, read in (
            ("rgb", lambda k=k: seq.rgb(k)),
            ("depth", lambda k=k: seq.depth(k)),
            *((f"flow {n}", lambda k=k, n=n: seq.flow(k, n)) for n in seq.flow_sets()),
            *((f"mask {n}", lambda k=k, n=n: seq.mask(k, n)) for n in seq.mask_sets()),
        ):
            try:
                read()  # type: ignore[no-untyped-call]  # lambdas with defaults are untyped
            except DatasetFormatError as e:
                problems.append(f"frame {k} {what}: {e}")
    return problems


def _run_check(args: argparse.Namespace) -> int:
    if args.max_flow_frames < 1:
        raise ConfigError(
            f"--max-flow-frames must be at least 1 (frames per flow set checked against the "
            f"ground-truth motion), got {args.max_flow_frames}"
        )
    results = []
    for path in _sequences(args.path):
        fmt = args.format or detect_format(path)
        notes: list[str] = []
        if fmt == "fast-ycb":
            report = run_fast_ycb_check(path, max_flow_frames=args.max_flow_frames)
            problems, notes = report.problems, report.notes
        else:
            problems = read_every_frame(path, fmt)
        results.append({"path": str(path), "format": fmt, "problems": problems, "notes": notes})
        if not args.json:
            print(f"{'OK  ' if not problems else 'FAIL'} {path} ({fmt})")
            for p in problems:
                print(f"  problem: {p}")
            for n in notes:
                _log.info("  %s", n)
    if args.json:
        print(json.dumps({"sequences": results}, indent=2))
    return 1 if any(r["problems"] for r in results) else 0


def sequence_info(path: Path) -> dict[str, Any]:
    """A JSON-able description of one sequence."""
    seq = open_sequence(path)
    cam = seq.intrinsics
    gt = seq.ground_truth()
    model = seq.object_model()
    meta = seq.metadata()
    flows = {}
    for name in seq.flow_sets():
        f = seq.flow(1, name) if len(seq) > 1 else None
        flows[name] = {"grid_px": None if f is None else f.grid_px}
    return {
        "path": str(path),
        "format": detect_format(path),
        "name": seq.name,
        "object_name": seq.object_name,
        "n_frames": len(seq),
        "fps": seq.fps,
        "duration_s": seq.time_s(len(seq) - 1) - seq.time_s(0),
        "camera": {
            "width_px": cam.width_px,
            "height_px": cam.height_px,
            "fx_px": cam.fx_px,
            "fy_px": cam.fy_px,
            "cx_px": cam.cx_px,
            "cy_px": cam.cy_px,
        },
        "flow_sets": flows,
        "mask_sets": list(seq.mask_sets()),
        "pose_sets": {
            name: {"valid_fraction": float(np.mean(seq.detector_poses(name).valid))}
            for name in seq.pose_sets()
        },
        "ground_truth": None
        if gt is None
        else {"poses": True, "velocities": bool(np.isfinite(gt.v_obj_mps).all())},
        "model_points": None if model is None else len(model.model_points_m),
        "seed": meta.get("seed"),
        "format_version": meta.get("format_version"),
    }


def _run_info(args: argparse.Namespace) -> int:
    infos = [sequence_info(p) for p in _sequences(args.path)]
    if args.json:
        print(json.dumps({"sequences": infos}, indent=2))
        return 0
    for i in infos:
        cam = i["camera"]
        gt = i["ground_truth"]
        print(f"{i['path']} ({i['format']})")
        print(f"  object {i['object_name']}, {i['n_frames']} frames at {i['fps']} fps")
        print(
            f"  camera {cam['width_px']}x{cam['height_px']}, fx {cam['fx_px']:.2f} fy "
            f"{cam['fy_px']:.2f} cx {cam['cx_px']:.2f} cy {cam['cy_px']:.2f} px"
        )
        flows = ", ".join(f"{n} (grid {f['grid_px']})" for n, f in i["flow_sets"].items())
        print(f"  flow sets: {flows or 'none'}")
        print(f"  mask sets: {', '.join(i['mask_sets']) or 'none'}")
        poses = ", ".join(
            f"{n} ({p['valid_fraction']:.0%} valid)" for n, p in i["pose_sets"].items()
        )
        print(f"  pose sets: {poses or 'none'}")
        print(
            "  ground truth: "
            + ("none" if gt is None else "poses" + (" + velocities" if gt["velocities"] else ""))
        )
        print(f"  model points: {i['model_points'] if i['model_points'] else 'none'}")
    return 0


def _run_convert(args: argparse.Namespace) -> int:
    sources = _sequences(args.path)
    out = prepare_output_dir(args.out, overwrite=args.overwrite)
    for path in sources:
        written = write_sequence(open_sequence(path), args.to, out)
        print(f"{path} -> {written}")
    return 0
