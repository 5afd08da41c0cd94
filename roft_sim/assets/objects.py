"""Loading an object's assets: the real YCB mesh when installed, else a procedural stand-in.

Where real meshes are looked up, in order (the first hit wins):

1. ``assets_dir`` (the CLI passes ``--assets DIR`` or ``$ROFT_SIM_ASSETS``):
   ``<assets_dir>/<name>/textured.obj`` or ``<assets_dir>/<name>/google_16k/textured.obj``;
2. the user cache filled by ``roft-sim assets install``: ``<cache_dir>/ycb/<name>/textured.obj``.

Loaded objects are kept in a small in-process cache (keyed by the files' paths, sizes and
modification times, and the arguments), and every array they hold is read-only.
"""

from __future__ import annotations

import difflib
import functools
import hashlib
import json
import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.assets.meshes import (
    MESH_SUFFIXES,
    TexturedMesh,
    freeze_arrays,
    geometry_mesh,
    model_point_seed,
    mtl_texture_path,
    read_mesh_file,
    read_texture_image,
    sample_surface_points,
)
from roft_sim.assets.procedural import AtlasMesh, projected_atlas, stand_in_mesh
from roft_sim.assets.registry import ObjectInfo, UnknownObjectError, object_registry
from roft_sim.assets.texture_cache import load_cached_image, save_cached_image
from roft_sim.assets.textures import TEXTURE_GENERATOR_VERSION, procedural_texture
from roft_sim.errors import AssetNotFoundError, ConfigError, DatasetFormatError, located
from roft_sim.records import ObjectModel

F64 = NDArray[np.float64]

__all__ = [
    "ObjectAssets",
    "Source",
    "ALIGNMENT_TOLERANCE_M",
    "FILE_PALETTE_RGB",
    "find_ycb_mesh",
    "ycb_mesh_candidates",
    "load_object",
    "install_hint",
]

_log = logging.getLogger(__name__)

Source = Literal["ycb", "procedural", "file"]

ALIGNMENT_TOLERANCE_M = 0.003
"""A real YCB mesh is accepted when, after the alignment, its bounding-box centre is within this
distance of the origin and each extent within this distance of the manifest's."""

FILE_PALETTE_RGB = ((196, 196, 190), (40, 70, 150), (220, 140, 40), (60, 60, 60), (170, 40, 40))
"""Colours of the procedural texture given to mesh files that have no texture."""

_MAX_TEXTURE_PX = 8192


@dataclass(frozen=True, slots=True, kw_only=True)
class ObjectAssets:
    """Everything the simulator needs about one object, in the object frame of its poses."""

    model: ObjectModel
    """Geometry for metrics and depth rendering: vertices merged along UV seams, faces, and the
    fixed model points (all read-only)."""
    mesh: TexturedMesh
    """The textured mesh to render (same frame and surface as ``model``)."""
    source: Source
    """``ycb``: a real YCB mesh; ``procedural``: the stand-in; ``file``: a mesh file given by
    path."""
    info: ObjectInfo | None = None
    """The registry entry (None for a mesh file given by path)."""
    source_path: Path | None = None
    """The mesh file that was read (None for procedural stand-ins). For ``ycb`` it is in the
    ORIGINAL YCB frame; the arrays here are already aligned."""


def install_hint(names: list[str] | tuple[str, ...]) -> str:
    """How to get real meshes, as printed in error messages."""
    objs = " ".join(names)
    return (
        f"install them with `roft-sim assets install --from /path/to/ycb --objects {objs}` (a "
        "folder holding <name>/google_16k/textured.obj) or `roft-sim assets install --from ycb "
        f"--objects {objs}` (downloads the official YCB archives), or point --assets DIR "
        "(or $ROFT_SIM_ASSETS) at such a folder"
    )


def ycb_mesh_candidates(
    name: str, *, assets_dir: Path | None = None, cache_dir: Path | None = None
) -> list[Path]:
    """The files a real mesh of ``name`` is looked for in, in lookup order."""
    out = []
    if assets_dir is not None:
        out += [assets_dir / name / "textured.obj", assets_dir / name / "google_16k/textured.obj"]
    if cache_dir is not None:
        out += [cache_dir / "ycb" / name / "textured.obj"]
    return out


def find_ycb_mesh(
    name: str, *, assets_dir: Path | None = None, cache_dir: Path | None = None
) -> Path | None:
    """The first real mesh file of ``name`` found (see the module docstring), or None."""
    for path in ycb_mesh_candidates(name, assets_dir=assets_dir, cache_dir=cache_dir):
        if path.is_file():
            return path
    return None


def _check_load_options(prefer: str, max_texture_px: int, assets_dir: Path | None) -> None:
    """The checks of :func:`load_object`'s options (see its Raises)."""
    if prefer not in ("auto", "ycb", "procedural"):
        raise ConfigError(f"prefer must be 'auto', 'ycb' or 'procedural', got {prefer!r}")
    if not isinstance(max_texture_px, int) or not 8 <= max_texture_px <= _MAX_TEXTURE_PX:
        raise ConfigError(
            f"max_texture_px must be an integer in 8..{_MAX_TEXTURE_PX}, got {max_texture_px!r}"
        )
    if assets_dir is not None and not Path(assets_dir).is_dir():
        raise AssetNotFoundError(
            f"assets directory {located(assets_dir)} does not exist; give a folder of YCB objects "
            "(<name>/google_16k/textured.obj) or leave it out"
        )


def load_object(
    name_or_path: str | os.PathLike[str],
    *,
    assets_dir: Path | None = None,
    cache_dir: Path | None = None,
    prefer: Literal["auto", "ycb", "procedural"] = "auto",
    max_texture_px: int = 2048,
) -> ObjectAssets:
    """Loads an object by registry name, or a mesh file by path.

    Args:
        name_or_path: a registry name (``003_cracker_box``; see ``list_objects()``) or the path
            of a ``.obj``/``.ply``/``.stl`` file in metres. A file is used in its own frame; an
            OBJ's texture (``map_Kd``) is used when present, otherwise the file gets a box-
            projected procedural texture.
        assets_dir: folder of YCB google_16k objects searched first (``<name>/textured.obj`` or
            ``<name>/google_16k/textured.obj``); must exist when given.
        cache_dir: the user cache (installed meshes in ``ycb/``; procedural textures are
            written to ``procedural/`` and reused). None: nothing is read from or written to
            disk besides ``assets_dir``.
        prefer: ``auto``: the real mesh when found, else the stand-in; ``ycb``: the real mesh or
            an error; ``procedural``: always the stand-in.
        max_texture_px: the texture's longer side is at most this many pixels (real textures
            are downscaled; procedural ones generated at this size).

    Returns:
        The assets, with every array read-only and in the object frame of the poses (for
        registry objects the NVDU-aligned frame: bounding-box centre at the origin).

    Raises:
        UnknownObjectError: neither a registry name nor an existing mesh file.
        AssetNotFoundError: ``prefer="ycb"`` and no real mesh is installed; ``assets_dir`` does
            not exist.
        DatasetFormatError: a mesh or texture file is malformed, or a real mesh does not fit
            the registry's alignment.
        ConfigError: bad ``prefer`` or ``max_texture_px``.
    """
    _check_load_options(prefer, max_texture_px, assets_dir)
    assets_dir = Path(assets_dir) if assets_dir is not None else None
    cache_dir = Path(cache_dir) if cache_dir is not None else None
    key = os.fspath(name_or_path)
    registry = object_registry()
    if key in registry:
        info = registry[key]
        if prefer != "procedural":
            path = find_ycb_mesh(key, assets_dir=assets_dir, cache_dir=cache_dir)
            if path is not None:
                return _load_ycb_cached(info, path, _file_stamp(path), max_texture_px)
            if prefer == "ycb":
                looked = ycb_mesh_candidates(key, assets_dir=assets_dir, cache_dir=cache_dir)
                where = ", ".join(str(p) for p in looked) or "nowhere (no assets_dir or cache_dir)"
                raise AssetNotFoundError(
                    f"no real mesh of {key!r} is installed (looked for {where}); "
                    + install_hint([key])
                )
        return _load_procedural_cached(info, max_texture_px, cache_dir)
    path = Path(key).expanduser()
    if path.suffix.lower() in MESH_SUFFIXES or path.exists():
        if not path.is_file():
            raise AssetNotFoundError(f"mesh file {located(path)} does not exist; check the path")
        if prefer == "ycb":
            raise ConfigError(
                f"prefer='ycb' needs a registry name, got the file {located(path)}; use 'auto'"
            )
        return _load_file_cached(path.resolve(), _file_stamp(path), max_texture_px, cache_dir)
    close = difflib.get_close_matches(key, list(registry), n=1, cutoff=0.5)
    hint = f"did you mean {close[0]!r}? " if close else ""
    raise UnknownObjectError(
        f"{key!r} is neither a registry object nor a mesh file; {hint}known objects: "
        f"{', '.join(registry)}; or give the path of a .obj/.ply/.stl file in metres"
    )


def _file_stamp(path: Path) -> tuple[str, int, int]:
    st = path.stat()
    return str(path.resolve()), st.st_size, st.st_mtime_ns


def _finish(
    *,
    name: str,
    vertices_m: F64,
    faces: NDArray[np.int64],
    uv: F64,
    texture_rgb: NDArray[np.uint8],
    model_point_count: int,
    mesh_path: Path | None,
) -> tuple[ObjectModel, TexturedMesh]:
    mesh = TexturedMesh(
        vertices_m=np.ascontiguousarray(vertices_m, dtype=np.float64),
        faces=np.ascontiguousarray(faces, dtype=np.int64),
        uv=np.ascontiguousarray(uv, dtype=np.float64),
        texture_rgb=np.ascontiguousarray(texture_rgb, dtype=np.uint8),
    )
    geo_v, geo_f = geometry_mesh(mesh.vertices_m, mesh.faces)
    points = sample_surface_points(geo_v, geo_f, model_point_count, seed=model_point_seed(name))
    model = ObjectModel(
        name=name, vertices_m=geo_v, faces=geo_f, model_points_m=points, mesh_path=mesh_path
    )
    freeze_arrays(mesh.vertices_m, mesh.faces, mesh.uv, mesh.texture_rgb, geo_v, geo_f, points)
    return model, mesh


# ---------------------------------------------------------------------------------------- YCB


@functools.lru_cache(maxsize=12)
def _load_ycb_cached(
    info: ObjectInfo, path: Path, stamp: tuple[str, int, int], max_texture_px: int
) -> ObjectAssets:
    del stamp  # part of the cache key only
    if info.nvdu_alignment is None:
        raise DatasetFormatError(
            f"registry object {info.name!r} has no nvdu_alignment, so its YCB mesh cannot be "
            "aligned; add one to the manifest"
        )
    vertices, faces, uv = read_mesh_file(path)
    if uv is None:
        raise DatasetFormatError(
            f"{located(path)} has no texture coordinates (vt); expected the textured.obj of "
            f"YCB google_16k. Re-install it: {install_hint([info.name])}"
        )
    texture_path = mtl_texture_path(path)
    if texture_path is None:
        raise DatasetFormatError(
            f"{located(path)} names no texture (no mtllib with map_Kd); expected textured.obj, "
            f"textured.mtl and texture_map.png of YCB google_16k. Re-install it: "
            f"{install_hint([info.name])}"
        )
    texture = read_texture_image(texture_path, max_px=max_texture_px)
    T = info.nvdu_alignment.T_nvdu_orig
    aligned = vertices @ T[:3, :3].T + T[:3, 3]
    lo, hi = aligned.min(axis=0), aligned.max(axis=0)
    centre, extent = 0.5 * (lo + hi), hi - lo
    dims = np.asarray(info.dimensions_m)
    if (
        np.abs(centre).max() > ALIGNMENT_TOLERANCE_M
        or np.abs(extent - dims).max() > ALIGNMENT_TOLERANCE_M
    ):
        raise DatasetFormatError(
            f"{located(path)} does not fit the registry entry {info.name!r}: after the NVDU "
            f"alignment its bounding-box centre is {np.round(centre * 1000, 2).tolist()} mm "
            f"(expected 0 within {ALIGNMENT_TOLERANCE_M * 1000:g} mm) and its extents "
            f"{np.round(extent * 1000, 2).tolist()} mm (manifest: "
            f"{np.round(dims * 1000, 2).tolist()} mm). Is it the google_16k mesh of this object, "
            "in metres and in the original YCB frame?"
        )
    model, mesh = _finish(
        name=info.name,
        vertices_m=aligned,
        faces=faces,
        uv=uv,
        texture_rgb=texture,
        model_point_count=info.model_point_count,
        mesh_path=None,  # the file on disk is in the original YCB frame, not the pose frame
    )
    return ObjectAssets(model=model, mesh=mesh, source="ycb", info=info, source_path=path)


# --------------------------------------------------------------------------------- procedural


def _texture_cache_path(
    cache_dir: Path, label: str, params: dict[str, object], shape: tuple[int, int]
) -> Path:
    """The cache file of a procedural texture (``.npy``; earlier versions wrote ``.png``)."""
    digest = hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:16]
    return (
        cache_dir
        / "procedural"
        / f"{label}-v{TEXTURE_GENERATOR_VERSION}-{shape[1]}x{shape[0]}-{digest}.npy"
    )


def _atlas_texture(
    atlas: AtlasMesh,
    *,
    label: str,
    palette_rgb: tuple[tuple[int, int, int], ...],
    weights: tuple[float, ...],
    max_texture_px: int,
    cache_dir: Path | None,
) -> NDArray[np.uint8]:
    """The procedural texture for ``atlas``, from the cache when present."""
    shape = atlas.texture_shape(max_texture_px)
    px_per_mm = max(shape) / max(atlas.atlas_size_m) / 1000.0
    params = {
        "version": TEXTURE_GENERATOR_VERSION,
        # numpy's Generator and OpenCV's drawing are not bit-stable across versions: a cache
        # written by another environment must not stand in for this one's texture
        "numpy": np.__version__,
        "opencv": cv2.__version__,
        "label": label,
        "palette": [list(c) for c in palette_rgb],
        "weights": list(weights),
        "atlas_size_m": [round(x, 9) for x in atlas.atlas_size_m],
        "shape": list(shape),
    }
    path = _texture_cache_path(cache_dir, label, params, shape) if cache_dir else None
    if path is not None:
        image = load_cached_image(path)
        if image is not None and image.shape[:2] == shape:
            return image
        if image is not None:
            _log.warning(
                "ignoring the cached texture %s of another size; generating it again", path
            )
    texture = procedural_texture(
        np.asarray(palette_rgb, dtype=np.uint8),
        np.asarray(weights, dtype=np.float64),
        shape_px=shape,
        px_per_mm=px_per_mm,
        rng=np.random.default_rng(model_point_seed(f"texture:{label}")),
    )
    if path is not None:
        try:
            save_cached_image(path, texture, legacy=path.with_suffix(".png"))
        except OSError as e:  # a read-only cache must not stop the simulation
            _log.warning("could not cache the procedural texture at %s: %s", path, e)
    return texture


@functools.lru_cache(maxsize=12)
def _load_procedural_cached(
    info: ObjectInfo, max_texture_px: int, cache_dir: Path | None
) -> ObjectAssets:
    atlas = stand_in_mesh(info)
    texture = _atlas_texture(
        atlas,
        label=info.name,
        palette_rgb=info.colors_rgb,
        weights=info.color_weights,
        max_texture_px=max_texture_px,
        cache_dir=cache_dir,
    )
    model, mesh = _finish(
        name=info.name,
        vertices_m=atlas.vertices_m,
        faces=atlas.faces,
        uv=atlas.uv,
        texture_rgb=texture,
        model_point_count=info.model_point_count,
        mesh_path=None,
    )
    return ObjectAssets(model=model, mesh=mesh, source="procedural", info=info)


# ---------------------------------------------------------------------------------- mesh file


@functools.lru_cache(maxsize=12)
def _load_file_cached(
    path: Path, stamp: tuple[str, int, int], max_texture_px: int, cache_dir: Path | None
) -> ObjectAssets:
    del stamp  # part of the cache key only
    vertices, faces, uv = read_mesh_file(path)
    texture_path = mtl_texture_path(path) if path.suffix.lower() == ".obj" else None
    if uv is not None and texture_path is not None:
        texture = read_texture_image(texture_path, max_px=max_texture_px)
    else:
        if uv is not None:
            _log.info("%s has texture coordinates but no texture; box-projecting instead", path)
        atlas = projected_atlas(vertices, faces)
        vertices, faces, uv = atlas.vertices_m, atlas.faces, atlas.uv
        label = f"file-{path.stem}-{hashlib.sha256(str(path).encode()).hexdigest()[:8]}"
        texture = _atlas_texture(
            atlas,
            label=label,
            palette_rgb=FILE_PALETTE_RGB,
            weights=(0.4, 0.2, 0.15, 0.15, 0.1),
            max_texture_px=max_texture_px,
            cache_dir=cache_dir,
        )
    model, mesh = _finish(
        name=path.stem,
        vertices_m=vertices,
        faces=faces,
        uv=uv,
        texture_rgb=texture,
        model_point_count=2620,
        mesh_path=path,
    )
    return ObjectAssets(model=model, mesh=mesh, source="file", source_path=path)


def _clear_caches() -> None:
    """Empties the in-process caches (tests use it)."""
    for f in (_load_ycb_cached, _load_procedural_cached, _load_file_cached):
        f.cache_clear()
