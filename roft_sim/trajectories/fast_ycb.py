"""Reader for Fast-YCB ground-truth object poses (``gt/poses.txt``).

One pose per line and frame, ``x y z ax ay az angle``: the object origin in the camera frame
[m], then a unit rotation axis and the angle [rad] LAST (axis-angle, not a quaternion), meaning
``p_cam = R p_obj + t``. Frame ``k`` is at ``t = k / rate`` (Fast-YCB: 30 fps). A row of seven
zeros marks a missing detection in ``dope/poses.txt`` and is rejected here: a trajectory needs
a pose on every frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from roft_sim.errors import ConfigError, DatasetFormatError, located
from roft_sim.geometry.se3 import transform_from_rt
from roft_sim.geometry.so3 import matrix_from_axis_angle
from roft_sim.trajectories.samples import PoseSamples
from roft_sim.trajectories.spline import MIN_SPLINE_SAMPLES
from roft_sim.trajectories.tum import FILE_QUAT_NORM_TOLERANCE

__all__ = ["read_fast_ycb_poses", "FAST_YCB_RATE_HZ"]

FAST_YCB_RATE_HZ = 30.0
"""Frame rate of the Fast-YCB sequences [Hz]."""

_HELP = "each line must be 'x y z ax ay az angle' (metres, unit axis, angle in radians last)"


def read_fast_ycb_poses(path: str | Path, *, rate_hz: float = FAST_YCB_RATE_HZ) -> PoseSamples:
    """Reads Fast-YCB object poses.

    Args:
        path: a ``poses.txt`` file, or a sequence folder (``<folder>/gt/poses.txt`` is read).
        rate_hz: camera rate [Hz]; frame k is at ``k / rate_hz``.

    Returns:
        Samples of ``T_cam_obj`` (camera frame).

    Raises:
        DatasetFormatError: missing file, wrong field count, a value that is not a finite
            number, an axis that is not unit length, an all-zero row, or fewer than four poses;
            the message names the file and line.
    """
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ConfigError(f"sample_rate_hz must be positive, got {rate_hz}")
    path = Path(path)
    if path.is_dir():
        path = path / "gt" / "poses.txt"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise DatasetFormatError(
            f"Fast-YCB pose file {located(path)} does not exist; give gt/poses.txt or the "
            "sequence folder"
        ) from None
    except UnicodeDecodeError as e:
        raise DatasetFormatError(
            f"{located(path)} is not a UTF-8 text file ({e}); {_HELP}"
        ) from None
    rows: list[list[float]] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        fields = line.split()
        if len(fields) != 7:
            raise DatasetFormatError(
                f"{located(path, number)}: {len(fields)} fields, expected 7 (truncated line?); "
                f"{_HELP}"
            )
        try:
            values = [float(f) for f in fields]
        except ValueError:
            raise DatasetFormatError(
                f"{located(path, number)}: {line[:80]!r} has a field that is not a number; {_HELP}"
            ) from None
        if not np.isfinite(values).all():
            raise DatasetFormatError(
                f"{located(path, number)}: NaN or infinite value in {line[:80]!r}; repair the line"
            )
        if not any(values):
            raise DatasetFormatError(
                f"{located(path, number)}: a row of seven zeros marks a missing detection "
                "(dope/poses.txt); read the ground truth gt/poses.txt, which has a pose on "
                "every frame"
            )
        axis_norm = float(np.linalg.norm(values[3:6]))
        if abs(axis_norm - 1.0) > FILE_QUAT_NORM_TOLERANCE:
            raise DatasetFormatError(
                f"{located(path, number)}: rotation axis {values[3:6]} has length "
                f"{axis_norm:.6g}, not 1 within {FILE_QUAT_NORM_TOLERANCE:g}; {_HELP}"
            )
        rows.append(values)
    if len(rows) < MIN_SPLINE_SAMPLES:
        raise DatasetFormatError(
            f"{located(path)} holds {len(rows)} poses; a trajectory needs at least "
            f"{MIN_SPLINE_SAMPLES}; {_HELP}"
        )
    data = np.array(rows)
    return PoseSamples(
        t_s=np.arange(len(rows)) / rate_hz,
        T_ref_obj=transform_from_rt(matrix_from_axis_angle(data[:, 3:]), data[:, :3]),
        source=str(path),
        camera_frame=True,
    )
