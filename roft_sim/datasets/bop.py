"""The BOP scene layout (bop_toolkit's ``docs/bop_datasets_format.md``) plus our extras.

One scene folder per sequence, numbered as bop_toolkit expects (``<root>/000001/``, ...; write
into a split folder such as ``test/`` for bop_toolkit). A sequence whose name is not a number
gets the next free scene id (or the ``scene_id`` option; ``roft-sim generate`` numbers its
scenarios in order), and ``<root>/scene_names.json`` maps each scene folder to the sequence name
(``{"000001": "fast_ycb_003_cracker_box", ...}``); the scene's ``metadata.json`` keeps it too::

    scene_camera.json   {im_id: {cam_K, depth_scale, cam_R_w2c, cam_t_w2c [mm]}}
    scene_gt.json       {im_id: [{cam_R_m2c (row-major 3x3), cam_t_m2c [mm], obj_id}]}
    scene_gt_info.json  {im_id: [{bbox_obj, bbox_visib, px_count_all, px_count_valid,
                                  px_count_visib, visib_fract}]}
    rgb/<im_id:06d>.png   depth/<im_id:06d>.png (uint16, depth [mm] = value * depth_scale)
    mask/<im_id:06d>_<gt_idx:06d>.png   mask_visib/<im_id:06d>_<gt_idx:06d>.png
    models/obj_<obj_id:06d>.ply [mm]    models/models_info.json
    metadata.json and extras/ (ours):
        extras/scene_time.json            {im_id: {"t_s": t}}
        extras/scene_gt_velocity.json     {im_id: [{obj_id, v_obj_mps, w_radps}]} (SI units)
        extras/flow/<set>/<im_id:06d>.float      (Fast-YCB flow encoding; F_k, none for k = 0)
        extras/flow_valid/<set>/<im_id:06d>.png
        extras/masks/<set>/<im_id:06d>.png       (detector masks; miss = no file)
        extras/poses/<set>.csv            (BOP results format: scene_id,im_id,obj_id,score,R,t,time;
                                           a miss has no row)
        extras/model/{points.xyz, mesh.obj}      (metres, exact)

Precision: depth is quantised to ``depth_scale`` mm (round to nearest), so it round-trips to
within ``depth_scale / 2`` mm (bit-exactly when it is already a multiple of ``depth_scale``);
poses are written as full-precision JSON numbers (translation in mm: ~1e-16 relative error).
Everything else (rgb, masks, flow, velocities, time) is exact.
"""

from __future__ import annotations

import csv
import io
import json
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
    encode_flow_float,
    format_number,
)
from roft_sim.datasets.folder_writer import FolderWriter, check_finished_folder
from roft_sim.datasets.frames import GT_FULL_MASK_SET, DatasetFrame
from roft_sim.datasets.image_files import (
    decode_png_mask,
    decode_png_rgb,
    decode_png_u16,
    encode_png_mask,
    encode_png_rgb,
    encode_png_u16,
    read_file_bytes,
)
from roft_sim.datasets.metadata import read_json
from roft_sim.datasets.model_files import (
    read_mesh_obj,
    read_mesh_ply_mm,
    read_points_xyz,
    write_mesh_obj,
    write_mesh_ply_mm,
    write_points_xyz,
)
from roft_sim.datasets.reader_base import (
    SequenceReaderBase,
    check_time_stamps,
    read_flow_field,
    subfolder_names,
)
from roft_sim.datasets.writer_base import WriterSettings
from roft_sim.errors import ConfigError, DatasetFormatError, located
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import invert_transform, transform_from_rt
from roft_sim.geometry.so3 import as_rotation_matrix
from roft_sim.records import FlowField, ObjectModel, PoseTrack

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]

__all__ = [
    "BopWriter",
    "BopSequence",
    "is_bop_scene",
    "YCBV_OBJ_IDS",
    "DEFAULT_DEPTH_SCALE_MM",
    "bop_obj_id",
    "SCENE_NAMES_FILE",
    "bop_scene_folder",
    "read_scene_names",
    "model_diameter_m",
]

SCENE_NAMES_FILE = "scene_names.json"
"""The dataset root's map from scene folder (``000001``) to sequence name."""

DEFAULT_DEPTH_SCALE_MM = 0.1
"""Depth unit of our BOP files [mm] (as YCB-V): uint16 covers 0 .. 6.5535 m in 0.1 mm steps."""

YCBV_OBJ_IDS: dict[str, int] = {
    name: i + 1
    for i, name in enumerate(
        [
            "002_master_chef_can",
            "003_cracker_box",
            "004_sugar_box",
            "005_tomato_soup_can",
            "006_mustard_bottle",
            "007_tuna_fish_can",
            "008_pudding_box",
            "009_gelatin_box",
            "010_potted_meat_can",
            "011_banana",
            "019_pitcher_base",
            "021_bleach_cleanser",
            "024_bowl",
            "025_mug",
            "035_power_drill",
            "036_wood_block",
            "037_scissors",
            "040_large_marker",
            "051_large_clamp",
            "052_extra_large_clamp",
            "061_foam_brick",
        ]
    )
}
"""BOP YCB-V object ids by YCB name (used as ``obj_id`` when the object is a YCB-V object)."""


def bop_obj_id(object_name: str) -> int:
    """The ``obj_id`` we write for an object: its YCB-V id, or 1 for other objects."""
    return YCBV_OBJ_IDS.get(object_name, 1)


def is_bop_scene(path: Path) -> bool:
    """True when ``path`` is a folder with ``scene_camera.json``."""
    return (path / "scene_camera.json").is_file()


def _bop_json(entries: Mapping[int, Any]) -> str:
    """BOP-style JSON: one image id per line, keys in numeric order (deterministic)."""
    lines = [f'  "{k}": {json.dumps(v, allow_nan=False)}' for k, v in sorted(entries.items())]
    return "{\n" + ",\n".join(lines) + "\n}\n"


def _bbox(mask: Bool) -> list[int]:
    """BOP bounding box ``[x, y, width, height]`` [px] of a mask; ``[-1, -1, -1, -1]`` if empty.

    As bop_toolkit's ``misc.calc_2d_bbox`` computes it, so our ``scene_gt_info.json`` equals the
    toolkit's: width = x_max - x_min and height = y_max - y_min over the mask's pixel indices (a
    one-pixel mask has width and height 0).
    """
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return [-1, -1, -1, -1]
    return [int(cols[0]), int(rows[0]), int(cols[-1] - cols[0]), int(rows[-1] - rows[0])]


def _gt_info(full: Bool, visib: Bool, depth_m: F32) -> dict[str, Any]:
    """One ``scene_gt_info.json`` entry of an instance: its full silhouette ``full`` and visible
    pixels ``visib``, both (H, W) bool; ``depth_m`` (H, W) the frame's depth [m], 0 = no return."""
    n_all, n_visib = int(full.sum()), int(visib.sum())
    return {
        "bbox_obj": _bbox(full),
        "bbox_visib": _bbox(visib),
        "px_count_all": n_all,
        "px_count_valid": int((full & (depth_m > 0)).sum()),
        "px_count_visib": n_visib,
        "visib_fract": n_visib / n_all if n_all else 0.0,
    }


def read_scene_names(root: str | Path) -> dict[str, str]:
    """``<root>/scene_names.json`` (scene folder -> sequence name); empty when absent.

    Raises:
        DatasetFormatError: not a JSON object of strings.
    """
    path = Path(root) / SCENE_NAMES_FILE
    if not path.is_file():
        return {}
    data = read_json(path, "scene names")
    if not isinstance(data, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in data.items()
    ):
        raise DatasetFormatError(
            f"{located(path)} must map scene folders to sequence names, e.g. "
            '{"000001": "fast_ycb_003_cracker_box"}'
        )
    return dict(data)


def bop_scene_folder(root: str | Path, sequence_name: str, scene_id: int | None = None) -> str:
    """The scene folder of ``sequence_name`` under ``root``, recorded in ``scene_names.json``.

    A numeric name is its own folder. Otherwise the folder already mapped to the name, else
    ``scene_id`` (``%06d``), else the next id after every mapped or existing numbered folder.
    The map is read, updated and rewritten under an exclusive lock (parallel writers).

    Raises:
        ConfigError: ``scene_id`` is taken by another sequence.
    """
    if sequence_name.isdigit():
        return sequence_name
    import fcntl

    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    lock = os.open(root, os.O_RDONLY)  # the root folder itself is the lock: no file left
    try:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return _claim_scene_folder(root, sequence_name, scene_id)
    finally:
        os.close(lock)  # releases the lock


def _claim_scene_folder(root: Path, sequence_name: str, scene_id: int | None) -> str:
    """:func:`bop_scene_folder` under the lock."""
    names = read_scene_names(root)
    for folder, name in names.items():
        if name == sequence_name:
            return folder
    if scene_id is None:
        taken = [int(f) for f in names] + [
            int(p.name) for p in root.iterdir() if p.is_dir() and p.name.isdigit()
        ]
        scene_id = max(taken, default=0) + 1
    folder = f"{scene_id:06d}"
    if folder in names or (root / folder).exists():
        raise ConfigError(
            f"BOP scene {folder} under {str(root)!r} is taken (by "
            f"{names.get(folder, 'a folder')!r}), so sequence {sequence_name!r} cannot use "
            "it; write into an empty root or choose another scene_id"
        )
    names[folder] = sequence_name
    atomic_write_text(
        root / SCENE_NAMES_FILE, json.dumps(dict(sorted(names.items())), indent=2) + "\n"
    )
    return folder


def model_diameter_m(vertices_m: F64) -> float:
    """Largest distance between model vertices [m], exact, as bop_toolkit's
    ``misc.calc_pts_diameter`` on the model's vertices (here via the convex hull, whose vertices
    hold the farthest pair; flat and degenerate sets too).

    Args:
        vertices_m: (V, 3) mesh vertices (or points) in the object frame [m].
    """
    return _diameter_m(vertices_m)


def _diameter_m(points_m: F64) -> float:
    """Largest distance between points [m] (via the convex hull; flat models too)."""
    from scipy.spatial import ConvexHull, QhullError, distance

    pts = np.asarray(points_m, dtype=np.float64)
    if len(pts) > 4:
        try:
            pts = pts[ConvexHull(pts).vertices]
        except QhullError:  # flat or degenerate point sets
            pts = pts[ConvexHull(pts, qhull_options="QJ").vertices]
    return float(distance.pdist(pts).max(initial=0.0))


def _r_t_mm(T: Any) -> tuple[list[float], list[float]]:
    T = np.asarray(T, dtype=np.float64) + 0.0  # + 0.0 turns -0.0 into 0.0
    return T[:3, :3].ravel().tolist(), (T[:3, 3] * 1000.0 + 0.0).tolist()


class BopWriter(FolderWriter):
    """Streams one sequence into the BOP scene folder ``<root>/<sequence_name>/``.

    Options (``settings.options``): ``depth_scale_mm`` (default 0.1), ``obj_id`` (default: the
    YCB-V id of the object, else 1) and ``scene_id`` (the scene folder of a sequence whose name is
    not a number; default: the next free one, :func:`bop_scene_folder`).
    """

    FORMAT = "bop"

    def __init__(
        self,
        root: Path,
        settings: WriterSettings,
        *,
        object_model: ObjectModel | None,
        resume: bool,
    ) -> None:
        scale = settings.options.get("depth_scale_mm", DEFAULT_DEPTH_SCALE_MM)
        obj_id = settings.options.get("obj_id", bop_obj_id(settings.object_name))
        if not isinstance(scale, int | float) or not scale > 0:
            raise ConfigError(f"BOP depth_scale_mm must be > 0, got {scale!r}")
        if not isinstance(obj_id, int) or obj_id < 1:
            raise ConfigError(f"BOP obj_id must be an int >= 1, got {obj_id!r}")
        scene_id = settings.options.get("scene_id")
        if scene_id is not None and (not isinstance(scene_id, int) or scene_id < 1):
            raise ConfigError(f"BOP scene_id must be an int >= 1, got {scene_id!r}")
        self.depth_scale_mm = float(scale)
        self.obj_id = obj_id
        seq = Path(root) / bop_scene_folder(root, settings.sequence_name, scene_id)
        super().__init__(seq, settings, object_model=object_model, resume=resume)

    def _format_options(self) -> dict[str, Any]:
        return {"depth_scale_mm": self.depth_scale_mm, "obj_id": self.obj_id}

    def _format_conventions(self) -> dict[str, str]:
        return {
            "bop_units": "BOP files keep BOP's units: cam_t_m2c, cam_t_w2c in mm; depth PNG "
            "value * depth_scale = depth in mm; models in mm",
            "depth_precision": f"depth is quantised to depth_scale = {self.depth_scale_mm} mm",
            "extras": "extras/ holds time stamps, velocities (SI), flow, detector masks and "
            "poses, exact model points; see docs/formats.md",
            "mask_full": "mask/ is the full silhouette when the generator gave one, else a copy "
            "of mask_visib/ (see ground_truth.full_masks)",
            "bbox": "bbox_obj and bbox_visib are [x, y, width, height] of the full and visible "
            "masks inside the image, width = x_max - x_min as bop_toolkit's calc_2d_bbox",
        }

    def _write_frame_files(self, frame: DatasetFrame) -> dict[str, Any]:
        seq, k = self.sequence_path, frame.k
        png = self.settings.png_compression  # zlib level of every PNG of the frame
        atomic_write_bytes(f"{seq}/rgb/{k:06d}.png", encode_png_rgb(frame.rgb, level=png))
        q = np.rint(frame.depth_m.astype(np.float64) * (1000.0 / self.depth_scale_mm))
        if q.size and q.max() > 65535:
            raise ValueError(
                f"frame {k}: depth {frame.depth_m.max():.3f} m exceeds the uint16 range of BOP "
                f"depth with depth_scale {self.depth_scale_mm} mm "
                f"({65535 * self.depth_scale_mm / 1000:.4f} m); raise depth_scale_mm"
            )
        atomic_write_bytes(
            f"{seq}/depth/{k:06d}.png", encode_png_u16(q.astype(np.uint16), level=png)
        )
        extra: dict[str, Any] = {"gt_info": None}
        if frame.gt_mask is not None:
            full = frame.gt_mask_full if frame.gt_mask_full is not None else frame.gt_mask
            atomic_write_bytes(f"{seq}/mask/{k:06d}_000000.png", encode_png_mask(full, level=png))
            atomic_write_bytes(
                f"{seq}/mask_visib/{k:06d}_000000.png", encode_png_mask(frame.gt_mask, level=png)
            )
            extra["gt_info"] = _gt_info(full, frame.gt_mask, frame.depth_m)
        if frame.gt_distractors:
            extra["distractors"] = self._write_distractors(frame)
        for name, flow in frame.flows.items():
            atomic_write_bytes(
                f"{seq}/extras/flow/{name}/{k:06d}.float",
                encode_flow_float(flow.flow_px, self.settings.flow_encoding(name)),
            )
            valid_path = f"{seq}/extras/flow_valid/{name}/{k:06d}.png"
            if flow.valid is not None:
                atomic_write_bytes(valid_path, encode_png_mask(flow.valid, level=png))
            else:
                remove_file(valid_path)
        for name, mask in frame.detector_masks.items():
            path = f"{seq}/extras/masks/{name}/{k:06d}.png"
            if mask is not None:
                atomic_write_bytes(path, encode_png_mask(mask, level=png))
            else:
                remove_file(path)
        return extra

    def _write_distractors(self, frame: DatasetFrame) -> list[dict[str, Any]]:
        """Clutter: each distractor is one more ground-truth instance of the image (index 1,
        2, ... after the tracked object's 0): its masks and its scene_gt / scene_gt_info entries
        (``obj_id`` from its YCB-V name, else 1; no model is written for it)."""
        seq, k, png = self.sequence_path, frame.k, self.settings.png_compression
        out = []
        for i, d in enumerate(frame.gt_distractors, start=1):
            full = d.mask_full if d.mask_full is not None else d.mask
            atomic_write_bytes(f"{seq}/mask/{k:06d}_{i:06d}.png", encode_png_mask(full, level=png))
            atomic_write_bytes(
                f"{seq}/mask_visib/{k:06d}_{i:06d}.png", encode_png_mask(d.mask, level=png)
            )
            R, t = _r_t_mm(d.T_cam_obj)
            out.append(
                {
                    "gt": {"cam_R_m2c": R, "cam_t_m2c": t, "obj_id": bop_obj_id(d.name)},
                    "gt_info": _gt_info(full, d.mask, frame.depth_m),
                }
            )
        return out

    def _write_model(self, model: ObjectModel) -> None:
        seq = self.sequence_path
        write_mesh_ply_mm(
            seq / "models" / f"obj_{self.obj_id:06d}.ply", model.vertices_m, model.faces
        )
        v_mm = model.vertices_m * 1000.0
        lo, hi = v_mm.min(axis=0), v_mm.max(axis=0)
        info = {
            "diameter": model_diameter_m(
                model.vertices_m if len(model.vertices_m) else model.model_points_m
            )
            * 1000.0,
            "min_x": lo[0],
            "min_y": lo[1],
            "min_z": lo[2],
            "size_x": hi[0] - lo[0],
            "size_y": hi[1] - lo[1],
            "size_z": hi[2] - lo[2],
        }
        atomic_write_text(
            seq / "models" / "models_info.json",
            _bop_json({self.obj_id: {k: float(v) for k, v in info.items()}}),
        )
        write_mesh_obj(seq / "extras" / "model" / "mesh.obj", model.vertices_m, model.faces)
        write_points_xyz(seq / "extras" / "model" / "points.xyz", model.model_points_m)

    def _assemble(
        self, records: Callable[[], Iterator[dict[str, Any]]], metadata: dict[str, Any]
    ) -> None:
        seq, s = self.sequence_path, self.settings
        scene_id = int(seq.name)
        camera_path, gt_path = seq / "scene_camera.json", seq / "scene_gt.json"
        info_path, time_path = seq / "scene_gt_info.json", seq / "extras" / "scene_time.json"
        velocity_path = seq / "extras" / "scene_gt_velocity.json"
        pose_paths = {n: seq / "extras" / "poses" / f"{n}.csv" for n in metadata["sets"]["pose"]}
        with AtomicTextFiles() as out:

            def entry(path: Path, k: int, value: Any) -> None:
                """One line of a BOP JSON map (``{"k": value, ...}``, one image per line)."""
                out.write(
                    path,
                    ("{\n" if k == 0 else ",\n") + f'  "{k}": {json.dumps(value, allow_nan=False)}',
                )

            for path in pose_paths.values():
                out.write(path, "scene_id,im_id,obj_id,score,R,t,time\n")
            for r in records():
                k = r["k"]
                R_w2c, t_w2c = _r_t_mm(invert_transform(np.asarray(r["T_world_cam"])))
                entry(
                    camera_path,
                    k,
                    {
                        "cam_K": s.intrinsics.K.ravel().tolist(),
                        "depth_scale": self.depth_scale_mm,
                        "cam_R_w2c": R_w2c,
                        "cam_t_w2c": t_w2c,
                    },
                )
                gt = []
                if r["gt_T_cam_obj"] is not None:
                    R, t = _r_t_mm(r["gt_T_cam_obj"])
                    gt = [{"cam_R_m2c": R, "cam_t_m2c": t, "obj_id": self.obj_id}]
                info = [r["gt_info"]] if r["gt_info"] is not None else []
                for distractor in r.get("distractors", []):  # clutter: instances 1, 2, ...
                    gt.append(distractor["gt"])
                    info.append(distractor["gt_info"])
                entry(gt_path, k, gt)
                entry(info_path, k, info)
                entry(time_path, k, {"t_s": r["t_s"]})
                if r["gt_v_obj_mps"] is not None:
                    velocity = {"v_obj_mps": r["gt_v_obj_mps"], "w_radps": r["gt_w_radps"]}
                    entry(velocity_path, k, [{"obj_id": self.obj_id, **velocity}])
                for name, path in pose_paths.items():
                    T = r["detector_poses"][name]
                    if T is not None:
                        R, t = _r_t_mm(T)
                        R_text, t_text = (
                            " ".join(map(format_number, R)),
                            " ".join(map(format_number, t)),
                        )
                        out.write(path, f"{scene_id},{k},{self.obj_id},1,{R_text},{t_text},-1\n")
            for path in (camera_path, gt_path, info_path, time_path):
                out.write(path, "\n}\n")
            if metadata["ground_truth"]["velocities"]:
                out.write(velocity_path, "\n}\n")
        self._finish_folder(
            metadata,
            mask_set_dir=lambda name: seq / "extras" / "masks" / name,
            flow_set_dir=lambda name: seq / "extras" / "flow" / name,
        )


class BopSequence(SequenceReaderBase):
    """One BOP scene read lazily as a sequence of one object (implements ``Sequence``).

    Works on scenes we wrote and on BOP datasets from elsewhere (one object per sequence: pick
    it with ``object_name`` when the scene shows several).

    Args:
        path: the scene folder (holds ``scene_camera.json``).
        object_name: the tracked object: a YCB-V name (``003_cracker_box``), ``obj_000002`` or
            ``2``; by default ours from ``metadata.json``, else the only object of the scene.
        fps: nominal rate [Hz] when the scene has no ``metadata.json`` (default 30).

    Frame ``k`` is the k-th image id in increasing order. Time stamps come from
    ``extras/scene_time.json``, else ``k / fps``.

    Raises:
        DatasetFormatError: missing or malformed JSON files, intrinsics that change between
            frames, an object that is not in the scene.
    """

    def __init__(
        self, path: str | Path, *, object_name: str | None = None, fps: int | None = None
    ) -> None:
        self.path = Path(path)
        check_finished_folder(self.path)
        meta_path = self.path / "metadata.json"
        self._metadata: dict[str, Any] = (
            read_json(meta_path, "metadata") if meta_path.is_file() else {}
        )
        if not isinstance(self._metadata, dict):
            raise DatasetFormatError(f"{located(meta_path)} must hold a JSON object")
        self._name = str(self._metadata.get("sequence_name", self.path.name))
        cam_path = self.path / "scene_camera.json"
        cameras = self._json_by_id(cam_path, "scene camera")
        if not cameras:
            raise DatasetFormatError(f"{located(cam_path)} lists no images")
        self._im_ids = sorted(cameras)
        self._cameras = [cameras[i] for i in self._im_ids]
        self._intrinsics = self._find_intrinsics(cam_path)
        meta_fps = self._metadata.get("fps")
        if (
            fps is None
            and meta_fps is not None
            and not (isinstance(meta_fps, int) and not isinstance(meta_fps, bool) and meta_fps > 0)
        ):
            raise DatasetFormatError(
                f"{located(meta_path)}: fps = {meta_fps!r}; expected a positive integer [Hz]"
            )
        self._fps = int(fps or meta_fps or 30)
        gt_path = self.path / "scene_gt.json"
        self._gt = self._json_by_id(gt_path, "scene ground truth") if gt_path.is_file() else {}
        self._obj_id, self._object_name = self._find_object(object_name)
        time_path = self.path / "extras" / "scene_time.json"
        if time_path.is_file():
            times = self._json_by_id(time_path, "time stamps")
            try:
                self._t_s = np.array([float(times[i]["t_s"]) for i in self._im_ids])
            except (KeyError, TypeError, ValueError) as e:
                raise DatasetFormatError(
                    f"{located(time_path)}: bad or missing entry {e}"
                ) from None
            check_time_stamps(self._t_s, time_path, lambda k: f"image {self._im_ids[k]}")
        else:
            self._t_s = np.arange(len(self._im_ids)) / self._fps
        self._T_world_cam = np.stack(
            [
                self._camera_pose(c, i, cam_path)
                for c, i in zip(self._cameras, self._im_ids, strict=True)
            ]
        )

    # ------------------------------------------------------------------------ parsing
    def _json_by_id(self, path: Path, what: str) -> dict[int, Any]:
        data = read_json(path, what)
        if not isinstance(data, dict):
            raise DatasetFormatError(f"{located(path)} must hold a JSON object keyed by image id")
        try:
            return {int(k): v for k, v in data.items()}
        except ValueError:
            raise DatasetFormatError(f"{located(path)} has a key that is not an image id") from None

    def _numbers(self, value: Any, n: int, path: Path, what: str) -> F64:
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != (n,) or not np.isfinite(a).all():
            raise DatasetFormatError(f"{located(path)}: {what} must be {n} finite numbers")
        return a

    def _find_intrinsics(self, cam_path: Path) -> CameraIntrinsics:
        Ks = [
            self._numbers(
                c.get("cam_K") if isinstance(c, dict) else None, 9, cam_path, f"cam_K of image {i}"
            )
            for c, i in zip(self._cameras, self._im_ids, strict=True)
        ]
        for K, i in zip(Ks, self._im_ids, strict=True):
            if not np.array_equal(K, Ks[0]):
                raise DatasetFormatError(
                    f"{located(cam_path)}: cam_K of image {i} differs from image "
                    f"{self._im_ids[0]}; a sequence needs one camera"
                )
        size = self._metadata.get("intrinsics")
        if isinstance(size, dict) and "width_px" in size:
            try:
                w, h = int(size["width_px"]), int(size["height_px"])
            except (KeyError, TypeError, ValueError) as e:
                raise DatasetFormatError(
                    f"{located(self.path / 'metadata.json')}: intrinsics need integer width_px "
                    f"and height_px ({type(e).__name__}: {e})"
                ) from None
        else:
            h, w = self._rgb_at(0, shape=None).shape[:2]
        try:
            return CameraIntrinsics.from_matrix(Ks[0].reshape(3, 3), w, h)
        except ValueError as e:
            raise DatasetFormatError(f"{located(cam_path)}: invalid cam_K: {e}") from None

    def _camera_pose(self, cam: dict[str, Any], im_id: int, path: Path) -> F64:
        if "cam_R_w2c" not in cam:
            return np.eye(4)
        R = self._numbers(cam["cam_R_w2c"], 9, path, f"cam_R_w2c of image {im_id}")
        t = self._numbers(cam.get("cam_t_w2c"), 3, path, f"cam_t_w2c of image {im_id}")
        try:
            R = as_rotation_matrix(R.reshape(3, 3))
        except ValueError as e:
            raise DatasetFormatError(f"{located(path)}: cam_R_w2c of image {im_id}: {e}") from None
        return invert_transform(transform_from_rt(R, t / 1000.0))

    def _find_object(self, object_name: str | None) -> tuple[int, str]:
        gt_path = self.path / "scene_gt.json"
        try:
            ids_in_scene = sorted(
                {int(o["obj_id"]) for v in self._gt.values() for o in v if isinstance(o, dict)}
            )
        except (KeyError, TypeError, ValueError) as e:
            raise DatasetFormatError(
                f"{located(gt_path)}: every image needs a list of objects with an integer "
                f"obj_id ({type(e).__name__}: {e})"
            ) from None
        if object_name is None:
            if "object_name" in self._metadata:
                opts = self._metadata.get("format_options", {})
                name = str(self._metadata["object_name"])
                obj_id = opts.get("obj_id", bop_obj_id(name)) if isinstance(opts, dict) else None
                if isinstance(obj_id, bool) or not isinstance(obj_id, int):
                    raise DatasetFormatError(
                        f"{located(self.path / 'metadata.json')}: format_options.obj_id = "
                        f"{obj_id!r}; expected an integer BOP obj_id"
                    )
                return obj_id, name
            if len(ids_in_scene) != 1:
                raise DatasetFormatError(
                    f"{located(self.path)} shows objects {ids_in_scene}; pass object_name to "
                    "pick the one to track"
                )
            obj_id = ids_in_scene[0]
        elif object_name in YCBV_OBJ_IDS:
            obj_id = YCBV_OBJ_IDS[object_name]
        else:
            m = re.fullmatch(r"(?:obj_)?0*(\d+)", object_name)
            if not m:
                raise DatasetFormatError(
                    f"object {object_name!r} is neither a YCB-V name nor an obj_id like "
                    "'obj_000002' or '2'"
                )
            obj_id = int(m.group(1))
        if self._gt and obj_id not in ids_in_scene:
            raise DatasetFormatError(
                f"object id {obj_id} is not in {located(self.path / 'scene_gt.json')} "
                f"(it shows {ids_in_scene})"
            )
        names = {v: k for k, v in YCBV_OBJ_IDS.items()}
        return obj_id, object_name or names.get(obj_id, f"obj_{obj_id:06d}")

    def _gt_index(self, k: int) -> int | None:
        """Index of our object in scene_gt's list for frame k (None if not annotated)."""
        for idx, o in enumerate(self._gt.get(self._im_ids[k], [])):
            if isinstance(o, dict) and int(o.get("obj_id", -1)) == self._obj_id:
                return idx
        return None

    def _rgb_at(self, k: int, shape: tuple[int, int] | None) -> U8:
        stem = f"{self._im_ids[k]:06d}"
        for ext in ("png", "jpg", "jpeg"):
            path = f"{self.path}/rgb/{stem}.{ext}"
            if os.path.isfile(path):
                break
        else:
            raise DatasetFormatError(
                f"rgb file {located(self.path / 'rgb' / (stem + '.png'))} is missing"
            )
        data = read_file_bytes(path, "rgb")
        if ext == "png":
            return decode_png_rgb(data, path, shape=shape)
        import cv2

        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        if image is None:
            raise DatasetFormatError(f"rgb file {located(path)} is a corrupt JPEG")
        if shape is not None and image.shape[:2] != tuple(shape):
            raise DatasetFormatError(f"rgb file {located(path)} has the wrong size")
        return np.ascontiguousarray(image[..., ::-1])

    # ------------------------------------------------------------------------ Sequence
    def rgb(self, k: int) -> U8:
        return self._rgb_at(self._check_k(k), self._intrinsics.shape)

    def depth(self, k: int) -> F32:
        k = self._check_k(k)
        path = f"{self.path}/depth/{self._im_ids[k]:06d}.png"
        raw = decode_png_u16(read_file_bytes(path, "depth"), path, shape=self._intrinsics.shape)
        scale = self._cameras[k].get("depth_scale", 1.0)
        if not isinstance(scale, int | float) or not scale > 0:
            raise DatasetFormatError(
                f"{located(self.path / 'scene_camera.json')}: depth_scale of image "
                f"{self._im_ids[k]} is {scale!r}; expected a positive number"
            )
        return (raw.astype(np.float64) * (float(scale) / 1000.0)).astype(np.float32)

    def flow_sets(self) -> tuple[str, ...]:
        return self._cached_sets("flow", self._find_flow_sets)

    def _find_flow_sets(self) -> tuple[str, ...]:
        return subfolder_names(self.path / "extras" / "flow")

    def flow(self, k: int, flow_set: str) -> FlowField | None:
        if flow_set not in self.flow_sets():
            raise KeyError(f"no flow set {flow_set!r} in {self.path}; sets: {self.flow_sets()}")
        if self._check_k(k) == 0:
            return None
        stem = f"{self._im_ids[k]:06d}"
        return read_flow_field(
            f"{self.path}/extras/flow/{flow_set}/{stem}.float",
            f"{self.path}/extras/flow_valid/{flow_set}/{stem}.png",
            k,
            self._intrinsics.shape,
        )

    def mask_sets(self) -> tuple[str, ...]:
        return self._cached_sets("mask", self._find_mask_sets)

    def _find_mask_sets(self) -> tuple[str, ...]:
        sets = []
        if (self.path / "mask_visib").is_dir():
            sets.append(GT_MASK_SET)
        gt_info = self._metadata.get("ground_truth", {})
        full_masks = gt_info.get("full_masks", True) if isinstance(gt_info, dict) else True
        if (self.path / "mask").is_dir() and full_masks:
            sets.append(GT_FULL_MASK_SET)
        d = self.path / "extras" / "masks"
        if d.is_dir():
            sets += sorted(p.name for p in d.iterdir() if p.is_dir())
        return tuple(sets)

    def mask(self, k: int, mask_set: str) -> Bool | None:
        if mask_set not in self.mask_sets():
            raise KeyError(f"no mask set {mask_set!r} in {self.path}; sets: {self.mask_sets()}")
        k = self._check_k(k)
        stem = f"{self._im_ids[k]:06d}"
        if mask_set in (GT_MASK_SET, GT_FULL_MASK_SET):
            idx = self._gt_index(k)
            if idx is None:
                return None
            folder = "mask_visib" if mask_set == GT_MASK_SET else "mask"
            path = f"{self.path}/{folder}/{stem}_{idx:06d}.png"
        else:
            path = f"{self.path}/extras/masks/{mask_set}/{stem}.png"
        try:
            with open(path, "rb") as f:
                data = f.read()
        except FileNotFoundError:
            if mask_set in (GT_MASK_SET, GT_FULL_MASK_SET):
                raise DatasetFormatError(f"mask file {located(path)} is missing") from None
            return None
        return decode_png_mask(data, path, shape=self._intrinsics.shape)

    def pose_sets(self) -> tuple[str, ...]:
        d = self.path / "extras" / "poses"
        return tuple(sorted(p.stem for p in d.glob("*.csv"))) if d.is_dir() else ()

    def detector_poses(self, pose_set: str) -> DetectorPoses:
        if pose_set not in self.pose_sets():
            raise KeyError(f"no pose set {pose_set!r} in {self.path}; sets: {self.pose_sets()}")
        path = self.path / "extras" / "poses" / f"{pose_set}.csv"
        text = read_file_bytes(path, "poses").decode("utf-8", errors="replace")
        n = len(self)
        T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
        valid = np.zeros(n, dtype=bool)
        index = {im: k for k, im in enumerate(self._im_ids)}
        reader = csv.DictReader(io.StringIO(text))
        want = ["scene_id", "im_id", "obj_id", "score", "R", "t", "time"]
        if reader.fieldnames != want:
            raise DatasetFormatError(f"{located(path, 1)}: header must be {','.join(want)}")
        for line, row in enumerate(reader, start=2):
            try:
                if int(row["obj_id"]) != self._obj_id:
                    continue
                k = index[int(row["im_id"])]
                R = np.array([float(x) for x in row["R"].split()]).reshape(3, 3)
                t = np.array([float(x) for x in row["t"].split()]) / 1000.0
                if t.shape != (3,) or not np.isfinite(t).all():
                    raise ValueError(f"t must be 3 finite numbers [mm], got {row['t']!r}")
                T[k] = transform_from_rt(as_rotation_matrix(R), t)
            except (KeyError, ValueError, TypeError, AttributeError) as e:
                raise DatasetFormatError(f"{located(path, line)}: bad pose row: {e}") from None
            valid[k] = True
        return DetectorPoses(T_cam_obj=T, valid=valid)

    def ground_truth(self) -> PoseTrack | None:
        if not any(self._gt.values()):
            return None
        path = self.path / "scene_gt.json"
        n = len(self)
        T = np.full((n, 4, 4), np.nan)
        for k in range(n):
            idx = self._gt_index(k)
            if idx is None:
                continue
            o = self._gt[self._im_ids[k]][idx]
            R = self._numbers(o.get("cam_R_m2c"), 9, path, f"cam_R_m2c of image {self._im_ids[k]}")
            t = self._numbers(o.get("cam_t_m2c"), 3, path, f"cam_t_m2c of image {self._im_ids[k]}")
            try:
                T[k] = transform_from_rt(as_rotation_matrix(R.reshape(3, 3)), t / 1000.0)
            except ValueError as e:
                raise DatasetFormatError(f"{located(path)}: image {self._im_ids[k]}: {e}") from None
        v = np.full((n, 3), np.nan)
        w = np.full((n, 3), np.nan)
        vel_path = self.path / "extras" / "scene_gt_velocity.json"
        if vel_path.is_file():
            vel = self._json_by_id(vel_path, "velocities")
            for k, im in enumerate(self._im_ids):
                entries = vel.get(im, [])
                try:
                    ours = [o for o in entries if int(o.get("obj_id", -1)) == self._obj_id]
                except (AttributeError, TypeError, ValueError):
                    raise DatasetFormatError(
                        f"{located(vel_path)}: image {im} needs a list of objects with an "
                        f"integer obj_id, got {entries!r:.80}"
                    ) from None
                for o in ours:
                    v[k] = self._numbers(o.get("v_obj_mps"), 3, vel_path, f"v_obj_mps of {im}")
                    w[k] = self._numbers(o.get("w_radps"), 3, vel_path, f"w_radps of {im}")
        return PoseTrack(t_s=self._t_s.copy(), T_cam_obj=T, v_obj_mps=v, w_radps=w)

    def camera_poses(self) -> F64:
        return self._T_world_cam.copy()

    def object_model(self) -> ObjectModel | None:
        extras = self.path / "extras" / "model"
        if (extras / "points.xyz").is_file():
            points = read_points_xyz(extras / "points.xyz")
            if (extras / "mesh.obj").is_file():
                vertices, faces = read_mesh_obj(extras / "mesh.obj")
            else:
                vertices, faces = points, np.zeros((0, 3), np.int64)
            return ObjectModel(
                name=self._object_name, vertices_m=vertices, faces=faces, model_points_m=points
            )
        for models in (self.path / "models", self.path.parent.parent / "models"):
            ply = models / f"obj_{self._obj_id:06d}.ply"
            if ply.is_file():
                vertices, faces = read_mesh_ply_mm(ply)
                return ObjectModel(
                    name=self._object_name,
                    vertices_m=vertices,
                    faces=faces,
                    model_points_m=vertices,
                    mesh_path=ply,
                )
        return None

    def metadata(self) -> Mapping[str, Any]:
        return dict(self._metadata)

    def __repr__(self) -> str:
        return f"BopSequence({str(self.path)!r}, {len(self)} frames, obj_id {self._obj_id})"
