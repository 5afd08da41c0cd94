"""Procedural stand-in meshes: boxes, superelliptic cylinders and lofted bottles with UV atlases.

Each surface is cut into charts (box faces; bands of a round shape's side whose ring perimeters
differ by at most :data:`MAX_CHART_STRETCH`; end caps) that are unrolled with their true metric
size and packed, at one common scale, into a square texture atlas. The texture therefore has
the same number of texels per metre everywhere, up to the bounded ring-perimeter stretch.

Conventions: the aligned object frame has the round shapes' axis along y and the object's top
towards -y (the YCB original frame's z axis is the aligned frame's -y axis). Charts are laid out
so that "up" in the texture image points to the object's top on the sides; faces are
counter-clockwise seen from outside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from roft_sim.assets.registry import ObjectInfo

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = [
    "AtlasMesh",
    "projected_atlas",
    "MAX_CHART_STRETCH",
    "RING_SEGMENTS",
    "box_mesh",
    "lofted_mesh",
    "stand_in_mesh",
    "superellipse_ring",
]

MAX_CHART_STRETCH = 1.5
"""Largest ratio between ring perimeters inside one side chart of a round shape (texture
compression along the ring is at most this factor)."""

RING_SEGMENTS = 96
"""Segments around a ring of a round shape (a multiple of 4: the four extreme points are
vertices, so the bounding box is exact)."""

_GUTTER_FRACTION = 0.01
"""Empty border around each chart, as a fraction of the atlas side (limits texture bleeding)."""


@dataclass(frozen=True, slots=True)
class _Chart:
    vertices_m: F64  # (n, 3) object frame
    faces: I64  # (m, 3) indices into vertices_m, counter-clockwise seen from outside
    st_m: F64  # (n, 2) unrolled metric chart coordinates, origin at the chart's lower-left
    size_m: tuple[float, float]  # (width, height) of the chart [m]


@dataclass(frozen=True, slots=True, kw_only=True)
class AtlasMesh:
    """A procedural mesh with its UV atlas (before a texture is attached)."""

    vertices_m: F64
    """(V, 3) vertices [m], object frame; seams split (one copy per chart)."""
    faces: I64
    """(F, 3) int64, counter-clockwise seen from outside."""
    uv: F64
    """(V, 2) texture coordinates in [0, 1], OBJ convention (v up)."""
    atlas_size_m: tuple[float, float]
    """(width, height) [m] of surface that the full texture spans (u from 0 to 1, v from 0 to
    1); a texture of the same aspect ratio has equal texel density along u and v."""

    def texture_shape(self, max_px: int) -> tuple[int, int]:
        """``(height, width)`` in pixels of a texture for this atlas, longer side ``max_px``."""
        w, h = self.atlas_size_m
        scale = max_px / max(w, h)
        return max(1, round(h * scale)), max(1, round(w * scale))


def _shelf_pack_widths(padded: F64, row_widths: F64) -> tuple[F64, F64, F64]:
    """Places padded rectangles (n, 2) in rows of at most each of ``row_widths`` (R,), tallest
    first (a stable order), one packing per width, vectorised over the widths: the float64
    operations of the one-width loop, so bit for bit what that loop gives (tested).

    Returns:
        Offsets (R, n, 2), atlas widths (R,) and heights (R,), all float64.
    """
    order = np.argsort(-padded[:, 1], kind="stable")
    limit = np.asarray(row_widths, dtype=np.float64) + 1e-12
    r = limit.shape[0]
    offsets = np.zeros((r, padded.shape[0], 2))
    x, y, row_h, used_w = (np.zeros(r) for _ in range(4))
    for i in order:
        w, h = padded[i]
        wrap = (x > 0) & (x + w > limit)
        y = np.where(wrap, y + row_h, y)
        x = np.where(wrap, 0.0, x)
        row_h = np.where(wrap, 0.0, row_h)
        offsets[:, i, 0], offsets[:, i, 1] = x, y
        x = x + w
        row_h = np.maximum(row_h, h)
        used_w = np.maximum(used_w, x)
    return offsets, used_w, y + row_h


def _pack_charts(sizes_m: list[tuple[float, float]]) -> tuple[F64, NDArray[np.bool_], F64]:
    """Packs chart rectangles (optionally turned by 90 degrees) into a small atlas.

    Minimises the atlas' longer side (which sets the texel density for a given texture size),
    then its area, over every turn option and 48 row widths (the first such layout in that
    order). Returns lower-left offsets (n, 2) [m], the turned flags (n,) and the atlas size
    (width, height) [m], gutters included.
    """
    sizes = np.asarray(sizes_m, dtype=np.float64)
    n = len(sizes)
    gutter = _GUTTER_FRACTION * np.sqrt(float((sizes[:, 0] * sizes[:, 1]).sum()))
    if n <= 8:
        turn_options = [np.array([(m >> i) & 1 for i in range(n)], dtype=bool) for m in range(2**n)]
    else:
        turn_options = [np.zeros(n, dtype=bool), sizes[:, 1] > sizes[:, 0]]
    best: tuple[tuple[float, float], F64, NDArray[np.bool_], F64] | None = None
    for turned in turn_options:
        padded = np.where(turned[:, None], sizes[:, ::-1], sizes) + 2 * gutter
        widths = np.linspace(padded[:, 0].max(), padded[:, 0].sum(), 48)
        offsets, w, h = _shelf_pack_widths(padded, widths)
        # (longer side rounded as round() rounds a numpy scalar, area): the first minimum
        longer = np.round(np.maximum(w, h), 12)
        ties = np.flatnonzero(longer == longer.min())
        k = int(ties[np.argmin((w * h)[ties])])
        score = (float(longer[k]), float(w[k] * h[k]))
        if best is None or score < best[0]:
            best = (score, offsets[k] + gutter, turned, np.array([w[k], h[k]]))
    assert best is not None  # the loops run at least once
    return best[1], best[2], best[3]


def _assemble(charts: list[_Chart]) -> AtlasMesh:
    offsets, turned, size = _pack_charts([c.size_m for c in charts])
    vertices, faces, uv = [], [], []
    base = 0
    for chart, offset, turn in zip(charts, offsets, turned, strict=True):
        st = chart.st_m
        if turn:  # a quarter turn counter-clockwise keeps the orientation (no mirroring)
            st = np.stack([chart.size_m[1] - st[:, 1], st[:, 0]], axis=1)
        vertices.append(chart.vertices_m)
        faces.append(chart.faces + base)
        uv.append((st + offset) / size)
        base += len(chart.vertices_m)
    return AtlasMesh(
        vertices_m=np.concatenate(vertices),
        faces=np.concatenate(faces).astype(np.int64),
        uv=np.concatenate(uv),
        atlas_size_m=(float(size[0]), float(size[1])),
    )


def box_mesh(dimensions_m: tuple[float, float, float]) -> AtlasMesh:
    """An axis-aligned box centred at the origin, one chart per face (24 vertices, 12 faces).

    Args:
        dimensions_m: extents ``(x, y, z)`` [m].
    """
    h = 0.5 * np.asarray(dimensions_m, dtype=np.float64)
    ex, ey, ez = np.eye(3)
    # (outward normal, s axis, t axis) with s x t = normal; t = -y (the object's top) on sides.
    faces_def = [
        (ex, ez, -ey),
        (-ex, -ez, -ey),
        (ez, -ex, -ey),
        (-ez, ex, -ey),
        (-ey, ex, ez),
        (ey, ex, -ez),
    ]
    charts = []
    for n, s_axis, t_axis in faces_def:
        hs, ht, hn = float(h @ np.abs(s_axis)), float(h @ np.abs(t_axis)), float(h @ np.abs(n))
        st = np.array([[0.0, 0.0], [2 * hs, 0.0], [2 * hs, 2 * ht], [0.0, 2 * ht]])
        centre = n * hn
        verts = centre + (st[:, :1] - hs) * s_axis + (st[:, 1:] - ht) * t_axis
        charts.append(
            _Chart(
                vertices_m=verts,
                faces=np.array([[0, 1, 2], [0, 2, 3]], dtype=np.int64),
                st_m=st,
                size_m=(2 * hs, 2 * ht),
            )
        )
    return _assemble(charts)


def superellipse_ring(
    half_x_m: float, half_z_m: float, exponent: float, phi_rad: F64
) -> tuple[F64, F64]:
    """Points of the superellipse ``|x/a|^n + |z/b|^n = 1`` at parameter angles ``phi_rad``.

    Returns:
        ``(x_m, z_m)``, each shaped like ``phi_rad``.
    """
    c, s = np.cos(phi_rad), np.sin(phi_rad)
    p = 2.0 / exponent
    return half_x_m * np.sign(c) * np.abs(c) ** p, half_z_m * np.sign(s) * np.abs(s) ** p


def _ring_angles(half_x_m: float, half_z_m: float, exponent: float, segments: int) -> F64:
    """``segments + 1`` angles from 0 to 2 pi, equal arc length within each quadrant."""
    per_quadrant = segments // 4
    dense = np.linspace(0.0, 0.5 * np.pi, 4097)
    x, z = superellipse_ring(half_x_m, half_z_m, exponent, dense)
    arc = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(x), np.diff(z)))])
    quadrant = np.interp(np.linspace(0.0, arc[-1], per_quadrant + 1), arc, dense)
    quadrant[0], quadrant[-1] = 0.0, 0.5 * np.pi
    # mirror the first quadrant so the ring is symmetric about both axes
    rising, falling = quadrant[:-1], quadrant[::-1][:-1]  # [0, pi/2) and (0, pi/2] reversed
    return np.concatenate(
        [rising, np.pi - falling, np.pi + rising, 2 * np.pi - falling, [2 * np.pi]]
    )


def lofted_mesh(stations: F64, *, segments: int = RING_SEGMENTS) -> AtlasMesh:
    """A closed surface lofted through superelliptic cross-sections along the y axis.

    Args:
        stations: (K, 4) rows ``(y_m, half_x_m, half_z_m, exponent)`` with increasing ``y``; the
            first row is the top (flat cap facing -y), the last the bottom (cap facing +y).
        segments: segments around each ring (multiple of 4).

    Returns:
        The mesh, with its side cut into charts of bounded perimeter ratio and one chart per cap.
    """
    st = np.asarray(stations, dtype=np.float64)
    if segments % 4:
        raise ValueError(f"segments must be a multiple of 4, got {segments}")
    widest = int(np.argmax(st[:, 1] + st[:, 2]))
    phi = _ring_angles(st[widest, 1], st[widest, 2], st[widest, 3], segments)
    rings = []
    for y, a, b, n in st:
        x, z = superellipse_ring(a, b, n, phi)
        ring = np.stack([x, np.full_like(x, y), z], axis=1)
        ring[-1] = ring[0]  # exact seam
        rings.append(ring)
    rings_arr = np.stack(rings)  # (K, M+1, 3)
    seg_len = np.linalg.norm(np.diff(rings_arr, axis=1), axis=2)  # (K, M)
    perimeter = seg_len.sum(axis=1)
    arc_fraction = np.concatenate(
        [np.zeros((len(st), 1)), np.cumsum(seg_len, axis=1) / perimeter[:, None]], axis=1
    )
    arc_fraction[:, -1] = 1.0
    # meridian distance between consecutive rings (mean over the ring)
    step = np.linalg.norm(np.diff(rings_arr, axis=0), axis=2).mean(axis=1)  # (K-1,)

    charts: list[_Chart] = []
    start = 0
    while start < len(st) - 1:
        stop = start + 1
        while stop + 1 < len(st):
            p = perimeter[start : stop + 2]
            if p.max() / p.min() > MAX_CHART_STRETCH:
                break
            stop += 1
        charts.append(_side_chart(rings_arr, arc_fraction, perimeter, step, start, stop))
        start = stop
    charts.append(_cap_chart(rings_arr[0], top=True))
    charts.append(_cap_chart(rings_arr[-1], top=False))
    return _assemble(charts)


def _side_chart(
    rings: F64, arc_fraction: F64, perimeter: F64, step: F64, start: int, stop: int
) -> _Chart:
    """Rings ``start..stop`` (inclusive) as one chart; s along the ring, t towards -y (up)."""
    k = np.arange(start, stop + 1)
    m1 = rings.shape[1]
    width = float(perimeter[k].max())
    # t = meridian distance from the lowest ring (largest y) of the chart, growing towards -y
    t_rev = np.concatenate([[0.0], np.cumsum(step[start:stop][::-1])])[::-1]
    verts = rings[k].reshape(-1, 3)
    s = arc_fraction[k] * width
    t = np.repeat(t_rev[:, None], m1, axis=1)
    st = np.stack([s.ravel(), t.ravel()], axis=1)
    faces = []
    for r in range(len(k) - 1):  # ring r (smaller y, higher t) and r + 1 (larger y, lower t)
        for j in range(m1 - 1):
            a = (r + 1) * m1 + j
            b = (r + 1) * m1 + j + 1
            c = r * m1 + j + 1
            d = r * m1 + j
            faces += [(a, b, c), (a, c, d)]
    return _Chart(
        vertices_m=verts,
        faces=np.asarray(faces, dtype=np.int64),
        st_m=st,
        size_m=(width, float(t_rev[0])),
    )


def _cap_chart(ring: F64, *, top: bool) -> _Chart:
    """A flat fan closing ``ring`` (M+1, 3); ``top``: facing -y, else facing +y."""
    pts = ring[:-1]
    centre = np.array([0.0, ring[0, 1], 0.0])
    verts = np.concatenate([centre[None], pts])
    m = len(pts)
    j = np.arange(m)
    nxt = (j + 1) % m
    if top:
        faces = np.stack([np.zeros(m, dtype=np.int64), 1 + j, 1 + nxt], axis=1)
        s, t = verts[:, 0], verts[:, 2]  # s = x, t = z (s x t = -y)
    else:
        faces = np.stack([np.zeros(m, dtype=np.int64), 1 + nxt, 1 + j], axis=1)
        s, t = verts[:, 0], -verts[:, 2]  # s = x, t = -z (s x t = +y)
    st = np.stack([s - s.min(), t - t.min()], axis=1)
    return _Chart(
        vertices_m=verts,
        faces=faces.astype(np.int64),
        st_m=st,
        size_m=(float(np.ptp(s)), float(np.ptp(t))),
    )


def _bottle_stations(info: ObjectInfo) -> F64:
    """The manifest profile rescaled so that its bounding box is ``dimensions_m`` exactly."""
    p = np.asarray(info.profile, dtype=np.float64).copy()
    hx, hy, hz = info.half_extents_m
    p[:, 0] = -hy + (p[:, 0] - p[0, 0]) * (2 * hy / (p[-1, 0] - p[0, 0]))
    p[:, 1] *= hx / p[:, 1].max()
    p[:, 2] *= hz / p[:, 2].max()
    p[0, 0], p[-1, 0] = -hy, hy
    return p


def projected_atlas(vertices_m: F64, faces: I64) -> AtlasMesh:
    """A UV atlas for an untextured mesh by box projection.

    Each face goes to the chart of its dominant normal direction (+-x, +-y, +-z) and is projected
    onto that chart's plane, so texels keep their metric size up to a factor of at most
    sqrt(3) (a face at 54.7 degrees to its chart plane). Surfaces that overlap in projection
    share texture. Vertices are split between charts.

    Args:
        vertices_m: (V, 3) vertices [m].
        faces: (F, 3) vertex indices, counter-clockwise seen from outside.
    """
    v = np.asarray(vertices_m, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    normals = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    axis = np.argmax(np.abs(normals), axis=1)
    sign = np.sign(normals[np.arange(len(f)), axis])
    ex, ey, ez = np.eye(3)
    # (axis, sign) -> (s axis, t axis) with s x t = the outward direction, as in box_mesh
    frames = {
        (0, 1.0): (ez, -ey),
        (0, -1.0): (-ez, -ey),
        (2, 1.0): (-ex, -ey),
        (2, -1.0): (ex, -ey),
        (1, -1.0): (ex, ez),
        (1, 1.0): (ex, -ez),
    }
    charts = []
    for (ax, sg), (s_axis, t_axis) in frames.items():
        selected = f[(axis == ax) & (sign == sg)]
        if not len(selected):
            continue
        used, local = np.unique(selected, return_inverse=True)
        pts = v[used]
        st = np.stack([pts @ s_axis, pts @ t_axis], axis=1)
        st -= st.min(axis=0)
        size = st.max(axis=0)
        charts.append(
            _Chart(
                vertices_m=pts,
                faces=local.reshape(-1, 3).astype(np.int64),
                st_m=st,
                size_m=(max(float(size[0]), 1e-9), max(float(size[1]), 1e-9)),
            )
        )
    return _assemble(charts)


def stand_in_mesh(info: ObjectInfo) -> AtlasMesh:
    """The procedural mesh of a registry entry, in its aligned frame (bounding box centred at the
    origin with extents ``info.dimensions_m``)."""
    if info.shape == "box":
        return box_mesh(info.dimensions_m)
    if info.shape == "cylinder":
        hx, hy, hz = info.half_extents_m
        n = info.section_exponent
        return lofted_mesh(np.array([[-hy, hx, hz, n], [hy, hx, hz, n]]))
    return lofted_mesh(_bottle_stations(info))
