"""Entry points over the three formats: :func:`open_writer`, :func:`open_sequence`,
:func:`list_sequences`, and :func:`write_sequence` (any ``Sequence`` -> any format)."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from collections.abc import Sequence as SequenceABC
from pathlib import Path
from typing import Any, Literal, cast

import numpy as np

from roft_sim.datasets.base import GT_MASK_SET, Sequence
from roft_sim.datasets.bop import BopSequence, BopWriter, is_bop_scene
from roft_sim.datasets.fast_ycb import PARTS_DIR_NAME, FastYcbSequence, FastYcbWriter
from roft_sim.datasets.fast_ycb import is_fast_ycb_sequence as _is_fast_ycb
from roft_sim.datasets.fast_ycb_codec import CV_16SC2
from roft_sim.datasets.frames import GT_FULL_MASK_SET, DatasetFrame, FlowEncoding, SequenceWriter
from roft_sim.datasets.hdf5 import Hdf5Sequence, Hdf5Writer
from roft_sim.datasets.image_files import PNG_COMPRESSION
from roft_sim.datasets.metadata import read_json
from roft_sim.datasets.writer_base import RESERVED_METADATA_KEYS, WriterSettings, model_digest
from roft_sim.errors import ConfigError, DatasetFormatError, located
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import FlowField, ObjectModel

__all__ = [
    "stored_flow_encodings",
    "DatasetFormat",
    "DATASET_FORMATS",
    "open_writer",
    "open_sequence",
    "detect_format",
    "list_sequences",
    "find_sequences",
    "dataset_frames",
    "write_sequence",
]

DatasetFormat = Literal["fast-ycb", "bop", "hdf5"]
DATASET_FORMATS: tuple[str, ...] = ("fast-ycb", "bop", "hdf5")
_HDF5_SUFFIXES = (".h5", ".hdf5")


def open_writer(
    fmt: DatasetFormat,
    root: str | Path,
    *,
    sequence_name: str,
    object_name: str,
    intrinsics: CameraIntrinsics,
    fps: int,
    n_frames: int,
    metadata: Mapping[str, Any],
    object_model: ObjectModel | None,
    flow_encodings: Mapping[str, FlowEncoding] | None = None,
    resume: bool = False,
    depth_scale_mm: float | None = None,
    bop_obj_id: int | None = None,
    bop_scene_id: int | None = None,
    compression: Literal["gzip", "lzf"] | None = None,
    compression_level: int | None = None,
    png_compression: int = PNG_COMPRESSION,
) -> SequenceWriter:
    """Opens a streaming writer for one sequence.

    Args:
        fmt: ``fast-ycb`` (folder ``root/sequence_name/``), ``bop`` (numbered scene folder
            ``root/000001/``, see :func:`~roft_sim.datasets.bop.bop_scene_folder`) or ``hdf5``
            (file ``root/sequence_name.h5``).
        root: dataset root folder (created if needed).
        sequence_name: folder/file name of the sequence, e.g. ``003_cracker_box``.
        object_name: the object's registry name (mask file names, model folder).
        intrinsics: the camera; every frame must have its resolution.
        fps: nominal camera rate [Hz].
        n_frames: number of frames the sequence will have (finalize checks all are written).
        metadata: JSON-able user metadata written into the sequence's metadata (scenario,
            resolved config, seed, ...); must not use the writer's own keys.
        object_model: mesh and model points in the object frame of the poses, or None.
        flow_encodings: flow set name -> ``float32`` (default) or ``s10.5``.
        resume: continue an unfinished sequence (settings must match) instead of refusing a
            non-empty output; on a finished sequence the writer reports every frame complete.
        depth_scale_mm: BOP only: depth unit of the uint16 PNGs [mm] (default 0.1).
        bop_obj_id: BOP only: ``obj_id`` (default: the YCB-V id of the object, else 1).
        bop_scene_id: BOP only: the scene folder number of a sequence whose name is not a
            number (default: the next free one; ``<root>/scene_names.json`` maps it to the name).
        compression: HDF5 only: ``gzip`` (default) or ``lzf``.
        compression_level: HDF5 only: gzip level 1-9 (default 4).
        png_compression: compression level 0-9 of the PNG files (fast-ycb, bop; default
            :data:`~roft_sim.datasets.image_files.PNG_COMPRESSION`).

    Returns:
        A picklable :class:`~roft_sim.datasets.SequenceWriter`.

    Raises:
        ConfigError: bad settings, a non-empty output without ``resume``, or a resume with
            different settings.
    """
    if fmt not in DATASET_FORMATS:
        raise ConfigError(f"unknown dataset format {fmt!r}; expected one of {DATASET_FORMATS}")
    options: dict[str, Any] = {}
    per_format: dict[str, dict[str, Any]] = {
        "bop": {"depth_scale_mm": depth_scale_mm, "obj_id": bop_obj_id, "scene_id": bop_scene_id},
        "hdf5": {"compression": compression, "compression_level": compression_level},
    }
    for name, opts in per_format.items():
        for key, value in opts.items():
            if value is None:
                continue
            if fmt != name:
                raise ConfigError(f"option {key} applies to the {name} format only, not {fmt}")
            options[key] = value
    settings = WriterSettings(
        format=fmt,
        sequence_name=sequence_name,
        object_name=object_name,
        intrinsics=intrinsics,
        fps=fps,
        n_frames=n_frames,
        metadata=dict(metadata),
        flow_encodings=dict(flow_encodings or {}),
        options=options,
        model_digest=model_digest(object_model),
        png_compression=png_compression,
    )
    writer_types: dict[str, type[FastYcbWriter | BopWriter | Hdf5Writer]] = {
        "fast-ycb": FastYcbWriter,
        "bop": BopWriter,
        "hdf5": Hdf5Writer,
    }
    cls = writer_types[fmt]
    return cls(Path(root), settings, object_model=object_model, resume=resume)


def detect_format(path: str | Path) -> DatasetFormat:
    """The format of a sequence at ``path`` (a folder or an ``.h5`` file).

    Raises:
        DatasetFormatError: ``path`` is none of the three (the message says what was found).
    """
    path = Path(path)
    if path.is_file():
        with open(path, "rb") as f:
            if f.read(8) == b"\x89HDF\r\n\x1a\n":
                return "hdf5"
        raise DatasetFormatError(f"{located(path)} is a file but not an HDF5 file")
    if path.suffix in _HDF5_SUFFIXES and path.with_name(path.name + ".parts").is_dir():
        return "hdf5"
    if path.is_dir():
        settings = path / PARTS_DIR_NAME / "writer.json"
        if settings.is_file():  # unfinished: its reader will say so clearly
            fmt = read_json(settings, "writer settings").get("format")
            if fmt in ("fast-ycb", "bop"):
                return cast(DatasetFormat, fmt)
        if _is_fast_ycb(path):
            return "fast-ycb"
        if is_bop_scene(path):
            return "bop"
        raise DatasetFormatError(
            f"{located(path)} is no sequence: expected cam_K.json + data.txt (fast-ycb), "
            "scene_camera.json (bop) or an .h5 file; use list_sequences() for a dataset root"
        )
    raise DatasetFormatError(f"dataset path {located(path)} does not exist")


def open_sequence(
    path: str | Path,
    fmt: str | None = None,
    *,
    object_name: str | None = None,
    fps: int | None = None,
) -> Sequence:
    """Opens one sequence lazily, detecting its format unless ``fmt`` is given.

    Args:
        path: a Fast-YCB sequence folder, a BOP scene folder or an ``.h5`` file.
        fmt: ``fast-ycb``, ``bop`` or ``hdf5``; None = detect.
        object_name: Fast-YCB: the name in mask files; BOP: which object of the scene.
        fps: nominal rate for data that does not state it.

    Raises:
        DatasetFormatError: unknown layout or malformed files.
    """
    fmt = fmt or detect_format(path)
    if fmt == "fast-ycb":
        return FastYcbSequence(path, object_name=object_name, fps=fps)
    if fmt == "bop":
        return BopSequence(path, object_name=object_name, fps=fps)
    if fmt == "hdf5":
        return Hdf5Sequence(path)
    raise ConfigError(f"unknown dataset format {fmt!r}; expected one of {DATASET_FORMATS}")


def list_sequences(root: str | Path, *, max_depth: int = 3) -> list[Path]:
    """Sequences under a dataset root (sorted): Fast-YCB folders, BOP scenes, ``.h5`` files.

    ``root`` itself is returned when it is a sequence. Folders are searched ``max_depth``
    levels deep (BOP: ``root/<split>/<scene>``), never inside a sequence.
    """
    root = Path(root)
    found: list[Path] = []

    def visit(path: Path, depth: int) -> None:
        if path.is_file():
            if path.suffix in _HDF5_SUFFIXES:
                found.append(path)
            return
        if _is_fast_ycb(path) or is_bop_scene(path):
            found.append(path)
            return
        if depth >= max_depth or not path.is_dir():
            return
        for child in sorted(path.iterdir()):
            if not child.name.startswith("."):
                visit(child, depth + 1)

    if not root.exists():
        raise DatasetFormatError(f"dataset root {located(root)} does not exist")
    visit(root, 0)
    return found


def find_sequences(paths: SequenceABC[str | Path]) -> list[Path]:
    """Sequence paths under ``paths``: each is a sequence (folder or ``.h5``) or a dataset root.

    Raises:
        DatasetFormatError: a path does not exist or holds no sequence.
    """
    found: list[Path] = []
    for p in map(Path, paths):
        if not p.exists():
            raise DatasetFormatError(
                f"dataset path {str(p)!r} does not exist; give a sequence folder, an .h5 file or "
                "a dataset root (e.g. the folder `roft-sim generate --out` wrote)"
            )
        sequences = list_sequences(p)
        if not sequences:
            raise DatasetFormatError(
                f"no sequence found under {str(p)!r}: expected Fast-YCB folders (cam_K.json + "
                "data.txt), BOP scenes or .h5 files, up to 3 levels deep"
            )
        found.extend(sequences)
    return found


def dataset_frames(sequence: Sequence) -> Iterator[DatasetFrame]:
    """The frames of any ``Sequence`` as :class:`DatasetFrame` objects, one at a time.

    Detector pose misses become None; GT velocities that are NaN (unknown) are left out.
    Ground truth must cover every frame or none (what every writer stores): a sequence whose
    ground truth has NaN poses on some frames (a BOP scene that leaves images unannotated)
    raises :class:`DatasetFormatError` naming the first such frame.
    """
    gt = sequence.ground_truth()
    if gt is not None:
        missing = np.flatnonzero(~np.isfinite(gt.T_cam_obj).all(axis=(1, 2)))
        if missing.size:
            raise DatasetFormatError(
                f"{sequence.name}: no ground-truth pose of {sequence.object_name} on "
                f"{missing.size} of {len(sequence)} frames (first: frame {int(missing[0])}); "
                "roft-sim datasets need ground truth on every frame or on none. Annotate those "
                "frames, or cut the sequence to the annotated frames before converting it"
            )
    cams = sequence.camera_poses()
    poses = {name: sequence.detector_poses(name) for name in sequence.pose_sets()}
    has_vel = gt is not None and bool(np.isfinite(gt.v_obj_mps).all())
    for k in range(len(sequence)):
        masks = {n: sequence.mask(k, n) for n in sequence.mask_sets()}
        yield DatasetFrame(
            k=k,
            t_s=sequence.time_s(k),
            rgb=sequence.rgb(k),
            depth_m=sequence.depth(k),
            T_world_cam=cams[k],
            gt_T_cam_obj=None if gt is None else gt.T_cam_obj[k],
            gt_v_obj_mps=gt.v_obj_mps[k] if has_vel and gt is not None else None,
            gt_w_radps=gt.w_radps[k] if has_vel and gt is not None else None,
            gt_mask=masks.pop(GT_MASK_SET, None),
            gt_mask_full=masks.pop(GT_FULL_MASK_SET, None),
            # flow() is None only for k = 0 (a None here is refused by DatasetFrame's checks)
            flows={}
            if k == 0
            else cast(dict[str, FlowField], {n: sequence.flow(k, n) for n in sequence.flow_sets()}),
            detector_masks=masks,
            detector_poses={n: (p.T_cam_obj[k] if p.valid[k] else None) for n, p in poses.items()},
        )


def stored_flow_encodings(sequence: Sequence) -> dict[str, FlowEncoding]:
    """The on-disk encoding of each flow set of ``sequence`` (``float32`` or ``s10.5``).

    From the sequence's metadata (``sets.flow.<name>.encoding``, which our writers record), else,
    for a Fast-YCB folder without it (the real Fast-YCB), from the ``cv_type`` of the set's first
    flow file (11 = CV_16SC2 = NVOF's S10.5); ``float32`` otherwise (in-memory sequences).
    """
    sets = sequence.metadata().get("sets")
    recorded = sets.get("flow") if isinstance(sets, Mapping) else None
    out: dict[str, FlowEncoding] = {}
    for name in sequence.flow_sets():
        info = recorded.get(name) if isinstance(recorded, Mapping) else None
        encoding = info.get("encoding") if isinstance(info, Mapping) else None
        if encoding is None and isinstance(sequence, FastYcbSequence):
            encoding = _probe_fast_ycb_flow_encoding(sequence.path / "optical_flow" / name)
        out[name] = "s10.5" if encoding == "s10.5" else "float32"
    return out


def _probe_fast_ycb_flow_encoding(folder: Path) -> str | None:
    """``s10.5`` or ``float32`` from the cv_type of the first ``<k>.float`` in ``folder``."""
    files = sorted(folder.glob("*.float"), key=lambda p: (len(p.stem), p.stem))
    if not files:
        return None
    with open(files[0], "rb") as f:
        header = f.read(4)
    if len(header) < 4:
        return None
    cv_type = int.from_bytes(header, "little", signed=True)
    return "s10.5" if cv_type == CV_16SC2 else "float32"


def write_sequence(
    sequence: Sequence,
    fmt: DatasetFormat,
    root: str | Path,
    *,
    sequence_name: str | None = None,
    flow_encodings: Mapping[str, FlowEncoding] | None = None,
    **options: Any,
) -> Path:
    """Writes any ``Sequence`` (in memory, or read from another format) in format ``fmt``.

    Frames stream one by one. ``options`` are passed to :func:`open_writer`. Flow sets keep
    their stored encoding (:func:`stored_flow_encodings`: NVOF's int16 S10.5 stays int16) unless
    ``flow_encodings`` says otherwise.

    Returns:
        The written sequence's path.
    """
    writer = open_writer(
        fmt,
        root,
        sequence_name=sequence_name or sequence.name,
        object_name=sequence.object_name,
        intrinsics=sequence.intrinsics,
        fps=sequence.fps,
        n_frames=len(sequence),
        metadata={k: v for k, v in sequence.metadata().items() if k not in RESERVED_METADATA_KEYS},
        object_model=sequence.object_model(),
        flow_encodings=(
            flow_encodings if flow_encodings is not None else stored_flow_encodings(sequence)
        ),
        **options,
    )
    for frame in dataset_frames(sequence):
        writer.write_frame(frame)
    return writer.finalize()
