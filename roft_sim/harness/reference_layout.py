"""The reference ROFT evaluation's tree (``roft-sim run --layout reference``).

hsp-iit/roft ``evaluation/evaluate.py`` (with ``data_loader.py`` and ``metrics.py``) reads, relative
to the folder it runs in (docs/formats.md, "The reference evaluation's tree"):

==============================================================  ==================================
``results/ROFT_results/fastycb/<config>/<object>/``             one run of one tracker
    ``pose_estimate_ycb.txt``                                   13 columns ``v_obj(3) w(3) x y z
                                                                ax ay az angle``; the evaluation
                                                                keeps columns 6..12
    ``velocity_estimate.txt``                                   6 columns ``v_o(3) w(3)``
    ``execution_times.txt``                                     ``step_ms load_ms``
    ``pose_measurements.txt``                                   7 columns, the newest pose received
    ``velocity_measurements.txt``                               6 columns ``v_o(3) w(3)``
``dataset/fast-ycb/<object>/``                                  the sequence's ground truth
    ``cam_K.json``, ``gt/poses.txt``, ``gt/poses_ycb.txt``,
    ``gt/velocities.txt``, ``dope/poses.txt``,
    ``dope/poses_ycb.txt``
``YCB_Video_Models/models/<object>/points.xyz``                 the model points ADD uses
==============================================================  ==================================

``<config>`` is named as ``data_loader.load_ours`` composes it:
``full_mask_<mask set>_of_<flow set>_pose_<pose set>`` plus the reference's ablation suffix
(``_no_outrej``, ``_no_posesync``, ``_no_flowaid``, ``_no_velocity``, ``_no_pose``) for a ROFT
ablation, and ``_<tracker>`` for a tracker other than ROFT (:func:`reference_config_name`).
The reference's ``evaluation/experiments.py`` reads fixed ``<config>`` folders
(:data:`REFERENCE_EXPERIMENTS`); ``evaluate.py`` stops with ``FileNotFoundError`` on the first
file it opens (``execution_times.txt``) of a folder its experiment names and the tree lacks, so a
tree of another tracker, or of other inputs, is scored by ``exp_fastycb_roft`` when written with
``<config>`` = :data:`REFERENCE_ROFT_CONFIG` (``--reference-config``); the CLI says so
(:attr:`ReferenceTree.experiments`).

Object frame: the ``*_ycb.txt`` files and ``points.xyz`` are in the object frame of our poses
(for registry objects the NVDU-aligned frame, bounding-box centre at the origin), the same frame
as ``poses.txt``: the points written are the ones our ADD uses, so the reference's numbers are
ours. The real YCB-Video models are in another frame (the reference converts with
``tools/dataset/conversion/nvdu_poses_to_ycbv.py``); do not swap their ``points.xyz`` in.

Rows: the reference scores every row and divides by the norm of the axis of each, so no row is
all zeros. A frame without a tracker pose shows the last pose before it, and frames before the
tracker's first pose show that first pose (the reference has no way to leave them out of a
tracker's rows). The reference's numbers therefore equal ours under ``--invalid hold`` whenever
the tracker has a pose from frame 0 (always, under the ``paper`` faults, when the detector sees
frame 0), and differ on the frames before the first pose otherwise. Velocities follow
docs/conventions.md ("Velocity"): the reference's ``v = v_o + w x t_gt`` yields the tracker's
estimate.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.assets.registry import FAST_YCB_OBJECTS
from roft_sim.datasets.atomic_files import atomic_write_text
from roft_sim.datasets.base import Sequence as DatasetSequence
from roft_sim.datasets.fast_ycb_codec import encode_cam_k_json, format_rows, pose_row_from_transform
from roft_sim.datasets.model_files import write_points_xyz
from roft_sim.errors import ConfigError
from roft_sim.harness.outputs import pose_estimate_rows, velocity_estimate_rows
from roft_sim.harness.runner import SequenceRun
from roft_sim.records import PoseTrack

F64 = NDArray[np.float64]

__all__ = [
    "REFERENCE_DATASET",
    "REFERENCE_OBJECTS",
    "REFERENCE_RESULTS_DIR",
    "REFERENCE_DATASET_DIR",
    "REFERENCE_MODELS_DIR",
    "REFERENCE_TOP_FOLDERS",
    "REFERENCE_RESULT_FILES",
    "REFERENCE_ROFT_CONFIG",
    "REFERENCE_EXPERIMENTS",
    "ReferenceTree",
    "reference_config_name",
    "check_reference_objects",
    "write_reference_tree",
]

REFERENCE_DATASET = "fastycb"
"""The dataset name of the reference's experiments (``config['dataset']``)."""
REFERENCE_OBJECTS: tuple[str, ...] = FAST_YCB_OBJECTS
"""The objects ``evaluation/objects.py`` lists for ``fastycb``: it loads every one of them."""
REFERENCE_RESULTS_DIR = Path("results") / "ROFT_results" / REFERENCE_DATASET
REFERENCE_DATASET_DIR = Path("dataset") / "fast-ycb"
REFERENCE_MODELS_DIR = Path("YCB_Video_Models") / "models"
REFERENCE_TOP_FOLDERS: tuple[str, ...] = ("results", "dataset", "YCB_Video_Models")
"""The folders the tree adds at its root."""
REFERENCE_RESULT_FILES: tuple[str, ...] = (
    "execution_times.txt",
    "pose_estimate_ycb.txt",
    "velocity_estimate.txt",
    "pose_measurements.txt",
    "velocity_measurements.txt",
)
"""Every file ``data_loader.load_ours`` opens in a result folder, in its order.
``execution_times.txt`` holds ``step_ms load_ms`` per frame, as the reference ROFT logs them; the
reference's ``time`` metric is the mean of the first column plus 3 ms of NVOF 1.0 for an
``nvof_1`` flow set."""

REFERENCE_ROFT_CONFIG = "full_mask_mrcnn_ycbv_bop_pbr_of_nvof_1_slow_pose_dope"
"""The ``<config>`` of the reference's ROFT row on Fast-YCB (its Tables I, II and IV)."""

REFERENCE_EXPERIMENTS: dict[str, tuple[str, ...]] = {
    "exp_fastycb_roft": (REFERENCE_ROFT_CONFIG,),
    "exp_fastycb_velocities": (REFERENCE_ROFT_CONFIG, f"{REFERENCE_ROFT_CONFIG}_no_flowaid"),
    "exp_fastycb_ablation": (
        "full_mask_gt_of_nvof_1_slow_pose_gt",
        "full_mask_mrcnn_ycbv_bop_pbr_of_nvof_1_slow_pose_gt",
        "full_mask_gt_of_nvof_1_slow_pose_dope",
        REFERENCE_ROFT_CONFIG,
        f"{REFERENCE_ROFT_CONFIG}_no_posesync",
        f"{REFERENCE_ROFT_CONFIG}_no_outrej",
        f"{REFERENCE_ROFT_CONFIG}_no_flowaid",
        f"{REFERENCE_ROFT_CONFIG}_no_velocity",
        f"{REFERENCE_ROFT_CONFIG}_no_pose",
    ),
}
"""The Fast-YCB experiments of the reference's ``evaluation/experiments.py`` that read ROFT
result folders and the dataset only (``exp_fastycb`` also reads PoseRBPF's and se3-TrackNet's
results): experiment -> every ``<config>`` folder it reads (the tree must hold them all; trees of
several runs merge, one ``<config>`` folder each)."""

_ROFT_SUFFIXES = {
    "no_outlier_rejection": "no_outrej",
    "no_pose_sync": "no_posesync",
    "no_mask_sync": "no_flowaid",
    "no_velocity": "no_velocity",
    "no_pose": "no_pose",
}
"""Our ROFT ablation names -> the reference's config suffixes (``experiments.py``)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class ReferenceTree:
    """What :func:`write_reference_tree` wrote."""

    root: Path
    """The folder to run ``evaluate.py`` from."""
    config_name: str
    """The ``<config>`` folder of the results."""
    objects: tuple[str, ...]
    """The objects written."""

    @property
    def missing_objects(self) -> tuple[str, ...]:
        """Fast-YCB objects the reference loads but this tree lacks (it fails on any of them)."""
        return tuple(o for o in REFERENCE_OBJECTS if o not in self.objects)

    @property
    def experiments(self) -> tuple[str, ...]:
        """The reference experiments (:data:`REFERENCE_EXPERIMENTS`) that read this tree's
        ``<config>``; none for another name (``evaluate.py`` would stop on the first file it
        opens in the folder its experiment names: rerun with
        ``--reference-config`` :data:`REFERENCE_ROFT_CONFIG` to be scored as its ROFT row)."""
        reading = REFERENCE_EXPERIMENTS.items()
        return tuple(e for e, configs in reading if self.config_name in configs)

    @property
    def results_dir(self) -> Path:
        """``results/ROFT_results/fastycb/<config>``."""
        return self.root / REFERENCE_RESULTS_DIR / self.config_name


def _set_name(value: str | None) -> str:
    if value is None:
        return "none"
    value = value.removeprefix("stored:")
    return re.sub(r"[^A-Za-z0-9_]+", "_", value).strip("_") or "none"


def reference_config_name(inputs: dict[str, str | None], tracker: str, config: Any = None) -> str:
    """``full_mask_<masks>_of_<flow>_pose_<poses>[_<suffix>]`` as ``load_ours`` composes it.

    Args:
        inputs: the run's resolved inputs (``SequenceRun.inputs``: ``poses``, ``masks``,
            ``flow``); a stored flow set ``stored:nvof_1_slow`` is named ``nvof_1_slow``.
        tracker: registry name of the tracker; ROFT gets the reference's ablation suffix when
            ``config`` is one of :data:`~roft_sim.trackers.roft.ABLATIONS`, any other tracker
            ``_<tracker>``.
        config: the tracker's configuration.
    """
    name = (
        f"full_mask_{_set_name(inputs.get('masks'))}_of_{_set_name(inputs.get('flow'))}"
        f"_pose_{_set_name(inputs.get('poses'))}"
    )
    if tracker == "roft":
        from roft_sim.trackers.roft import ablation_config

        for ablation, suffix in _ROFT_SUFFIXES.items():
            if config is not None and config == ablation_config(ablation):
                return f"{name}_{suffix}"
        return name
    return f"{name}_{_set_name(tracker)}"


def check_reference_objects(object_names: Sequence[str]) -> None:
    """The reference tree has one folder per object: each object at most once in a run.

    Raises:
        ConfigError: an object appears in several sequences.
    """
    dup = sorted({n for n in object_names if list(object_names).count(n) > 1})
    if dup:
        raise ConfigError(
            f"--layout reference names result folders by object, but {dup} appear in more than "
            "one sequence; run one sequence per object (e.g. one roft-sim run per dataset)"
        )


def _write_rows(path: Path, rows: F64) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, format_rows(rows))


def _pose_rows(T: F64) -> F64:
    """(N, 7) ``x y z ax ay az angle`` rows of (N, 4, 4) transforms."""
    return np.array([pose_row_from_transform(t) for t in T]).reshape(len(T), 7)


def _detector_rows(sequence: DatasetSequence, pose_set: str | None) -> F64 | None:
    """(N, 7) rows of the detector pose set (zeros = miss), ``dope`` first, else the run's."""
    sets = tuple(sequence.pose_sets())
    name = "dope" if "dope" in sets else pose_set if pose_set in sets else None
    if name is None:
        return None
    poses = sequence.detector_poses(name)
    rows = _pose_rows(poses.T_cam_obj)
    rows[~np.asarray(poses.valid, dtype=bool)] = 0.0
    return rows


def _measurement_rows(run: SequenceRun, sequence: DatasetSequence, fallback: F64) -> F64:
    """(N, 7) the newest pose received by each frame (by capture frame), from the stored set.

    Frames before the first arrival show the first one; the tracker's own rows when it got no
    pose (``--poses none``) or the set is not stored. Content faults (outliers) are not replayed.
    """
    pose_set = run.inputs.get("poses")
    if pose_set is None or pose_set not in tuple(sequence.pose_sets()) or not run.pose_deliveries:
        return fallback
    poses = sequence.detector_poses(pose_set)
    n = len(run)
    newest = np.full(n, -1, dtype=np.int64)
    for event in run.pose_deliveries:
        if event.arrival_k < n and poses.valid[event.true_capture_k]:
            k = event.arrival_k
            newest[k] = max(newest[k], event.true_capture_k)
    newest = np.maximum.accumulate(newest)
    if (newest < 0).all():
        return fallback
    newest[newest < 0] = newest[newest >= 0][0]
    return _pose_rows(poses.T_cam_obj[newest])


def _write_ground_truth(folder: Path, sequence: DatasetSequence, gt: PoseTrack) -> None:
    atomic_write_text(folder / "cam_K.json", encode_cam_k_json(sequence.intrinsics))
    pose_rows = _pose_rows(gt.T_cam_obj)
    for name in ("poses.txt", "poses_ycb.txt"):
        _write_rows(folder / "gt" / name, pose_rows)
    _write_rows(folder / "gt" / "velocities.txt", np.hstack([gt.v_obj_mps, gt.w_radps]))


def write_reference_tree(
    root: str | Path,
    runs: Sequence[tuple[SequenceRun, DatasetSequence]],
    *,
    config_name: str,
) -> ReferenceTree:
    """Writes the reference evaluation's tree for ``runs`` under ``root`` (module docstring).

    Args:
        root: the folder ``evaluate.py`` is to run in (created).
        runs: each run with the sequence it ran on; one per object, with ground truth.
        config_name: the ``<config>`` folder (:func:`reference_config_name`).

    Returns:
        The :class:`ReferenceTree`.

    Raises:
        ConfigError: an object twice, a sequence without ground truth or ground-truth
            velocities, a tracker that never had a pose, or a bad ``config_name``.
    """
    root = Path(root)
    if not re.fullmatch(r"[A-Za-z0-9_.-]+", config_name) or config_name in (".", ".."):
        raise ConfigError(
            f"reference config name {config_name!r} must be a folder name of letters, digits, "
            "'_', '.' and '-', e.g. full_mask_mrcnn_ycbv_bop_pbr_of_nvof_1_slow_pose_dope"
        )
    check_reference_objects([run.object_name for run, _ in runs])
    written = []
    for run, sequence in runs:
        gt = run.ground_truth
        where = f"sequence {run.sequence_name!r}"
        if gt is None or not (np.isfinite(gt.v_obj_mps).all() and np.isfinite(gt.w_radps).all()):
            raise ConfigError(
                f"{where} has no ground-truth poses and velocities; the reference evaluation "
                "needs both (gt/poses_ycb.txt, gt/velocities.txt): drop --layout reference"
            )
        if not any(e.valid and np.isfinite(e.T_cam_obj).all() for e in run.estimates):
            raise ConfigError(
                f"{where}: the tracker never reported a pose, so there is no row the reference "
                "evaluation can read (it divides by the norm of a zero axis); check its inputs"
            )
        obj = run.object_name
        results = root / REFERENCE_RESULTS_DIR / config_name / obj
        poses = pose_estimate_rows(run.estimates, hold=True)
        _write_rows(results / "pose_estimate_ycb.txt", poses)
        velocity = velocity_estimate_rows(run.estimates, gt.T_cam_obj[:, :3, 3], hold=True)
        _write_rows(results / "velocity_estimate.txt", velocity)
        _write_rows(results / "velocity_measurements.txt", velocity)
        _write_rows(
            results / "execution_times.txt",
            np.stack([1e3 * run.step_times_s, 1e3 * run.load_times_s], axis=1),
        )
        _write_rows(
            results / "pose_measurements.txt", _measurement_rows(run, sequence, poses[:, 6:])
        )
        data = root / REFERENCE_DATASET_DIR / obj
        _write_ground_truth(data, sequence, gt)
        detector = _detector_rows(sequence, run.inputs.get("poses"))
        if detector is not None:
            for name in ("poses.txt", "poses_ycb.txt"):
                _write_rows(data / "dope" / name, detector)
        points = root / REFERENCE_MODELS_DIR / obj / "points.xyz"
        points.parent.mkdir(parents=True, exist_ok=True)
        write_points_xyz(points, run.object_model.model_points_m)
        written.append(obj)
    return ReferenceTree(root=root, config_name=config_name, objects=tuple(written))
