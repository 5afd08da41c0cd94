"""Object-model files stored with a dataset, so metrics need nothing but the dataset.

- ``points.xyz``: one ``x y z`` row in metres per model point (object frame), exact text floats.
- ``mesh.obj``: the triangle mesh, ``v x y z`` [m] and 1-based ``f a b c`` lines (geometry only;
  textures are not copied).
- BOP ``obj_XXXXXX.ply``: binary little-endian PLY in millimetres (float32), as BOP expects.

Readers accept what other tools write too (extra OBJ statements, ``f a/b/c`` faces, any PLY that
trimesh reads).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import cast

import numpy as np
from numpy.typing import NDArray

from roft_sim.datasets.atomic_files import atomic_write_bytes, atomic_write_text
from roft_sim.datasets.fast_ycb_codec import format_rows, parse_rows
from roft_sim.datasets.image_files import read_file_bytes
from roft_sim.errors import DatasetFormatError, located

F64 = NDArray[np.float64]

__all__ = [
    "write_points_xyz",
    "read_points_xyz",
    "write_mesh_obj",
    "read_mesh_obj",
    "write_mesh_ply_mm",
    "read_mesh_ply_mm",
]


_OUR_PLY_LAYOUT = [
    "ply",
    "format binary_little_endian 1.0",
    "element vertex N",
    "property float x",
    "property float y",
    "property float z",
    "element face N",
    "property list uchar int vertex_indices",
]


def write_points_xyz(path: Path, points_m: F64) -> None:
    """Writes ``(M, 3)`` model points [m], one ``x y z`` row each."""
    atomic_write_text(path, format_rows(points_m))


def read_points_xyz(path: Path) -> F64:
    """``(M, 3)`` model points [m] from a ``points.xyz`` file."""
    text = read_file_bytes(path, "model points").decode("utf-8", errors="replace")
    points = parse_rows(text, path, 3)
    if len(points) == 0:
        raise DatasetFormatError(f"model points file {located(path)} is empty")
    return points


def write_mesh_obj(path: Path, vertices_m: F64, faces: NDArray[np.int64]) -> None:
    """Writes a Wavefront OBJ with vertices [m] and 1-based triangle faces."""
    lines = ["# roft_sim object mesh, object frame, metres\n"]
    lines += ["v " + row + "\n" for row in format_rows(vertices_m).splitlines()]
    lines += [f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in np.asarray(faces)]
    atomic_write_text(path, "".join(lines))


def read_mesh_obj(path: Path) -> tuple[F64, NDArray[np.int64]]:
    """Vertices ``(V, 3)`` [m] and triangles ``(F, 3)`` (0-based) of an OBJ file.

    Only ``v`` and ``f`` statements are used; polygons are fan-triangulated; ``a/b/c`` face tokens
    take the vertex index.
    """
    text = read_file_bytes(path, "mesh").decode("utf-8", errors="replace")
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    for i, line in enumerate(text.splitlines(), start=1):
        tokens = line.split()
        if not tokens:
            continue
        try:
            if tokens[0] == "v":
                vertices.append([float(x) for x in tokens[1:4]])
            elif tokens[0] == "f":
                idx = [int(t.split("/")[0]) for t in tokens[1:]]
                idx = [j - 1 if j > 0 else len(vertices) + j for j in idx]
                faces += [[idx[0], idx[j], idx[j + 1]] for j in range(1, len(idx) - 1)]
        except (ValueError, IndexError):
            raise DatasetFormatError(f"{located(path, i)}: malformed OBJ line {line!r}") from None
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(v) == 0 or not np.isfinite(v).all():
        raise DatasetFormatError(f"mesh {located(path)} has no vertices or non-finite ones")
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise DatasetFormatError(f"mesh {located(path)} has faces with out-of-range indices")
    return v, f


def write_mesh_ply_mm(path: Path, vertices_m: F64, faces: NDArray[np.int64]) -> None:
    """Writes a binary little-endian PLY in millimetres (float32), the BOP model layout."""
    v = (np.asarray(vertices_m) * 1000.0).astype("<f4")
    f = np.asarray(faces)
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment roft_sim object model, millimetres\n"
        f"element vertex {len(v)}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    face_rows = np.zeros(len(f), dtype=[("n", "u1"), ("idx", "<i4", (3,))])
    face_rows["n"] = 3
    face_rows["idx"] = f
    atomic_write_bytes(path, header.encode("ascii") + v.tobytes() + face_rows.tobytes())


def read_mesh_ply_mm(path: Path) -> tuple[F64, NDArray[np.int64]]:
    """Vertices ``(V, 3)`` [m] and triangles of a PLY in millimetres (BOP models).

    The layout written by :func:`write_mesh_ply_mm` is parsed directly; other PLY files go
    through trimesh.
    """
    data = read_file_bytes(path, "mesh")
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise DatasetFormatError(f"mesh {located(path)} is not a PLY file")
    header = [
        h
        for h in data[:end].decode("ascii", errors="replace").splitlines()
        if not h.startswith("comment")
    ]
    body = data[end + len(b"end_header\n") :]
    layout = [re.sub(r"^element (vertex|face) \d+$", r"element \1 N", h) for h in header]
    if layout == _OUR_PLY_LAYOUT:
        nv, nf = int(header[2].split()[2]), int(header[6].split()[2])
        if len(body) != 12 * nv + 13 * nf:
            raise DatasetFormatError(
                f"mesh {located(path)} has {len(body)} body bytes; its header says {nv} vertices "
                f"and {nf} triangles ({12 * nv + 13 * nf} bytes)"
            )
        v = np.frombuffer(body[: 12 * nv], dtype="<f4").reshape(nv, 3).astype(np.float64)
        rows = np.frombuffer(body[12 * nv :], dtype=[("n", "u1"), ("idx", "<i4", (3,))])
        if (rows["n"] != 3).any():
            raise DatasetFormatError(f"mesh {located(path)} has non-triangle faces")
        f = rows["idx"].astype(np.int64)
    else:
        import trimesh

        try:
            # force="mesh" returns a Trimesh (the stub types load as returning any Geometry)
            mesh = cast(trimesh.Trimesh, trimesh.load(path, force="mesh", process=False))
        except Exception as e:  # trimesh raises many types on bad files
            raise DatasetFormatError(f"mesh {located(path)} could not be read: {e}") from None
        v, f = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, np.int64)
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise DatasetFormatError(f"mesh {located(path)} has faces with out-of-range indices")
    return v / 1000.0, f
