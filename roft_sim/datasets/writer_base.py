"""Machinery shared by the three streaming writers: settings, per-frame records, resume, finalize.

Every writer works the same way:

1. :meth:`StreamingWriter.__init__` creates ``<sequence>/.roft_sim_parts/`` (HDF5: a
   ``<name>.h5.parts/`` folder beside the file) holding ``writer.json`` (the settings, compared on
   resume) and writes the object model.
2. :meth:`~StreamingWriter.write_frame` writes the frame's images atomically, then, last, the
   frame's small record ``frame_<k>.json`` (times, poses, which sets it holds). A frame counts as
   complete exactly when its record exists, so a crash never leaves a half frame counted.
3. :meth:`~StreamingWriter.finalize` checks that every frame is there and consistent, assembles
   the per-sequence files from the records, writes ``metadata.json``, removes temp files and the
   parts folder.

Writers hold no open files and pickle, so worker processes can share one (distinct frames).
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from roft_sim.config_files import jsonable
from roft_sim.datasets.atomic_files import atomic_write_text, remove_temp_files
from roft_sim.datasets.frames import FLOW_ENCODINGS, DatasetFrame, check_set_name
from roft_sim.datasets.image_files import PNG_COMPRESSION, check_png_compression
from roft_sim.datasets.metadata import (
    COMMON_CONVENTIONS,
    FORMAT_VERSION,
    dumps_json,
    package_versions,
    read_json,
)
from roft_sim.errors import ConfigError, DatasetFormatError, located
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import ObjectModel

__all__ = [
    "WriterSettings",
    "StreamingWriter",
    "format_frame_ranges",
    "visible_fraction_stats",
    "RESERVED_METADATA_KEYS",
]

RESERVED_METADATA_KEYS = frozenset(
    {
        "format",
        "format_version",
        "sequence_name",
        "object_name",
        "n_frames",
        "fps",
        "intrinsics",
        "sets",
        "ground_truth",
        "ground_truth_visibility",
        "conventions",
        "package_versions",
        "format_options",
        "object_model",
    }
)
"""Top-level ``metadata.json`` keys the writers own; user metadata may not use them."""

_RECORD = re.compile(r"^frame_(\d+)\.json$")


def format_frame_ranges(frames: list[int] | set[int]) -> str:
    """``[1, 2, 3, 7]`` -> ``'1-3, 7'`` (for messages)."""
    out: list[str] = []
    for k in sorted(frames):
        if out and out[-1].split("-")[-1] == str(k - 1):
            out[-1] = out[-1].split("-")[0] + f"-{k}"
        else:
            out.append(str(k))
    return ", ".join(out)


@dataclass(frozen=True, slots=True, kw_only=True)
class WriterSettings:
    """What a writer was opened with; stored in ``writer.json`` and checked on resume."""

    format: str
    sequence_name: str
    object_name: str
    intrinsics: CameraIntrinsics
    fps: int
    n_frames: int
    metadata: Mapping[str, Any] = field(default_factory=dict)
    flow_encodings: Mapping[str, str] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)
    model_digest: str | None = None
    png_compression: int = PNG_COMPRESSION
    """zlib level 0-9 of the sequence's PNG files (fast-ycb, bop); part of the settings so that a
    resumed sequence is written with the level it was started with."""

    def __post_init__(self) -> None:
        if not re.match(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$", self.sequence_name):
            raise ConfigError(
                f"sequence_name {self.sequence_name!r} must be a plain folder name (letters, "
                "digits, '_', '.', '-'), e.g. '003_cracker_box'"
            )
        if not self.object_name or "/" in self.object_name:
            raise ConfigError(f"object_name {self.object_name!r} must be a non-empty name")
        if isinstance(self.fps, bool) or not isinstance(self.fps, int) or self.fps <= 0:
            raise ConfigError(f"fps must be a positive integer, got {self.fps!r}")
        if isinstance(self.n_frames, bool) or not isinstance(self.n_frames, int):
            raise ConfigError(f"n_frames must be an integer, got {self.n_frames!r}")
        if self.n_frames <= 0:
            raise ConfigError(f"n_frames must be >= 1, got {self.n_frames}")
        for name, enc in self.flow_encodings.items():
            check_set_name("flow", name)
            if enc not in FLOW_ENCODINGS:
                raise ConfigError(
                    f"flow_encodings[{name!r}] = {enc!r}; expected one of {FLOW_ENCODINGS}"
                )
        clash = RESERVED_METADATA_KEYS & set(self.metadata)
        if clash:
            raise ConfigError(
                f"metadata keys {sorted(clash)} are written by the dataset writer itself; "
                "rename them (e.g. put them under 'scenario' or 'config')"
            )
        dumps_json(self.metadata)  # fails early on NaN or non-serialisable values
        check_png_compression(self.png_compression)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = jsonable(self)
        return out

    def flow_encoding(self, set_name: str) -> str:
        """Encoding of a flow set (``float32`` unless configured)."""
        return self.flow_encodings.get(set_name, "float32")


def visible_fraction_stats(values: list[float | None]) -> dict[str, float] | None:
    """Per-sequence statistics of the object's visible fraction (frames' values in [0, 1]):
    mean, min, 10th/50th/90th percentiles and the fractions of frames below 0.5 and at 0 (out of
    view or fully hidden); None unless every frame has a value."""
    if not values or any(v is None for v in values):
        return None
    v = np.asarray(values, dtype=np.float64)
    p10, p50, p90 = np.percentile(v, [10, 50, 90])
    return {
        "mean": round(float(v.mean()), 6),
        "min": round(float(v.min()), 6),
        "p10": round(float(p10), 6),
        "p50": round(float(p50), 6),
        "p90": round(float(p90), 6),
        "frames_below_half": round(float((v < 0.5).mean()), 6),
        "frames_hidden": round(float((v == 0).mean()), 6),
    }


def model_digest(model: ObjectModel | None) -> str | None:
    """SHA-256 of a model's arrays (to tell, on resume, whether the model changed)."""
    if model is None:
        return None
    h = hashlib.sha256(model.name.encode())
    for a in (model.vertices_m, model.faces, model.model_points_m):
        arr = np.ascontiguousarray(a)
        h.update(str(arr.dtype).encode() + str(arr.shape).encode() + arr.tobytes())
    return h.hexdigest()


class StreamingWriter(ABC):
    """Shared implementation of :class:`~roft_sim.datasets.SequenceWriter` (see module doc)."""

    FORMAT: ClassVar[str]

    def __init__(
        self,
        *,
        sequence_path: Path,
        parts_dir: Path,
        settings: WriterSettings,
        object_model: ObjectModel | None,
        resume: bool,
    ) -> None:
        self.sequence_path = sequence_path
        self.parts_dir = parts_dir
        self.settings = settings
        self._finalized = False
        settings_path = parts_dir / "writer.json"
        if self._is_finalized():
            if not resume:
                raise ConfigError(
                    f"{located(sequence_path)} already holds a finished sequence; choose another "
                    "output, delete it, or pass resume=True to keep it"
                )
            found = self._finished_n_frames()
            if found != settings.n_frames:
                raise ConfigError(
                    f"{located(sequence_path)} is a finished sequence of {found} frames, not "
                    f"{settings.n_frames}; choose another output"
                )
            self._finalized = True
            return
        if parts_dir.is_dir():
            if not resume:
                raise ConfigError(
                    f"{located(sequence_path)} holds an unfinished sequence; pass resume=True to "
                    "continue it, or delete it"
                )
            self._check_resume_settings(read_json(settings_path, "writer settings"))
        elif self._exists_non_empty():
            raise ConfigError(
                f"{located(sequence_path)} exists and is not an unfinished roft_sim sequence; "
                "choose an empty output"
            )
        else:
            parts_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(settings_path, dumps_json(settings.to_json()))
        if object_model is not None:
            self._write_model(object_model)

    # ----------------------------------------------------------------- format-specific hooks
    @abstractmethod
    def _write_frame_files(self, frame: DatasetFrame) -> dict[str, Any]:
        """Writes the frame's bulk files; returns extra record fields."""

    @abstractmethod
    def _assemble(
        self, records: Callable[[], Iterator[dict[str, Any]]], metadata: dict[str, Any]
    ) -> None:
        """Writes the per-sequence files from the frame records (``records()`` streams them in
        frame order, one at a time), and the metadata LAST: its presence marks the sequence
        finished."""

    @abstractmethod
    def _write_model(self, model: ObjectModel) -> None:
        """Writes the object model files."""

    @abstractmethod
    def _metadata_path(self) -> Path:
        """The file whose presence marks the sequence finished (``metadata.json``, or the
        ``.h5`` file)."""

    def _finished_n_frames(self) -> int | None:
        """Number of frames of the finished sequence on disk."""
        n_frames: int | None = read_json(self._metadata_path(), "metadata").get("n_frames")
        return n_frames

    def _format_conventions(self) -> dict[str, str]:
        return {}

    def _format_options(self) -> dict[str, Any]:
        return dict(self.settings.options)

    def _exists_non_empty(self) -> bool:
        p = self.sequence_path
        return p.exists() and (not p.is_dir() or any(p.iterdir()))

    def _is_finalized(self) -> bool:
        return self._metadata_path().is_file() and not self.parts_dir.exists()

    def _extra_package_names(self) -> tuple[str, ...]:
        return ()

    # ------------------------------------------------------------------------ public API
    def write_frame(self, frame: DatasetFrame) -> None:
        """Writes one frame atomically (images first, then its record). See the module doc."""
        if self._finalized or self._is_finalized():
            raise DatasetFormatError(
                f"{located(self.sequence_path)} is already finalized; frames cannot be added"
            )
        s = self.settings
        if not 0 <= frame.k < s.n_frames:
            raise ValueError(f"frame index {frame.k} is outside 0..{s.n_frames - 1}")
        frame.check_intrinsics(s.intrinsics)
        record = {
            "k": int(frame.k),
            "t_s": float(frame.t_s),
            "T_world_cam": frame.T_world_cam,
            "gt_T_cam_obj": frame.gt_T_cam_obj,
            "gt_v_obj_mps": frame.gt_v_obj_mps,
            "gt_w_radps": frame.gt_w_radps,
            "gt_mask": frame.gt_mask is not None,
            "gt_mask_full": frame.gt_mask_full is not None,
            "flows": {
                name: {"grid_px": f.grid_px, "valid": f.valid is not None}
                for name, f in sorted(frame.flows.items())
            },
            "detector_masks": {n: m is not None for n, m in sorted(frame.detector_masks.items())},
            "detector_poses": dict(sorted(frame.detector_poses.items())),
        }
        # Scene-side ground truth (clutter, visibility): only when given, so that records and
        # files of scenes without them stay as they were.
        if frame.gt_visible_fraction is not None:
            record["gt_visible_fraction"] = float(frame.gt_visible_fraction)
        if frame.gt_distractors:
            record["gt_distractors"] = [
                {"name": d.name, "T_cam_obj": d.T_cam_obj} for d in frame.gt_distractors
            ]
        record.update(self._write_frame_files(frame))
        self.parts_dir.mkdir(parents=True, exist_ok=True)
        atomic_write_text(self._record_path(frame.k), dumps_json(record))

    def completed_frames(self) -> set[int]:
        """Frames whose record exists (all frames once finalized)."""
        if self._finalized or self._is_finalized():
            return set(range(self.settings.n_frames))
        if not self.parts_dir.is_dir():
            return set()
        done = set()
        for name in os.listdir(self.parts_dir):  # strings: no per-frame Path objects
            m = _RECORD.match(name)
            if m and int(m.group(1)) < self.settings.n_frames:
                done.add(int(m.group(1)))
        return done

    def finalize(self) -> Path:
        """Checks completeness and consistency, assembles files, writes metadata, cleans up.

        Raises:
            DatasetFormatError: frames missing (named) or inconsistent between frames.
        """
        if self._finalized or self._is_finalized():
            self._finalized = True
            return self.sequence_path
        n = self.settings.n_frames
        missing = sorted(set(range(n)) - self.completed_frames())
        if missing:
            raise DatasetFormatError(
                f"cannot finalize {located(self.sequence_path)}: {len(missing)} of {n} frames "
                f"are missing ({format_frame_ranges(missing)}); write them (e.g. resume the "
                "generator) and finalize again"
            )
        summary = self._check_records(self._records())
        self._assemble(self._records, self._metadata(summary))
        remove_temp_files(self.sequence_path if self.sequence_path.is_dir() else self.parts_dir)
        shutil.rmtree(self.parts_dir)
        self._finalized = True
        return self.sequence_path

    # ------------------------------------------------------------------------ internals
    def _check_resume_settings(self, found: dict[str, Any]) -> None:
        want = dumps_json(self.settings.to_json())
        if dumps_json(found) != want:
            mine = self.settings.to_json()
            diff = sorted(k for k in set(found) | set(mine) if found.get(k) != mine.get(k))
            raise ConfigError(
                f"cannot resume {located(self.sequence_path)}: it was started with different "
                f"settings ({', '.join(diff)} differ); use the original settings or start over"
            )

    def _record_path(self, k: int) -> str:
        """Path of frame k's record (a string: see atomic_files.temp_path_for)."""
        return os.path.join(self.parts_dir, f"frame_{k:06d}.json")

    def _records(self) -> Iterator[dict[str, Any]]:
        """The frame records in frame order, read one at a time (flat memory)."""
        for k in range(self.settings.n_frames):
            yield read_json(self._record_path(k), "frame record")

    def _check_records(self, records: Iterator[dict[str, Any]]) -> dict[str, Any]:
        """Checks, in one streaming pass, that frames agree on what they hold; returns a summary
        for the metadata."""
        checks: dict[str, Any] = {
            "ground-truth poses": lambda r: r["gt_T_cam_obj"] is not None,
            "ground-truth velocities": lambda r: r["gt_v_obj_mps"] is not None,
            "ground-truth masks": lambda r: r["gt_mask"],
            "full ground-truth masks": lambda r: r["gt_mask_full"],
            "detector mask sets": lambda r: sorted(r["detector_masks"]),
            "detector pose sets": lambda r: sorted(r["detector_poses"]),
            "flow sets and grids": lambda r: {n: f["grid_px"] for n, f in r["flows"].items()},
        }
        first: dict[str, Any] = {}
        odd: dict[str, list[int]] = {key: [] for key in checks}
        previous_t = -np.inf
        visible: list[float | None] = []
        for r in records:
            k = r["k"]
            visible.append(r.get("gt_visible_fraction"))
            for key, value_of in checks.items():
                value = value_of(r)
                if key == "flow sets and grids" and k == 0:
                    continue  # frame 0 has no flow
                if key not in first:
                    first[key] = value
                elif value != first[key] and len(odd[key]) < 1000:
                    odd[key].append(k)
            if not r["t_s"] > previous_t:
                raise DatasetFormatError(
                    f"cannot finalize {located(self.sequence_path)}: time stamps must increase, "
                    f"but t[{k}] = {r['t_s']} after t[{k - 1}] = {previous_t}"
                )
            previous_t = r["t_s"]
        for key, frames in odd.items():
            if frames:
                where = "frame 1" if key == "flow sets and grids" else "frame 0"
                raise DatasetFormatError(
                    f"cannot finalize {located(self.sequence_path)}: frames disagree on {key} "
                    f"({where}: {first[key]!r}; different in frames {format_frame_ranges(frames)})"
                )
        flow_grids: dict[str, int] = first.get("flow sets and grids", {})
        unknown = set(self.settings.flow_encodings) - set(flow_grids)
        if unknown and self.settings.n_frames > 1:
            raise DatasetFormatError(
                f"cannot finalize {located(self.sequence_path)}: flow_encodings names sets "
                f"{sorted(unknown)} that no frame holds (frames hold {sorted(flow_grids)})"
            )
        return {
            "visibility": visible_fraction_stats(visible),
            "ground_truth": {
                "poses": first["ground-truth poses"],
                "velocities": first["ground-truth velocities"],
                "masks": first["ground-truth masks"],
                "full_masks": first["full ground-truth masks"],
            },
            "sets": {
                "flow": {
                    name: {"encoding": self.settings.flow_encoding(name), "grid_px": grid}
                    for name, grid in sorted(flow_grids.items())
                },
                "mask": first["detector mask sets"],
                "pose": first["detector pose sets"],
            },
        }

    def _metadata(self, summary: dict[str, Any]) -> dict[str, Any]:
        s = self.settings
        meta = dict(s.metadata)
        meta.update(
            {
                "format": self.FORMAT,
                "format_version": FORMAT_VERSION,
                "sequence_name": s.sequence_name,
                "object_name": s.object_name,
                "n_frames": s.n_frames,
                "fps": s.fps,
                "intrinsics": jsonable(s.intrinsics),
                "sets": summary["sets"],
                "ground_truth": summary["ground_truth"],
                "conventions": {**COMMON_CONVENTIONS, **self._format_conventions()},
                "package_versions": package_versions(*self._extra_package_names()),
                "format_options": self._format_options(),
                "object_model": s.model_digest is not None,
            }
        )
        if summary.get("visibility") is not None:
            meta["ground_truth_visibility"] = summary["visibility"]
        return meta
