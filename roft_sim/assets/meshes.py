"""Textured triangle meshes: the record, reading mesh files, texture images and model points.

A :class:`TexturedMesh` holds per-vertex texture coordinates (vertices are split along UV seams,
as trimesh does when it reads an OBJ) and one RGB texture image. UVs follow the OBJ convention:
``v`` points up, so texture coordinate ``(u, v)`` samples image column ``u * W`` and row
``(1 - v) * H``.
"""

from __future__ import annotations

import hashlib
import logging
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import AssetNotFoundError, DatasetFormatError, located

if TYPE_CHECKING:  # trimesh is imported where a mesh file is read: it takes 0.1-0.5 s
    import trimesh

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]
I64 = NDArray[np.int64]

__all__ = [
    "TexturedMesh",
    "MESH_SUFFIXES",
    "read_mesh_file",
    "read_texture_image",
    "mtl_texture_path",
    "model_point_seed",
    "sample_surface_points",
    "geometry_mesh",
    "GEOMETRY_MERGE_DIGITS",
    "freeze_arrays",
]

_log = logging.getLogger(__name__)

MESH_SUFFIXES = (".obj", ".ply", ".stl")
"""Mesh file types :func:`read_mesh_file` accepts."""

_MAX_PLAUSIBLE_EXTENT_M = 5.0


@dataclass(frozen=True, slots=True, kw_only=True)
class TexturedMesh:
    """A triangle mesh with per-vertex texture coordinates and one RGB texture.

    Faces are counter-clockwise seen from outside (outward normals by the right-hand rule).
    """

    vertices_m: F64
    """(V, 3) vertex positions [m] in the object frame of the poses (for YCB objects the
    NVDU-aligned frame: bounding-box centre at the origin). Vertices on UV seams are repeated."""
    faces: I64
    """(F, 3) int64 vertex indices per triangle."""
    uv: F64
    """(V, 2) texture coordinates, OBJ convention (v up): image column = u * W,
    row = (1 - v) * H."""
    texture_rgb: U8
    """(Ht, Wt, 3) uint8 RGB texture image."""

    def __post_init__(self) -> None:
        v, f, uv, tex = self.vertices_m, self.faces, self.uv, self.texture_rgb
        if v.ndim != 2 or v.shape[1] != 3 or v.dtype != np.float64 or not np.isfinite(v).all():
            raise ValueError(f"vertices_m must be finite float64 (V, 3), got {v.dtype} {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or f.dtype != np.int64:
            raise ValueError(f"faces must be int64 (F, 3), got {f.dtype} {f.shape}")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(f"faces index vertices 0..{len(v) - 1}, got {f.min()}..{f.max()}")
        if uv.shape != (len(v), 2) or uv.dtype != np.float64 or not np.isfinite(uv).all():
            raise ValueError(
                f"uv must be finite float64 ({len(v)}, 2) (one per vertex), got {uv.dtype} "
                f"{uv.shape}"
            )
        if tex.ndim != 3 or tex.shape[2] != 3 or tex.dtype != np.uint8 or min(tex.shape[:2]) < 1:
            raise ValueError(f"texture_rgb must be uint8 (H, W, 3), got {tex.dtype} {tex.shape}")

    @property
    def bounds_m(self) -> F64:
        """(2, 3) axis-aligned bounding box ``[min, max]`` [m]."""
        return np.stack([self.vertices_m.min(axis=0), self.vertices_m.max(axis=0)])

    def to_trimesh(self) -> trimesh.Trimesh:
        """The geometry as a ``trimesh.Trimesh`` (no texture; vertices not merged)."""
        import trimesh

        return trimesh.Trimesh(self.vertices_m, self.faces, process=False)

    def sample_texture(self, uv: F64) -> U8:
        """Nearest-texel colours ``(N, 3)`` uint8 at texture coordinates ``uv`` ``(N, 2)``."""
        h, w = self.texture_rgb.shape[:2]
        uv = np.asarray(uv, dtype=np.float64)
        col = np.clip(np.floor(uv[:, 0] * w), 0, w - 1).astype(np.intp)
        row = np.clip(np.floor((1.0 - uv[:, 1]) * h), 0, h - 1).astype(np.intp)
        colours: U8 = self.texture_rgb[row, col]
        return colours


def freeze_arrays(*arrays: np.ndarray) -> None:
    """Marks arrays read-only, so records shared through a cache cannot be changed in place."""
    for a in arrays:
        a.flags.writeable = False


GEOMETRY_MERGE_DIGITS = 8
"""Vertices whose coordinates agree to this many decimals (of a metre) are merged by
:func:`geometry_mesh` (trimesh's ``tol.merge`` of 1e-8)."""


def geometry_mesh(vertices_m: F64, faces: I64) -> tuple[F64, I64]:
    """Merges vertices that share a position (UV seams) into one geometric mesh.

    What ``trimesh``'s ``merge_vertices(merge_tex=True, merge_norm=True)`` gives (tested
    against it), without importing trimesh: positions rounded to
    :data:`GEOMETRY_MERGE_DIGITS` decimals are equal; each kept vertex is the first of its
    group, in the order of first occurrence among the vertices that faces use; vertices no
    face uses are dropped (when there are faces).

    Returns:
        ``(vertices_m (V', 3), faces (F, 3) int64)``; faces keep their order and orientation.
    """
    vertices = np.asarray(vertices_m, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if len(vertices) == 0:
        return vertices.copy(), faces.copy()
    used = np.zeros(len(vertices), dtype=bool)
    if len(faces):
        used[faces] = True
    else:
        used[:] = True
    rounded = np.round(vertices[used] * 10**GEOMETRY_MERGE_DIGITS).astype(np.int64)
    rows = np.ascontiguousarray(rounded).view(np.dtype((np.void, rounded.itemsize * 3)))
    _, first, group = np.unique(rows.reshape(-1), return_index=True, return_inverse=True)
    order = first.argsort()  # groups in the order of their first vertex
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    new_index = np.zeros(len(vertices), dtype=np.int64)
    new_index[used] = rank[group.reshape(-1)]
    kept = np.flatnonzero(used)[first[order]]
    return vertices[kept], new_index[faces]


def model_point_seed(name: str) -> int:
    """A 64-bit seed derived from an object name (SHA-256), stable across runs and platforms."""
    return int.from_bytes(hashlib.sha256(name.encode("utf-8")).digest()[:8], "little")


def _uniform_stream(seed: int, count: int) -> F64:
    # PCG64's raw output is covered by numpy's bit-stream stability guarantee (Generator methods
    # are not), so model points stay the same across numpy versions.
    raw = np.random.PCG64(seed).random_raw(count)
    return (raw >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def sample_surface_points(vertices_m: F64, faces: I64, count: int, *, seed: int) -> F64:
    """Area-uniform random points on a triangle mesh surface, reproducible from ``seed``.

    Faces are picked with probability proportional to their area; the point inside a face uses
    the square-root barycentric rule (uniform over the triangle). The random numbers come from
    PCG64's raw stream, whose values numpy keeps stable across versions.

    Args:
        vertices_m: (V, 3) vertex positions [m], any frame.
        faces: (F, 3) vertex indices.
        count: number of points M.
        seed: e.g. :func:`model_point_seed` of the object name.

    Returns:
        (M, 3) float64 points [m] in the frame of ``vertices_m``.
    """
    tri = np.asarray(vertices_m, dtype=np.float64)[np.asarray(faces)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    cumulative = np.cumsum(area)
    if not cumulative.size or cumulative[-1] <= 0:
        raise ValueError("cannot sample points on a mesh with zero surface area")
    u = _uniform_stream(seed, 3 * count).reshape(3, count)
    face = np.searchsorted(cumulative, u[0] * cumulative[-1], side="right")
    face = np.minimum(face, len(area) - 1)
    s, r = np.sqrt(u[1]), u[2]
    a, b, c = tri[face, 0], tri[face, 1], tri[face, 2]
    points: F64 = (1.0 - s)[:, None] * a + (s * (1.0 - r))[:, None] * b + (s * r)[:, None] * c
    return points


def read_texture_image(path: Path, *, max_px: int) -> U8:
    """Reads an image file as RGB uint8, downscaled (area filter) so that its larger side is at
    most ``max_px``.

    Raises:
        AssetNotFoundError: the file does not exist.
        DatasetFormatError: the file cannot be decoded as an image.
    """
    if not path.is_file():
        raise AssetNotFoundError(f"texture image {located(path)} does not exist")
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise DatasetFormatError(
            f"texture image {located(path)} cannot be decoded (expected PNG or JPEG); "
            "re-install the asset"
        )
    scale = max_px / max(image.shape[:2])
    if scale < 1.0:
        size = (max(1, round(image.shape[1] * scale)), max(1, round(image.shape[0] * scale)))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA)
    return np.ascontiguousarray(image[:, :, ::-1])


def _mtl_files(obj_path: Path) -> list[Path]:
    names: list[Path] = []
    with obj_path.open("r", encoding="utf-8", errors="replace") as f:
        for line in f:
            if line.startswith("mtllib"):
                rest = line[len("mtllib") :].strip()
                if rest:
                    names.append(obj_path.parent / rest)
    return names


def mtl_texture_path(obj_path: Path) -> Path | None:
    """The diffuse texture (``map_Kd``) named by an OBJ file's material library, if any.

    Options before the file name (``-s 1 1 1``, ``-bm 1``, ...) are skipped; the path is
    relative to the .mtl file.
    """
    for mtl in _mtl_files(obj_path):
        if not mtl.is_file():
            continue
        for line in mtl.read_text(encoding="utf-8", errors="replace").splitlines():
            parts = line.strip().split(maxsplit=1)
            if len(parts) == 2 and parts[0] == "map_Kd":
                try:
                    tokens = shlex.split(parts[1])
                except ValueError:
                    tokens = parts[1].split()
                if tokens:
                    return mtl.parent / tokens[-1]
    return None


def read_mesh_file(path: Path) -> tuple[F64, I64, F64 | None]:
    """Reads a triangle mesh file (.obj, .ply, .stl) with trimesh, without merging vertices.

    Returns:
        ``(vertices_m (V, 3), faces (F, 3) int64, uv (V, 2) or None)`` in the file's own frame and
        units (expected: metres). Several objects in one file are concatenated.

    Raises:
        AssetNotFoundError: the file does not exist.
        DatasetFormatError: unknown suffix, unreadable file, no triangles, non-finite numbers, or
            a size that suggests millimetres.
    """
    if not path.is_file():
        raise AssetNotFoundError(f"mesh file {located(path)} does not exist")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise DatasetFormatError(
            f"mesh file {located(path)} has suffix {path.suffix!r}; expected one of "
            f"{', '.join(MESH_SUFFIXES)}"
        )
    import trimesh

    try:
        mesh = trimesh.load_mesh(str(path), process=False)
    except Exception as e:  # trimesh raises many types on malformed files
        raise DatasetFormatError(f"mesh file {located(path)} cannot be read: {e}") from e
    if isinstance(mesh, trimesh.Scene):
        geometries = [g for g in mesh.geometry.values() if isinstance(g, trimesh.Trimesh)]
        if not geometries:
            raise DatasetFormatError(f"mesh file {located(path)} holds no triangle mesh")
        mesh = trimesh.util.concatenate(geometries)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    if len(faces) == 0:
        raise DatasetFormatError(f"mesh file {located(path)} has no triangles")
    if not np.isfinite(vertices).all():
        raise DatasetFormatError(f"mesh file {located(path)} has NaN or infinite vertices")
    extent = float(np.ptp(vertices, axis=0).max())
    if extent > _MAX_PLAUSIBLE_EXTENT_M:
        raise DatasetFormatError(
            f"mesh file {located(path)} is {extent:g} units across; roft_sim expects metres "
            "(is it in millimetres? scale it by 0.001, e.g. with trimesh: "
            "mesh.apply_scale(0.001); mesh.export(...))"
        )
    uv = getattr(mesh.visual, "uv", None)
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape != (len(vertices), 2) or not np.isfinite(uv).all():
            _log.warning("%s: ignoring texture coordinates of shape %s", path, uv.shape)
            uv = None
    return vertices, faces, uv
