"""Reader for one object's poses in a BOP ``scene_gt.json``.

``scene_gt.json`` maps each image id (a decimal string) to a list of annotations
``{"obj_id": int, "cam_R_m2c": [9 numbers], "cam_t_m2c": [3 numbers]}``: the rotation
model -> camera as a ROW-MAJOR 3x3 matrix and the translation in MILLIMETRES, so
``p_cam = R p_model + t``. BOP stores no time stamps: image ``i`` is taken at ``i / rate``.
Images where the object is absent are skipped (the spline bridges them).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError, DatasetFormatError, located
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import as_rotation_matrix
from roft_sim.trajectories.samples import PoseSamples
from roft_sim.trajectories.spline import MIN_SPLINE_SAMPLES

__all__ = ["read_bop_scene_gt", "BOP_ROTATION_TOLERANCE"]

BOP_ROTATION_TOLERANCE = 1e-3
"""Largest accepted ``max |R^T R - I|`` of ``cam_R_m2c`` (files print a few decimals); the
rotations are then re-orthonormalised."""

_HELP = (
    'scene_gt.json maps image ids to lists of {"obj_id": int, "cam_R_m2c": [9 numbers, '
    'row-major], "cam_t_m2c": [3 numbers, mm]}'
)


def _orthonormalise(R: NDArray[np.float64]) -> NDArray[np.float64]:
    u, _, vt = np.linalg.svd(R)
    rotation: NDArray[np.float64] = u @ vt
    return rotation


def _scene_gt_entries(path: Path) -> dict[int, list[dict[str, Any]]]:
    """The annotations of ``scene_gt.json`` per image id, each with an integer ``obj_id``."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetFormatError(
            f"BOP file {located(path)} does not exist; give scene_gt.json or its scene folder"
        ) from None
    except UnicodeDecodeError as e:
        raise DatasetFormatError(
            f"{located(path)} is not a UTF-8 text file ({e}); {_HELP}"
        ) from None
    except json.JSONDecodeError as e:
        raise DatasetFormatError(
            f"{located(path, e.lineno)}: not valid JSON ({e.msg}, column {e.colno}); {_HELP}"
        ) from None
    if not isinstance(data, dict):
        raise DatasetFormatError(f"{located(path)}: top level is not an object; {_HELP}")
    entries: dict[int, list[dict[str, Any]]] = {}
    for key, listed in data.items():
        if not str(key).isdigit() or not isinstance(listed, list):
            raise DatasetFormatError(
                f"{located(path)}: image {key!r} must be a decimal image id mapping to a list; "
                f"{_HELP}"
            )
        entries[int(key)] = listed
    for key, listed in entries.items():
        for a in listed:
            if not isinstance(a, dict) or not isinstance(a.get("obj_id"), int):
                raise DatasetFormatError(
                    f"{located(path)}: image {key}: annotation {str(a)[:80]} lacks an integer "
                    f"obj_id; {_HELP}"
                )
    return entries


def _followed_object(
    path: Path, entries: dict[int, list[dict[str, Any]]], object_id: int | None
) -> int:
    """The ``obj_id`` to follow: the one asked for, or the only one in the file."""
    present: set[int] = {a["obj_id"] for listed in entries.values() for a in listed}
    if object_id is None:
        if len(present) != 1:
            raise ConfigError(
                f"{located(path)} shows objects {sorted(present)}; choose one with object_id"
            )
        return next(iter(present))
    if object_id not in present:
        raise ConfigError(
            f"{located(path)} has no object with obj_id {object_id}; it shows {sorted(present)}"
        )
    return object_id


def _annotation_pose(
    path: Path, key: int, annotation: dict[str, Any]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``R`` (3, 3) and ``t`` (3,) [m] of one annotation (``cam_R_m2c`` row-major, ``cam_t_m2c``
    [mm]), checked and re-orthonormalised."""
    try:
        R = np.array(annotation["cam_R_m2c"], dtype=np.float64)
        t = np.array(annotation["cam_t_m2c"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise DatasetFormatError(
            f"{located(path)}: image {key}: cam_R_m2c / cam_t_m2c missing or not numbers; {_HELP}"
        ) from None
    if R.shape != (9,) or t.shape != (3,):
        raise DatasetFormatError(
            f"{located(path)}: image {key}: cam_R_m2c has {R.size} values (need 9) and "
            f"cam_t_m2c {t.size} (need 3); {_HELP}"
        )
    try:
        R = as_rotation_matrix(R.reshape(3, 3), atol=BOP_ROTATION_TOLERANCE)
    except ValueError as e:
        raise DatasetFormatError(
            f"{located(path)}: image {key}: cam_R_m2c is not a rotation ({e}); it must be "
            "row-major and orthonormal"
        ) from None
    if not np.isfinite(t).all():
        raise DatasetFormatError(f"{located(path)}: image {key}: cam_t_m2c is not finite")
    return _orthonormalise(R), t * 1e-3


def read_bop_scene_gt(
    path: str | Path, *, object_id: int | None = None, rate_hz: float = 30.0
) -> PoseSamples:
    """Reads the poses of one object from a BOP ``scene_gt.json``.

    Args:
        path: the JSON file, or a scene folder that contains ``scene_gt.json``.
        object_id: the ``obj_id`` to follow; may be omitted when only one object appears.
        rate_hz: camera rate [Hz]; image ``i`` is at ``i / rate_hz``.

    Returns:
        Samples of ``T_cam_obj`` [m] (camera frame).

    Raises:
        DatasetFormatError: missing file, invalid JSON (with its line), wrong structure, an
            object that appears twice in one image, a non-rotation ``cam_R_m2c``, or fewer
            than four poses; the message names the file and the image id.
        ConfigError: ``object_id`` is needed (several objects) or absent from the file.
    """
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ConfigError(f"sample_rate_hz must be positive, got {rate_hz}")
    path = Path(path)
    if path.is_dir():
        path = path / "scene_gt.json"
    entries = _scene_gt_entries(path)
    object_id = _followed_object(path, entries, object_id)
    image_ids, rotations, translations = [], [], []
    for key in sorted(entries):
        mine = [a for a in entries[key] if a["obj_id"] == object_id]
        if not mine:
            continue
        if len(mine) > 1:
            raise DatasetFormatError(
                f"{located(path)}: image {key} has {len(mine)} instances of obj_id {object_id}; "
                "a trajectory follows exactly one instance"
            )
        R, t = _annotation_pose(path, key, mine[0])
        image_ids.append(key)
        rotations.append(R)
        translations.append(t)
    if len(image_ids) < MIN_SPLINE_SAMPLES:
        raise DatasetFormatError(
            f"{located(path)}: obj_id {object_id} appears in {len(image_ids)} images; a "
            f"trajectory needs at least {MIN_SPLINE_SAMPLES}"
        )
    ids = np.array(image_ids, dtype=np.float64)
    return PoseSamples(
        t_s=(ids - ids[0]) / rate_hz,
        T_ref_obj=transform_from_rt(np.array(rotations), np.array(translations)),
        source=f"{path} obj_id {object_id}",
        camera_frame=True,
    )
