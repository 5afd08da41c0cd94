"""Scoring a bag recorded from a tracker with the metrics of ``roft-sim run``.

The tracker's ``PoseStamped`` messages (and optionally ``TwistStamped``) are matched to camera
frames by their ``header.stamp``: a stamp within the tolerance of ``k / fps`` belongs to frame
``k``, and every message must match a frame of the sequence. When several messages match one
frame, the last one logged counts (the tracker's newest answer). Each frame then becomes an
:class:`~roft_sim.records.Estimate`:

- a pose message: a valid estimate with that pose; none: ``Estimate.invalid`` (identity pose,
  zero velocity), scored by the run's invalid-estimate policy;
- a twist message: ``spatial`` (``twist.linear`` is ``v_o``) sets the estimate's spatial twist,
  scored with ``v = v_o + w x t_gt``; ``origin`` sets ``v_obj`` and ``w``, scored as they are;
  a twist stamped in the object frame (``object``, the body twist) is turned into ``v_obj`` and
  ``w`` with the pose of its frame, whatever the convention; a frame with a pose but no twist
  has no velocity (left out of the velocity RMSEs).

The estimates are scored by :func:`~roft_sim.metrics.evaluate_estimates` as
:func:`~roft_sim.harness.evaluation.evaluate_run` scores a run (``velocity="auto"``); the
figures that need what a bag does not hold (the fault ledger, covariances, pose ids, step times)
are not computed.
"""

from __future__ import annotations

from collections.abc import Sequence as SequenceABC
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from roft_sim.bags.messages import (
    OBJECT_FRAME,
    POSE_STAMPED,
    TWIST_LINEARS,
    TWIST_STAMPED,
    TwistLinear,
    frame_from_stamp_ns,
    ns_from_time_msg,
    stamp_ns_from_frame,
    transform_from_pose_msg,
    twist_from_msg,
)
from roft_sim.bags.reader import BagMessage, bag_files, bag_metadata, bag_topics, read_messages
from roft_sim.datasets.base import Sequence
from roft_sim.errors import ConfigError, DatasetFormatError
from roft_sim.harness.evaluation import SequenceEvaluation
from roft_sim.harness.inputs import resolve_object_model
from roft_sim.harness.outputs import write_estimate_files, write_json
from roft_sim.harness.run_dataset import METRICS_FILE, RUN_FILE
from roft_sim.metrics import (
    INVALID_POLICIES,
    POOLED_ALL,
    POOLED_MEAN,
    InvalidPolicy,
    evaluate_estimates,
    pool_metrics,
)
from roft_sim.records import Estimate

__all__ = [
    "BagEstimates",
    "BagScore",
    "DEFAULT_STAMP_TOLERANCE_NS",
    "estimates_from_messages",
    "score_bag",
    "write_score_outputs",
]

DEFAULT_STAMP_TOLERANCE_NS = 1_000_000
"""A stamp within 1 ms of ``k / fps`` belongs to frame ``k``: far above the rounding of any
time conversion, far below a frame period (33 ms at 30 fps)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class BagEstimates:
    """The per-frame estimates read from a bag, and how the messages mapped onto frames."""

    estimates: tuple[Estimate, ...]
    """One estimate per frame, ``estimates[k].k == k``."""
    pose_messages: int
    """Messages on the pose topic."""
    twist_messages: int
    """Messages on the twist topic (0 without one)."""
    replaced: int
    """Messages that a later one for the same frame replaced."""
    frames_with_pose: int
    """Frames that got a pose."""

    def summary(self) -> dict[str, int]:
        """JSON-ready counts."""
        return {
            "pose_messages": self.pose_messages,
            "twist_messages": self.twist_messages,
            "replaced": self.replaced,
            "frames_with_pose": self.frames_with_pose,
        }


def _frame_of(message: BagMessage, n_frames: int, fps: int, tolerance_ns: int) -> int | None:
    stamp_ns = ns_from_time_msg(message.message.header.stamp)
    k = frame_from_stamp_ns(stamp_ns, fps)
    if 0 <= k < n_frames and abs(stamp_ns - stamp_ns_from_frame(k, fps)) <= tolerance_ns:
        return k
    return None


def _by_frame(
    messages: SequenceABC[BagMessage], n_frames: int, fps: int, tolerance_ns: int
) -> tuple[dict[int, BagMessage], int]:
    """The last-logged message of each frame, and how many were replaced.

    Raises:
        ConfigError: a message whose stamp is no frame's time (naming the first).
    """
    out: dict[int, BagMessage] = {}
    unmatched: list[BagMessage] = []
    replaced = 0
    for message in sorted(messages, key=lambda m: m.log_time_ns):
        k = _frame_of(message, n_frames, fps, tolerance_ns)
        if k is None:
            unmatched.append(message)
            continue
        replaced += k in out
        out[k] = message
    if unmatched:
        first = unmatched[0]
        stamp_s = ns_from_time_msg(first.message.header.stamp) / 1e9
        raise ConfigError(
            f"{len(unmatched)} of {len(messages)} messages on {first.topic} match no frame of the "
            f"sequence ({n_frames} frames at {fps} Hz, stamps k / fps within "
            f"{tolerance_ns / 1e6:g} ms); the first is stamped {stamp_s:.9f} s. Stamp each "
            "estimate with the header.stamp of the image it was computed from, score against the "
            "sequence the bag was played from, or widen --stamp-tolerance-ms"
        )
    return out, replaced


def _pose(message: BagMessage) -> Any:
    try:
        return transform_from_pose_msg(message.message.pose)
    except ValueError as e:
        stamp_s = ns_from_time_msg(message.message.header.stamp) / 1e9
        raise DatasetFormatError(
            f"pose on {message.topic} stamped {stamp_s:.9f} s is not a pose: {e}"
        ) from None


def estimates_from_messages(
    poses: SequenceABC[BagMessage],
    twists: SequenceABC[BagMessage],
    *,
    n_frames: int,
    fps: int,
    twist_linear: TwistLinear = "origin",
    tolerance_ns: int = DEFAULT_STAMP_TOLERANCE_NS,
) -> BagEstimates:
    """One :class:`Estimate` per frame from decoded pose and twist messages (module docstring).

    Raises:
        ConfigError: a stamp that matches no frame, an unknown ``twist_linear``.
        DatasetFormatError: a pose with a zero or non-finite quaternion or position.
    """
    if twist_linear not in TWIST_LINEARS:
        raise ConfigError(
            f"unknown twist convention {twist_linear!r}; expected one of {TWIST_LINEARS}"
        )
    pose_of, replaced_poses = _by_frame(poses, n_frames, fps, tolerance_ns)
    twist_of, replaced_twists = _by_frame(twists, n_frames, fps, tolerance_ns)
    estimates = []
    for k in range(n_frames):
        pose = pose_of.get(k)
        e = Estimate.invalid(k)
        if pose is not None:
            nan = np.full(3, np.nan)
            e = Estimate(k=k, T_cam_obj=_pose(pose), v_obj_mps=nan, w_radps=nan.copy())
        twist = twist_of.get(k)
        if twist is not None and twist.message.header.frame_id == OBJECT_FRAME:
            # a body twist: v_obj and w in the estimated object frame, turned back with its pose
            linear, angular = twist_from_msg(twist.message)
            if pose is not None:
                R = e.T_cam_obj[:3, :3]
                e = Estimate(k=k, T_cam_obj=e.T_cam_obj, v_obj_mps=R @ linear, w_radps=R @ angular)
        elif twist is not None:
            linear, angular = twist_from_msg(twist.message)
            if twist_linear == "spatial":
                e = Estimate(
                    k=k,
                    T_cam_obj=e.T_cam_obj,
                    v_obj_mps=e.v_obj_mps,
                    w_radps=e.w_radps,
                    valid=e.valid,
                    spatial_twist=np.concatenate([linear, angular]),
                )
            else:
                e = Estimate(
                    k=k, T_cam_obj=e.T_cam_obj, v_obj_mps=linear, w_radps=angular, valid=e.valid
                )
        estimates.append(e)
    return BagEstimates(
        estimates=tuple(estimates),
        pose_messages=len(poses),
        twist_messages=len(twists),
        replaced=replaced_poses + replaced_twists,
        frames_with_pose=len(pose_of),
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class BagScore:
    """The metrics of a bag of tracker estimates on one sequence."""

    sequence_name: str
    """The sequence scored."""
    read: BagEstimates
    """The estimates and message counts."""
    evaluation: SequenceEvaluation
    """The sequence's metrics (figures: the bag's counts under ``bag``)."""
    metrics: dict[str, dict[str, Any]]
    """The content of ``metrics.json``: ``ALL``, ``MEAN`` and the sequence's entry."""
    invalid: InvalidPolicy
    """The invalid-estimate policy used."""
    twist_linear: TwistLinear
    """The twist convention used."""
    files: tuple[Path, ...]
    """The MCAP files read."""


def _check_topic(topics: dict[str, Any], topic: str, datatype: str, option: str) -> None:
    seen = topics.get(topic)
    if seen is None or seen.datatype != datatype:
        have = ", ".join(f"{t} ({c.datatype})" for t, c in sorted(topics.items())) or "none"
        problem = "is not in the bag" if seen is None else f"carries {seen.datatype}"
        raise ConfigError(f"{option} {topic!r} {problem}; expected {datatype}. Topics: {have}")


def _check_against(metadata: dict[str, str], sequence: Sequence) -> None:
    """A bag that says which frames it covers must cover the sequence's."""
    for key, value in (("frames", len(sequence)), ("fps", int(sequence.fps))):
        if key in metadata and metadata[key] != str(value):
            raise ConfigError(
                f"the bag was written for {metadata[key]} {key}, the dataset "
                f"{sequence.name!r} has {value}; score it against the sequence it came from "
                f"({metadata.get('sequence', '?')})"
            )


def score_bag(
    bag: str | Path,
    sequence: Sequence,
    *,
    pose_topic: str,
    twist_topic: str | None = None,
    twist_linear: TwistLinear | None = None,
    invalid: InvalidPolicy | None = None,
    tolerance_ns: int = DEFAULT_STAMP_TOLERANCE_NS,
) -> BagScore:
    """Scores the tracker estimates in ``bag`` against ``sequence``'s ground truth.

    Args:
        bag: a ``.mcap`` file or a rosbag2 folder of them.
        sequence: the sequence the tracker was fed (its ground truth, object model and fps).
        pose_topic: the tracker's ``PoseStamped`` topic.
        twist_topic: its ``TwistStamped`` topic; None = no velocity metrics.
        twist_linear: what ``twist.linear`` holds; None = what the bag's metadata says
            (``roft-sim bag export-run`` writes it), else ``origin``.
        invalid: the invalid-estimate policy; None = the bag's (export-run), else ``failure``.
        tolerance_ns: how far a stamp may be from its frame's time [ns].

    Raises:
        ConfigError: a missing topic or one of another type, a stamp matching no frame, a
            sequence without ground truth or not the one the bag covers, an unknown policy.
        DatasetFormatError: an unreadable bag or pose.
    """
    files = bag_files(bag)
    topics = bag_topics(files)
    _check_topic(topics, pose_topic, POSE_STAMPED, "--pose-topic")
    if twist_topic is not None:
        _check_topic(topics, twist_topic, TWIST_STAMPED, "--twist-topic")
    metadata = bag_metadata(files)
    _check_against(metadata, sequence)
    truth = sequence.ground_truth()
    if truth is None:
        raise ConfigError(f"sequence {sequence.name!r} has no ground truth to score against")
    linear: Any = twist_linear or metadata.get("twist_linear", "origin")
    policy: Any = invalid or metadata.get("invalid", "failure")
    if policy not in INVALID_POLICIES:
        raise ConfigError(f"unknown invalid-estimate policy {policy!r}; one of {INVALID_POLICIES}")
    wanted = [pose_topic] + ([twist_topic] if twist_topic is not None else [])
    messages = list(read_messages(files, wanted))
    read = estimates_from_messages(
        [m for m in messages if m.topic == pose_topic],
        [m for m in messages if m.topic == twist_topic],
        n_frames=len(sequence),
        fps=int(sequence.fps),
        twist_linear=linear,
        tolerance_ns=tolerance_ns,
    )
    model = resolve_object_model(sequence)
    m = evaluate_estimates(read.estimates, truth, model.model_points_m, invalid=policy)
    evaluation = SequenceEvaluation(metrics=m, figures={"bag": read.summary()})
    pooled = pool_metrics({sequence.name: m})
    metrics = {name: pooled[name].summary() for name in (POOLED_ALL, POOLED_MEAN)}
    metrics[sequence.name] = evaluation.entry()
    return BagScore(
        sequence_name=sequence.name,
        read=read,
        evaluation=evaluation,
        metrics=metrics,
        invalid=policy,
        twist_linear=linear,
        files=tuple(files),
    )


def write_score_outputs(
    out_dir: str | Path, score: BagScore, sequence: Sequence, record: dict[str, Any]
) -> Path:
    """Writes a scored bag as a run folder: ``metrics.json`` (``ALL``, ``MEAN``, the sequence),
    ``run.json`` (``kind = "bag-score"`` with ``record``: the bag, topics, policies) and, in the
    sequence's folder, ``metrics.json``, ``estimates.npz``, ``frame_errors.npz``,
    ``pose_estimate.txt`` and ``velocity_estimate.txt`` (docs/running.md, "Outputs")."""
    out = Path(out_dir)
    truth = sequence.ground_truth()
    t_gt = None if truth is None else truth.T_cam_obj[:, :3, 3]
    write_estimate_files(out / score.sequence_name, score.read.estimates, score.evaluation, t_gt)
    write_json(out / METRICS_FILE, score.metrics)
    write_json(
        out / RUN_FILE,
        {
            "kind": "bag-score",
            "bag": [str(f) for f in score.files],
            "sequences": [
                {"name": sequence.name, "frames": len(sequence), "fps": int(sequence.fps)}
            ],
            "invalid": score.invalid,
            "twist_linear": score.twist_linear,
            **record,
        },
    )
    return out
