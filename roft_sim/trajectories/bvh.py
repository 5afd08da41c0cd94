"""Reader for BVH (Biovision hierarchy) motion capture, with forward kinematics.

A BVH file has a ``HIERARCHY`` section (joints with ``OFFSET x y z`` from their parent and
``CHANNELS n name...``; ``End Site`` blocks carry only an offset) and a ``MOTION`` section
(``Frames: n``, ``Frame Time: dt``, then one line of channel values per frame, in the order
the channels are declared, depth first).

Forward kinematics, as in the BVH convention: a joint's pose in its parent is the translation
by its OFFSET followed by its channels applied in the listed order, ``Xposition`` etc. as
translations in file units and ``Xrotation`` etc. as rotations about the current axes in
DEGREES; so ``CHANNELS 3 Zrotation Yrotation Xrotation`` gives ``R = Rz Ry Rx``. Root position
channels are therefore added to the root's OFFSET. The world frame is the file's: +y up.

Units: BVH files carry none. ``unit="auto"`` picks metres, centimetres, inches or millimetres by
the skeleton's size (see :func:`detect_bvh_unit`).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError, DatasetFormatError, located
from roft_sim.geometry.se3 import invert_transform
from roft_sim.trajectories.samples import PoseSamples
from roft_sim.trajectories.spline import MIN_SPLINE_SAMPLES

F64 = NDArray[np.float64]

__all__ = [
    "BvhJoint",
    "BvhMotion",
    "BvhUnit",
    "BVH_UNIT_METRES",
    "read_bvh",
    "detect_bvh_unit",
    "bvh_pose_samples",
]

BvhUnit = Literal["auto", "m", "cm", "mm", "in"]

BVH_UNIT_METRES: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254}
"""Metres per file unit."""

_REFERENCE_CHAIN_M = 1.0
"""Length of the longest root-to-end chain of an adult human skeleton [m] (hip to toe tip or
finger tip is 0.9-1.3 m); unit detection picks the unit that brings a file closest to it."""

_AXES = {"x": 0, "y": 1, "z": 2}


@dataclass(frozen=True, slots=True)
class BvhJoint:
    """One joint of the hierarchy (End Sites are not joints; their offsets are kept)."""

    name: str
    parent: int
    """Index of the parent joint, -1 for the root."""
    offset: F64
    """(3,) offset from the parent joint, parent frame [file units]."""
    channels: tuple[str, ...]
    """Channel names as declared, e.g. ``('Zrotation', 'Yrotation', 'Xrotation')``."""
    first_column: int
    """Column of the joint's first channel in a motion line."""
    end_offsets: tuple[F64, ...] = ()
    """(3,) offsets of the End Sites below this joint [file units]."""


@dataclass(frozen=True, slots=True)
class BvhMotion:
    """A parsed BVH file, with lengths already converted to metres."""

    path: Path
    joints: tuple[BvhJoint, ...]
    """Joints in file order (parents before children); offsets in METRES."""
    values: F64
    """(F, C) channel values per frame: positions in METRES, rotations in degrees."""
    frame_time_s: float
    """Time between frames [s] (``1/fps`` exactly when the file's value is ``1/fps`` rounded to
    its printed digits, e.g. 0.016667 -> 1/60)."""
    unit: str
    """The file's length unit, one of ``m``, ``cm``, ``mm``, ``in``."""

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)

    @property
    def num_frames(self) -> int:
        return int(self.values.shape[0])

    def joint_index(self, name: str) -> int:
        """Index of the joint called ``name``.

        Raises:
            ConfigError: no such joint; the message lists the available joints.
        """
        for i, joint in enumerate(self.joints):
            if joint.name == name:
                return i
        names = self.joint_names
        close = difflib.get_close_matches(name, names, n=3)
        hint = f"did you mean {', '.join(repr(c) for c in close)}? " if close else ""
        raise ConfigError(
            f"BVH file {located(self.path)} has no joint {name!r}; {hint}available joints: "
            f"{', '.join(names)}"
        )

    def global_transforms(self, name: str) -> F64:
        """Pose ``T_world_joint`` of joint ``name`` in every frame, ``(F, 4, 4)`` [m]."""
        chain = []
        i = self.joint_index(name)
        while i >= 0:
            chain.append(i)
            i = self.joints[i].parent
        T = np.broadcast_to(np.eye(4), (self.num_frames, 4, 4)).copy()
        for i in reversed(chain):
            T = T @ self._local_transforms(self.joints[i])
        return T

    def _local_transforms(self, joint: BvhJoint) -> F64:
        n = self.num_frames
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        T[:, :3, 3] = joint.offset
        for k, channel in enumerate(joint.channels):
            value = self.values[:, joint.first_column + k]
            axis = _AXES[channel[0].lower()]
            step = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
            if channel[1:].lower() == "position":
                step[:, axis, 3] = value
            else:
                angle = np.radians(value)
                c, s = np.cos(angle), np.sin(angle)
                a, b = [(1, 2), (2, 0), (0, 1)][axis]
                step[:, a, a] = c
                step[:, a, b] = -s
                step[:, b, a] = s
                step[:, b, b] = c
            T = T @ step
        return T


def detect_bvh_unit(chain_length: float) -> str:
    """The unit (``m``, ``cm``, ``in``, ``mm``) in which a skeleton whose longest root-to-end
    chain measures ``chain_length`` file units is closest (in log scale) to a human's 1 m.

    Boundaries: below 6.3 -> m, 6.3-62.7 -> in, 62.7-316 -> cm, above -> mm.
    """
    if not (np.isfinite(chain_length) and chain_length > 0):
        raise ValueError(f"chain length must be positive, got {chain_length}")
    return min(
        BVH_UNIT_METRES,
        key=lambda u: abs(np.log(chain_length * BVH_UNIT_METRES[u] / _REFERENCE_CHAIN_M)),
    )


class _Tokens:
    """Whitespace tokens of the HIERARCHY section with their line numbers."""

    def __init__(self, path: Path, lines: list[str], end_line: int) -> None:
        self.path = path
        self.items = [
            (tok, number)
            for number, line in enumerate(lines[:end_line], start=1)
            for tok in line.split()
        ]
        self.pos = 0

    def next(self, expected: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            last = self.items[-1][1] if self.items else 1
            raise DatasetFormatError(
                f"{located(self.path, last)}: HIERARCHY ends early, expected {expected}; the "
                "file is truncated or braces are unbalanced"
            )
        item = self.items[self.pos]
        self.pos += 1
        return item

    def expect(self, word: str) -> int:
        tok, line = self.next(repr(word))
        if tok != word:
            raise DatasetFormatError(
                f"{located(self.path, line)}: expected {word!r}, found {tok!r}; check the "
                "HIERARCHY syntax (ROOT/JOINT name { OFFSET x y z CHANNELS n ... })"
            )
        return line

    def number(self, what: str) -> float:
        tok, line = self.next(what)
        try:
            value = float(tok)
        except ValueError:
            raise DatasetFormatError(
                f"{located(self.path, line)}: {what} {tok!r} is not a number"
            ) from None
        if not np.isfinite(value):
            raise DatasetFormatError(f"{located(self.path, line)}: {what} is {tok}; need finite")
        return value


def _parse_joint(
    tokens: _Tokens, name: str, parent: int, joints: list[dict[str, Any]], column: list[int]
) -> None:
    path = tokens.path
    tokens.expect("{")
    tokens.expect("OFFSET")
    offset = np.array([tokens.number("OFFSET value") for _ in range(3)])
    tok, line = tokens.next("CHANNELS")
    if tok != "CHANNELS":
        raise DatasetFormatError(
            f"{located(path, line)}: joint {name!r} needs 'CHANNELS n ...' after OFFSET, found "
            f"{tok!r}"
        )
    count_tok, line = tokens.next("channel count")
    if not count_tok.isdigit():
        raise DatasetFormatError(
            f"{located(path, line)}: channel count {count_tok!r} of joint {name!r} is not an "
            "integer"
        )
    channels = []
    for _ in range(int(count_tok)):
        ch, line = tokens.next("channel name")
        if (
            len(ch) < 2
            or ch[0].lower() not in _AXES
            or ch[1:].lower()
            not in (
                "position",
                "rotation",
            )
        ):
            raise DatasetFormatError(
                f"{located(path, line)}: unknown channel {ch!r} of joint {name!r}; expected "
                "Xposition, Yposition, Zposition, Xrotation, Yrotation or Zrotation"
            )
        channels.append(ch)
    index = len(joints)
    joints.append(
        {
            "name": name,
            "parent": parent,
            "offset": offset,
            "channels": tuple(channels),
            "first_column": column[0],
            "end_offsets": [],
        }
    )
    column[0] += len(channels)
    while True:
        tok, line = tokens.next("JOINT, End Site or '}'")
        if tok == "}":
            return
        if tok == "JOINT":
            child, _ = tokens.next("joint name")
            _parse_joint(tokens, child, index, joints, column)
        elif tok == "End":
            tokens.expect("Site")
            tokens.expect("{")
            tokens.expect("OFFSET")
            joints[index]["end_offsets"].append(
                np.array([tokens.number("End Site OFFSET value") for _ in range(3)])
            )
            tokens.expect("}")
        else:
            raise DatasetFormatError(
                f"{located(path, line)}: expected JOINT, End Site or '}}' inside joint "
                f"{name!r}, found {tok!r}"
            )


def _longest_chain(joints: list[dict[str, Any]]) -> float:
    depth = np.zeros(len(joints))
    best = 0.0
    for i, j in enumerate(joints):
        depth[i] = (depth[j["parent"]] if j["parent"] >= 0 else 0.0) + float(
            np.linalg.norm(j["offset"]) if j["parent"] >= 0 else 0.0
        )
        ends = [float(np.linalg.norm(e)) for e in j["end_offsets"]] or [0.0]
        best = max(best, depth[i] + max(ends))
    return best


def _bvh_lines(path: Path) -> list[str]:
    """The file's lines; a missing file, a folder or a non-UTF-8 file raises naming it."""
    try:
        return path.read_text(encoding="utf-8", errors="strict").splitlines()
    except FileNotFoundError:
        raise DatasetFormatError(
            f"BVH file {located(path)} does not exist; check the path"
        ) from None
    except IsADirectoryError:
        raise DatasetFormatError(
            f"{located(path)} is a folder; give the .bvh file itself"
        ) from None
    except UnicodeDecodeError as e:
        raise DatasetFormatError(f"{located(path)} is not a UTF-8 text file ({e})") from None


def _bvh_hierarchy(
    path: Path, lines: list[str], motion_line: int
) -> tuple[list[dict[str, Any]], int]:
    """The joints of the HIERARCHY section (one ROOT) and the number of MOTION columns."""
    tokens = _Tokens(path, lines, motion_line)
    tokens.expect("HIERARCHY")
    tokens.expect("ROOT")
    root, _ = tokens.next("root name")
    joints: list[dict[str, Any]] = []
    column = [0]
    _parse_joint(tokens, root, -1, joints, column)
    if tokens.pos != len(tokens.items):
        tok, line = tokens.items[tokens.pos]
        raise DatasetFormatError(
            f"{located(path, line)}: unexpected {tok!r} after the root joint's closing brace "
            "(only one ROOT is supported)"
        )
    return joints, column[0]


def _bvh_motion_header(path: Path, lines: list[str], motion_line: int) -> tuple[int, float]:
    """``Frames:`` and ``Frame Time:`` [s] after MOTION; a frame time printed with few digits
    (0.0083333) snaps to the exact 1 / fps it rounds."""

    def header(offset: int, prefix: str) -> str:
        number = motion_line + offset
        text = lines[number].strip() if number < len(lines) else ""
        if not text.startswith(prefix):
            raise DatasetFormatError(
                f"{located(path, number + 1)}: expected '{prefix} ...' after MOTION, found "
                f"{text[:40]!r}"
            )
        return text[len(prefix) :].strip()

    frames_text, frame_time_text = header(1, "Frames:"), header(2, "Frame Time:")
    try:
        n_frames = int(frames_text)
        frame_time = float(frame_time_text)
    except ValueError:
        raise DatasetFormatError(
            f"{located(path, motion_line + 2)}: 'Frames: {frames_text}' / 'Frame Time: "
            f"{frame_time_text}' must be an integer and a number"
        ) from None
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise DatasetFormatError(
            f"{located(path, motion_line + 3)}: Frame Time must be positive, got {frame_time}"
        )
    fps = round(1.0 / frame_time)
    decimals = len(frame_time_text.split(".")[1]) if "." in frame_time_text else 0
    if fps > 0 and abs(frame_time - 1.0 / fps) <= 0.5 * 10.0**-decimals:
        frame_time = 1.0 / fps
    return n_frames, frame_time


def _bvh_motion_values(
    path: Path, lines: list[str], motion_line: int, n_columns: int, n_frames: int
) -> NDArray[np.float64]:
    """The ``(n_frames, n_columns)`` channel values of the MOTION lines, in the file's units."""
    first_data = motion_line + 3
    data_lines = [(i, s) for i, s in enumerate(lines[first_data:], start=first_data) if s.strip()]
    values = np.empty((len(data_lines), n_columns))
    for k, (i, s) in enumerate(data_lines):
        fields = s.split()
        if len(fields) != n_columns:
            raise DatasetFormatError(
                f"{located(path, i + 1)}: frame {k} has {len(fields)} values, the hierarchy "
                f"declares {n_columns} channels (truncated line?); each MOTION line needs one "
                "value per channel"
            )
        try:
            values[k] = [float(f) for f in fields]
        except ValueError:
            raise DatasetFormatError(
                f"{located(path, i + 1)}: frame {k} has a value that is not a number"
            ) from None
        if not np.isfinite(values[k]).all():
            raise DatasetFormatError(
                f"{located(path, i + 1)}: frame {k} contains NaN or inf; repair or cut the frame"
            )
    if len(data_lines) != n_frames:
        raise DatasetFormatError(
            f"{located(path, motion_line + 2)}: 'Frames: {n_frames}' but {len(data_lines)} frame "
            "lines follow (truncated file?); fix the count or restore the missing lines"
        )
    return values


def _joints_in_metres(
    path: Path, joints: list[dict[str, Any]], values: NDArray[np.float64], unit: BvhUnit
) -> tuple[tuple[BvhJoint, ...], str]:
    """The joints with offsets in metres and the unit used (detected for ``"auto"``); scales
    the position channels of ``values`` in place."""
    if unit == "auto":
        chain = _longest_chain(joints)
        if chain <= 0:
            raise DatasetFormatError(
                f"{located(path)}: all offsets are zero, so the unit cannot be detected; "
                "give the unit explicitly (bvh_unit)"
            )
        unit = detect_bvh_unit(chain)  # type: ignore[assignment]
    scale = BVH_UNIT_METRES[unit]
    built = []
    for j in joints:
        built.append(
            BvhJoint(
                name=j["name"],
                parent=j["parent"],
                offset=j["offset"] * scale,
                channels=j["channels"],
                first_column=j["first_column"],
                end_offsets=tuple(e * scale for e in j["end_offsets"]),
            )
        )
        for k, ch in enumerate(j["channels"]):
            if ch[1:].lower() == "position":
                values[:, j["first_column"] + k] *= scale
    return tuple(built), unit


def read_bvh(path: str | Path, *, unit: BvhUnit = "auto") -> BvhMotion:
    """Parses a BVH file.

    Args:
        path: the ``.bvh`` file.
        unit: the file's length unit, or ``"auto"`` to detect it (:func:`detect_bvh_unit`).

    Raises:
        DatasetFormatError: missing file, syntax errors in the hierarchy, a motion line with the
            wrong number of values, a value that is not a finite number, or a frame count that
            differs from ``Frames:``; the message names the file and line.
        ConfigError: an unknown ``unit``.
    """
    path = Path(path)
    if unit != "auto" and unit not in BVH_UNIT_METRES:
        raise ConfigError(f"bvh unit {unit!r} is not one of auto, {', '.join(BVH_UNIT_METRES)}")
    lines = _bvh_lines(path)
    motion_line = next((i for i, s in enumerate(lines) if s.strip() == "MOTION"), None)
    if motion_line is None:
        raise DatasetFormatError(
            f"{located(path)} has no MOTION line; a BVH file needs HIERARCHY and MOTION sections"
        )
    joints, n_columns = _bvh_hierarchy(path, lines, motion_line)
    n_frames, frame_time = _bvh_motion_header(path, lines, motion_line)
    values = _bvh_motion_values(path, lines, motion_line, n_columns, n_frames)
    built, unit_used = _joints_in_metres(path, joints, values, unit)
    return BvhMotion(
        path=path, joints=built, values=values, frame_time_s=frame_time, unit=unit_used
    )


def bvh_pose_samples(
    motion: BvhMotion, joint: str, *, relative_to: str | None = None
) -> PoseSamples:
    """Poses of one joint in every frame, optionally relative to another joint.

    Args:
        motion: a parsed file.
        joint: joint to follow, e.g. ``CC_Base_L_Hand``.
        relative_to: optional joint (e.g. ``CC_Base_Pelvis``) whose motion is removed: the
            result is ``T_world_rel(0) @ inv(T_world_rel(t)) @ T_world_joint(t)``, the joint's
            motion relative to that joint, shown as if that joint stayed at its first-frame pose
            (so "up" is still +y).

    Raises:
        ConfigError: unknown joint names (the message lists the available ones).
        DatasetFormatError: fewer than four frames.
    """
    T = motion.global_transforms(joint)
    source = f"{motion.path} joint {joint}"
    if relative_to is not None:
        T_rel = motion.global_transforms(relative_to)
        T = T_rel[0] @ invert_transform(T_rel) @ T
        source += f" relative to {relative_to}"
    if motion.num_frames < MIN_SPLINE_SAMPLES:
        raise DatasetFormatError(
            f"{located(motion.path)} has {motion.num_frames} frames; a trajectory needs at "
            f"least {MIN_SPLINE_SAMPLES}"
        )
    return PoseSamples(
        t_s=np.arange(motion.num_frames, dtype=np.float64) * motion.frame_time_s,
        T_ref_obj=T,
        source=source,
        up_ref=np.array([0.0, 1.0, 0.0]),
    )
