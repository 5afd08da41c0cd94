"""The files a run writes per sequence, and their readers.

One folder per sequence (docs/running.md, "Outputs"):

=========================  ====================================================================
``pose_estimate.txt``      13 columns per frame, the reference ROFT format:
                           ``vx vy vz wx wy wz x y z ax ay az angle``: ``v_obj`` [m/s], ``w``
                           [rad/s], position [m], unit axis and angle [rad] in [0, pi], camera
                           frame. A frame without a valid, finite estimate is a row of 13 zeros
                           (the reference pads missing results with zeros).
``velocity_estimate.txt``  6 columns ``v_o(3) w(3)``, written so that the reference's conversion
                           ``v = v_o + w x t_gt`` gives back the tracker's estimate: its spatial
                           twist when it reports one (ROFT's velocity KF, which the reference
                           converts the same way), else ``v_o = v_obj - w x t_gt`` of its
                           ``v_obj`` and ``w`` (``t_gt``: ground-truth position; the estimate's
                           own position when the sequence has no ground truth).
``execution_times.txt``    2 columns ``step_ms load_ms``: ``tracker.step`` time and the time the
                           harness took to build the observation (the reference's layout).
``estimates.npz``          every :class:`~roft_sim.records.Estimate` field, lossless (float64):
                           covariances, validity, spatial twists, pose ids, diagnostics.
``deliveries.npz``         every pose and mask delivery: ids, true and reported capture frame,
                           arrival frame, outlier and corruption flags (from the fault ledger).
``frame_errors.npz``       the per-frame errors behind the metrics (ADD, position, rotation,
                           velocity errors) and the metric scalars; pooled by sweeps and reports.
``metrics.json``           this sequence's metrics entry.
``wall_clock.npz``         with ``--clock wall``: per frame ``release_s``, ``started_s``,
                           ``delivered_s`` (the run's clock [s]), ``seen``, ``dropped_busy``,
                           ``held_from_k`` (the frame whose estimate was scored, -1: none), and
                           ``fps``, ``time_scale``, ``when_busy``; the pose and velocity files and
                           ``estimates.npz`` then hold the estimates scored at each deadline.
``tracker_estimates.npz``  with ``--clock wall``: the tracker's own estimate of each frame
                           (the format of ``estimates.npz``).
``gt.tum``, ``estimate.tum``  with ``--tum``: TUM trajectories ``t tx ty tz qx qy qz qw`` (time
                           [s] = k / fps, ``T_cam_obj`` position [m], unit quaternion scalar
                           LAST) of the ground truth and of the frames with a valid estimate,
                           for ``evo_ape tum gt.tum estimate.tum`` / ``evo_rpe``.
=========================  ====================================================================

Every file is written atomically (temporary file, then rename).
"""

from __future__ import annotations

import io
import json
from collections.abc import Sequence as SequenceABC
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.atomic_files import atomic_write_bytes, atomic_write_text
from roft_sim.datasets.fast_ycb_codec import (
    format_rows,
    parse_rows,
    pose_row_from_transform,
    transforms_from_pose_rows,
)
from roft_sim.errors import DatasetFormatError, located
from roft_sim.faults.events import DeliveryEvent
from roft_sim.geometry.se3 import v_o_from_v_obj
from roft_sim.geometry.so3 import canonical_quat, quat_from_matrix, quat_xyzw_from_wxyz
from roft_sim.harness.evaluation import SequenceEvaluation
from roft_sim.harness.runner import SequenceRun
from roft_sim.metrics import SequenceMetrics, held_estimate_index, step_time_stats
from roft_sim.records import Estimate

F64 = NDArray[np.float64]

__all__ = [
    "POSE_ESTIMATE_FILE",
    "VELOCITY_ESTIMATE_FILE",
    "EXECUTION_TIMES_FILE",
    "ESTIMATES_FILE",
    "DELIVERIES_FILE",
    "FRAME_ERRORS_FILE",
    "SEQUENCE_METRICS_FILE",
    "WALL_CLOCK_FILE",
    "TRACKER_ESTIMATES_FILE",
    "save_wall_clock",
    "GT_TUM_FILE",
    "ESTIMATE_TUM_FILE",
    "tum_text",
    "write_tum_files",
    "write_json",
    "read_json",
    "pose_estimate_rows",
    "velocity_estimate_rows",
    "write_estimate_files",
    "write_sequence_outputs",
    "read_pose_estimate",
    "read_velocity_estimate",
    "save_estimates",
    "load_estimates",
    "save_frame_errors",
    "load_frame_errors",
    "load_deliveries",
    "Deliveries",
]

POSE_ESTIMATE_FILE = "pose_estimate.txt"
VELOCITY_ESTIMATE_FILE = "velocity_estimate.txt"
EXECUTION_TIMES_FILE = "execution_times.txt"
ESTIMATES_FILE = "estimates.npz"
DELIVERIES_FILE = "deliveries.npz"
FRAME_ERRORS_FILE = "frame_errors.npz"
SEQUENCE_METRICS_FILE = "metrics.json"
WALL_CLOCK_FILE = "wall_clock.npz"
TRACKER_ESTIMATES_FILE = "tracker_estimates.npz"
GT_TUM_FILE = "gt.tum"
ESTIMATE_TUM_FILE = "estimate.tum"


def write_json(path: Path, data: Any) -> None:
    """Writes ``data`` as indented JSON, atomically (NaN is not allowed: use None)."""
    atomic_write_text(path, json.dumps(data, indent=2, allow_nan=False) + "\n")


def read_json(path: Path) -> Any:
    """Reads a JSON file written by :func:`write_json`.

    Raises:
        DatasetFormatError: missing or not valid JSON.
    """
    try:
        return json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetFormatError(f"{located(path)} does not exist") from None
    except json.JSONDecodeError as e:
        raise DatasetFormatError(f"{located(path, e.lineno)} is not valid JSON: {e.msg}") from None


def _savez(path: Path, **arrays: Any) -> None:
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    atomic_write_bytes(path, buffer.getvalue())


def _usable(e: Estimate) -> bool:
    return e.valid and bool(np.isfinite(e.T_cam_obj).all())


def _held_or_own(estimates: SequenceABC[Estimate]) -> NDArray[np.int64]:
    """(N,) the estimate each frame shows under ``hold``: the last usable one at or before it,
    the first usable one before that; the frame's own where none is usable."""
    held = held_estimate_index([_usable(e) for e in estimates])
    usable = held[held >= 0]
    if usable.size == 0:
        return np.arange(len(estimates))
    return np.where(held >= 0, held, usable[0])


def pose_estimate_rows(estimates: SequenceABC[Estimate], *, hold: bool = False) -> F64:
    """(N, 13) rows of ``pose_estimate.txt``: ``v_obj w p axis angle``; zeros for frames without
    a valid, finite estimate.

    Args:
        estimates: one estimate per frame.
        hold: fill frames without one instead (see :func:`velocity_estimate_rows`), as the
            reference layout needs (its evaluation divides by the norm of a zero axis).
    """
    source = _held_or_own(estimates) if hold else np.arange(len(estimates))
    rows = np.zeros((len(estimates), 13))
    for i in range(len(estimates)):
        e = estimates[int(source[i])]
        vel = np.concatenate([e.v_obj_mps, e.w_radps])
        if _usable(e) and np.isfinite(vel).all():
            rows[i] = [*vel, *pose_row_from_transform(e.T_cam_obj)]
        elif _usable(e):
            rows[i, 6:] = pose_row_from_transform(e.T_cam_obj)
    return rows


def velocity_estimate_rows(
    estimates: SequenceABC[Estimate], t_gt_m: F64 | None = None, *, hold: bool = False
) -> F64:
    """(N, 6) rows of ``velocity_estimate.txt``: ``v_o w`` [m/s, rad/s], camera frame.

    The spatial twist when the estimate carries one, else ``v_o = v_obj - w x t_gt`` of the
    estimate's ``v_obj`` and ``w``, so that the reference's ``v = v_o + w x t_gt`` yields
    ``v_obj`` (docs/conventions.md, "Velocity"); zeros where neither is finite.

    Args:
        estimates: one estimate per frame.
        t_gt_m: (N, 3) ground-truth object position [m], camera frame; None = each estimate's
            own position (sequences without ground truth).
        hold: rows come from :func:`~roft_sim.metrics.held_estimate_index` (a frame without a
            valid estimate takes the last valid one, frames before the first the first one)
            while ``t_gt`` stays the frame's own: what the reference scores under ``hold``.
    """
    n = len(estimates)
    if t_gt_m is not None and np.shape(t_gt_m) != (n, 3):
        raise ValueError(f"t_gt_m must have shape ({n}, 3), got {np.shape(t_gt_m)}")
    source = _held_or_own(estimates) if hold else np.arange(n)
    rows = np.zeros((n, 6))
    for i in range(n):
        e = estimates[int(source[i])]
        if e.spatial_twist is not None:
            row = np.asarray(e.spatial_twist, dtype=np.float64)
        elif _usable(e):
            t = e.T_cam_obj[:3, 3] if t_gt_m is None else np.asarray(t_gt_m[i], dtype=np.float64)
            v_o = v_o_from_v_obj(e.v_obj_mps, e.w_radps, t)
            row = np.concatenate([v_o, e.w_radps])
        else:
            continue
        if np.isfinite(row).all():
            rows[i] = row
    return rows


def _write_rows(path: Path, rows: F64) -> None:
    atomic_write_text(path, format_rows(rows))


def read_pose_estimate(path: str | Path) -> tuple[F64, F64, F64, NDArray[np.bool_]]:
    """Reads a ``pose_estimate.txt``.

    Returns:
        ``T_cam_obj`` (N, 4, 4) [m], ``v_obj`` (N, 3) [m/s], ``w`` (N, 3) [rad/s], and ``valid``
        (N,): False for all-zero rows (no estimate; identity pose returned).

    Raises:
        DatasetFormatError: not 13 numbers per row, or a non-unit axis (naming the line).
    """
    path = Path(path)
    rows = parse_rows(path.read_text(encoding="utf-8"), path, 13)
    T, _ = transforms_from_pose_rows(rows, path, allow_zero_rows=True, t_col=6)
    valid = ~np.all(rows == 0.0, axis=1)
    return T, rows[:, 0:3].copy(), rows[:, 3:6].copy(), valid


def read_velocity_estimate(path: str | Path) -> F64:
    """Reads a ``velocity_estimate.txt``: (N, 6) ``v_o w`` [m/s, rad/s]."""
    path = Path(path)
    return parse_rows(path.read_text(encoding="utf-8"), path, 6)


# ----------------------------------------------------------------------------- estimates.npz
def _ragged(values: SequenceABC[tuple[int, ...]]) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Flat ids and (N+1,) offsets of per-frame id tuples."""
    offsets = np.zeros(len(values) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(v) for v in values])
    flat = np.array([i for v in values for i in v], dtype=np.int64)
    return flat, offsets


def _unragged(flat: NDArray[np.int64], offsets: NDArray[np.int64], i: int) -> tuple[int, ...]:
    return tuple(int(x) for x in flat[offsets[i] : offsets[i + 1]])


def save_estimates(
    path: Path,
    estimates: SequenceABC[Estimate],
    *,
    step_times_s: F64 | None = None,
    load_times_s: F64 | None = None,
) -> None:
    """Writes every field of ``estimates`` to an ``.npz`` (lossless; see :func:`load_estimates`)."""
    n = len(estimates)
    cov = np.full((n, 12, 12), np.nan)
    has_cov = np.zeros(n, dtype=bool)
    twist = np.full((n, 6), np.nan)
    has_twist = np.zeros(n, dtype=bool)
    for i, e in enumerate(estimates):
        if e.covariance is not None:
            cov[i], has_cov[i] = e.covariance, True
        if e.spatial_twist is not None:
            twist[i], has_twist[i] = e.spatial_twist, True
    arrays: dict[str, Any] = {
        "k": np.array([e.k for e in estimates], dtype=np.int64),
        "T_cam_obj": np.array([e.T_cam_obj for e in estimates], dtype=np.float64).reshape(n, 4, 4),
        "v_obj_mps": np.array([e.v_obj_mps for e in estimates], dtype=np.float64).reshape(n, 3),
        "w_radps": np.array([e.w_radps for e in estimates], dtype=np.float64).reshape(n, 3),
        "valid": np.array([e.valid for e in estimates], dtype=bool),
        "covariance": cov,
        "has_covariance": has_cov,
        "spatial_twist": twist,
        "has_spatial_twist": has_twist,
        "diagnostics_json": np.array(
            json.dumps([dict(e.diagnostics) for e in estimates], allow_nan=True)
        ),
    }
    for name in ("accepted_pose_ids", "rejected_pose_ids", "dropped_pose_ids"):
        flat, offsets = _ragged([getattr(e, name) for e in estimates])
        arrays[name], arrays[f"{name}_offsets"] = flat, offsets
    if step_times_s is not None:
        arrays["step_times_s"] = np.asarray(step_times_s, dtype=np.float64)
    if load_times_s is not None:
        arrays["load_times_s"] = np.asarray(load_times_s, dtype=np.float64)
    _savez(path, **arrays)


def load_estimates(path: str | Path) -> tuple[Estimate, ...]:
    """The estimates written by :func:`save_estimates`, field for field."""
    with np.load(path, allow_pickle=False) as z:
        data = {name: z[name] for name in z.files}
    diagnostics = json.loads(str(data["diagnostics_json"]))
    out = []
    for i in range(data["k"].shape[0]):
        out.append(
            Estimate(
                k=int(data["k"][i]),
                T_cam_obj=data["T_cam_obj"][i].copy(),
                v_obj_mps=data["v_obj_mps"][i].copy(),
                w_radps=data["w_radps"][i].copy(),
                covariance=data["covariance"][i].copy() if data["has_covariance"][i] else None,
                valid=bool(data["valid"][i]),
                spatial_twist=(
                    data["spatial_twist"][i].copy() if data["has_spatial_twist"][i] else None
                ),
                accepted_pose_ids=_unragged(
                    data["accepted_pose_ids"], data["accepted_pose_ids_offsets"], i
                ),
                rejected_pose_ids=_unragged(
                    data["rejected_pose_ids"], data["rejected_pose_ids_offsets"], i
                ),
                dropped_pose_ids=_unragged(
                    data["dropped_pose_ids"], data["dropped_pose_ids_offsets"], i
                ),
                diagnostics=diagnostics[i],
            )
        )
    return tuple(out)


# ---------------------------------------------------------------------------- deliveries.npz
_DELIVERY_COLUMNS = ("detection_id", "true_capture_k", "reported_capture_k", "arrival_k")


def _delivery_arrays(events: SequenceABC[DeliveryEvent]) -> tuple[NDArray[np.int64], Any, Any]:
    table = np.array(
        [[getattr(e, c) for c in _DELIVERY_COLUMNS] for e in events], dtype=np.int64
    ).reshape(len(events), len(_DELIVERY_COLUMNS))
    outlier = np.array([e.is_outlier for e in events], dtype=bool)
    corrupted = np.array([e.is_corrupted for e in events], dtype=bool)
    return table, outlier, corrupted


class Deliveries:
    """The deliveries of one stream, as arrays (read back from ``deliveries.npz``)."""

    __slots__ = (
        "detection_id",
        "true_capture_k",
        "reported_capture_k",
        "arrival_k",
        "outlier",
        "corrupted",
    )
    # (M,) one entry per delivery, in delivery order
    detection_id: NDArray[np.int64]
    true_capture_k: NDArray[np.int64]
    reported_capture_k: NDArray[np.int64]
    arrival_k: NDArray[np.int64]
    outlier: NDArray[np.bool_]
    corrupted: NDArray[np.bool_]

    def __init__(self, table: NDArray[np.int64], outlier: Any, corrupted: Any) -> None:
        for i, name in enumerate(_DELIVERY_COLUMNS):
            setattr(self, name, table[:, i].copy())
        self.outlier = np.asarray(outlier, dtype=bool)
        self.corrupted = np.asarray(corrupted, dtype=bool)

    def __len__(self) -> int:
        return int(self.arrival_k.shape[0])

    def latest_arrived(self, k: int) -> int | None:
        """Index of the newest-captured delivery that has arrived by frame ``k``, or None."""
        arrived = np.flatnonzero(self.arrival_k <= k)
        if arrived.size == 0:
            return None
        return int(arrived[np.argmax(self.reported_capture_k[arrived])])


def save_deliveries(path: Path, run: SequenceRun) -> None:
    """Writes the pose and mask deliveries of ``run``."""
    arrays: dict[str, Any] = {}
    for stream, events in (("pose", run.pose_deliveries), ("mask", run.mask_deliveries)):
        table, outlier, corrupted = _delivery_arrays(events)
        arrays[stream] = table
        arrays[f"{stream}_outlier"] = outlier
        arrays[f"{stream}_corrupted"] = corrupted
    _savez(path, **arrays)


def load_deliveries(path: str | Path) -> dict[str, Deliveries]:
    """``{"pose": Deliveries, "mask": Deliveries}`` from ``deliveries.npz``."""
    with np.load(path, allow_pickle=False) as z:
        return {
            s: Deliveries(z[s], z[f"{s}_outlier"], z[f"{s}_corrupted"]) for s in ("pose", "mask")
        }


# -------------------------------------------------------------------------- frame_errors.npz
_SCALARS = ("add_auc_pct", "adds_auc_pct", "rmse_t_cm", "rmse_a_deg", "rmse_v_cmps", "rmse_w_dps")
_COUNTS = ("frames", "frames_invalid", "frames_rmse", "frames_velocity")
_ARRAYS = ("frame_index", "add_m", "t_err_cm", "a_err_deg", "v_err_cmps", "w_err_dps")


def save_frame_errors(path: Path, m: SequenceMetrics) -> None:
    """Writes a :class:`~roft_sim.metrics.SequenceMetrics` (scalars and per-frame arrays)."""
    arrays: dict[str, Any] = {name: getattr(m, name) for name in _ARRAYS}
    arrays |= {name: np.float64(getattr(m, name)) for name in _SCALARS}
    arrays |= {name: np.int64(getattr(m, name)) for name in _COUNTS}
    arrays["rmse_t_axes_cm"] = np.array(m.rmse_t_axes_cm)
    if m.adds_m is not None:
        arrays["adds_m"] = m.adds_m
    if m.step_times_s is not None:
        arrays["step_times_s"] = m.step_times_s
    _savez(path, **arrays)


def load_frame_errors(path: str | Path) -> SequenceMetrics:
    """The :class:`~roft_sim.metrics.SequenceMetrics` written by :func:`save_frame_errors`."""
    with np.load(path, allow_pickle=False) as z:
        d = {name: z[name] for name in z.files}
    times = d.get("step_times_s")
    return SequenceMetrics(
        # mypy checks each **dict against every field, float ones against the int fields too
        **{name: float(d[name]) for name in _SCALARS},  # type: ignore[arg-type]
        **{name: int(d[name]) for name in _COUNTS},
        rmse_t_axes_cm=tuple(float(x) for x in d["rmse_t_axes_cm"]),  # type: ignore[arg-type]
        step_time=None if times is None else step_time_stats(times),
        frame_index=d["frame_index"].astype(np.int64),
        add_m=d["add_m"],
        adds_m=d.get("adds_m"),
        t_err_cm=d["t_err_cm"],
        a_err_deg=d["a_err_deg"],
        v_err_cmps=d["v_err_cmps"],
        w_err_dps=d["w_err_dps"],
        step_times_s=times,
    )


# -------------------------------------------------------------------------------- wall clock
def save_wall_clock(folder: Path, run: SequenceRun) -> None:
    """Writes ``wall_clock.npz`` and ``tracker_estimates.npz`` of a ``--clock wall`` run (nothing
    for a simulated-time run)."""
    timeline = run.wall_clock
    if timeline is None:
        return
    _savez(
        folder / WALL_CLOCK_FILE,
        release_s=timeline.release_s,
        started_s=timeline.started_s,
        delivered_s=timeline.delivered_s,
        seen=timeline.seen,
        dropped_busy=timeline.dropped_busy,
        held_from_k=timeline.held_index(),
        fps=np.int64(timeline.fps),
        time_scale=np.float64(timeline.clock.time_scale),
        when_busy=np.str_(timeline.clock.when_busy),
    )
    save_estimates(
        folder / TRACKER_ESTIMATES_FILE, timeline.tracker_estimates, step_times_s=run.step_times_s
    )


# ------------------------------------------------------------------------------------ TUM
def tum_text(t_s: F64, T_cam_obj: F64) -> str:
    """TUM trajectory text, one ``t tx ty tz qx qy qz qw`` line per pose (quaternion scalar
    LAST, ``w >= 0``), as evo's ``file_interface.read_tum_trajectory_file`` reads it.

    Args:
        t_s: (N,) time stamps [s].
        T_cam_obj: (N, 4, 4) poses [m].
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    T = np.asarray(T_cam_obj, dtype=np.float64)
    if T.shape != (t_s.shape[0], 4, 4):
        raise ValueError(f"need (N,) times and (N, 4, 4) poses, got {t_s.shape} and {T.shape}")
    q = canonical_quat(quat_from_matrix(T[:, :3, :3])) if len(T) else np.zeros((0, 4))
    rows = np.hstack([t_s[:, None], T[:, :3, 3], quat_xyzw_from_wxyz(q).reshape(-1, 4)])
    return "# timestamp tx ty tz qx qy qz qw\n" + format_rows(rows)


def write_tum_files(folder: str | Path, run: SequenceRun) -> tuple[Path, ...]:
    """Writes ``estimate.tum`` (frames with a valid, finite estimate) and, when the sequence has
    ground truth, ``gt.tum`` into ``folder``; returns the paths written."""
    folder = Path(folder)
    t_s = np.arange(len(run)) / float(run.fps)
    usable = np.array([_usable(e) for e in run.estimates], dtype=bool)
    T_est = np.array([e.T_cam_obj for e in run.estimates], dtype=np.float64).reshape(-1, 4, 4)
    paths = [folder / ESTIMATE_TUM_FILE]
    atomic_write_text(paths[0], tum_text(t_s[usable], T_est[usable]))
    if run.ground_truth is not None:
        paths.append(folder / GT_TUM_FILE)
        atomic_write_text(paths[1], tum_text(t_s, run.ground_truth.T_cam_obj))
    return tuple(paths)


# ------------------------------------------------------------------------------- all at once
def write_sequence_outputs(
    folder: str | Path, run: SequenceRun, evaluation: SequenceEvaluation, *, tum: bool = False
) -> Path:
    """Writes every per-sequence file of ``run`` into ``folder`` (created); returns it.

    ``tum``: also the TUM trajectories (:func:`write_tum_files`)."""
    folder = Path(folder)
    t_gt = None if run.ground_truth is None else run.ground_truth.T_cam_obj[:, :3, 3]
    write_estimate_files(
        folder,
        run.estimates,
        evaluation,
        t_gt,
        step_times_s=run.step_times_s,
        load_times_s=run.load_times_s,
    )
    _write_rows(
        folder / EXECUTION_TIMES_FILE,
        np.stack([1e3 * run.step_times_s, 1e3 * run.load_times_s], axis=1),
    )
    save_deliveries(folder / DELIVERIES_FILE, run)
    save_wall_clock(folder, run)
    if tum:
        write_tum_files(folder, run)
    return folder


def write_estimate_files(
    folder: str | Path,
    estimates: SequenceABC[Estimate],
    evaluation: SequenceEvaluation,
    t_gt: F64 | None,
    *,
    step_times_s: F64 | None = None,
    load_times_s: F64 | None = None,
) -> None:
    """Writes the per-sequence files of any scored estimates into ``folder`` (created):
    ``pose_estimate.txt``, ``velocity_estimate.txt`` (``t_gt`` (N, 3) [m], the ground-truth
    positions, or None), ``estimates.npz`` (with the step and load times when given),
    ``frame_errors.npz`` (when scored) and ``metrics.json``. A run's folder
    (:func:`write_sequence_outputs`) and a scored bag's (``roft_sim.bags.score``) both hold them.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    _write_rows(folder / POSE_ESTIMATE_FILE, pose_estimate_rows(estimates))
    _write_rows(folder / VELOCITY_ESTIMATE_FILE, velocity_estimate_rows(estimates, t_gt))
    save_estimates(
        folder / ESTIMATES_FILE, estimates, step_times_s=step_times_s, load_times_s=load_times_s
    )
    if evaluation.metrics is not None:
        save_frame_errors(folder / FRAME_ERRORS_FILE, evaluation.metrics)
    write_json(folder / SEQUENCE_METRICS_FILE, evaluation.entry())
