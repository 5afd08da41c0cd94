"""``roft-sim report``: a self-contained report of a results folder.

For a ``roft-sim run`` folder: ``report.md`` (configuration, metrics, synchronisation figures),
per sequence a PNG of the per-frame errors with pose arrivals marked, the ADD accuracy curve,
and an overlay video (the object's silhouette at the estimate and at the ground truth over the
rgb, the delayed masks the tracker received, markers when a pose arrives) with a few stills.
The masks and arriving poses are rebuilt exactly from the run's recorded options and seeds
(the fault schedule does not depend on the tracker or the flow), so the video shows what the
tracker was given.

For a ``roft-sim sweep`` folder: the summary tables and plots, rebuilt from the cells.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from roft_sim.datasets import open_sequence
from roft_sim.datasets.atomic_files import atomic_write_bytes, atomic_write_text
from roft_sim.datasets.image_files import encode_png_rgb
from roft_sim.errors import ConfigError, DatasetFormatError, RoftSimError
from roft_sim.faults import fault_config_from_mapping
from roft_sim.harness.cells import CELLS_DIR, SweepCell, finished_cells
from roft_sim.harness.inputs import resolve_object_model
from roft_sim.harness.options import RunOptions
from roft_sim.harness.outputs import (
    DELIVERIES_FILE,
    ESTIMATES_FILE,
    FRAME_ERRORS_FILE,
    load_deliveries,
    load_estimates,
    load_frame_errors,
    read_json,
)
from roft_sim.harness.run_dataset import METRICS_FILE, RUN_FILE
from roft_sim.harness.runner import make_observation_stream
from roft_sim.metrics import SequenceMetrics, accuracy_curve
from roft_sim.records import Estimate, MaskDetection, PoseTrack
from roft_sim.report.overlay import OverlayFrame, draw_overlay, silhouette_mask
from roft_sim.report.plotting import Panel, Series, line_figure, save_figure
from roft_sim.report.tables import METRIC_COLUMNS, Column, markdown_table
from roft_sim.report.video import VideoWriter

__all__ = ["ReportOptions", "ReportResult", "build_report", "newest_mask", "options_from_record"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class ReportOptions:
    """What the report includes."""

    video: bool = True
    """Write the overlay videos (and stills)."""
    max_video_frames: int | None = None
    """Frames per video (from frame 0); None = all."""
    video_scale: float | None = None
    """Scale of the video frames; None = 1 up to 960 px wide, else 0.5."""
    sequences: tuple[str, ...] | None = None
    """Only these sequences; None = all."""

    def __post_init__(self) -> None:
        if self.max_video_frames is not None and self.max_video_frames < 1:
            raise ConfigError(f"max_video_frames must be >= 1, got {self.max_video_frames}")
        if self.video_scale is not None and not 0 < self.video_scale <= 4:
            raise ConfigError(f"video_scale must be in (0, 4], got {self.video_scale}")


@dataclass(frozen=True, slots=True, kw_only=True)
class ReportResult:
    """What :func:`build_report` wrote."""

    out_dir: Path
    """The report folder."""
    markdown: Path
    """``report.md``."""
    files: tuple[Path, ...]
    """Every other file written (plots, videos, stills)."""
    notes: tuple[str, ...]
    """What could not be included and why (also in the report)."""


def options_from_record(record: dict[str, Any]) -> RunOptions:
    """The :class:`RunOptions` of a ``run.json`` / ``cell.json`` ``options`` record (the tracker
    settings are left at None: a report does not re-run the tracker)."""
    return RunOptions(
        tracker=record["tracker"],
        faults=fault_config_from_mapping(dict(record["faults"])),
        flow=record["flow"],
        poses=record["poses"],
        masks=record["masks"],
        init=record["init"],
        seed=int(record["seed"]),
        include_rgb=False,
        invalid=record["invalid"],
    )


def _rel(path: Path, base: Path) -> str:
    return path.relative_to(base).as_posix()


# ------------------------------------------------------------------------------------ plots
def _error_plot(
    m: SequenceMetrics, arrivals: np.ndarray, path: Path, title: str, tracker: str
) -> Path:
    """Per-frame pose and velocity errors (2x2 panels), pose arrivals marked."""
    frames = m.frame_index
    specs = (
        ("position error", "cm", m.t_err_norm_cm),
        ("rotation error", "deg", m.a_err_deg),
        ("linear velocity error", "cm/s", np.linalg.norm(m.v_err_cmps, axis=1)),
        ("angular velocity error", "deg/s", np.linalg.norm(m.w_err_dps, axis=1)),
    )
    panels = [
        Panel(
            title=name,
            y_label=f"{name} [{unit}]",
            series=(Series(x=frames, y=values, label=tracker),),
        )
        for name, unit, values in specs
    ]
    figure = line_figure(
        panels,
        x_label="frame",
        title=f"{title}: per-frame errors",
        integer_x=True,
        events_x=arrivals,
    )
    return save_figure(figure, path)


def _velocity_plot(
    estimates: Sequence[Estimate],
    gt: PoseTrack,
    arrivals: np.ndarray,
    path: Path,
    title: str,
    tracker: str,
) -> Path:
    """Estimated and ground-truth velocity per axis (camera frame), pose arrivals marked:
    rows x, y, z; columns linear [cm/s] and angular [deg/s]."""
    frames = np.array([e.k for e in estimates], dtype=np.int64)
    valid = np.array([e.valid for e in estimates])
    v_est = np.array([e.v_obj_mps for e in estimates], dtype=np.float64) * 100.0
    w_est = np.degrees(np.array([e.w_radps for e in estimates], dtype=np.float64))
    v_est[~valid] = np.nan
    w_est[~valid] = np.nan
    v_gt = gt.v_obj_mps[frames] * 100.0
    w_gt = np.degrees(gt.w_radps[frames])
    panels = []
    for axis, name in enumerate("xyz"):
        for kind, unit, est, truth in (
            ("linear", "cm/s", v_est, v_gt),
            ("angular", "deg/s", w_est, w_gt),
        ):
            panels.append(
                Panel(
                    title=f"{kind} velocity, camera {name}",
                    y_label=f"{kind} velocity {name} [{unit}]",
                    series=(
                        Series(x=frames, y=truth[:, axis], label="ground truth"),
                        Series(x=frames, y=est[:, axis], label=f"{tracker} estimate"),
                    ),
                )
            )
    figure = line_figure(
        panels,
        x_label="frame",
        title=f"{title}: velocity (camera frame)",
        integer_x=True,
        events_x=arrivals,
        panel_in=(5.6, 2.6),
    )
    return save_figure(figure, path)


def _accuracy_plot(m: SequenceMetrics, path: Path, title: str, tracker: str) -> Path:
    """The ADD accuracy curve whose area is the ADD-AUC."""
    thresholds_m = np.linspace(0.0, 0.1, 201)
    acc = accuracy_curve(m.add_m, thresholds_m)
    panel = Panel(
        title=f"ADD accuracy (AUC {m.add_auc_pct:.2f} %)",
        y_label="frames within threshold [%]",
        series=(Series(x=100 * thresholds_m, y=100 * np.asarray(acc), label=tracker),),
        y_range=(0.0, 100.0),
    )
    figure = line_figure([panel], x_label="ADD threshold [cm]", title=title, columns=1)
    return save_figure(figure, path)


# ------------------------------------------------------------------------------------ video
def _video_scale(width: int, options: ReportOptions) -> float:
    if options.video_scale is not None:
        return options.video_scale
    return 1.0 if width <= 960 else 0.5


def _frame_errors(errors: SequenceMetrics | None, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Per frame (n_frames,) position [cm] and rotation [deg] error of a sequence's metrics; NaN
    where there is none (no ground truth, or a frame not scored)."""
    err_t = np.full(n_frames, np.nan)
    err_a = np.full(n_frames, np.nan)
    if errors is not None:
        err_t[errors.frame_index] = errors.t_err_norm_cm
        err_a[errors.frame_index] = errors.a_err_deg
    return err_t, err_a


def _scaled(image: np.ndarray, scale: float) -> np.ndarray:
    """``image`` (H, W, 3) resized by ``scale`` (area interpolation); itself at scale 1."""
    if scale == 1.0:
        return image
    import cv2

    size = (int(round(image.shape[1] * scale)), int(round(image.shape[0] * scale)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def _write_video(
    seq_record: dict[str, Any],
    run_record: dict[str, Any],
    folder: Path,
    out_dir: Path,
    options: ReportOptions,
    still_frames: Sequence[int],
    errors: SequenceMetrics | None,
) -> tuple[list[Path], str | None]:
    """Writes the overlay video and stills of one sequence (``errors``: its frame errors, None
    without ground truth); returns the files and a note."""
    name = seq_record["name"]
    path = seq_record.get("path")
    if not path or not Path(path).exists():
        return [], f"{name}: no overlay video, the dataset {path!r} is not available"
    sequence = open_sequence(path)
    gt = sequence.ground_truth()
    model = resolve_object_model(sequence)
    run_options = options_from_record(run_record["options"])
    stream, _, _ = make_observation_stream(
        sequence,
        run_options,
        detection_mode=run_record["tracker"]["detection_mode"],
        with_flow=False,
    )
    estimates = load_estimates(folder / ESTIMATES_FILE)
    err_t, err_a = _frame_errors(errors, len(sequence))
    intr = sequence.intrinsics
    scale = _video_scale(intr.width_px, options)
    n = (
        len(sequence)
        if options.max_video_frames is None
        else min(len(sequence), options.max_video_frames)
    )
    video_path = out_dir / "videos" / f"{name}_overlay.mp4"
    files: list[Path] = []
    shown_mask: MaskDetection | None = None
    mask_text = "no mask yet"
    banner_until, banner = -1, None
    wanted = {k for k in still_frames if 0 <= k < n}
    with VideoWriter(video_path, fps=float(sequence.fps)) as video:
        for k in range(n):
            obs = stream.observation(k)
            newer = newest_mask(shown_mask, obs.masks)
            if newer is not None and newer is not shown_mask:
                shown_mask, mask_text = newer, f"mask of frame {newer.capture_k} (arrived {k})"
            arrived = None
            if obs.poses:
                det = max(obs.poses, key=lambda d: d.capture_k)
                arrived = silhouette_mask(model, det.T_cam_obj, intr)
                banner = f"pose of frame {det.capture_k} arrives (+{k - det.capture_k})"
                banner_until = k + 3
            e = estimates[k]
            frame = OverlayFrame(
                rgb=np.asarray(sequence.rgb(k)),
                gt_mask=None if gt is None else silhouette_mask(model, gt.T_cam_obj[k], intr),
                estimate_mask=silhouette_mask(model, e.T_cam_obj, intr) if e.valid else None,
                delayed_mask=None if shown_mask is None else np.asarray(shown_mask.mask),
                arrived_pose_mask=arrived,
                banner=banner if k <= banner_until else None,
                lines=(
                    f"{name}  frame {k}  {run_record['tracker']['name']}",
                    f"e_t {err_t[k]:.1f} cm  e_a {err_a[k]:.1f} deg" if gt is not None else "",
                    mask_text,
                ),
            )
            image = _scaled(draw_overlay(frame), scale)
            video.write(image)
            if k in wanted:
                still = out_dir / "stills" / f"{name}_k{k:04d}.png"
                atomic_write_bytes(still, encode_png_rgb(image))
                files.append(still)
    files.insert(0, video_path)
    return files, None


def _ground_truth_if_available(seq_record: dict[str, Any]) -> PoseTrack | None:
    """The ground truth of a run's sequence when its dataset is still at the recorded path."""
    path = seq_record.get("path")
    if not path or not Path(path).exists():
        return None
    return open_sequence(path).ground_truth()


def newest_mask(
    shown: MaskDetection | None, arriving: Sequence[MaskDetection]
) -> MaskDetection | None:
    """The mask the overlay shows after a frame's arrivals: the one of the latest capture frame.

    A mask delivered late (reordered, stale or duplicated) never replaces one of a later capture
    frame, so the yellow overlay is always the newest mask the tracker has received.
    """
    best = shown
    for d in arriving:
        if best is None or d.capture_k > best.capture_k:
            best = d
    return best


def _still_frames(m: SequenceMetrics | None, arrivals: np.ndarray, n: int) -> list[int]:
    frames = []
    later = arrivals[arrivals > 0]
    if later.size:
        frames.append(int(later[0]))
    if m is not None and np.isfinite(m.t_err_norm_cm).any():
        frames.append(int(m.frame_index[int(np.nanargmax(m.t_err_norm_cm))]))
    frames.append(n - 1)
    return sorted(set(frames))


# ------------------------------------------------------------------------------------ tables
def _metrics_rows(metrics: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    names = [n for n in metrics if n not in ("ALL", "MEAN")] + [
        n for n in ("ALL", "MEAN") if n in metrics
    ]
    return [{"name": n, **metrics[n]} for n in names]


_SYNC_COLUMNS = (
    Column("name", "sequence", align="left"),
    Column("arrivals", "pose arrivals", "d"),
    Column("t_before", "e_t before [cm]", ".2f"),
    Column("t_after", "e_t after [cm]", ".2f"),
    Column("a_before", "e_a before [deg]", ".2f"),
    Column("a_after", "e_a after [deg]", ".2f"),
    Column("w_before", "e_w before [deg/s]", ".2f"),
    Column("w_after", "e_w after [deg/s]", ".2f"),
    Column("rejected", "poses rejected", "d"),
    Column("catch_rate", "outliers caught", ".2f"),
    Column("recovery", "recovery [frames]", ".1f"),
    Column("nees", "NEES mean (12 dof)", ".1f"),
)


def _sync_rows(metrics: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    rows = []
    for name, entry in metrics.items():
        if name in ("ALL", "MEAN"):
            continue
        sync = entry.get("sync", {})
        outliers = entry.get("outliers", {})
        rows.append(
            {
                "name": name,
                "arrivals": sync.get("arrivals"),
                "t_before": sync.get("t_err_cm", {}).get("before"),
                "t_after": sync.get("t_err_cm", {}).get("after"),
                "a_before": sync.get("a_err_deg", {}).get("before"),
                "a_after": sync.get("a_err_deg", {}).get("after"),
                "w_before": sync.get("w_err_dps", {}).get("before"),
                "w_after": sync.get("w_err_dps", {}).get("after"),
                "rejected": outliers.get("poses_rejected"),
                "catch_rate": outliers.get("catch_rate"),
                "recovery": entry.get("recovery", {}).get("recovery_frames_mean"),
                "nees": entry.get("consistency", {}).get("nees_mean"),
            }
        )
    return rows


# ------------------------------------------------------------------------------------ reports
def _run_header(results: Path, run: dict[str, Any], metrics: dict[str, Any]) -> list[str]:
    """The report's Markdown down to the sequences: configuration, metrics, synchronisation."""
    tracker = run["tracker"]
    opts = run["options"]
    faults = fault_config_from_mapping(dict(opts["faults"]))
    return [
        f"# Report: {tracker['name']} on {len(run['sequences'])} sequence(s)",
        "",
        f"Results folder: `{results}`. Tracker: **{tracker['name']}** ({tracker['description']});"
        f" detection mode `{tracker['detection_mode']}`.",
        "",
        "## Configuration",
        "",
        f"- faults: **{faults.name}** — {faults.description or 'custom'}",
        *[f"  - {line}" for line in faults.describe_lines()],
        f"- inputs requested: poses `{opts['poses']}`, masks `{opts['masks']}`, flow "
        f"`{opts['flow']}`; initial condition `{opts['init']}`; seed {opts['seed']}; invalid "
        f"estimates scored as `{opts['invalid']}`",
        f"- versions: {', '.join(f'{k} {v}' for k, v in run.get('versions', {}).items())}",
        "",
        "## Metrics",
        "",
        "ALL pools the frames of every sequence; MEAN averages the per-sequence numbers "
        "(docs/metrics.md).",
        "",
        markdown_table(
            [Column("name", "sequence", align="left"), *METRIC_COLUMNS], _metrics_rows(metrics)
        ),
        "## Synchronisation and consistency",
        "",
        "Mean error (position, rotation, angular velocity) in the 3 frames before / from each "
        "pose arrival (an arrival that disturbs the estimate shows as after > before); poses "
        "rejected by the "
        "tracker and the share of injected outliers among them; frames to recover after a "
        "burst of lost poses; mean NEES of the 12-D state (95 % band for one run: "
        "[4.40, 23.34]).",
        "",
        markdown_table(_SYNC_COLUMNS, _sync_rows(metrics)),
    ]


def _sequence_section(
    seq: dict[str, Any], run: dict[str, Any], results: Path, out: Path, options: ReportOptions
) -> tuple[list[str], list[Path], list[str]]:
    """One sequence's Markdown, the files written for it (plots, video, stills) and the notes."""
    tracker = run["tracker"]
    files: list[Path] = []
    notes: list[str] = []
    name = seq["name"]
    folder = results / name
    md = [f"## {name}", ""]
    md.append(
        f"{seq['frames']} frames at {seq['fps']} fps, {seq['resolution'][0]}x"
        f"{seq['resolution'][1]}; inputs: poses `{seq['inputs']['poses']}`, masks "
        f"`{seq['inputs']['masks']}`, flow `{seq['inputs']['flow']}`."
    )
    md.append("")
    arrivals = np.unique(load_deliveries(folder / DELIVERIES_FILE)["pose"].arrival_k)
    m = None
    if (folder / FRAME_ERRORS_FILE).is_file():
        m = load_frame_errors(folder / FRAME_ERRORS_FILE)
        p1 = _error_plot(m, arrivals, out / "plots" / f"{name}_errors.png", name, tracker["name"])
        p2 = _accuracy_plot(m, out / "plots" / f"{name}_accuracy.png", name, tracker["name"])
        files += [p1, p2]
        md += [f"![errors]({_rel(p1, out)})", "", f"![accuracy]({_rel(p2, out)})", ""]
        gt = _ground_truth_if_available(seq)
        if gt is not None:
            p3 = _velocity_plot(
                load_estimates(folder / ESTIMATES_FILE),
                gt,
                arrivals,
                out / "plots" / f"{name}_velocity.png",
                name,
                tracker["name"],
            )
            files.append(p3)
            md += [f"![velocity]({_rel(p3, out)})", ""]
    else:
        notes.append(f"{name}: no ground truth, no error plots")
    if options.video:
        try:
            written, note = _write_video(
                seq, run, folder, out, options, _still_frames(m, arrivals, seq["frames"]), m
            )
        except (RoftSimError, OSError) as e:
            written, note = [], f"{name}: no overlay video ({e})"
        if note:
            notes.append(note)
        files += written
        if written:
            md.append(
                f"Overlay video: [{_rel(written[0], out)}]({_rel(written[0], out)}) "
                "(green: ground truth, magenta: estimate, yellow: the newest mask the "
                "tracker received, cyan: a pose detection as it arrives, red banner: "
                "arrival)."
            )
            md.append("")
            md += [f"![{p.stem}]({_rel(p, out)})" for p in written[1:]]
            md.append("")
    return md, files, notes


def _run_report(results: Path, out: Path, options: ReportOptions) -> ReportResult:
    run = read_json(results / RUN_FILE)
    metrics = read_json(results / METRICS_FILE)
    names = [seq["name"] for seq in run["sequences"]]
    unknown = [n for n in options.sequences or () if n not in names]
    if unknown:
        raise ConfigError(
            f"{str(results)!r} has no sequence {unknown[0]!r}; its sequences: {', '.join(names)}"
        )
    md = _run_header(results, run, metrics)
    files: list[Path] = []
    notes: list[str] = []
    wanted = set(options.sequences) if options.sequences else None
    for seq in run["sequences"]:
        if wanted is not None and seq["name"] not in wanted:
            continue
        section, written, sequence_notes = _sequence_section(seq, run, results, out, options)
        md += section
        files += written
        notes += sequence_notes
    if notes:
        md += ["## Notes", "", *[f"- {n}" for n in notes], ""]
    report = out / "report.md"
    atomic_write_text(report, "\n".join(md) + "\n")
    return ReportResult(out_dir=out, markdown=report, files=tuple(files), notes=tuple(notes))


def _cells_from_records(records: dict[str, dict[str, Any]]) -> list[SweepCell]:
    cells = []
    for cell_id, r in records.items():
        cells.append(
            SweepCell(
                cell_id=cell_id,
                label=r["label"],
                fault_label=r["faults"],
                parameter=r["parameter"],
                value=r["value"],
                sequence_path=r["sequence_path"],
                sequence_name=r["sequence"],
                options=options_from_record(r["options"]),
            )
        )
    return cells


def _sweep_report(results: Path, out: Path, options: ReportOptions) -> ReportResult:
    from roft_sim.harness.sweep import write_summary

    sweep = read_json(results / "sweep.json")
    records = finished_cells(results / CELLS_DIR)
    planned = sweep.get("cells", list(records))
    missing = [c for c in planned if c not in records]
    ordered = {c: records[c] for c in planned if c in records}
    cells = _cells_from_records(ordered)
    if not cells:
        raise ConfigError(f"sweep {str(results)!r} has no finished cell; run it (--resume)")
    parameter = cells[0].parameter
    _, plots = write_summary(
        sweep["config"]["name"],
        cells,
        ordered,
        out,
        parameter=parameter,
        cells_dir=results / CELLS_DIR,
    )
    notes = [f"{len(missing)} planned cells are not finished"] if missing else []
    summary = (out / "summary.md").read_text(encoding="utf-8")
    report = out / "report.md"
    text = summary + ("\n## Notes\n\n" + "\n".join(f"- {n}" for n in notes) + "\n" if notes else "")
    atomic_write_text(report, text)
    return ReportResult(out_dir=out, markdown=report, files=tuple(plots), notes=tuple(notes))


def build_report(
    results_dir: str | Path,
    *,
    out_dir: str | Path | None = None,
    options: ReportOptions | None = None,
) -> ReportResult:
    """Writes the report of a ``run`` or ``sweep`` results folder (default: into
    ``<results_dir>/report``).

    Raises:
        ConfigError: not a results folder of ``roft-sim run`` or ``roft-sim sweep``.
    """
    results = Path(results_dir)
    options = options or ReportOptions()
    out = Path(out_dir) if out_dir is not None else results / "report"
    if (results / RUN_FILE).is_file():
        try:
            return _run_report(results, out, options)
        except DatasetFormatError as e:
            raise ConfigError(f"{results}: {e}") from None
    if (results / "sweep.json").is_file():
        return _sweep_report(results, out, options)
    if (results / "paper.json").is_file():
        raise ConfigError(
            f"{str(results)!r} is a roft-sim paper folder: its report is tables.md there (rerun "
            "roft-sim paper --resume to rebuild it); for plots and videos of one row, run it with "
            "roft-sim run and report on that folder"
        )
    raise ConfigError(
        f"{str(results)!r} is not a results folder: expected run.json (roft-sim run) or "
        "sweep.json (roft-sim sweep)"
    )
