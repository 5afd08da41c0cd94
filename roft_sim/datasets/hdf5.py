"""One HDF5 file per sequence: streaming writer and lazy reader.

Layout of ``<root>/<sequence_name>.h5`` (every dataset carries ``units`` and ``description``
attributes; the root carries the metadata; see docs/formats.md)::

    /time_s (N,) f8                /T_world_cam (N,4,4) f8
    /rgb (N,H,W,3) u1              /depth_m (N,H,W) f4            chunked (1, ...) per frame
    /gt/T_cam_obj (N,4,4) f8       /gt/v_obj_mps (N,3) f8         /gt/w_radps (N,3) f8
    /masks/<set>/mask (N,H,W) u1 0/1     /masks/<set>/present (N,) u1   (sets gt, gt_full, ...)
    /flow/<set>/flow (N,Hg,Wg,2) f4 [px] or i2 [px*32]            /flow/<set>/present (N,) u1
    /flow/<set>/valid (N,Hg,Wg) u1       /flow/<set>/valid_present (N,) u1
    /poses/<set>/T_cam_obj (N,4,4) f8    /poses/<set>/valid (N,) u1
    /model/vertices_m (V,3) f8  /model/faces (F,3) i8  /model/model_points_m (M,3) f8

Crash safety and parallel workers: frames are first written as small per-frame HDF5 files in
``<name>.h5.parts/`` (each written to memory and renamed into place, so a crash leaves every
completed frame readable); :meth:`Hdf5Writer.finalize` copies their compressed chunks unchanged
into a temp file (``write_direct_chunk``, no recompression) and renames it to ``<name>.h5``.
The ``.h5`` therefore exists only when complete; a ``.parts`` folder marks an unfinished one.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any, Literal

import h5py
import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.atomic_files import atomic_path, atomic_write_bytes
from roft_sim.datasets.base import GT_MASK_SET, DetectorPoses
from roft_sim.datasets.fast_ycb_codec import S10_5_SCALE
from roft_sim.datasets.frames import GT_FULL_MASK_SET, DatasetFrame
from roft_sim.datasets.metadata import dumps_json
from roft_sim.datasets.reader_base import SequenceReaderBase, check_time_stamps
from roft_sim.datasets.writer_base import StreamingWriter, WriterSettings
from roft_sim.errors import ConfigError, DatasetFormatError, located
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.geometry.se3 import as_transform
from roft_sim.records import FlowField, ObjectModel, PoseTrack

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]
U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]

__all__ = ["Hdf5Writer", "Hdf5Sequence", "HDF5_FORMAT_NAME", "HDF5_COMPRESSIONS"]

HDF5_FORMAT_NAME = "roft_sim-hdf5"
"""Value of the root attribute ``format`` of our files."""
HDF5_COMPRESSIONS = ("gzip", "lzf")
_ROW_BLOCK = 256
"""Frames per block when finalize writes the small per-frame datasets (bounded buffers)."""
_H5_ERRORS = (OSError, KeyError, ValueError, RuntimeError, TypeError, IndexError)


def _filters(compression: str, level: int, *, shuffle: bool) -> dict[str, Any]:
    if compression == "gzip":
        return {"compression": "gzip", "compression_opts": level, "shuffle": shuffle}
    return {"compression": "lzf", "shuffle": shuffle}


class Hdf5Writer(StreamingWriter):
    """Streams one sequence into ``<root>/<sequence_name>.h5`` (see module doc).

    Options (``settings.options``): ``compression`` (``gzip`` or ``lzf``) and
    ``compression_level`` (gzip 1-9).
    """

    FORMAT = "hdf5"

    def __init__(
        self,
        root: Path,
        settings: WriterSettings,
        *,
        object_model: ObjectModel | None,
        resume: bool,
    ) -> None:
        compression = settings.options.get("compression", "gzip")
        level = settings.options.get("compression_level", 4)
        if compression not in HDF5_COMPRESSIONS:
            raise ConfigError(f"hdf5 compression {compression!r}: expected one of gzip, lzf")
        if not isinstance(level, int) or not 1 <= level <= 9:
            raise ConfigError(f"hdf5 compression_level must be an int in 1..9, got {level!r}")
        root = Path(root)
        super().__init__(
            sequence_path=root / f"{settings.sequence_name}.h5",
            parts_dir=root / f"{settings.sequence_name}.h5.parts",
            settings=settings,
            object_model=object_model,
            resume=resume,
        )

    # ------------------------------------------------------------------------- hooks
    def _metadata_path(self) -> Path:
        return self.sequence_path

    def _finished_n_frames(self) -> int | None:
        with h5py.File(self.sequence_path, "r") as f:
            return int(f.attrs["n_frames"])

    def _exists_non_empty(self) -> bool:
        return self.sequence_path.exists()

    def _extra_package_names(self) -> tuple[str, ...]:
        return ("h5py",)

    def _format_options(self) -> dict[str, Any]:
        return {
            "compression": self.settings.options.get("compression", "gzip"),
            "compression_level": self.settings.options.get("compression_level", 4),
            "hdf5_library": h5py.version.hdf5_version,
        }

    def _format_conventions(self) -> dict[str, str]:
        return {
            "layout": "see the 'description' and 'units' attributes of every dataset",
            "booleans": "stored as uint8 0/1",
            "flow_s10_5": "int16 flow datasets hold px * 32 (attribute scale = 1/32)",
        }

    def _kw(self, *, shuffle: bool) -> dict[str, Any]:
        opts = self.settings.options
        return _filters(
            opts.get("compression", "gzip"), opts.get("compression_level", 4), shuffle=shuffle
        )

    def _frame_arrays(self, frame: DatasetFrame) -> dict[str, tuple[np.ndarray, bool]]:
        """Per-frame bulk arrays: HDF5 path -> (array without the frame axis, shuffle)."""
        arrays: dict[str, tuple[np.ndarray, bool]] = {
            "rgb": (frame.rgb, False),
            "depth_m": (frame.depth_m, True),
        }
        masks = {GT_MASK_SET: frame.gt_mask, GT_FULL_MASK_SET: frame.gt_mask_full}
        masks.update(frame.detector_masks)
        for name, m in masks.items():
            if m is not None:
                arrays[f"masks/{name}/mask"] = (m.view(np.uint8), False)
        for name, flow in frame.flows.items():
            if self.settings.flow_encoding(name) == "s10.5":
                q = np.rint(flow.flow_px.astype(np.float64) * S10_5_SCALE)
                if q.size and (q.min() < -32768 or q.max() > 32767):
                    raise ValueError(
                        f"flow {name!r} of frame {frame.k} does not fit S10.5 (|flow| < 1024 px)"
                    )
                arrays[f"flow/{name}/flow"] = (q.astype(np.int16), True)
            else:
                arrays[f"flow/{name}/flow"] = (flow.flow_px, True)
            if flow.valid is not None:
                arrays[f"flow/{name}/valid"] = (flow.valid.view(np.uint8), False)
        return arrays

    def _write_frame_files(self, frame: DatasetFrame) -> dict[str, Any]:
        arrays = self._frame_arrays(frame)
        buffer = io.BytesIO()
        with h5py.File(buffer, "w") as f:
            for key, (a, shuffle) in arrays.items():
                f.create_dataset(
                    key, data=a[None], chunks=(1, *a.shape), **self._kw(shuffle=shuffle)
                )
        atomic_write_bytes(self._part_path(frame.k), buffer.getvalue())
        return {"arrays": {k: [str(a.dtype), list(a.shape)] for k, (a, _) in arrays.items()}}

    def _part_path(self, k: int) -> str:
        return os.path.join(self.parts_dir, f"frame_{k:06d}.h5")

    def _write_model(self, model: ObjectModel) -> None:
        buffer = io.BytesIO()
        with h5py.File(buffer, "w") as f:
            f.attrs["name"] = model.name
            f.create_dataset("vertices_m", data=model.vertices_m.astype(np.float64))
            f.create_dataset("faces", data=model.faces.astype(np.int64))
            f.create_dataset("model_points_m", data=model.model_points_m.astype(np.float64))
        atomic_write_bytes(self.parts_dir / "model.h5", buffer.getvalue())

    # ---------------------------------------------------------------------- assembly
    def _assemble(
        self, records: Callable[[], Iterator[dict[str, Any]]], metadata: dict[str, Any]
    ) -> None:
        n = self.settings.n_frames
        layouts: dict[str, tuple[str, tuple[int, ...]]] = {}
        for r in records():
            for key, (dtype, shape) in r["arrays"].items():
                layouts.setdefault(key, (dtype, tuple(shape)))
        gt = metadata["ground_truth"]
        mask_sets = [GT_MASK_SET] if gt["masks"] else []
        mask_sets += [GT_FULL_MASK_SET] if gt["full_masks"] else []
        mask_sets += list(metadata["sets"]["mask"])
        for name in mask_sets:  # a detector that missed on every frame still gets its dataset
            layouts.setdefault(f"masks/{name}/mask", ("uint8", self.settings.intrinsics.shape))
        with atomic_path(self.sequence_path) as tmp, h5py.File(tmp, "w") as f:
            self._write_root_attributes(f, metadata)
            rows = self._row_datasets(f, metadata, mask_sets, layouts)
            targets = {}
            for key, (dtype, shape) in sorted(layouts.items()):
                targets[key] = f.create_dataset(
                    key,
                    shape=(n, *shape),
                    dtype=dtype,
                    chunks=(1, *shape),
                    fillvalue=0,
                    **self._kw(shuffle=dtype != "uint8"),
                )
                _describe(targets[key], key, dtype)
            buffers = [np.zeros((_ROW_BLOCK, *d.shape[1:]), d.dtype) for d, _ in rows]

            def flush(end: int) -> None:
                start = (end - 1) // _ROW_BLOCK * _ROW_BLOCK
                for (dataset, _), buffer in zip(rows, buffers, strict=True):
                    dataset[start:end] = buffer[: end - start]

            for r in records():  # one frame at a time: flat memory
                k = r["k"]
                for (_, value_of), buffer in zip(rows, buffers, strict=True):
                    buffer[k % _ROW_BLOCK] = value_of(r)
                if (k + 1) % _ROW_BLOCK == 0 or k + 1 == self.settings.n_frames:
                    flush(k + 1)
                if r["arrays"]:
                    with h5py.File(self._part_path(k), "r") as part:
                        for key in r["arrays"]:
                            source = part[key]
                            mask, chunk = source.id.read_direct_chunk((0,) * source.ndim)
                            offset = (k,) + (0,) * (source.ndim - 1)
                            targets[key].id.write_direct_chunk(offset, chunk, mask)
            for name, info in metadata["sets"]["flow"].items():
                g = f.require_group(f"flow/{name}")
                g.attrs["grid_px"] = info["grid_px"]
                g.attrs["encoding"] = info["encoding"]
            self._write_model_group(f)

    def _write_root_attributes(self, f: h5py.File, metadata: dict[str, Any]) -> None:
        s = self.settings
        f.attrs["format"] = HDF5_FORMAT_NAME
        f.attrs["format_version"] = metadata["format_version"]
        f.attrs["sequence_name"] = s.sequence_name
        f.attrs["object_name"] = s.object_name
        f.attrs["n_frames"] = s.n_frames
        f.attrs["fps"] = s.fps
        f.attrs["width_px"] = s.intrinsics.width_px
        f.attrs["height_px"] = s.intrinsics.height_px
        f.attrs["K"] = s.intrinsics.K
        f.attrs["metadata_json"] = dumps_json(metadata)

    def _row_datasets(
        self,
        f: h5py.File,
        metadata: dict[str, Any],
        mask_sets: list[str],
        layouts: Mapping[str, tuple[str, tuple[int, ...]]],
    ) -> list[tuple[h5py.Dataset, Callable[[dict[str, Any]], Any]]]:
        """The small per-frame datasets, created empty, each with how to get its row from a
        frame record."""
        specs: list[tuple[str, tuple[int, ...], str, str, str, Callable[..., Any]]] = [
            ("time_s", (), "f8", "s", "camera time stamp t_k", lambda r: r["t_s"]),
            (
                "T_world_cam", (4, 4), "f8", "m",
                "camera pose in the world per frame (4x4, p_world = T p_cam)",
                lambda r: r["T_world_cam"],
            ),
        ]  # fmt: skip
        gt = metadata["ground_truth"]
        if gt["poses"]:
            specs.append((
                "gt/T_cam_obj", (4, 4), "f8", "m",
                "ground-truth object pose in the OpenCV camera frame (4x4, p_cam = T p_obj)",
                lambda r: r["gt_T_cam_obj"],
            ))  # fmt: skip
        if gt["velocities"]:
            specs.append((
                "gt/v_obj_mps", (3,), "f8", "m/s",
                "velocity of the object origin, d/dt t_cam_obj, camera frame",
                lambda r: r["gt_v_obj_mps"],
            ))  # fmt: skip
            specs.append((
                "gt/w_radps", (3,), "f8", "rad/s",
                "angular velocity, camera frame: dR_cam_obj/dt = [w]x R_cam_obj",
                lambda r: r["gt_w_radps"],
            ))  # fmt: skip
        for name in metadata["sets"]["pose"]:
            specs.append((
                f"poses/{name}/T_cam_obj", (4, 4), "f8", "m",
                "detector object pose per frame (identity where valid = 0)",
                lambda r, n=name: np.eye(4) if r["detector_poses"][n] is None
                else r["detector_poses"][n],
            ))  # fmt: skip
            specs.append((
                f"poses/{name}/valid", (), "u1", "",
                "1 = the detector returned a pose on this frame, 0 = miss",
                lambda r, n=name: r["detector_poses"][n] is not None,
            ))  # fmt: skip
        for name in mask_sets:
            key = f"masks/{name}/mask"
            specs.append((
                f"masks/{name}/present", (), "u1", "", "1 = a mask is stored for this frame",
                lambda r, key=key: key in r["arrays"],
            ))  # fmt: skip
        for name in metadata["sets"]["flow"]:
            for leaf, flag in (("flow", "present"), ("valid", "valid_present")):
                key = f"flow/{name}/{leaf}"
                if key in layouts:
                    specs.append((
                        f"flow/{name}/{flag}", (), "u1", "", f"1 = {leaf} stored for this frame",
                        lambda r, key=key: key in r["arrays"],
                    ))  # fmt: skip
        rows = []
        for key, tail, dtype, units, description, value_of in specs:
            d = f.create_dataset(key, shape=(self.settings.n_frames, *tail), dtype=dtype)
            d.attrs["units"] = units
            d.attrs["description"] = description
            rows.append((d, value_of))
        return rows

    def _write_model_group(self, f: h5py.File) -> None:
        path = self.parts_dir / "model.h5"
        if not path.is_file():
            return
        with h5py.File(path, "r") as m:
            g = f.create_group("model")
            g.attrs["name"] = m.attrs["name"]
            _put(g, "vertices_m", m["vertices_m"][()], "m", "mesh vertices, object frame")
            _put(g, "faces", m["faces"][()], "", "triangles, 0-based vertex indices")
            _put(
                g,
                "model_points_m",
                m["model_points_m"][()],
                "m",
                "model points for ADD metrics, object frame",
            )


def _put(group: h5py.Group, key: str, data: np.ndarray, units: str, description: str) -> None:
    d = group.create_dataset(key, data=data)
    d.attrs["units"] = units
    d.attrs["description"] = description


_DESCRIPTIONS = {
    "rgb": ("", "RGB image per frame, uint8, RGB channel order"),
    "depth_m": ("m", "z-depth per frame, float32, 0 = no measurement"),
    "mask": ("", "mask per frame, uint8 0/1 (1 = object); see 'present' for detector misses"),
    "flow": ("px", "flow F_k from frame k-1 to k, (du, dv); frame 0 holds zeros"),
    "valid": ("", "1 where the flow vector is meaningful"),
}


def _describe(d: h5py.Dataset, key: str, dtype: str) -> None:
    units, description = _DESCRIPTIONS[key.rsplit("/", 1)[-1]]
    if key.endswith("/flow") and dtype == "int16":
        units, description = "px/32", description + "; S10.5 fixed point: divide by 32"
        d.attrs["scale"] = 1.0 / S10_5_SCALE
    d.attrs["units"] = units
    d.attrs["description"] = description


class Hdf5Sequence(SequenceReaderBase):
    """A sequence in one of our HDF5 files, read lazily (implements ``Sequence``).

    The file is opened on first use and kept open; the object pickles (it reopens the file in
    the new process). Use :meth:`close` or ``with`` to release the file.

    Raises:
        DatasetFormatError: not one of our HDF5 files, a missing dataset, or corrupt data
            (naming the file, the dataset and the frame).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        parts = self.path.with_name(self.path.name + ".parts")
        if not self.path.is_file():
            if parts.is_dir():
                raise DatasetFormatError(
                    f"{located(self.path)} is unfinished: its frames are in {parts.name}/ and "
                    "finalize() was not run; resume the generator or call finalize()"
                )
            raise DatasetFormatError(f"HDF5 sequence file {located(self.path)} is missing")
        self._file: h5py.File | None = None
        with self._guard("the root attributes"):
            f = self._h5()
            if f.attrs.get("format") != HDF5_FORMAT_NAME:
                raise DatasetFormatError(
                    f"{located(self.path)} is an HDF5 file but not a roft_sim sequence (root "
                    f"attribute format = {f.attrs.get('format')!r}, expected "
                    f"{HDF5_FORMAT_NAME!r})"
                )
            self._n = int(f.attrs["n_frames"])
            self._fps = int(f.attrs["fps"])
            self._name = str(f.attrs["sequence_name"])
            self._object_name = str(f.attrs["object_name"])
            self._metadata = json.loads(str(f.attrs["metadata_json"]))
            self._intrinsics = CameraIntrinsics.from_matrix(
                np.asarray(f.attrs["K"], dtype=np.float64),
                int(f.attrs["width_px"]),
                int(f.attrs["height_px"]),
            )
            self._t_s = self._small("time_s", (self._n,))
            check_time_stamps(self._t_s, self.path, lambda k: f"/time_s frame {k}")
            self._T_world_cam = self._transforms("T_world_cam")
            for key in ("rgb", "depth_m"):
                want = (self._n, *self._intrinsics.shape) + ((3,) if key == "rgb" else ())
                if f[key].shape != want:
                    raise DatasetFormatError(
                        f"{located(self.path)}: dataset /{key} has shape {f[key].shape}, "
                        f"expected {want}"
                    )

    # -------------------------------------------------------------------------- file
    def _h5(self) -> h5py.File:
        if self._file is None:
            self._file = h5py.File(self.path, "r")
        return self._file

    def close(self) -> None:
        """Closes the file (it is reopened on the next read)."""
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> Hdf5Sequence:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_file"] = None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    def _guard(self, what: str) -> _Guard:
        return _Guard(self.path, what)

    def _small(self, key: str, shape: tuple[int, ...]) -> np.ndarray:
        f = self._h5()
        if key not in f:
            raise DatasetFormatError(f"{located(self.path)} has no dataset /{key}")
        data = np.asarray(f[key][()])
        if data.shape != shape:
            raise DatasetFormatError(
                f"{located(self.path)}: /{key} has shape {data.shape}, expected {shape}"
            )
        if data.dtype.kind == "f" and not np.isfinite(data).all():
            raise DatasetFormatError(f"{located(self.path)}: /{key} holds NaN/inf values")
        return data

    def _transforms(self, key: str) -> np.ndarray:
        """``(N, 4, 4)`` rigid transforms [m] from dataset ``key``, checked as other readers do."""
        T = self._small(key, (self._n, 4, 4))
        try:
            as_transform(T)
        except ValueError:
            for k in range(self._n):  # name the first bad frame
                try:
                    as_transform(T[k])
                except ValueError as e:
                    raise DatasetFormatError(
                        f"{located(self.path)}: /{key} frame {k} is not a rigid transform: {e}"
                    ) from None
        return T

    def _groups(self, key: str) -> tuple[str, ...]:
        with self._guard(f"/{key}"):
            f = self._h5()
            return tuple(sorted(f[key].keys())) if key in f else ()

    # ------------------------------------------------------------------------ Sequence
    def rgb(self, k: int) -> U8:
        k = self._check_k(k)
        with self._guard(f"/rgb frame {k}"):
            return np.asarray(self._h5()["rgb"][k], dtype=np.uint8)

    def depth(self, k: int) -> F32:
        k = self._check_k(k)
        with self._guard(f"/depth_m frame {k}"):
            depth = np.asarray(self._h5()["depth_m"][k], dtype=np.float32)
        if not np.isfinite(depth).all():
            raise DatasetFormatError(f"{located(self.path)}: /depth_m frame {k} has NaN/inf")
        return depth

    def flow_sets(self) -> tuple[str, ...]:
        return self._cached_sets("flow", self._find_flow_sets)

    def _find_flow_sets(self) -> tuple[str, ...]:
        return self._groups("flow")

    def flow(self, k: int, flow_set: str) -> FlowField | None:
        if flow_set not in self.flow_sets():
            raise KeyError(f"no flow set {flow_set!r} in {self.path}; sets: {self.flow_sets()}")
        if self._check_k(k) == 0:
            return None
        with self._guard(f"/flow/{flow_set} frame {k}"):
            g = self._h5()["flow"][flow_set]
            if not g["present"][k]:
                raise DatasetFormatError(f"{located(self.path)}: /flow/{flow_set} lacks frame {k}")
            raw = np.asarray(g["flow"][k])
            flow = (
                raw.astype(np.float32) / np.float32(S10_5_SCALE)
                if raw.dtype == np.int16
                else raw.astype(np.float32)
            )
            valid = None
            if "valid" in g and g["valid_present"][k]:
                valid = np.asarray(g["valid"][k]) != 0
            grid = int(g.attrs["grid_px"])
        if not np.isfinite(flow).all():
            raise DatasetFormatError(f"{located(self.path)}: /flow/{flow_set} frame {k} has NaN")
        return FlowField(flow_px=flow, from_k=k - 1, to_k=k, grid_px=grid, valid=valid)

    def mask_sets(self) -> tuple[str, ...]:
        return self._cached_sets("mask", self._find_mask_sets)

    def _find_mask_sets(self) -> tuple[str, ...]:
        names = self._groups("masks")
        first = [n for n in (GT_MASK_SET, GT_FULL_MASK_SET) if n in names]
        return tuple(first + [n for n in names if n not in first])

    def mask(self, k: int, mask_set: str) -> Bool | None:
        if mask_set not in self.mask_sets():
            raise KeyError(f"no mask set {mask_set!r} in {self.path}; sets: {self.mask_sets()}")
        k = self._check_k(k)
        with self._guard(f"/masks/{mask_set} frame {k}"):
            g = self._h5()["masks"][mask_set]
            if not g["present"][k]:
                return None
            mask: Bool = np.asarray(g["mask"][k]) != 0
            return mask

    def pose_sets(self) -> tuple[str, ...]:
        return self._groups("poses")

    def detector_poses(self, pose_set: str) -> DetectorPoses:
        if pose_set not in self.pose_sets():
            raise KeyError(f"no pose set {pose_set!r} in {self.path}; sets: {self.pose_sets()}")
        with self._guard(f"/poses/{pose_set}"):
            T = self._transforms(f"poses/{pose_set}/T_cam_obj")
            valid = self._small(f"poses/{pose_set}/valid", (self._n,)) != 0
        return DetectorPoses(T_cam_obj=T, valid=valid)

    def ground_truth(self) -> PoseTrack | None:
        with self._guard("/gt"):
            if "gt" not in self._h5():
                return None
            T = self._transforms("gt/T_cam_obj")
            if "v_obj_mps" in self._h5()["gt"]:
                v = self._small("gt/v_obj_mps", (self._n, 3))
                w = self._small("gt/w_radps", (self._n, 3))
            else:
                v = np.full((self._n, 3), np.nan)
                w = np.full((self._n, 3), np.nan)
        return PoseTrack(t_s=self._t_s.copy(), T_cam_obj=T, v_obj_mps=v, w_radps=w)

    def camera_poses(self) -> F64:
        return self._T_world_cam.copy()

    def object_model(self) -> ObjectModel | None:
        with self._guard("/model"):
            f = self._h5()
            if "model" not in f:
                return None
            g = f["model"]
            return ObjectModel(
                name=str(g.attrs["name"]),
                vertices_m=np.asarray(g["vertices_m"][()], dtype=np.float64),
                faces=np.asarray(g["faces"][()], dtype=np.int64),
                model_points_m=np.asarray(g["model_points_m"][()], dtype=np.float64),
            )

    def metadata(self) -> Mapping[str, Any]:
        return dict(self._metadata)

    def __repr__(self) -> str:
        return f"Hdf5Sequence({str(self.path)!r}, {self._n} frames)"


class _Guard:
    """Turns h5py/HDF5 errors into DatasetFormatError naming the file and what was read."""

    def __init__(self, path: Path, what: str) -> None:
        self.path, self.what = path, what

    def __enter__(self) -> None:
        return None

    def __exit__(
        self, exc_type: type | None, exc: BaseException | None, tb: object
    ) -> Literal[False]:
        if (
            exc is not None
            and isinstance(exc, _H5_ERRORS)
            and not isinstance(exc, DatasetFormatError | IndexError)
        ):
            raise DatasetFormatError(
                f"{located(self.path)}: cannot read {self.what}: {type(exc).__name__}: {exc}"
            ) from None
        return False
