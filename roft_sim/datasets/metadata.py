"""The ``metadata.json`` written beside every sequence: conventions, versions, sets, user data.

Determinism: metadata holds package versions but never a wall-clock time, a host name or a
random id, so the same inputs give byte-identical files (JSON with sorted keys, fixed indent).
"""

from __future__ import annotations

import json
import platform
from collections.abc import Mapping
from importlib import metadata as importlib_metadata
from pathlib import Path
from typing import Any

import numpy as np

from roft_sim.config_files import jsonable
from roft_sim.errors import DatasetFormatError, located

__all__ = [
    "FORMAT_VERSION",
    "COMMON_CONVENTIONS",
    "package_versions",
    "dumps_json",
    "read_json",
]

FORMAT_VERSION = "1.0"
"""Version of the on-disk layouts described in docs/formats.md (all three formats)."""

COMMON_CONVENTIONS: dict[str, str] = {
    "units": "SI: metres, radians, seconds (BOP files keep BOP's millimetres where BOP says so)",
    "camera_frame": "OpenCV optical frame: x right, y down, z forward; pinhole K, no distortion",
    "pixels": "(u, v) = (column, row); the centre of pixel (column i, row j) is at (i, j)",
    "object_pose": "T_cam_obj: pose of the object frame in the camera frame, p_cam = R p_obj + t",
    "camera_pose": "T_world_cam: pose of the camera in the world (identity = static camera)",
    "velocity": (
        "v_obj [m/s] = d/dt of t_cam_obj (velocity of the object origin) and w [rad/s] with "
        "dR_cam_obj/dt = [w]x R_cam_obj, both in the camera frame; ROFT's spatial velocity is "
        "v_o = v_obj - w x t_cam_obj"
    ),
    "flow": (
        "F_k maps pixels of frame k-1 to frame k: a pixel at p in frame k-1 is at p + F_k(p) in "
        "frame k; (du, dv) in full-resolution px; on a grid of g px the vector of pixel (u, v) "
        "is F[v // g, u // g]; there is no flow for frame 0"
    ),
    "depth": "z-depth along the optical axis [m], 0 = no measurement",
    "masks": "stored 0/255 (read as value > 1); a detector miss has no mask",
    "time": "t_k [s] per frame; k / fps for a clean camera",
}


def package_versions(*extra: str) -> dict[str, str]:
    """Versions of Python and the packages that shape the files (no times, no host names)."""
    import cv2

    versions = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "opencv": cv2.__version__,
    }
    for name in ("roft-sim", "isal", *extra):  # isal: the PNG files' deflate
        try:
            versions[name] = importlib_metadata.version(name)
        except importlib_metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def dumps_json(data: Mapping[str, Any]) -> str:
    """Deterministic JSON text (sorted keys, 2-space indent, trailing newline, no NaN).

    Raises:
        ValueError: the data holds NaN/inf or values JSON cannot represent.
    """
    try:
        return json.dumps(jsonable(data), indent=2, sort_keys=True, allow_nan=False) + "\n"
    except (TypeError, ValueError) as e:
        raise ValueError(f"metadata is not JSON-serialisable without NaN/inf: {e}") from None


def read_json(path: str | Path, what: str) -> Any:
    """Parses a JSON file; a missing file or bad JSON raises DatasetFormatError naming it."""
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except FileNotFoundError:
        raise DatasetFormatError(f"{what} file {located(path)} is missing") from None
    except UnicodeDecodeError:
        raise DatasetFormatError(f"{what} file {located(path)} is not UTF-8 text") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise DatasetFormatError(
            f"{what} file {located(path, e.lineno)} is not valid JSON: {e.msg}"
        ) from None
