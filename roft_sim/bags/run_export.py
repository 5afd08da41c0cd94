"""A ``roft-sim run`` folder's estimates as a bag of ``PoseStamped`` and ``TwistStamped``, as
a ROS 2 tracker would have published them, so that ``roft-sim bag score`` on it gives back the
run's metrics (docs/bags.md).

Each frame ``k`` is stamped and logged at ``k / fps``. A valid estimate gives a pose on
:data:`~roft_sim.bags.messages.TRACKER_POSE_TOPIC`; an invalid one none. The twist on
:data:`~roft_sim.bags.messages.TRACKER_TWIST_TOPIC` carries what the run's velocity metrics
scored: when any estimate has a spatial twist (ROFT's velocity filter) the convention is
``spatial`` and each twist is the spatial twist, or, for a frame without one, the body twist
(``v_obj`` and ``w`` in the estimated object frame, stamped in :data:`OBJECT_FRAME`, which the
score turns back into ``v_obj`` and ``w`` with that frame's pose); otherwise
it is ``origin`` and each twist is the estimate's ``v_obj`` and ``w``. The bag's metadata names
the convention and the run's invalid-estimate policy, which ``bag score`` then uses.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from roft_sim import __version__
from roft_sim.bags.export import BagExport
from roft_sim.bags.messages import (
    CAMERA_FRAME,
    OBJECT_FRAME,
    POSE_STAMPED,
    TRACKER_POSE_TOPIC,
    TRACKER_TWIST_TOPIC,
    TWIST_STAMPED,
    pose_stamped_msg,
    stamp_ns_from_frame,
    twist_stamped_msg,
)
from roft_sim.bags.writer import BagWriter, check_bag_path, open_bag
from roft_sim.errors import ConfigError
from roft_sim.harness.outputs import (
    ESTIMATES_FILE,
    load_estimates,
    read_json,
)
from roft_sim.harness.run_dataset import RUN_FILE
from roft_sim.records import Estimate

__all__ = ["export_run_bag"]


def _sequence_record(run: dict[str, Any], run_dir: Path, name: str | None) -> dict[str, Any]:
    """The ``run.json`` entry of the sequence to export (the only one when ``name`` is None)."""
    records = run.get("sequences") or []
    names = [r["name"] for r in records]
    if name is None:
        if len(records) != 1:
            raise ConfigError(
                f"run {str(run_dir)!r} has {len(records)} sequences ({', '.join(names)}); "
                "choose one with --sequence NAME"
            )
        return dict(records[0])
    if name not in names:
        raise ConfigError(f"run {str(run_dir)!r} has no sequence {name!r}; it has {names}")
    return dict(records[names.index(name)])


def _usable(e: Estimate) -> bool:
    return e.valid and bool(np.isfinite(e.T_cam_obj).all())


def _write_estimates(
    bag: BagWriter, estimates: tuple[Estimate, ...], fps: int, spatial: bool
) -> None:
    for e in estimates:
        stamp_ns = stamp_ns_from_frame(e.k, fps)
        if _usable(e):
            bag.write(
                TRACKER_POSE_TOPIC, POSE_STAMPED, pose_stamped_msg(stamp_ns, e.T_cam_obj), stamp_ns
            )
        frame = CAMERA_FRAME
        if spatial and e.spatial_twist is not None:
            linear, angular = e.spatial_twist[:3], e.spatial_twist[3:]
        elif _usable(e) and np.isfinite(e.v_obj_mps).all() and np.isfinite(e.w_radps).all():
            linear, angular = e.v_obj_mps, e.w_radps
            if spatial:  # no spatial twist: the body twist, which the score turns back exactly
                R = np.asarray(e.T_cam_obj)[:3, :3]
                linear, angular, frame = R.T @ linear, R.T @ angular, OBJECT_FRAME
        else:
            continue
        if np.isfinite(linear).all() and np.isfinite(angular).all():
            twist = twist_stamped_msg(stamp_ns, linear, angular, frame)
            bag.write(TRACKER_TWIST_TOPIC, TWIST_STAMPED, twist, stamp_ns)


def export_run_bag(
    run_dir: str | Path,
    path: str | Path,
    *,
    sequence: str | None = None,
    overwrite: bool = False,
) -> BagExport:
    """Writes one sequence's estimates of a run folder as a bag (module docstring).

    Args:
        run_dir: a ``roft-sim run`` output folder.
        path: the ``.mcap`` file to write (atomically).
        sequence: the sequence to export; None = the run's only one.
        overwrite: replace an existing file.

    Raises:
        ConfigError: not a run folder, an unknown or ambiguous sequence, a bad bag path.
        DatasetFormatError: a damaged run file.
    """
    t0 = time.perf_counter()
    run_dir = Path(run_dir)
    path = check_bag_path(path, overwrite=overwrite)
    if not (run_dir / RUN_FILE).is_file():
        raise ConfigError(f"{str(run_dir)!r} is not a roft-sim run folder (no {RUN_FILE})")
    run = read_json(run_dir / RUN_FILE)
    record = _sequence_record(run, run_dir, sequence)
    folder = run_dir / record["name"]
    estimates = load_estimates(folder / ESTIMATES_FILE)
    fps = int(record["fps"])
    if len(estimates) != int(record["frames"]):
        raise ConfigError(
            f"{folder}: {len(estimates)} estimates for {record['frames']} frames; the run "
            "folder is incomplete"
        )
    spatial = any(e.spatial_twist is not None for e in estimates)
    metadata = {
        "kind": "estimates",
        "roft_sim": __version__,
        "sequence": str(record["name"]),
        "frames": str(record["frames"]),
        "fps": str(fps),
        "tracker": str((run.get("tracker") or {}).get("name", "?")),
        "invalid": str((run.get("options") or {}).get("invalid", "failure")),
        "twist_linear": "spatial" if spatial else "origin",
        "pose_topic": TRACKER_POSE_TOPIC,
        "twist_topic": TRACKER_TWIST_TOPIC,
    }
    with open_bag(path) as bag:
        bag.add_metadata(metadata)
        _write_estimates(bag, estimates, fps, spatial)
        topics = bag.topics
    return BagExport(
        path=path,
        topics=topics,
        frames=len(estimates),
        dropped_frames=0,
        size_bytes=path.stat().st_size,
        wall_s=time.perf_counter() - t0,
    )
