"""A sequence under a fault configuration as a ROS 2 bag: what ``roft-sim run`` would feed a
tracker, on standard topics, each message logged when the run delivers it (docs/bags.md).

Per camera frame ``k`` (log time ``k / fps``), unless a camera fault dropped it: the colour image
(``rgb8``), the depth image (REP 118, depth faults applied) and a ``CameraInfo`` for each. Then
every detection the fault schedule delivers at ``k``: the detector's pose (``PoseStamped``) and
mask (``mono8`` ``Image``), stamped with the capture frame they report, content faults applied.
Then, unless left out, the ground truth of frame ``k``: ``/tf`` and a ``TwistStamped``. A dropped
camera frame has no image and no ``CameraInfo`` message; the detections and ground truth of that
frame are written all the same.

The observations come from :func:`~roft_sim.harness.runner.make_observation_stream`, so the same
sequence, faults, seed and inputs give exactly the detections, delays and drops of a run.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from roft_sim import __version__
from roft_sim.bags.messages import (
    CAMERA_INFO,
    COLOR_INFO_TOPIC,
    COLOR_TOPIC,
    DEPTH_ENCODINGS,
    DEPTH_INFO_TOPIC,
    DEPTH_TOPIC,
    DETECTOR_POSE_TOPIC,
    GT_TWIST_TOPIC,
    IMAGE,
    MASK_TOPIC,
    POSE_STAMPED,
    TF_MESSAGE,
    TF_TOPIC,
    TWIST_STAMPED,
    DepthEncoding,
    camera_info_msg,
    depth_image_msg,
    mask_image_msg,
    pose_stamped_msg,
    rgb_image_msg,
    stamp_ns_from_frame,
    tf_msg,
    twist_stamped_msg,
)
from roft_sim.bags.writer import BagWriter, TopicCount, check_bag_path, open_bag
from roft_sim.datasets.base import Sequence
from roft_sim.errors import ConfigError
from roft_sim.faults import FaultConfig, ObservationStream
from roft_sim.harness.inputs import check_inputs
from roft_sim.harness.options import RunOptions
from roft_sim.harness.runner import make_observation_stream
from roft_sim.records import Observation, PoseTrack

__all__ = ["BagExport", "export_sequence_bag", "export_options"]

_STREAM_ONLY = "bag-export"
"""The tracker name of the export's RunOptions: the stream depends on no tracker."""


@dataclass(frozen=True, slots=True, kw_only=True)
class BagExport:
    """What a bag export wrote."""

    path: Path
    """The bag."""
    topics: dict[str, TopicCount]
    """Each topic's type and message count."""
    frames: int
    """Camera frames of the sequence."""
    dropped_frames: int
    """Camera frames a fault dropped (no image messages)."""
    size_bytes: int
    """Size of the bag file."""
    wall_s: float
    """Wall time of the export [s]."""


def export_options(
    faults: FaultConfig, *, seed: int = 0, poses: str = "auto", masks: str = "auto"
) -> RunOptions:
    """The :class:`RunOptions` whose observation stream a bag holds (no tracker, no flow).

    Args:
        faults: a loaded :class:`~roft_sim.faults.FaultConfig`.
        seed: the run seed.
        poses: detector pose set (as ``roft-sim run --poses``).
        masks: mask set (as ``roft-sim run --masks``).
    """
    return RunOptions(
        tracker=_STREAM_ONLY, faults=faults, flow="none", poses=poses, masks=masks, seed=seed
    )


def _write_camera(
    bag: BagWriter, observation: Observation, stamp_ns: int, sequence: Sequence, encoding: str
) -> None:
    if observation.rgb is None or observation.depth_m is None:
        return
    info = camera_info_msg(stamp_ns, sequence.intrinsics)
    bag.write(COLOR_TOPIC, IMAGE, rgb_image_msg(stamp_ns, observation.rgb), stamp_ns)
    bag.write(COLOR_INFO_TOPIC, CAMERA_INFO, info, stamp_ns)
    depth = depth_image_msg(stamp_ns, observation.depth_m, encoding)  # type: ignore[arg-type]
    bag.write(DEPTH_TOPIC, IMAGE, depth, stamp_ns)
    bag.write(DEPTH_INFO_TOPIC, CAMERA_INFO, info, stamp_ns)


def _write_detections(bag: BagWriter, observation: Observation, fps: int, log_ns: int) -> None:
    for pose in observation.poses:
        stamp = stamp_ns_from_frame(pose.capture_k, fps)
        bag.write(
            DETECTOR_POSE_TOPIC, POSE_STAMPED, pose_stamped_msg(stamp, pose.T_cam_obj), log_ns
        )
    for mask in observation.masks:
        stamp = stamp_ns_from_frame(mask.capture_k, fps)
        bag.write(MASK_TOPIC, IMAGE, mask_image_msg(stamp, mask.mask), log_ns)


def _write_ground_truth(bag: BagWriter, truth: PoseTrack, k: int, stamp_ns: int) -> None:
    bag.write(TF_TOPIC, TF_MESSAGE, tf_msg(stamp_ns, truth.T_cam_obj[k]), stamp_ns)
    twist = twist_stamped_msg(stamp_ns, truth.v_obj_mps[k], truth.w_radps[k])
    bag.write(GT_TWIST_TOPIC, TWIST_STAMPED, twist, stamp_ns)


def _metadata(
    sequence: Sequence, options: RunOptions, stream: ObservationStream, encoding: str, gt: bool
) -> dict[str, str]:
    return {
        "kind": "sequence",
        "roft_sim": __version__,
        "sequence": sequence.name,
        "object": sequence.object_name,
        "frames": str(len(sequence)),
        "fps": str(int(sequence.fps)),
        "faults": options.faults.name,
        "seed": str(options.seed),
        "pose_set": str(stream.pose_set),
        "mask_set": str(stream.mask_set),
        "depth_encoding": encoding,
        "ground_truth": "yes" if gt else "no",
        "twist_linear": "origin",
    }


def export_sequence_bag(
    sequence: Sequence,
    options: RunOptions,
    path: str | Path,
    *,
    depth_encoding: DepthEncoding = "32FC1",
    ground_truth: bool = True,
    overwrite: bool = False,
    progress: Callable[[int], object] | None = None,
) -> BagExport:
    """Writes the observation stream of ``sequence`` under ``options`` as a ROS 2 bag.

    Args:
        sequence: the sequence.
        options: faults, seed, pose set and mask set (:func:`export_options`; tracker and flow
            are not used).
        path: the ``.mcap`` file to write (atomically).
        depth_encoding: ``32FC1`` metres or ``16UC1`` millimetres (REP 118).
        ground_truth: write ``/tf`` and ``/ground_truth/twist`` (needs the sequence's ground
            truth); False gives a bag with the tracker's inputs only.
        overwrite: replace an existing file.
        progress: called with 1 after every frame (e.g. ``tqdm.update``).

    Returns:
        The :class:`BagExport`.

    Raises:
        ConfigError: a bad path or encoding, an existing file without ``overwrite``, inputs the
            sequence does not have, or ground truth asked of a sequence without it; all checked
            before anything is written.
    """
    t0 = time.perf_counter()
    path = check_bag_path(path, overwrite=overwrite)
    if depth_encoding not in DEPTH_ENCODINGS:
        raise ConfigError(
            f"unknown depth encoding {depth_encoding!r}; expected one of {DEPTH_ENCODINGS}"
        )
    check_inputs(sequence, options)
    truth = sequence.ground_truth() if ground_truth else None
    if ground_truth and truth is None:
        raise ConfigError(
            f"sequence {sequence.name!r} has no ground truth; export it with --no-ground-truth"
        )
    stream, _, _ = make_observation_stream(sequence, options, with_flow=False)
    fps = int(sequence.fps)
    with open_bag(path) as bag:
        bag.add_metadata(_metadata(sequence, options, stream, depth_encoding, ground_truth))
        for k in range(len(sequence)):
            observation = stream.observation(k)
            stamp_ns = stamp_ns_from_frame(k, fps)
            _write_camera(bag, observation, stamp_ns, sequence, depth_encoding)
            _write_detections(bag, observation, fps, stamp_ns)
            if truth is not None:
                _write_ground_truth(bag, truth, k, stamp_ns)
            if progress is not None:
                progress(1)
        topics = bag.topics
    return BagExport(
        path=path,
        topics=topics,
        frames=len(sequence),
        dropped_frames=int(np.count_nonzero(stream.schedule.camera.dropped)),
        size_bytes=path.stat().st_size,
        wall_s=time.perf_counter() - t0,
    )
