"""The Fast-YCB layout (ROFT's dataset): streaming writer and lazy reader.

One folder per sequence (see docs/formats.md for every file)::

    cam_K.json  data.txt  rgb/<k>.png  depth/<k>.float  optical_flow/<set>/<k>.float (k >= 1)
    masks/gt/<object>_<k>.png  masks/<set>/<object>_<k>.png (miss = no file)
    <set>/poses.txt (e.g. dope/; miss = seven zeros)  gt/poses.txt  gt/velocities.txt
    metadata.json  models/<object>/{mesh.obj, points.xyz}          <- our additions
    masks/gt_full/<object>_<k>.png  optical_flow_valid/<set>/<k>.png <- our optional additions

The reader also reads the real Fast-YCB (string intrinsics, int16 S10.5 flow on a 4x4 grid,
measured time stamps, no ``gt/`` nor ``masks/gt/``, no metadata) and ROFT's HO-3D conversion.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.atomic_files import (
    AtomicTextFiles,
    atomic_write_bytes,
    atomic_write_text,
    remove_file,
)
from roft_sim.datasets.base import GT_MASK_SET, DetectorPoses
from roft_sim.datasets.fast_ycb_codec import (
    decode_cam_k_json,
    decode_depth_float,
    encode_cam_k_json,
    encode_data_txt_row,
    encode_depth_float,
    encode_flow_float,
    format_row,
    parse_rows,
    pose_row_from_transform,
    transforms_from_pose_rows,
)
from roft_sim.datasets.folder_writer import PARTS_DIR_NAME, FolderWriter, check_finished_folder
from roft_sim.datasets.frames import GT_FULL_MASK_SET, DatasetFrame
from roft_sim.datasets.image_files import (
    decode_png_mask,
    decode_png_rgb,
    encode_png_mask,
    encode_png_rgb,
    read_file_bytes,
)
from roft_sim.datasets.metadata import read_json
from roft_sim.datasets.model_files import (
    read_mesh_obj,
    read_points_xyz,
    write_mesh_obj,
    write_points_xyz,
)
from roft_sim.datasets.reader_base import (
    SequenceReaderBase,
    check_time_stamps,
    read_flow_field,
    subfolder_names,
)
from roft_sim.datasets.writer_base import WriterSettings
from roft_sim.errors import DatasetFormatError, located
from roft_sim.records import FlowField, ObjectModel, PoseTrack

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]

__all__ = ["FastYcbWriter", "FastYcbSequence", "is_fast_ycb_sequence", "PARTS_DIR_NAME"]

_NOT_POSE_SETS = {"gt", "rgb", "depth", "masks", "optical_flow", "optical_flow_valid", "models"}
_MASK_FILE = re.compile(r"^(.+)_(\d+)\.png$")
_ZERO_POSE_ROW = "0 0 0 0 0 0 0"


def is_fast_ycb_sequence(path: Path) -> bool:
    """True when ``path`` is a folder with ``cam_K.json`` and ``data.txt``."""
    return (path / "cam_K.json").is_file() and (path / "data.txt").is_file()


class FastYcbWriter(FolderWriter):
    """Streams one sequence into ``<root>/<sequence_name>/`` in the Fast-YCB layout.

    Use :func:`roft_sim.datasets.open_writer`; see :mod:`roft_sim.datasets.writer_base` for
    atomicity, resume and parallel use.
    """

    FORMAT = "fast-ycb"

    def __init__(
        self,
        root: Path,
        settings: WriterSettings,
        *,
        object_model: ObjectModel | None,
        resume: bool,
    ) -> None:
        super().__init__(
            Path(root) / settings.sequence_name, settings, object_model=object_model, resume=resume
        )

    def _mask_path(self, mask_set: str, k: int) -> str:
        return f"{self.sequence_path}/masks/{mask_set}/{self.settings.object_name}_{k}.png"

    def _write_frame_files(self, frame: DatasetFrame) -> dict[str, Any]:
        seq, k = self.sequence_path, frame.k
        png = self.settings.png_compression  # zlib level of every PNG of the frame
        atomic_write_bytes(f"{seq}/rgb/{k}.png", encode_png_rgb(frame.rgb, level=png))
        atomic_write_bytes(f"{seq}/depth/{k}.float", encode_depth_float(frame.depth_m))
        for name, flow in frame.flows.items():
            encoding = self.settings.flow_encoding(name)
            atomic_write_bytes(
                f"{seq}/optical_flow/{name}/{k}.float",
                encode_flow_float(flow.flow_px, encoding),
            )
            valid_path = f"{seq}/optical_flow_valid/{name}/{k}.png"
            if flow.valid is not None:
                atomic_write_bytes(valid_path, encode_png_mask(flow.valid, level=png))
            else:
                remove_file(valid_path)
        masks = {GT_MASK_SET: frame.gt_mask, GT_FULL_MASK_SET: frame.gt_mask_full}
        masks.update(frame.detector_masks)
        for name, mask in masks.items():
            path = self._mask_path(name, k)
            if mask is not None:
                atomic_write_bytes(path, encode_png_mask(mask, level=png))
            else:
                remove_file(path)
        return {}

    def _write_model(self, model: ObjectModel) -> None:
        folder = self.sequence_path / "models" / self.settings.object_name
        write_mesh_obj(folder / "mesh.obj", model.vertices_m, model.faces)
        write_points_xyz(folder / "points.xyz", model.model_points_m)

    def _format_conventions(self) -> dict[str, str]:
        return {
            "data_txt": "t_rgb t_depth x y z ax ay az angle: camera pose T_world_cam, axis-angle "
            "with a unit axis and the angle [rad] in [0, pi] LAST",
            "pose_rows": "<set>/poses.txt and gt/poses.txt: x y z ax ay az angle of T_cam_obj; "
            "a detector miss is a row of seven zeros",
            "velocity_rows": "gt/velocities.txt: vx vy vz wx wy wz = v_obj [m/s] and w [rad/s], "
            "camera frame (see 'velocity')",
            "depth_file": "depth/<k>.float: uint64 width, uint64 height, float32 metres "
            "row-major, little-endian",
            "flow_file": "optical_flow/<set>/<k>.float holds F_k: int32 cv_type (13 = CV_32FC2 "
            "float px, 11 = CV_16SC2 S10.5 = px * 32), uint64 cols, uint64 rows, interleaved "
            "(du, dv) row-major; grid = ceil(width / cols)",
            "flow_valid": "optional optical_flow_valid/<set>/<k>.png: 0/255 per flow cell, 255 = "
            "the vector is meaningful",
            "masks_gt_full": "optional masks/gt_full/: the object's full silhouette ignoring "
            "occluders",
            "model": "models/<object>/points.xyz: x y z [m] per model point; mesh.obj in metres, "
            "both in the object frame of the poses",
        }

    def _assemble(
        self, records: Callable[[], Iterator[dict[str, Any]]], metadata: dict[str, Any]
    ) -> None:
        seq, s = self.sequence_path, self.settings
        gt = metadata["ground_truth"]
        atomic_write_text(seq / "cam_K.json", encode_cam_k_json(s.intrinsics))
        with AtomicTextFiles() as out:
            for r in records():
                row_text = encode_data_txt_row(r["t_s"], np.asarray(r["T_world_cam"]))
                out.write(seq / "data.txt", row_text + "\n")
                if gt["poses"]:
                    row = pose_row_from_transform(np.asarray(r["gt_T_cam_obj"]))
                    out.write(seq / "gt" / "poses.txt", format_row(row) + "\n")
                if gt["velocities"]:
                    row = [*r["gt_v_obj_mps"], *r["gt_w_radps"]]
                    out.write(seq / "gt" / "velocities.txt", format_row(row) + "\n")
                for name in metadata["sets"]["pose"]:
                    T = r["detector_poses"][name]
                    row_text = (
                        _ZERO_POSE_ROW if T is None else format_row(pose_row_from_transform(T))
                    )
                    out.write(seq / name / "poses.txt", row_text + "\n")
        self._finish_folder(
            metadata,
            mask_set_dir=lambda name: seq / "masks" / name,
            flow_set_dir=lambda name: seq / "optical_flow" / name,
        )


class FastYcbSequence(SequenceReaderBase):
    """A Fast-YCB sequence folder read lazily (implements :class:`roft_sim.datasets.Sequence`).

    Images are read frame by frame; text files (poses, velocities) are read whole on first use.

    Args:
        path: the sequence folder (holds ``cam_K.json`` and ``data.txt``).
        object_name: the object's name as used in mask file names; by default taken from
            ``metadata.json``, else from the mask file names, else the folder name.
        fps: nominal rate [Hz]; by default from ``metadata.json``, else from the median time
            step of ``data.txt``.

    Raises:
        DatasetFormatError: a missing or malformed ``cam_K.json`` / ``data.txt`` /
            ``metadata.json``.
    """

    def __init__(
        self, path: str | Path, *, object_name: str | None = None, fps: int | None = None
    ) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise DatasetFormatError(f"Fast-YCB sequence folder {located(self.path)} is missing")
        check_finished_folder(self.path)
        cam_k = self.path / "cam_K.json"
        self._intrinsics = decode_cam_k_json(
            read_file_bytes(cam_k, "intrinsics").decode("utf-8", errors="replace"), cam_k
        )
        meta_path = self.path / "metadata.json"
        self._metadata: dict[str, Any] = (
            read_json(meta_path, "metadata") if meta_path.is_file() else {}
        )
        if not isinstance(self._metadata, dict):
            raise DatasetFormatError(f"{located(meta_path)} must hold a JSON object")
        data_path = self.path / "data.txt"
        rows = parse_rows(self._read_text(data_path, "data.txt"), data_path, 9)
        if len(rows) == 0:
            raise DatasetFormatError(f"{located(data_path)} has no rows (one per frame expected)")
        self._t_s = rows[:, 0].copy()
        check_time_stamps(self._t_s, data_path, lambda k: f"line {k + 1} (frame {k})")
        self._T_world_cam, _ = transforms_from_pose_rows(
            rows, data_path, allow_zero_rows=True, t_col=2
        )
        self._name = self.path.name
        self._object_name = object_name or self._find_object_name()
        self._fps = fps or self._find_fps()
        self._pose_files = self._find_pose_files()
        self._pose_cache: dict[str, DetectorPoses] = {}
        self._gt_cache: dict[str | None, PoseTrack | None] = {}

    # ---------------------------------------------------------------- discovery helpers
    def _read_text(self, path: Path, what: str) -> str:
        data = read_file_bytes(path, what)
        try:
            return data.decode("utf-8")
        except UnicodeDecodeError:
            raise DatasetFormatError(f"{what} file {located(path)} is not UTF-8 text") from None

    def _find_object_name(self) -> str:
        name = self._metadata.get("object_name")
        if isinstance(name, str) and name:
            return name
        masks = self.path / "masks"
        if masks.is_dir():
            for set_dir in sorted(p for p in masks.iterdir() if p.is_dir()):
                with os.scandir(set_dir) as it:
                    for entry in it:
                        m = _MASK_FILE.match(entry.name)
                        if m:
                            return m.group(1)
        return self.path.name

    def _find_fps(self) -> int:
        fps = self._metadata.get("fps")
        if isinstance(fps, int) and fps > 0:
            return fps
        if len(self._t_s) > 1:
            dt = float(np.median(np.diff(self._t_s)))
            if dt > 0:
                return max(1, round(1.0 / dt))
        return 30

    def _find_pose_files(self) -> dict[str, Path]:
        files: dict[str, Path] = {}
        for d in sorted(p for p in self.path.iterdir() if p.is_dir()):
            if d.name in _NOT_POSE_SETS or d.name.startswith("."):
                continue
            for f in sorted(d.glob("poses*.txt")):
                variant = f.stem[len("poses") :]
                if variant == "" or variant.startswith("_"):
                    files.setdefault(d.name + variant, f)
        return files

    # ------------------------------------------------------------------------ Sequence
    def rgb(self, k: int) -> U8:
        path = f"{self.path}/rgb/{self._check_k(k)}.png"
        return decode_png_rgb(read_file_bytes(path, "rgb"), path, shape=self._intrinsics.shape)

    def depth(self, k: int) -> F32:
        path = f"{self.path}/depth/{self._check_k(k)}.float"
        return decode_depth_float(
            read_file_bytes(path, "depth"), path, shape=self._intrinsics.shape
        )

    def flow_sets(self) -> tuple[str, ...]:
        return self._cached_sets("flow", self._find_flow_sets)

    def _find_flow_sets(self) -> tuple[str, ...]:
        return subfolder_names(self.path / "optical_flow")

    def flow(self, k: int, flow_set: str) -> FlowField | None:
        if flow_set not in self.flow_sets():
            raise KeyError(f"no flow set {flow_set!r} in {self.path}; sets: {self.flow_sets()}")
        if self._check_k(k) == 0:
            return None
        return read_flow_field(
            f"{self.path}/optical_flow/{flow_set}/{k}.float",
            f"{self.path}/optical_flow_valid/{flow_set}/{k}.png",
            k,
            self._intrinsics.shape,
        )

    def mask_sets(self) -> tuple[str, ...]:
        return self._cached_sets("mask", self._find_mask_sets)

    def _find_mask_sets(self) -> tuple[str, ...]:
        d = self.path / "masks"
        if not d.is_dir():
            return ()
        names = sorted(p.name for p in d.iterdir() if p.is_dir())
        first = [n for n in (GT_MASK_SET, GT_FULL_MASK_SET) if n in names]
        return tuple(first + [n for n in names if n not in first])

    def mask(self, k: int, mask_set: str) -> Bool | None:
        if mask_set not in self.mask_sets():
            raise KeyError(f"no mask set {mask_set!r} in {self.path}; sets: {self.mask_sets()}")
        path = f"{self.path}/masks/{mask_set}/{self._object_name}_{self._check_k(k)}.png"
        try:
            with open(path, "rb") as f:
                data = f.read()
        except FileNotFoundError:
            return None  # a detector miss: no file
        return decode_png_mask(data, path, shape=self._intrinsics.shape)

    def pose_sets(self) -> tuple[str, ...]:
        return tuple(self._pose_files)

    def detector_poses(self, pose_set: str) -> DetectorPoses:
        if pose_set not in self._pose_files:
            raise KeyError(f"no pose set {pose_set!r} in {self.path}; sets: {self.pose_sets()}")
        if pose_set not in self._pose_cache:
            path = self._pose_files[pose_set]
            rows = parse_rows(self._read_text(path, "poses"), path, 7, n_rows=len(self))
            T, valid = transforms_from_pose_rows(rows, path, allow_zero_rows=True)
            self._pose_cache[pose_set] = DetectorPoses(T_cam_obj=T, valid=valid)
        return self._pose_cache[pose_set]

    def ground_truth(self, variant: str | None = None) -> PoseTrack | None:
        """Ground truth from ``gt/poses.txt`` and ``gt/velocities.txt``; None when absent.

        Args:
            variant: read ``gt/poses_<variant>.txt`` instead (e.g. ``ycb``, the YCB-Video
                object frame of the reference); its velocities are NaN (they depend on the
                object frame and are not stored).

        Velocities are NaN when ``gt/velocities.txt`` is absent (e.g. HO-3D conversions).
        """
        if variant not in self._gt_cache:
            self._gt_cache[variant] = self._read_ground_truth(variant)
        return self._gt_cache[variant]

    def _read_ground_truth(self, variant: str | None) -> PoseTrack | None:
        path = self.path / "gt" / ("poses.txt" if variant is None else f"poses_{variant}.txt")
        if not path.is_file():
            if variant is not None:
                raise KeyError(f"no ground-truth variant file {path}")
            return None
        rows = parse_rows(self._read_text(path, "ground-truth poses"), path, 7, n_rows=len(self))
        T, _ = transforms_from_pose_rows(rows, path, allow_zero_rows=False)
        v = np.full((len(self), 3), np.nan)
        w = np.full((len(self), 3), np.nan)
        vel_path = self.path / "gt" / "velocities.txt"
        if variant is None and vel_path.is_file():
            vel = parse_rows(self._read_text(vel_path, "velocities"), vel_path, 6, n_rows=len(self))
            v, w = vel[:, :3].copy(), vel[:, 3:].copy()
        return PoseTrack(t_s=self._t_s.copy(), T_cam_obj=T, v_obj_mps=v, w_radps=w)

    def camera_poses(self) -> F64:
        return self._T_world_cam.copy()

    def object_model(self) -> ObjectModel | None:
        folder = self.path / "models" / self._object_name
        points_path = folder / "points.xyz"
        if not points_path.is_file():
            return None
        points = read_points_xyz(points_path)
        mesh_path = folder / "mesh.obj"
        if mesh_path.is_file():
            vertices, faces = read_mesh_obj(mesh_path)
        else:
            vertices, faces = points, np.zeros((0, 3), dtype=np.int64)
        return ObjectModel(
            name=self._object_name,
            vertices_m=vertices,
            faces=faces,
            model_points_m=points,
            mesh_path=mesh_path if mesh_path.is_file() else None,
        )

    def metadata(self) -> Mapping[str, Any]:
        return dict(self._metadata)

    def __repr__(self) -> str:
        return f"FastYcbSequence({str(self.path)!r}, {len(self)} frames)"
