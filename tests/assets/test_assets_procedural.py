"""Procedural stand-ins: geometry against the manifest and analytic oracles, UV atlas quality,
texture detail and determinism."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import trimesh
from scipy.special import gamma

from roft_sim.assets import get_object_info, list_objects, load_object
from roft_sim.assets.procedural import (
    MAX_CHART_STRETCH,
    _pack_charts,
    _shelf_pack_widths,
    box_mesh,
    lofted_mesh,
    projected_atlas,
    stand_in_mesh,
)
from roft_sim.assets.texture_cache import load_cached_image
from roft_sim.assets.textures import procedural_texture

NAMES = [info.name for info in list_objects()]
SMALL_TEXTURE_PX = 256


def _superellipse_area(a: float, b: float, n: float) -> float:
    return 4.0 * a * b * gamma(1.0 + 1.0 / n) ** 2 / gamma(1.0 + 2.0 / n)


@pytest.mark.parametrize("name", NAMES)
def test_stand_in_has_the_manifest_bounding_box_and_is_a_closed_outward_surface(name):
    info = get_object_info(name)
    assets = load_object(name, prefer="procedural", max_texture_px=SMALL_TEXTURE_PX)
    assert assets.source == "procedural" and assets.info == info
    lo, hi = assets.mesh.bounds_m
    np.testing.assert_allclose(hi - lo, info.dimensions_m, atol=1e-9)
    np.testing.assert_allclose(0.5 * (lo + hi), 0.0, atol=1e-9)
    geo = trimesh.Trimesh(assets.model.vertices_m, assets.model.faces, process=False)
    assert geo.is_watertight
    assert geo.is_winding_consistent
    assert geo.volume > 0  # outward normals
    # the render mesh and the geometry are the same surface
    render = assets.mesh.to_trimesh()
    assert render.area == pytest.approx(geo.area, rel=1e-12)
    assert np.isclose(np.abs(render.face_normals - geo.face_normals), 0).all()


def test_box_volume_and_area_are_exact():
    dims = (0.16404, 0.21344, 0.0718)
    mesh = box_mesh(dims)
    tm = trimesh.Trimesh(mesh.vertices_m, mesh.faces)
    x, y, z = dims
    assert tm.volume == pytest.approx(x * y * z, rel=1e-12)
    assert tm.area == pytest.approx(2 * (x * y + y * z + x * z), rel=1e-12)


@pytest.mark.parametrize("name", ["005_tomato_soup_can", "010_potted_meat_can"])
def test_cylinder_volume_matches_the_superellipse_formula(name):
    info = get_object_info(name)
    hx, hy, hz = info.half_extents_m
    mesh = stand_in_mesh(info)
    volume = trimesh.Trimesh(mesh.vertices_m, mesh.faces).volume
    expected = _superellipse_area(hx, hz, info.section_exponent) * 2 * hy
    assert volume == pytest.approx(expected, rel=2e-3)  # 96-gon inscribed in the curve


def test_lofted_cross_sections_follow_the_stations():
    stations = np.array([[-0.05, 0.02, 0.02, 2.0], [0.0, 0.04, 0.03, 3.0], [0.05, 0.03, 0.03, 2.0]])
    mesh = lofted_mesh(stations)
    for y, a, b, _ in stations:
        ring = mesh.vertices_m[np.isclose(mesh.vertices_m[:, 1], y)]
        assert np.abs(ring[:, 0]).max() == pytest.approx(a, abs=1e-12)
        assert np.abs(ring[:, 2]).max() == pytest.approx(b, abs=1e-12)


def test_bottle_is_narrow_at_the_cap_and_wide_at_the_body():
    info = get_object_info("006_mustard_bottle")
    v = stand_in_mesh(info).vertices_m
    top = v[v[:, 1] < -0.08]  # the cap end (-y is the object's top)
    middle = v[np.abs(v[:, 1]) < 0.02]
    assert np.abs(top[:, 0]).max() < 0.3 * info.half_extents_m[0]
    assert np.abs(middle[:, 0]).max() > 0.9 * info.half_extents_m[0]


def _uv_jacobian_singular_values(vertices_m, faces, uv, atlas_size_m):
    """Singular values of d(texture metres)/d(surface metres) per triangle."""
    tri = vertices_m[faces]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    n1 = e1 / np.linalg.norm(e1, axis=1, keepdims=True)
    normal = np.cross(e1, e2)
    n2 = np.cross(normal / np.linalg.norm(normal, axis=1, keepdims=True), n1)
    local = np.stack(
        [np.stack([(e * n1).sum(1), (e * n2).sum(1)], axis=1) for e in (e1, e2)], axis=2
    )  # (F, 2, 2): columns are edges in a 2-D surface frame
    tex = uv[faces] * np.asarray(atlas_size_m)
    t_edges = np.stack([tex[:, 1] - tex[:, 0], tex[:, 2] - tex[:, 0]], axis=2)
    jac = t_edges @ np.linalg.inv(local)
    return np.linalg.svd(jac, compute_uv=False), np.linalg.det(jac)


@pytest.mark.parametrize("name", NAMES)
def test_uv_atlas_keeps_metric_size_and_orientation(name):
    mesh = stand_in_mesh(get_object_info(name))
    assert (mesh.uv >= 0).all() and (mesh.uv <= 1).all()
    sv, det = _uv_jacobian_singular_values(mesh.vertices_m, mesh.faces, mesh.uv, mesh.atlas_size_m)
    assert (det > 0).all()  # no mirrored triangles: text in the texture reads correctly
    # texel density within the bounded chart stretch (1 = exact metric size)
    assert sv.max() <= MAX_CHART_STRETCH * 1.15
    assert sv.min() >= 1 / (MAX_CHART_STRETCH * 1.15)


def _coverage_count(uv, faces, shape=(512, 512), inset_px=1.5) -> np.ndarray:
    """How many triangles cover each texel (each triangle's edges moved inwards by
    ``inset_px``, by scaling it about its incentre, so shared edges are not counted twice)."""
    h, w = shape
    count = np.zeros(shape, dtype=np.int32)
    px = np.stack([uv[:, 0] * w, (1 - uv[:, 1]) * h], axis=1)
    for tri in px[faces]:
        sides = np.linalg.norm(np.roll(tri, -1, axis=0) - np.roll(tri, 1, axis=0), axis=1)
        incentre = sides @ tri / sides.sum()
        e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
        inradius = abs(e1[0] * e2[1] - e1[1] * e2[0]) / sides.sum()
        if inradius <= inset_px:
            continue
        shrunk = incentre + (tri - incentre) * (1 - inset_px / inradius)
        x0, y0 = np.floor(shrunk.min(axis=0)).astype(int)
        x1, y1 = np.ceil(shrunk.max(axis=0)).astype(int)
        mask = np.zeros((y1 - y0 + 1, x1 - x0 + 1), dtype=np.uint8)
        cv2.fillConvexPoly(mask, np.round((shrunk - (x0, y0)) * 16).astype(np.int32), 1, shift=4)
        count[y0 : y1 + 1, x0 : x1 + 1] += mask
    return count


@pytest.mark.parametrize("name", ["003_cracker_box", "005_tomato_soup_can", "006_mustard_bottle"])
def test_uv_charts_do_not_overlap(name):
    mesh = stand_in_mesh(get_object_info(name))
    count = _coverage_count(mesh.uv, mesh.faces)
    assert count.max() == 1
    tri = mesh.uv[mesh.faces]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    used = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    assert 0.6 < used <= 1.0  # the atlas is reasonably full


def test_box_projection_atlas_for_untextured_meshes():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    atlas = projected_atlas(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    tm = trimesh.Trimesh(atlas.vertices_m, atlas.faces)
    assert tm.area == pytest.approx(sphere.area, rel=1e-12)
    sv, det = _uv_jacobian_singular_values(
        atlas.vertices_m, atlas.faces, atlas.uv, atlas.atlas_size_m
    )
    assert (det > 0).all()
    assert sv.max() <= 1.0 + 1e-9 and sv.min() >= 1 / np.sqrt(3) - 1e-9  # projection shrinks


def _block_std(gray: np.ndarray, block: int) -> np.ndarray:
    h, w = (gray.shape[0] // block) * block, (gray.shape[1] // block) * block
    blocks = gray[:h, :w].reshape(h // block, block, w // block, block).swapaxes(1, 2)
    return blocks.reshape(h // block, w // block, -1).std(axis=2)


@pytest.mark.parametrize("name", NAMES)
def test_texture_is_detailed_everywhere(name):
    texture = load_object(
        name, prefer="procedural", max_texture_px=SMALL_TEXTURE_PX
    ).mesh.texture_rgb
    assert max(texture.shape[:2]) == SMALL_TEXTURE_PX
    gray = cv2.cvtColor(texture, cv2.COLOR_RGB2GRAY).astype(np.float64)
    std = _block_std(gray, 4)
    assert std.min() > 5.0  # grey levels in every 4x4 block: no flat areas
    assert np.median(std) > 20.0
    # an image made of the same colours in flat regions would fail the first check
    flat = np.repeat(np.repeat(gray[::32, ::32], 32, axis=0), 32, axis=1)
    assert _block_std(flat, 4).min() == 0.0


@pytest.mark.parametrize("name", ["003_cracker_box", "006_mustard_bottle"])
def test_texture_uses_the_object_colours(name):
    info = get_object_info(name)
    texture = load_object(
        name, prefer="procedural", max_texture_px=SMALL_TEXTURE_PX
    ).mesh.texture_rgb
    pixels = texture.reshape(-1, 3).astype(np.float64)
    palette = info.palette_rgb.astype(np.float64)
    nearest = np.argmin(((pixels[:, None] - palette[None]) ** 2).sum(2), axis=1)
    share = np.bincount(nearest, minlength=len(palette)) / len(pixels)
    assert int(np.argmax(share)) == 0  # the dominant colour dominates
    expected = np.asarray(info.color_weights) @ palette
    np.testing.assert_allclose(pixels.mean(axis=0), expected, atol=40)


def test_texture_is_deterministic_and_object_specific():
    a = load_object("004_sugar_box", prefer="procedural", max_texture_px=SMALL_TEXTURE_PX)
    from roft_sim.assets.objects import _clear_caches

    _clear_caches()
    b = load_object("004_sugar_box", prefer="procedural", max_texture_px=SMALL_TEXTURE_PX)
    assert a is not b
    np.testing.assert_array_equal(a.mesh.texture_rgb, b.mesh.texture_rgb)
    rng_args = dict(shape_px=(64, 64), px_per_mm=2.0)
    palette, weights = get_object_info("004_sugar_box").palette_rgb, np.ones(5)
    t1 = procedural_texture(palette, weights, rng=np.random.default_rng(1), **rng_args)
    t2 = procedural_texture(palette, weights, rng=np.random.default_rng(2), **rng_args)
    assert not np.array_equal(t1, t2)


def test_texture_cache_round_trip_and_recovery(tmp_path):
    from roft_sim.assets.objects import _clear_caches

    a = load_object("009_gelatin_box", cache_dir=tmp_path, max_texture_px=SMALL_TEXTURE_PX)
    (entry,) = (tmp_path / "procedural").glob("009_gelatin_box-v*.npy")
    np.testing.assert_array_equal(load_cached_image(entry), a.mesh.texture_rgb)
    _clear_caches()
    b = load_object("009_gelatin_box", cache_dir=tmp_path, max_texture_px=SMALL_TEXTURE_PX)
    np.testing.assert_array_equal(a.mesh.texture_rgb, b.mesh.texture_rgb)
    # a damaged cache file is replaced, not trusted
    entry.write_bytes(b"not an npy file")
    _clear_caches()
    c = load_object("009_gelatin_box", cache_dir=tmp_path, max_texture_px=SMALL_TEXTURE_PX)
    np.testing.assert_array_equal(a.mesh.texture_rgb, c.mesh.texture_rgb)
    np.testing.assert_array_equal(load_cached_image(entry), a.mesh.texture_rgb)
    # an entry of the earlier PNG format is not read; writing the entry again removes it
    legacy = entry.with_suffix(".png")
    legacy.write_bytes(b"an old PNG entry")
    entry.unlink()
    _clear_caches()
    d = load_object("009_gelatin_box", cache_dir=tmp_path, max_texture_px=SMALL_TEXTURE_PX)
    np.testing.assert_array_equal(a.mesh.texture_rgb, d.mesh.texture_rgb)
    assert entry.is_file() and not legacy.exists()


def test_arrays_are_read_only():
    assets = load_object("005_tomato_soup_can", prefer="procedural", max_texture_px=64)
    with pytest.raises(ValueError, match="read-only"):
        assets.mesh.vertices_m[0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        assets.model.model_points_m[0, 0] = 1.0


def test_texture_cache_is_keyed_by_the_numpy_and_opencv_versions(tmp_path, monkeypatch):
    """Review regression: neither library is bit-stable across versions, so a texture cached by
    another environment must not be reused as this one's."""
    from roft_sim.assets.objects import _clear_caches

    _clear_caches()
    load_object("009_gelatin_box", cache_dir=tmp_path, max_texture_px=SMALL_TEXTURE_PX)
    monkeypatch.setattr(np, "__version__", "0.0.0-other")
    _clear_caches()
    load_object("009_gelatin_box", cache_dir=tmp_path, max_texture_px=SMALL_TEXTURE_PX)
    monkeypatch.setattr(cv2, "__version__", "0.0.0-other")
    _clear_caches()
    load_object("009_gelatin_box", cache_dir=tmp_path, max_texture_px=SMALL_TEXTURE_PX)
    _clear_caches()
    assert len(list((tmp_path / "procedural").glob("009_gelatin_box-v*.npy"))) == 3


def _shelf_pack_numpy(padded, row_width):
    """The shelf packing on numpy scalars, as it was first written: the oracle of the faster
    float loop (the atlas layout, hence every stand-in's UVs, depends on it bit for bit)."""
    order = np.argsort(-padded[:, 1], kind="stable")
    offsets = np.zeros_like(padded)
    x = y = row_h = used_w = 0.0
    for i in order:
        w, h = padded[i]
        if x > 0 and x + w > row_width + 1e-12:
            y, x, row_h = y + row_h, 0.0, 0.0
        offsets[i] = (x, y)
        x += w
        row_h = max(row_h, h)
        used_w = max(used_w, x)
    return offsets, used_w, y + row_h


def test_shelf_packing_of_many_widths_is_the_numpy_scalar_loop_bit_for_bit():
    rng = np.random.default_rng(4)
    for n in (1, 2, 6, 11):
        padded = rng.uniform(0.005, 0.3, (n, 2))
        padded[n // 2] = padded[0]  # equal heights: the stable order matters
        widths = np.linspace(padded[:, 0].max(), padded[:, 0].sum(), 48)
        offsets, w, h = _shelf_pack_widths(padded, widths)
        for k, row_width in enumerate(widths):
            expected = _shelf_pack_numpy(padded, row_width)
            assert offsets[k].tobytes() == expected[0].tobytes()
            assert w[k] == expected[1] and h[k] == expected[2]


def _pack_charts_sequential(sizes_m):
    """The chart packing search as it was first written, one width at a time: the oracle of the
    vectorised search (every stand-in's atlas layout, hence its UVs, depends on it)."""
    sizes = np.asarray(sizes_m, dtype=np.float64)
    n = len(sizes)
    gutter = 0.01 * np.sqrt(float((sizes[:, 0] * sizes[:, 1]).sum()))
    if n <= 8:
        turn_options = [np.array([(m >> i) & 1 for i in range(n)], dtype=bool) for m in range(2**n)]
    else:
        turn_options = [np.zeros(n, dtype=bool), sizes[:, 1] > sizes[:, 0]]
    best = None
    for turned in turn_options:
        padded = np.where(turned[:, None], sizes[:, ::-1], sizes) + 2 * gutter
        for row_width in np.linspace(padded[:, 0].max(), padded[:, 0].sum(), 48):
            offsets, w, h = _shelf_pack_numpy(padded, row_width)
            score = (round(max(w, h), 12), w * h)
            if best is None or score < best[0]:
                best = (score, offsets + gutter, turned, np.array([w, h]))
    return best[1], best[2], best[3]


@pytest.mark.parametrize("seed", range(6))
def test_chart_packing_is_the_sequential_search_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    cases = [[tuple(rng.uniform(0.01, 0.3, 2)) for _ in range(n)] for n in (1, 3, 6, 9)]
    d = rng.uniform(0.03, 0.25, 3)  # a box's six faces: three pairs of equal charts
    cases.append([(d[0], d[1]), (d[1], d[2]), (d[0], d[2])] * 2)
    cases.append([(0.1, 0.1)] * 6)  # a cube: every turn option ties
    for sizes in cases:
        got, expected = _pack_charts(sizes), _pack_charts_sequential(sizes)
        for a, b in zip(got, expected, strict=True):
            assert a.dtype == b.dtype and a.tobytes() == b.tobytes()
