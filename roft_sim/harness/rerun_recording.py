"""``roft-sim view``: a Rerun recording (``.rrd``) of a ``roft-sim run`` folder.

Needs the optional extra ``view`` (``pip install -e '.[view]'``, rerun-sdk). Per sequence
``<seq>`` (docs/running.md, "Looking at a run"), on the timelines ``frame`` (k) and ``time``
(k / fps):

=====================================  =====================================================
``<seq>/camera``                       pinhole camera (OpenCV optical frame, RDF), static
``<seq>/camera/rgb``                   the image
``<seq>/camera/depth``                 z-depth [m]
``<seq>/camera/mask_gt``               ground-truth visible mask (class 1)
``<seq>/camera/mask_delivered``        the newest mask the tracker has received (class 2)
``<seq>/camera/flow``                  colour-coded flow ``F_k`` of the run's stored flow set
``<seq>/gt``, ``<seq>/estimate``       ground-truth and estimated ``T_cam_obj`` (3D frames),
                                       each with the object's model points (``.../points``)
``<seq>/detection``                    every pose arriving at frame k, a 3D frame with the
                                       model points, and a text log with its delay
``<seq>/delay/pose``, ``.../mask``     delay [frames] of each arriving detection
``<seq>/errors/<name>``                per-frame errors: ``t_cm``, ``a_deg``, ``v_cmps``,
                                       ``w_dps`` (norms), ``add_cm``
=====================================  =====================================================

The detections are rebuilt from the run's recorded options and seeds, exactly as ``roft-sim
report`` does (the fault schedule depends on neither the tracker nor the flow).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets import open_sequence
from roft_sim.errors import ConfigError, RoftSimError
from roft_sim.harness.inputs import resolve_object_model
from roft_sim.harness.outputs import (
    ESTIMATES_FILE,
    FRAME_ERRORS_FILE,
    load_estimates,
    load_frame_errors,
    read_json,
)
from roft_sim.harness.report_builder import newest_mask, options_from_record
from roft_sim.harness.run_dataset import RUN_FILE
from roft_sim.harness.runner import make_observation_stream
from roft_sim.records import MaskDetection

F64 = NDArray[np.float64]

__all__ = ["RecordingResult", "ERROR_SERIES", "write_run_recording", "rerun_missing_message"]

ERROR_SERIES = ("t_cm", "a_deg", "v_cmps", "w_dps", "add_cm")
"""The per-frame error series logged under ``<seq>/errors/``."""
FLOW_COLOUR_MAX_PX = 20.0
"""Flow magnitude [px] shown at full brightness."""


def rerun_missing_message() -> str:
    """What to do when rerun-sdk is not installed."""
    return "roft-sim view needs the rerun-sdk package: pip install -e '.[view]'"


@dataclass(frozen=True, slots=True, kw_only=True)
class RecordingResult:
    """What :func:`write_run_recording` wrote."""

    path: Path
    """The ``.rrd`` file."""
    sequences: tuple[str, ...]
    """The sequences recorded."""
    frames: int
    """Frames recorded, over all sequences."""
    notes: tuple[str, ...]
    """What could not be recorded (e.g. a dataset that moved)."""


def _per_frame_errors(folder: Path, n: int) -> dict[str, F64]:
    """(n,) per-frame error norms (NaN where a frame was not scored) from frame_errors.npz."""
    out = {name: np.full(n, np.nan) for name in ERROR_SERIES}
    if not (folder / FRAME_ERRORS_FILE).is_file():
        return out
    m = load_frame_errors(folder / FRAME_ERRORS_FILE)
    index = m.frame_index
    out["t_cm"][index] = m.t_err_norm_cm
    out["a_deg"][index] = m.a_err_deg
    out["v_cmps"][index] = np.linalg.norm(m.v_err_cmps, axis=1)
    out["w_dps"][index] = np.linalg.norm(m.w_err_dps, axis=1)
    out["add_cm"][index] = 100.0 * m.add_m
    return out


def _flow_set(sequence: Any, flow_input: str | None) -> str | None:
    sets = tuple(sequence.flow_sets())
    if flow_input and flow_input.startswith("stored:") and flow_input[7:] in sets:
        return flow_input[7:]
    for name in ("gt", "nvof_1_slow"):
        if name in sets:
            return name
    return sets[0] if sets else None


def _log_pose(rec: Any, rr: Any, path: str, T: F64) -> None:
    rec.log(path, rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))


def _record_sequence(
    rec: Any,
    rr: Any,
    seq_record: dict[str, Any],
    run: dict[str, Any],
    folder: Path,
    n_max: int | None,
) -> int:
    """Logs one sequence; returns the frames logged."""
    from roft_sim.render.preview import flow_to_rgb

    name = seq_record["name"]
    sequence = open_sequence(seq_record["path"])
    model = resolve_object_model(sequence)
    gt = sequence.ground_truth()
    estimates = load_estimates(folder / ESTIMATES_FILE)
    errors = _per_frame_errors(folder, len(sequence))
    stream, _, _ = make_observation_stream(
        sequence,
        options_from_record(run["options"]),
        detection_mode=run["tracker"]["detection_mode"],
        with_flow=False,
    )
    flow_set = _flow_set(sequence, (seq_record.get("inputs") or {}).get("flow"))
    intr = sequence.intrinsics
    points = np.asarray(model.model_points_m, dtype=np.float64)
    rec.log(name, rr.ViewCoordinates.RDF, static=True)
    rec.log(
        f"{name}/camera",
        rr.Pinhole(image_from_camera=intr.K, resolution=[intr.width_px, intr.height_px]),
        static=True,
    )
    for entity in ("gt", "estimate", "detection"):
        rec.log(f"{name}/{entity}/points", rr.Points3D(points, radii=0.002), static=True)
    shown: MaskDetection | None = None
    n = len(sequence) if n_max is None else min(len(sequence), n_max)
    for k in range(n):
        rec.set_time("frame", sequence=k)
        rec.set_time("time", duration=float(sequence.time_s(k)))
        rec.log(f"{name}/camera/rgb", rr.Image(np.asarray(sequence.rgb(k))))
        rec.log(f"{name}/camera/depth", rr.DepthImage(np.asarray(sequence.depth(k)), meter=1.0))
        if "gt" in sequence.mask_sets():
            gt_mask = sequence.mask(k, "gt")
            if gt_mask is not None:
                rec.log(f"{name}/camera/mask_gt", rr.SegmentationImage(gt_mask.astype(np.uint8)))
        if flow_set is not None:
            flow = sequence.flow(k, flow_set)
            if flow is not None:
                rec.log(f"{name}/camera/flow", rr.Image(flow_to_rgb(flow, FLOW_COLOUR_MAX_PX)))
        if gt is not None:
            _log_pose(rec, rr, f"{name}/gt", gt.T_cam_obj[k])
        e = estimates[k]
        if e.valid and np.isfinite(e.T_cam_obj).all():
            _log_pose(rec, rr, f"{name}/estimate", np.asarray(e.T_cam_obj))
        obs = stream.observation(k)
        for det in obs.poses:
            delay = k - det.capture_k
            _log_pose(rec, rr, f"{name}/detection", np.asarray(det.T_cam_obj))
            rec.log(f"{name}/delay/pose", rr.Scalars(float(delay)))
            rec.log(
                f"{name}/detection",
                rr.TextLog(f"pose of frame {det.capture_k} arrives at {k} ({delay} frames late)"),
            )
        for mask in obs.masks:
            rec.log(f"{name}/delay/mask", rr.Scalars(float(k - mask.capture_k)))
        newer = newest_mask(shown, obs.masks)
        if newer is not None and newer is not shown:
            shown = newer
            delivered = np.asarray(shown.mask).astype(np.uint8) * 2
            rec.log(f"{name}/camera/mask_delivered", rr.SegmentationImage(delivered))
        for series, values in errors.items():
            if np.isfinite(values[k]):
                rec.log(f"{name}/errors/{series}", rr.Scalars(float(values[k])))
    return n


def write_run_recording(
    results: str | Path,
    out_file: str | Path,
    *,
    sequences: Sequence[str] | None = None,
    max_frames: int | None = None,
) -> RecordingResult:
    """Writes the ``.rrd`` recording of the run folder ``results`` (module docstring).

    Args:
        results: a ``roft-sim run`` output folder.
        out_file: the ``.rrd`` file to write.
        sequences: the sequences to record (default: all).
        max_frames: frames per sequence from frame 0 (default: all).

    Raises:
        ConfigError: not a run folder, an unknown sequence, rerun-sdk missing, bad max_frames.
    """
    try:
        import rerun as rr
    except ImportError:
        raise ConfigError(rerun_missing_message()) from None
    results, out_file = Path(results), Path(out_file)
    if not (results / RUN_FILE).is_file():
        raise ConfigError(
            f"{str(results)!r} is not a roft-sim run folder (no {RUN_FILE}); give the --out "
            "folder of roft-sim run"
        )
    if max_frames is not None and max_frames < 1:
        raise ConfigError(f"--max-frames must be >= 1, got {max_frames}")
    run = read_json(results / RUN_FILE)
    names = [s["name"] for s in run["sequences"]]
    unknown = [s for s in sequences or () if s not in names]
    if unknown:
        raise ConfigError(f"no sequence {unknown[0]!r} in {str(results)!r}; its sequences: {names}")
    wanted = [s for s in run["sequences"] if not sequences or s["name"] in sequences]
    rec = rr.RecordingStream("roft_sim", recording_id=f"roft_sim:{results.resolve()}")
    out_file.parent.mkdir(parents=True, exist_ok=True)
    rec.save(str(out_file))
    done, notes, frames = [], [], 0
    try:
        for seq in wanted:
            path = seq.get("path")
            if not path or not Path(path).exists():
                notes.append(f"{seq['name']}: not recorded, its dataset {path!r} is not available")
                continue
            try:
                frames += _record_sequence(rec, rr, seq, run, results / seq["name"], max_frames)
            except RoftSimError as e:
                notes.append(f"{seq['name']}: not recorded ({e})")
                continue
            done.append(seq["name"])
    finally:
        rec.flush()
        rec.disconnect()
    return RecordingResult(path=out_file, sequences=tuple(done), frames=frames, notes=tuple(notes))
