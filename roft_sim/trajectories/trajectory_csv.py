"""The plain-CSV trajectory format: writer and reader.

Layout (UTF-8, comma separated, ``\\n`` line ends):

- optional comment lines starting with ``#`` (provenance);
- one header row whose first 14 names are exactly :data:`CSV_COLUMNS`
  ``t_s,x_m,y_m,z_m,qw,qx,qy,qz,vx_mps,vy_mps,vz_mps,wx_radps,wy_radps,wz_radps``; more
  columns may follow (this writer adds the accelerations :data:`CSV_EXTRA_COLUMNS`) and
  readers ignore them;
- one row per sample: time [s], object origin in the camera frame [m], the rotation as a unit
  quaternion SCALAR-FIRST (w, x, y, z) with ``w >= 0``, the object-origin velocity [m/s] and
  the angular velocity [rad/s], both in the camera frame (``dR/dt = [w]x R``).

Numbers are written with 17 significant digits, so a written file re-reads to the same
float64 values.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from roft_sim.errors import DatasetFormatError, located
from roft_sim.geometry.se3 import transform_from_pq
from roft_sim.geometry.so3 import quat_from_matrix
from roft_sim.records import PoseTrack
from roft_sim.trajectories.base import TrajectorySample
from roft_sim.trajectories.samples import PoseSamples
from roft_sim.trajectories.spline import MIN_SPLINE_SAMPLES
from roft_sim.trajectories.tum import FILE_QUAT_NORM_TOLERANCE

__all__ = [
    "CSV_COLUMNS",
    "CSV_EXTRA_COLUMNS",
    "write_trajectory_csv",
    "read_trajectory_csv",
    "csv_pose_samples",
]

CSV_COLUMNS = (
    "t_s",
    "x_m",
    "y_m",
    "z_m",
    "qw",
    "qx",
    "qy",
    "qz",
    "vx_mps",
    "vy_mps",
    "vz_mps",
    "wx_radps",
    "wy_radps",
    "wz_radps",
)
"""The 14 leading columns every trajectory CSV has, in this order."""

CSV_EXTRA_COLUMNS = (
    "ax_mps2",
    "ay_mps2",
    "az_mps2",
    "alphax_radps2",
    "alphay_radps2",
    "alphaz_radps2",
)
"""Columns :func:`write_trajectory_csv` appends: acceleration of the object origin [m/s^2] and
angular acceleration [rad/s^2], camera frame."""

_HELP = f"the header must start with {','.join(CSV_COLUMNS)}"


def write_trajectory_csv(
    path: str | Path, sample: TrajectorySample, *, comments: Iterable[str] = ()
) -> Path:
    """Writes a sampled trajectory as CSV (see the module docstring for the layout).

    Args:
        path: output file (its folder must exist).
        sample: the samples; ``T_ref_obj`` is written as ``T_cam_obj``.
        comments: lines written first, each prefixed with ``# ``.

    Returns:
        The path written.
    """
    path = Path(path)
    p = sample.T_ref_obj[:, :3, 3]
    q = quat_from_matrix(sample.T_ref_obj[:, :3, :3])
    table = np.column_stack(
        [sample.t_s, p, q, sample.v_mps, sample.w_radps, sample.a_mps2, sample.alpha_radps2]
    )
    table += 0.0  # writes -0.0 as 0
    with path.open("w", encoding="utf-8", newline="\n") as f:
        for line in comments:
            f.write(f"# {line}\n")
        f.write(",".join(CSV_COLUMNS + CSV_EXTRA_COLUMNS) + "\n")
        np.savetxt(f, table, fmt="%.17g", delimiter=",")
    return path


def _read_rows(path: Path) -> tuple[np.ndarray, list[int]]:
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        raise DatasetFormatError(
            f"CSV file {located(path)} does not exist; check the path"
        ) from None
    except IsADirectoryError:
        raise DatasetFormatError(
            f"{located(path)} is a folder; give the trajectory CSV file itself"
        ) from None
    except UnicodeDecodeError as e:
        raise DatasetFormatError(f"{located(path)} is not a UTF-8 text file ({e})") from None
    numbered = [
        (n, s.strip())
        for n, s in enumerate(lines, start=1)
        if s.strip() and not s.lstrip().startswith("#")
    ]
    if not numbered:
        raise DatasetFormatError(f"{located(path)} has no header row; {_HELP}")
    header_line, header = numbered[0]
    names = [c.strip() for c in header.split(",")]
    if tuple(names[: len(CSV_COLUMNS)]) != CSV_COLUMNS:
        raise DatasetFormatError(
            f"{located(path, header_line)}: header {header[:120]!r} is not a trajectory CSV "
            f"header; {_HELP}"
        )
    rows: list[list[float]] = []
    numbers: list[int] = []
    for number, line in numbered[1:]:
        fields = line.split(",")
        if len(fields) != len(names):
            raise DatasetFormatError(
                f"{located(path, number)}: {len(fields)} columns, the header has {len(names)} "
                "(truncated line?); every row needs one value per header column"
            )
        try:
            values = [float(f) for f in fields[: len(CSV_COLUMNS)]]
        except ValueError:
            raise DatasetFormatError(
                f"{located(path, number)}: {line[:80]!r} has a value that is not a number"
            ) from None
        if not np.isfinite(values).all():
            raise DatasetFormatError(
                f"{located(path, number)}: NaN or infinite value; repair or remove the row"
            )
        norm = float(np.linalg.norm(values[4:8]))
        if abs(norm - 1.0) > FILE_QUAT_NORM_TOLERANCE:
            raise DatasetFormatError(
                f"{located(path, number)}: quaternion (qw, qx, qy, qz) = {values[4:8]} has norm "
                f"{norm:.6g}, not 1 within {FILE_QUAT_NORM_TOLERANCE:g}; write unit quaternions, "
                "scalar first"
            )
        if rows and values[0] <= rows[-1][0]:
            raise DatasetFormatError(
                f"{located(path, number)}: t_s = {values[0]!r} does not increase (previous row "
                f"{rows[-1][0]!r}); sort the rows and drop duplicates"
            )
        rows.append(values)
        numbers.append(number)
    if not rows:
        raise DatasetFormatError(f"{located(path)} has a header but no rows")
    return np.array(rows), numbers


def read_trajectory_csv(path: str | Path) -> PoseTrack:
    """Reads a trajectory CSV exactly as stored: times, ``T_cam_obj``, ``v_obj`` and ``w``.

    Raises:
        DatasetFormatError: missing file, a wrong header, a row with the wrong number of
            columns, a non-number, NaN, a non-unit quaternion or non-increasing times; the
            message names the file and line.
    """
    path = Path(path)
    data, _ = _read_rows(path)
    q = data[:, 4:8] / np.linalg.norm(data[:, 4:8], axis=-1, keepdims=True)
    return PoseTrack(
        t_s=data[:, 0].copy(),
        T_cam_obj=transform_from_pq(data[:, 1:4], q),
        v_obj_mps=data[:, 8:11].copy(),
        w_radps=data[:, 11:14].copy(),
    )


def csv_pose_samples(path: str | Path) -> PoseSamples:
    """The poses of a trajectory CSV for spline replay (times shifted to start at 0).

    The stored velocities are not used: the replay derives them from the poses.

    Raises:
        DatasetFormatError: as :func:`read_trajectory_csv`, or fewer than four rows.
    """
    track = read_trajectory_csv(path)
    if len(track) < MIN_SPLINE_SAMPLES:
        raise DatasetFormatError(
            f"{located(path)} has {len(track)} rows; a trajectory needs at least "
            f"{MIN_SPLINE_SAMPLES}"
        )
    return PoseSamples(
        t_s=track.t_s - track.t_s[0],
        T_ref_obj=track.T_cam_obj,
        source=str(path),
        camera_frame=True,
    )
