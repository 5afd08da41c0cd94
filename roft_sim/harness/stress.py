"""The stress benchmark: every tracker under fast captured and synthetic motion, every shipped
fault preset and noisy flow, judged against the baselines.

A stress file (the shipped one is ``scenarios/sweeps/stress.toml``, found by
:func:`shipped_stress_config`) names the grid (trackers, flow sources, seeds, the initial
condition), the scene template (hand occluder, moving camera), the sequences (captured TUM VI
rooms and CMU hands from the shared trajectories folder, the continuous and bursty synthetic
profiles), each tagged TUNING or EVALUATION (or HOLDOUT, in ``stress_holdout.toml``, found by
:func:`shipped_holdout_config`), and three sizes (``quick``, ``medium`` and
``full``).

:func:`run_stress` renders every sequence once into ``<out>/data`` (kept: a second run reuses
it), runs the grid with the sweep machinery into ``<out>/grid`` (parallel, resumable; the cells
of a finished grid are never redone) and scores it: trackers x presets x metrics (ADD-AUC, e_t,
e_a, e_v, e_w, and the NEES of the pose and velocity blocks where a tracker reports
covariances), pooled per split and per sequence, and two verdict lines per split: first on the
default inputs (the stored NVOF-like flow, :data:`DEFAULT_FLOW`: the issue's criterion), then
pooled over every flow source.

A verdict is paired (docs/statistics.md): the subject and a baseline are compared on the same
cells (sequence, flow source, seed: the same fault draw), the mean difference of each verdict
metric gets its 95 % interval, and a preset is a win only when every interval excludes 0 in the
subject's favour. Each line says how many replicates it rests on and how many seeds would detect
a :data:`DETECTABLE_ADD_AUC_POINTS`-point ADD-AUC difference.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from roft_sim.config_files import dataclass_from_mapping, load_toml
from roft_sim.errors import ConfigError
from roft_sim.executors import Executor
from roft_sim.faults.config import fault_spec_name, list_fault_presets
from roft_sim.harness.cells import CELLS_DIR, SweepCell, load_cell_metrics
from roft_sim.harness.evaluation import estimate_errors
from roft_sim.harness.inputs import PREFERRED_FLOW_SET
from roft_sim.harness.options import InitPolicy
from roft_sim.harness.outputs import ESTIMATES_FILE, load_estimates
from roft_sim.harness.replicates import PairedSet, paired_set, replicate_scalars
from roft_sim.harness.robust_start import RobustStartConfig
from roft_sim.harness.sweep import SweepConfig, run_sweep
from roft_sim.metrics import SequenceMetrics, concatenate_metrics
from roft_sim.metrics.consistency import chi2_bounds, nees
from roft_sim.metrics.statistics import BETTER, replicates_needed
from roft_sim.shipped_files import scenarios_dir

__all__ = [
    "StressSequence",
    "StressSize",
    "StressConfig",
    "StressResult",
    "Verdict",
    "SeedAdvice",
    "shipped_stress_config",
    "shipped_holdout_config",
    "SPLITS",
    "load_stress_config",
    "stress_scenarios",
    "run_stress",
    "score_stress",
    "StressScores",
    "format_stress_report",
    "METRICS",
    "DEFAULT_FLOW",
    "DETECTABLE_ADD_AUC_POINTS",
]

_log = logging.getLogger(__name__)

Split = Literal["tuning", "evaluation", "holdout"]

SPLITS: tuple[Split, ...] = ("tuning", "evaluation", "holdout")
"""The splits in report order: ``tuning`` (defaults may be chosen on it), ``evaluation``
(reported, never tuned on) and ``holdout`` (``stress_holdout.toml``: windows, joints, objects and
seeds used by neither, run only to check that a result chosen on TUNING and reported on
EVALUATION transfers)."""

METRICS: tuple[tuple[str, str, str, bool], ...] = (
    ("add_auc_pct", "ADD-AUC %", ".1f", True),
    ("rmse_t_cm", "e_t cm", ".2f", False),
    ("rmse_a_deg", "e_a deg", ".1f", False),
    ("rmse_v_cmps", "e_v cm/s", ".1f", False),
    ("rmse_w_dps", "e_w deg/s", ".1f", False),
    ("nees_pose", "NEES pose", ".1f", False),
    ("nees_velocity", "NEES vel.", ".1f", False),
)
"""``(key, column title, format, higher is better)`` of the report's metrics."""

VERDICT_METRICS: dict[str, str] = {
    "add_auc_pct": "ADD-AUC",
    "rmse_t_cm": "e_t",
    "rmse_a_deg": "e_a",
}
"""The metrics the verdict compares, with their names in the verdict line."""

DETECTABLE_ADD_AUC_POINTS = 2.0
"""The ADD-AUC difference [points] the seed recommendation of a verdict line is sized for."""

MAX_REPLICATES = 10_000
"""Above this many replicates the seed recommendation gives up."""

DEFAULT_FLOW = f"stored:{PREFERRED_FLOW_SET}"
"""The flow source of the default inputs (the stored NVOF-like set a plain ``roft-sim run``
uses): the first verdict line of each split judges the cells with this flow only."""


@dataclass(frozen=True, slots=True, kw_only=True)
class StressSequence:
    """One benchmark sequence (``[[sequences]]``)."""

    name: str
    """Sequence name (unique)."""
    split: Split
    """``tuning``, ``evaluation`` (the project-wide split) or ``holdout`` (:data:`SPLITS`)."""
    motion: Literal["captured", "continuous", "bursty"]
    """Captured motion from the trajectories folder, or a synthetic profile."""
    seed: int
    """Scenario seed; also the synthetic profile's seed."""
    capture: str | None = None
    """Captured only: file under the trajectories folder (``tum/...txt``, ``bvh/...bvh``)."""
    format: Literal["tum", "bvh"] | None = None
    """Captured only: file format."""
    joint: str | None = None
    """BVH only: the joint followed (relative to the pelvis)."""
    start_s: float = 0.0
    """Captured only: where the window starts in the file [s]."""
    object: str | None = None
    """Registry name of the object (exactly one of ``object`` and ``mesh``)."""
    mesh: Path | None = None
    """A textured mesh file (``.obj`` with its ``.mtl`` and texture, metres, in the object frame
    of the poses) instead of a registry object: a tracker judged on an object of one's own.
    Relative paths resolve against the stress file's folder. Its pose network is the pooled
    DOPE-like estimator (no per-object calibration)."""

    def __post_init__(self) -> None:
        if (self.object is None) == (self.mesh is None):
            raise ConfigError(
                f"sequence {self.name!r}: needs exactly one of object = '<registry name>' or "
                f"mesh = '<file.obj>', got object={self.object!r}, "
                f"mesh={None if self.mesh is None else str(self.mesh)!r}"
            )
        if self.split not in SPLITS:
            raise ConfigError(
                f"sequence {self.name!r}: split {self.split!r} is not one of {', '.join(SPLITS)}"
            )
        captured = self.motion == "captured"
        if captured != (self.capture is not None and self.format is not None):
            raise ConfigError(
                f"sequence {self.name!r}: captured motion needs capture = '<file>' and format; "
                "synthetic motion takes neither"
            )
        if self.format == "bvh" and not self.joint:
            raise ConfigError(f"sequence {self.name!r}: a BVH capture needs joint = '<name>'")


@dataclass(frozen=True, slots=True, kw_only=True)
class StressSize:
    """A size of the benchmark (``[quick]``, ``[medium]``, ``[full]``)."""

    frames: int
    """Frames per sequence."""
    resolution: tuple[int, int]
    """(width, height) [px] (16:9, the Fast-YCB camera's field of view)."""
    seeds: tuple[int, ...]
    """Run seeds."""
    sequences: tuple[str, ...] = ()
    """Names of the sequences used (empty = all)."""
    faults: tuple[str, ...] = ()
    """Fault presets (empty = every shipped preset)."""
    flows: tuple[str, ...] = ()
    """Flow sources (empty = the config's)."""

    def __post_init__(self) -> None:
        if self.frames < 10:
            raise ConfigError(f"frames must be >= 10, got {self.frames}")
        if not self.seeds:
            raise ConfigError("a size needs at least one seed")


@dataclass(frozen=True, slots=True, kw_only=True)
class StressConfig:
    """The stress file (see the module docstring)."""

    name: str = "stress"
    """Shown in the report."""
    trackers: tuple[str, ...]
    """Tracker rows; those not registered are skipped with a note."""
    subject: str = "roft"
    """The tracker the verdict is about."""
    baselines: tuple[str, ...] = ("detector-hold", "pose-only-ukf")
    """The trackers it must beat."""
    flows: tuple[str, ...]
    """Flow sources (``roft-sim run --flow``): every one is a grid value."""
    init: InitPolicy = "first-detection"
    """Initial condition of every cell."""
    robust_start: RobustStartConfig = field(default_factory=RobustStartConfig)
    """Settings of ``init = "robust"``."""
    template: Path
    """Scenario file whose camera motion, scene (hand occluder), render and networks settings
    every sequence uses (relative to the stress file)."""
    sequences: tuple[StressSequence, ...]
    """The sequences."""
    quick: StressSize
    """The quick size."""
    medium: StressSize | None = None
    """The medium size (optional): every sequence, long enough that the start does not
    dominate, the default flow only."""
    full: StressSize
    """The full size."""
    notes: dict[str, Any] = field(default_factory=dict)
    """Free-form notes."""

    def __post_init__(self) -> None:
        names = [s.name for s in self.sequences]
        if len(set(names)) != len(names):
            raise ConfigError(f"sequence names must be unique, got {names}")
        for size_name in ("quick", "medium", "full"):
            size: StressSize | None = getattr(self, size_name)
            if size is None:
                continue
            unknown = sorted(set(size.sequences) - set(names))
            if unknown:
                raise ConfigError(f"[{size_name}] names unknown sequences {unknown}; have {names}")
        if self.subject not in self.trackers:
            raise ConfigError(f"subject {self.subject!r} is not among the trackers")


def shipped_stress_config() -> Path:
    """The shipped stress file, ``<package>/scenarios/sweeps/stress.toml``."""
    return scenarios_dir() / "sweeps" / "stress.toml"


def shipped_holdout_config() -> Path:
    """The shipped held-out stress file, ``<package>/scenarios/sweeps/stress_holdout.toml``:
    captured windows and joints, objects and seeds that neither split of the stress file uses,
    every sequence tagged ``holdout``."""
    return scenarios_dir() / "sweeps" / "stress_holdout.toml"


def load_stress_config(path: str | Path) -> StressConfig:
    """Reads a stress file strictly (the template path is resolved against it)."""
    path = Path(path)
    config = dataclass_from_mapping(StressConfig, load_toml(path), where=str(path))
    folder = path.resolve().parent
    template = config.template
    if not template.is_absolute():
        template = folder / template
    sequences = tuple(
        dataclasses.replace(seq, mesh=folder / seq.mesh)
        if seq.mesh is not None and not seq.mesh.is_absolute()
        else seq
        for seq in config.sequences
    )
    return dataclasses.replace(config, template=template, sequences=sequences)


def _trajectory_config(seq: StressSequence, duration_s: float, trajectories_dir: Path) -> Any:
    from roft_sim.trajectories import (
        CapturedMotionConfig,
        ContinuousMotionConfig,
        SyntheticMotionConfig,
    )

    if seq.motion == "continuous":
        return ContinuousMotionConfig(seed=seq.seed, duration_s=duration_s)
    if seq.motion == "bursty":
        return SyntheticMotionConfig(seed=seq.seed, duration_s=max(duration_s, 2.0))
    assert seq.capture is not None and seq.format is not None  # checked in __post_init__
    tum = seq.format == "tum"
    return CapturedMotionConfig(
        path=trajectories_dir / seq.capture,
        format=seq.format,
        joint=seq.joint,
        relative_to=None if tum else "CC_Base_Pelvis",
        lowpass_hz=10.0,
        remove_drift_window_s=2.0 if tum else None,
        window_s=(seq.start_s, seq.start_s + duration_s + 0.5),
    )


def stress_scenarios(
    config: StressConfig, size: StressSize, trajectories_dir: Path
) -> tuple[list[Any], list[str]]:
    """The scenarios of ``size`` and notes on the sequences skipped (captured motion absent).

    Each scenario is the template with the sequence's name, object, motion and seed, the
    Fast-YCB camera at ``size.resolution`` (the template's camera motion kept) and
    ``size.frames`` frames.
    """
    from roft_sim.scenario import FAST_YCB_CAMERA_CONFIG, ObjectConfig, load_scenario

    template = load_scenario(config.template)
    width, height = size.resolution
    k = FAST_YCB_CAMERA_CONFIG.intrinsics.resized(width, height)
    camera = dataclasses.replace(
        FAST_YCB_CAMERA_CONFIG,
        width_px=k.width_px,
        height_px=k.height_px,
        fx_px=k.fx_px,
        fy_px=k.fy_px,
        cx_px=k.cx_px,
        cy_px=k.cy_px,
        motion=template.camera.motion,
    )
    chosen = [s for s in config.sequences if not size.sequences or s.name in size.sequences]
    duration_s = size.frames / camera.fps
    scenarios, skipped = [], []
    for seq in chosen:
        if seq.motion == "captured":
            path = trajectories_dir / str(seq.capture)
            if not path.is_file():
                skipped.append(
                    f"{seq.name} ({seq.split}): captured motion {path} is absent (pass "
                    "--trajectories DIR, the shared trajectories folder); skipped"
                )
                continue
        scenarios.append(
            dataclasses.replace(
                template,
                name=seq.name,
                seed=seq.seed,
                camera=camera,
                object=ObjectConfig(name=seq.object, mesh=seq.mesh),
                trajectory=_trajectory_config(seq, duration_s, trajectories_dir),
                frames=size.frames,
                duration_s=None,
            )
        )
    return scenarios, skipped


def render_stress_sequences(
    scenarios: Sequence[Any], data_dir: Path, *, workers: int = 1
) -> list[Path]:
    """Renders the scenarios into ``data_dir`` (Fast-YCB layout), keeping what is already
    there: a finished sequence is not rendered again (``resume``)."""
    from roft_sim.generation.runner import GenerationOptions, generate_dataset

    data_dir.mkdir(parents=True, exist_ok=True)
    summary = generate_dataset(
        list(scenarios),
        data_dir,
        GenerationOptions(workers=workers, resume=True, progress=False),
    )
    _log.info("stress data: %d frames rendered into %s", summary.frames_generated, data_dir)
    return [data_dir / s.name for s in scenarios]


@dataclass(frozen=True, slots=True, kw_only=True)
class Verdict:
    """Whether the subject beats every baseline on every verdict metric, preset by preset, by
    paired intervals (a win only when every interval excludes 0)."""

    split: str
    """The split judged."""
    inputs: str = "all flows"
    """Which cells were judged, as the line names them (e.g. ``default inputs
    (stored:nvof_1_slow)`` or ``all flows``)."""
    wins: list[str]
    """Presets where it does."""
    fails: list[str]
    """``preset: which metric against which baseline, difference [interval] (verdict)`` where
    it does not."""
    pairs: int = 0
    """The fewest paired replicates any comparison of the line rests on."""
    design: str = ""
    """What the replicates are, e.g. ``2 sequences x 1 flow x 3 seeds``."""
    advice: tuple[SeedAdvice, ...] = ()
    """Per preset, the seeds a :data:`DETECTABLE_ADD_AUC_POINTS`-point difference needs."""
    evidence: tuple[tuple[str, PairedSet], ...] = ()
    """Per preset and baseline, ``(preset, paired set)``: every comparison the line rests on,
    wins included (:meth:`evidence_rows`)."""

    def evidence_rows(self) -> list[str]:
        """Markdown table rows ``| split | inputs | preset | baseline | pairs | ADD-AUC | e_t |
        e_a |``: each verdict metric's mean difference subject - baseline with its 95 %
        interval and verdict word."""
        rows = []
        for preset, pairs in self.evidence:
            cells = [
                f"{c.difference.text('+.2f')} ({c.verdict})"
                for c in (pairs.comparisons[key] for key in VERDICT_METRICS)
            ]
            rows.append(
                f"| {self.split.upper()} | {self.inputs} | {preset} | {pairs.b} | {pairs.pairs} | "
                + " | ".join(cells)
                + " |"
            )
        return rows

    def line(self, subject: str, baselines: Sequence[str]) -> str:
        """The verdict sentence, with what it rests on and the seeds it would need."""
        total = len(self.wins) + len({f.split(":")[0] for f in self.fails})
        text = (
            f"{self.split.upper()}, {self.inputs}: {subject} beats {' and '.join(baselines)} "
            "on ADD-AUC, e_t, "
            f"e_a under {len(self.wins)}/{total} presets"
        )
        if self.design:
            plural = "" if self.pairs == 1 else "s"
            text += (
                f" (paired 95 % intervals, at least {self.pairs} replicate{plural} each: "
                f"{self.design})"
            )
        return text + ("; fails: " + "; ".join(self.fails) if self.fails else "")

    def recommendation(self) -> str:
        """Per preset, how many seeds a :data:`DETECTABLE_ADD_AUC_POINTS`-point ADD-AUC
        difference needs (80 % power, every baseline)."""
        head = f"{self.split.upper()}, {self.inputs}: seeds for a "
        head += f"{DETECTABLE_ADD_AUC_POINTS:g}-point ADD-AUC difference (80 % power): "
        return head + "; ".join(a.text() for a in self.advice)


@dataclass(frozen=True, slots=True, kw_only=True)
class SeedAdvice:
    """How many seeds one preset's comparisons need (:func:`_seed_advice`)."""

    preset: str
    """The preset's name."""
    seeds: int | None
    """Seeds that would find a :data:`DETECTABLE_ADD_AUC_POINTS`-point ADD-AUC difference with
    80 % power against every baseline, from the largest paired standard deviation taken at its
    upper 80 % confidence bound (:func:`~roft_sim.metrics.statistics.replicates_needed`); None:
    more than :data:`MAX_REPLICATES` replicates, or not known."""
    paired_sd: float
    """That largest paired standard deviation [ADD-AUC points]; NaN with fewer than 2 pairs."""
    pairs: int
    """The fewest pairs it was measured on."""
    seeds_matter: bool
    """False when no seed changed the draw (each sequence counted once): more seeds cannot add
    replicates, only more sequences can."""

    def text(self) -> str:
        """``paper: 12 (paired sd 3.10 over 6 pairs)``, or why there is no number."""
        if not self.seeds_matter:
            return f"{self.preset}: seeds change nothing here, add sequences"
        if self.pairs < 2 or not math.isfinite(self.paired_sd):
            return f"{self.preset}: unknown (fewer than 2 pairs)"
        sd = f"paired sd {self.paired_sd:.2f} over {self.pairs} pairs"
        count = f"more than {MAX_REPLICATES} replicates" if self.seeds is None else self.seeds
        return f"{self.preset}: {count} ({sd})"


@dataclass(frozen=True, slots=True, kw_only=True)
class StressResult:
    """What :func:`run_stress` produced."""

    out_dir: Path
    """The benchmark folder."""
    size_name: str
    """``quick``, ``medium`` or ``full`` (or a custom label)."""
    trackers: tuple[str, ...]
    """The trackers run."""
    notes: tuple[str, ...]
    """Skipped trackers and sequences, with the reason."""
    splits: dict[str, list[str]]
    """Sequence names per split."""
    scores: StressScores
    """The pooled metrics and the verdicts (:func:`score_stress`)."""
    presets: tuple[str, ...]
    """The fault presets, in order."""
    flows: tuple[str, ...]
    """The flow sources."""
    interval_velocity: dict[str, Any] = field(default_factory=dict)
    """Per sequence name, the :class:`~roft_sim.metrics.IntervalVelocityErrors` of its ground
    truth: the e_v / e_w that the exact motion over each frame interval gives (what 30 fps
    leaves of the velocity; docs/metrics.md "Interval velocity"). Empty: not computed."""


def _nees_blocks(cells_dir: Path, cell: SweepCell, cache: dict[str, Any]) -> tuple[Any, Any]:
    """Per-frame NEES of the pose (6-D) and velocity (6-D) blocks of a cell's estimates, or
    ``(None, None)`` without covariances."""
    from roft_sim.datasets import open_sequence

    path = cells_dir / cell.cell_id / cell.sequence_name / ESTIMATES_FILE
    if not path.is_file():
        path = next((cells_dir / cell.cell_id).glob(f"**/{ESTIMATES_FILE}"), path)
    if not path.is_file():
        return None, None
    estimates = [e for e in load_estimates(path) if e.valid and e.covariance is not None]
    if not estimates:
        return None, None
    if cell.sequence_path not in cache:
        cache[cell.sequence_path] = open_sequence(cell.sequence_path).ground_truth()
    gt = cache[cell.sequence_path]
    if gt is None:
        return None, None
    errors, covs = estimate_errors(estimates, gt, np.array([e.k for e in estimates]))
    try:
        pose = nees(errors[:, :6], covs[:, :6, :6])
        velocity = nees(errors[:, 6:], covs[:, 6:, 6:])
    except ValueError:
        return None, None
    return pose, velocity


def _scalars(
    m: SequenceMetrics, nees_pose: list[Any], nees_velocity: list[Any]
) -> dict[str, float]:
    summary = m.summary()
    out = {
        key: float("nan") if summary.get(key) is None else float(summary[key])
        for key, *_ in METRICS[:5]
    }
    out["nees_pose"] = float(np.mean(np.concatenate(nees_pose))) if nees_pose else float("nan")
    out["nees_velocity"] = (
        float(np.mean(np.concatenate(nees_velocity))) if nees_velocity else float("nan")
    )
    return out


Scores = dict[tuple[str, str, str], dict[str, float]]
"""``(group, tracker, value) -> metrics`` (see :class:`StressScores`)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class StressScores:
    """What :func:`score_stress` computes from the finished cells."""

    pooled: Scores
    """``(split, tracker, preset)``, pooled over sequences, flows and seeds."""
    pooled_default: Scores
    """``(split, tracker, preset)``, pooled over sequences and seeds, default flow only."""
    per_sequence: Scores
    """``(sequence, tracker, preset)``, pooled over flows and seeds."""
    per_flow: Scores
    """``(split, tracker, flow)``, pooled over presets, sequences and seeds."""
    verdicts: dict[str, Verdict]
    """Per split, on every flow source (paired over sequences x flows x seeds)."""
    default_verdicts: dict[str, Verdict]
    """Per split, on the default flow only (paired over sequences x seeds)."""


CellKey = tuple[str, str, int]
"""``(sequence, flow, seed)``: the cells of two trackers with the same key saw the same data
under the same fault draw."""
Replicates = dict[tuple[str, str, str], dict[CellKey, dict[str, float]]]
"""``(split, tracker, preset) -> cell key -> metric scalars`` (see :class:`StressScores`)."""


def _design(keys: Sequence[CellKey]) -> str:
    """``"2 sequences x 1 flow x 3 seeds"`` of a set of cell keys."""
    counts = [len({k[i] for k in keys}) for i in range(3)]
    names = ("sequence", "flow", "seed")
    return " x ".join(f"{c} {n}{'' if c == 1 else 's'}" for c, n in zip(counts, names, strict=True))


def _judge_preset(
    replicates: Replicates, split: str, preset: str, subject: str, baselines: Sequence[str]
) -> tuple[list[str], list[PairedSet]]:
    """What the subject loses under one preset (empty: a win), and the paired sets behind it."""
    own = replicates[(split, subject, preset)]
    lost: list[str] = []
    sets: list[PairedSet] = []
    for base in baselines:
        other = replicates.get((split, base, preset))
        if other is None:
            continue
        pairs = paired_set(subject, base, own, other, (split, preset, base), list(VERDICT_METRICS))
        sets.append(pairs)
        for key, label in VERDICT_METRICS.items():
            c = pairs.comparisons[key]
            if c.verdict != BETTER:
                lost.append(f"{label} {c.difference.text('+.2f')} vs {base} ({c.verdict})")
    return lost, sets


def _seed_advice(preset: str, sets: Sequence[PairedSet], keys: Sequence[CellKey]) -> SeedAdvice:
    """The seeds one preset's comparisons need (see :class:`SeedAdvice`); ``keys`` are the
    subject's cells under the preset."""
    sds = [p.comparisons["add_auc_pct"].sd for p in sets]
    sd = max(sds) if sds and all(math.isfinite(x) for x in sds) else math.nan
    pairs = min((p.pairs for p in sets), default=0)
    per_seed = len({k[:2] for k in keys}) or 1
    needed = replicates_needed(
        sd, DETECTABLE_ADD_AUC_POINTS, pilot_pairs=pairs, max_n=MAX_REPLICATES
    )
    return SeedAdvice(
        preset=fault_spec_name(preset),
        seeds=None if needed is None else -(-needed // per_seed),
        paired_sd=sd,
        pairs=pairs,
        seeds_matter=len({k[2] for k in keys}) < 2 or pairs > per_seed,
    )


def _verdicts(
    replicates: Replicates,
    splits: Sequence[str],
    presets: Sequence[str],
    *,
    subject: str,
    baselines: Sequence[str],
    inputs: str,
) -> dict[str, Verdict]:
    """One :class:`Verdict` per split that has replicates: does ``subject`` beat every baseline
    on every :data:`VERDICT_METRICS` metric, preset by preset, by paired intervals over the
    cells they share; with the replicates it rests on and the seeds a
    :data:`DETECTABLE_ADD_AUC_POINTS`-point ADD-AUC difference needs."""
    verdicts = {}
    for split in splits:
        wins, fails, advice, pairs = [], [], [], []
        evidence: list[tuple[str, PairedSet]] = []
        keys: set[CellKey] = set()
        for preset in presets:
            if (split, subject, preset) not in replicates:
                continue
            own = sorted(replicates[(split, subject, preset)])
            keys |= set(own)
            lost, sets = _judge_preset(replicates, split, preset, subject, baselines)
            advice.append(_seed_advice(preset, sets, own))
            pairs += [p.pairs for p in sets]
            evidence += [(fault_spec_name(preset), s) for s in sets]
            if lost:
                fails.append(f"{fault_spec_name(preset)}: " + ", ".join(lost))
            else:
                wins.append(fault_spec_name(preset))
        if not (wins or fails):
            continue
        verdicts[split] = Verdict(
            split=split,
            inputs=inputs,
            wins=wins,
            fails=fails,
            pairs=min(pairs, default=0),
            design=_design(sorted(keys)),
            advice=tuple(advice),
            evidence=tuple(evidence),
        )
    return verdicts


def score_stress(
    cells: Sequence[SweepCell],
    cells_dir: Path,
    split_of: Mapping[str, str],
    *,
    subject: str,
    baselines: Sequence[str],
    default_flow: str = DEFAULT_FLOW,
) -> StressScores:
    """Pooled metrics per (split, tracker, preset) over every flow and on ``default_flow`` only,
    per (sequence, tracker, preset) and per (split, tracker, flow), and the two verdicts per
    split (default flow; every flow), paired cell by cell (:func:`_verdicts`).

    Pooling concatenates the per-frame errors (the reference's ALL row); NEES is the mean over
    the pooled frames of the pose and velocity blocks of the reported covariance.
    """
    parts: dict[tuple[str, ...], list[tuple[SequenceMetrics, Any, Any]]] = {}
    replicates: dict[str, Replicates] = {"split": {}, "default": {}}
    gt_cache: dict[str, Any] = {}
    for cell in cells:
        m = load_cell_metrics(cells_dir, cell.cell_id)
        if m is None:
            continue
        pose, vel = _nees_blocks(cells_dir, cell, gt_cache)
        split = split_of[cell.sequence_name]
        entry = (m, pose, vel)
        parts.setdefault(("split", split, cell.label, cell.fault_label), []).append(entry)
        cell_key = (cell.sequence_name, cell.options.flow, cell.options.seed)
        judged = ("split", "default") if cell.options.flow == default_flow else ("split",)
        for name in judged:
            by_cell = replicates[name].setdefault((split, cell.label, cell.fault_label), {})
            by_cell[cell_key] = replicate_scalars(m)
        if cell.options.flow == default_flow:
            parts.setdefault(("default", split, cell.label, cell.fault_label), []).append(entry)
        parts.setdefault(("seq", cell.sequence_name, cell.label, cell.fault_label), []).append(
            entry
        )
        parts.setdefault(("flow", split, cell.label, cell.options.flow), []).append(entry)
    tables: dict[str, Scores] = {"split": {}, "default": {}, "seq": {}, "flow": {}}
    for group, entries in parts.items():
        scalars = _scalars(
            concatenate_metrics([e[0] for e in entries]),
            [e[1] for e in entries if e[1] is not None],
            [e[2] for e in entries if e[2] is not None],
        )
        tables[group[0]][(group[1], group[2], group[3])] = scalars
    presets = list(dict.fromkeys(c.fault_label for c in cells))
    splits = sorted({split_of[c.sequence_name] for c in cells})

    def judge(group: str, inputs: str) -> dict[str, Verdict]:
        return _verdicts(
            replicates[group], splits, presets, subject=subject, baselines=baselines, inputs=inputs
        )

    return StressScores(
        pooled=tables["split"],
        pooled_default=tables["default"],
        per_sequence=tables["seq"],
        per_flow=tables["flow"],
        verdicts=judge("split", "all flows"),
        default_verdicts=judge("default", f"default inputs ({default_flow})"),
    )


def run_stress(
    config: StressConfig,
    size: StressSize,
    out_dir: str | Path,
    *,
    trajectories_dir: Path,
    size_name: str = "quick",
    executor: Executor | None = None,
    render_workers: int = 1,
    progress: bool = False,
) -> StressResult:
    """Renders (once), runs the grid (resumable) and scores it; see the module docstring.

    Raises:
        ConfigError: nothing to run (no sequence left, or no registered tracker).
    """
    from roft_sim.trackers import discover_trackers

    out = Path(out_dir)
    registered = discover_trackers()
    notes: list[str] = []
    trackers = []
    for name in config.trackers:
        if name in registered:
            trackers.append(name)
        else:
            notes.append(f"tracker {name!r} is not registered on this install; skipped")
    if config.subject not in trackers:
        raise ConfigError(f"the subject tracker {config.subject!r} is not registered")
    scenarios, skipped = stress_scenarios(config, size, trajectories_dir)
    notes += skipped
    if not scenarios:
        raise ConfigError("no stress sequence left to run (every one was skipped)")
    paths = render_stress_sequences(scenarios, out / "data", workers=render_workers)
    faults = size.faults or tuple(name for name, _ in list_fault_presets())
    flows = size.flows or config.flows
    sweep = SweepConfig(
        name=f"{config.name} ({size_name})",
        datasets=tuple(paths),
        trackers=tuple(trackers),
        faults=faults,
        flows=flows,
        seeds=size.seeds,
        init=config.init,
        robust_start=config.robust_start,
    )
    result = run_sweep(sweep, out / "grid", executor=executor, progress=progress, plots=False)
    split_of = {s.name: s.split for s in config.sequences}
    scores = score_stress(
        result.cells,
        out / "grid" / CELLS_DIR,
        split_of,
        subject=config.subject,
        baselines=[b for b in config.baselines if b in trackers],
    )
    names = [s.name for s in scenarios]
    splits: dict[str, list[str]] = {}
    for name in names:
        splits.setdefault(split_of[name], []).append(name)
    from roft_sim.datasets import open_sequence
    from roft_sim.metrics import interval_velocity_errors

    interval_velocity = {}
    for name, path in zip(names, paths, strict=True):
        truth = open_sequence(path).ground_truth()
        if truth is not None:
            interval_velocity[name] = interval_velocity_errors(truth)
    return StressResult(
        out_dir=out,
        size_name=size_name,
        trackers=tuple(trackers),
        notes=tuple(notes),
        splits=splits,
        scores=scores,
        presets=tuple(faults),
        flows=tuple(flows),
        interval_velocity=interval_velocity,
    )


def _table(
    title: str,
    rows: list[tuple[str, str, dict[str, float]]],
    first: str,
) -> list[str]:
    head = f"| {first} | tracker | " + " | ".join(t for _, t, _, _ in METRICS) + " |"
    lines = [title, "", head, "|" + "---|" * (len(METRICS) + 2)]
    for a, b, values in rows:
        cells = []
        for key, _, fmt, _ in METRICS:
            v = values.get(key, float("nan"))
            cells.append("-" if not math.isfinite(v) else format(v, fmt))
        lines.append(f"| {a} | {b} | " + " | ".join(cells) + " |")
    return [*lines, ""]


def _rows(
    scores: Mapping[tuple[str, str, str], dict[str, float]],
    group: str,
    values: Sequence[str],
    trackers: Sequence[str],
) -> list[tuple[str, str, dict[str, float]]]:
    """The ``(value, tracker, metrics)`` rows of ``scores[(group, tracker, value)]``, value by
    value, leaving out the combinations not scored."""
    return [
        (fault_spec_name(value), tracker, scores[(group, tracker, value)])
        for value in values
        for tracker in trackers
        if (group, tracker, value) in scores
    ]


def _interval_velocity_table(split: str, names: Sequence[str], errors: dict[str, Any]) -> list[str]:
    """The split's sequences' interval-velocity figures as a Markdown table (none if absent)."""
    known = [n for n in names if n in errors]
    if not known:
        return []
    out = [
        f"### {split.upper()}: velocity from the exact interval motion (what 30 fps leaves)",
        "",
        "e_v [cm/s] and e_w [deg/s] of the exact motion over each frame interval taken as the "
        "velocity at its end (held), carried half an interval forward (extrapolated), or the "
        "last three intervals fitted to the truth itself (fitted; docs/metrics.md). A tracker's "
        "e_v / e_w above are scored the same way.",
        "",
        "| sequence | e_v held | e_v extrapolated | e_v fitted | e_w held | e_w extrapolated "
        "| e_w fitted |",
        "|---|---|---|---|---|---|---|",
    ]
    for name in known:
        e = errors[name]
        values = (
            e.held_v_cmps,
            e.extrapolated_v_cmps,
            e.fitted_v_cmps,
            e.held_w_dps,
            e.extrapolated_w_dps,
            e.fitted_w_dps,
        )
        cells = [f"{v:.2f}" if math.isfinite(v) else "-" for v in values]
        out.append(f"| {name} | " + " | ".join(cells) + " |")
    return out + [""]


def format_stress_report(
    result: StressResult, *, subject: str, baselines: Sequence[str], per_sequence: bool = True
) -> str:
    """The report: per split (TUNING first, then EVALUATION), trackers x presets pooled, per
    flow source, per sequence (pooled over presets... per preset), and the verdict lines."""
    lo, hi = chi2_bounds(6, 1)
    out = [
        f"# Stress benchmark ({result.size_name}): {len(result.trackers)} trackers x "
        f"{len(result.presets)} fault presets x {len(result.flows)} flow sources",
        "",
        f"Flow sources: {', '.join(result.flows)}. NEES: mean over frames of the 6-D pose and "
        f"velocity blocks of the reported covariance (single-frame 95 % band of chi2(6): "
        f"[{lo:.2f}, {hi:.2f}]; '-' = no covariance).",
    ]
    out += [f"Note: {n}" for n in result.notes]
    out.append("")
    for split in SPLITS:
        if split not in result.splits:
            continue
        names = result.splits[split]
        out.append(f"## {split.upper()} split: {', '.join(names)}")
        out.append("")
        rows = _rows(result.scores.pooled, split, result.presets, result.trackers)
        title = f"### {split.upper()}: pooled over sequences, flows and seeds"
        out += _table(title, rows, "preset")
        rows = _rows(result.scores.pooled_default, split, result.presets, result.trackers)
        if rows:
            title = f"### {split.upper()}: default inputs ({DEFAULT_FLOW}), pooled over sequences"
            out += _table(title + " and seeds", rows, "preset")
        rows = _rows(result.scores.per_flow, split, result.flows, result.trackers)
        out += _table(f"### {split.upper()}: per flow source (pooled over presets)", rows, "flow")
        out += _interval_velocity_table(split, names, result.interval_velocity)
        if per_sequence:
            for name in names:
                rows = _rows(result.scores.per_sequence, name, result.presets, result.trackers)
                out += _table(f"### {split.upper()} sequence {name}", rows, "preset")
    out.append("## Verdict")
    out.append("")
    recommendations, evidence = [], []
    for verdicts in (
        result.scores.default_verdicts,
        result.scores.verdicts,
    ):  # the criterion first
        for split in SPLITS:
            if split in verdicts:
                out.append(verdicts[split].line(subject, baselines))
                recommendations.append(verdicts[split].recommendation())
                evidence += verdicts[split].evidence_rows()
    out += [
        "",
        "A preset is a win when, on the cells both trackers ran (same sequence, flow and seed), "
        "the 95 % interval of the mean difference excludes 0 in the subject's favour for every "
        "verdict metric and baseline (docs/statistics.md); a failure shows the difference "
        "subject - baseline with its interval.",
    ]
    if evidence:
        labels = " | ".join(VERDICT_METRICS.values())
        out += [
            "",
            f"### Paired differences behind the verdicts ({subject} - baseline, 95 % intervals)",
            "",
            f"| split | inputs | preset | baseline | pairs | {labels} |",
            "|" + "---|" * (5 + len(VERDICT_METRICS)),
            *evidence,
        ]
    out += ["", "## Seeds needed", "", *recommendations]
    return "\n".join(out) + "\n"
