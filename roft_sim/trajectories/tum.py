"""Reader for the TUM trajectory format.

One pose per line, ``timestamp tx ty tz qx qy qz qw``: time [s], position [m], a unit
quaternion SCALAR-LAST; fields separated by white space; lines starting with ``#`` and blank
lines are ignored. The pose is of the tracked body in the motion-capture world frame (TUM VI:
z up). Time stamps may be large (Unix epochs): they are parsed exactly as decimals and returned
relative to the first one.
"""

from __future__ import annotations

from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from roft_sim.errors import DatasetFormatError, located
from roft_sim.geometry.se3 import transform_from_pq
from roft_sim.geometry.so3 import quat_wxyz_from_xyzw
from roft_sim.trajectories.samples import PoseSamples
from roft_sim.trajectories.spline import MIN_SPLINE_SAMPLES

__all__ = ["read_tum", "TUM_COLUMNS", "FILE_QUAT_NORM_TOLERANCE"]

TUM_COLUMNS = ("timestamp_s", "tx_m", "ty_m", "tz_m", "qx", "qy", "qz", "qw")
"""The eight columns of a TUM trajectory line."""

FILE_QUAT_NORM_TOLERANCE = 1e-3
"""Largest accepted ``| |q| - 1 |`` of a quaternion read from a text file (files round to a few
decimals); quaternions within it are normalised, others are rejected."""

_HELP = "each line must be 'timestamp tx ty tz qx qy qz qw' (metres, unit quaternion, w last)"


def read_tum(path: str | Path) -> PoseSamples:
    """Reads a TUM trajectory file.

    Returns:
        Samples with ``t_s`` relative to the first time stamp, poses ``T_world_body``, up = +z.

    Raises:
        DatasetFormatError: missing file, a line with the wrong number of fields, a value that
            is not a finite number, a non-unit quaternion, non-increasing time stamps, or fewer
            than four poses; the message names the file and line.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DatasetFormatError(
            f"TUM file {located(path)} does not exist; check the path"
        ) from None
    except IsADirectoryError:
        raise DatasetFormatError(
            f"{located(path)} is a folder; give the TUM trajectory file itself"
        ) from None
    except UnicodeDecodeError as e:
        raise DatasetFormatError(
            f"{located(path)} is not a UTF-8 text file ({e}); {_HELP}"
        ) from None
    times: list[Decimal] = []
    rows: list[list[float]] = []
    line_numbers: list[int] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        fields = line.split()
        if len(fields) != len(TUM_COLUMNS):
            raise DatasetFormatError(
                f"{located(path, number)}: {len(fields)} fields, expected {len(TUM_COLUMNS)} "
                f"(truncated or not a TUM file?); {_HELP}"
            )
        try:
            stamp = Decimal(fields[0])
            values = [float(f) for f in fields[1:]]
        except (InvalidOperation, ValueError):
            raise DatasetFormatError(
                f"{located(path, number)}: {line[:80]!r} has a field that is not a number; {_HELP}"
            ) from None
        if not (stamp.is_finite() and np.isfinite(values).all()):
            raise DatasetFormatError(
                f"{located(path, number)}: NaN or infinite value in {line[:80]!r}; remove or "
                "repair the line"
            )
        norm = float(np.linalg.norm(values[3:]))
        if abs(norm - 1.0) > FILE_QUAT_NORM_TOLERANCE:
            raise DatasetFormatError(
                f"{located(path, number)}: quaternion (qx, qy, qz, qw) = {values[3:]} has norm "
                f"{norm:.6g}, not 1 within {FILE_QUAT_NORM_TOLERANCE:g}; {_HELP}"
            )
        if times and stamp <= times[-1]:
            raise DatasetFormatError(
                f"{located(path, number)}: time stamp {fields[0]} does not increase (previous "
                f"{times[-1]}, line {line_numbers[-1]}); sort the file and drop duplicates"
            )
        times.append(stamp)
        rows.append(values)
        line_numbers.append(number)
    if len(rows) < MIN_SPLINE_SAMPLES:
        raise DatasetFormatError(
            f"{located(path)} holds {len(rows)} poses; a trajectory needs at least "
            f"{MIN_SPLINE_SAMPLES}; {_HELP}"
        )
    t = np.array([float(s - times[0]) for s in times])
    data = np.array(rows)
    q = quat_wxyz_from_xyzw(data[:, 3:])
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return PoseSamples(
        t_s=t,
        T_ref_obj=transform_from_pq(data[:, :3], q),
        source=str(path),
        up_ref=np.array([0.0, 0.0, 1.0]),
    )
