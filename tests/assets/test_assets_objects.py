"""load_object: real YCB meshes (aligned frame), mesh files, model points and error messages."""

from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh

from roft_sim.assets import (
    AssetNotFoundError,
    DatasetFormatError,
    UnknownObjectError,
    get_object_info,
    list_objects,
    load_object,
    model_point_seed,
    sample_surface_points,
)
from roft_sim.assets.meshes import geometry_mesh, read_mesh_file
from roft_sim.assets.objects import _clear_caches, find_ycb_mesh
from roft_sim.assets.procedural import stand_in_mesh
from roft_sim.errors import ConfigError
from roft_sim.testing.mesh_oracles import closest_point_on_triangles

FAST_YCB = [info.name for info in list_objects()][:6]


# ----------------------------------------------------------------------------- model points


def test_the_surface_distance_oracle_agrees_with_trimesh_and_brute_force():
    rng = np.random.default_rng(3)
    tri = rng.normal(size=(400, 3, 3))
    p = rng.normal(size=(400, 3)) * 2
    ours = closest_point_on_triangles(tri, p)
    np.testing.assert_allclose(ours, trimesh.triangles.closest_point(tri, p), atol=1e-9)
    # brute force over a dense barycentric grid never finds a closer point
    g = np.linspace(0, 1, 60)
    u, v = np.meshgrid(g, g)
    keep = u + v <= 1
    bary = np.stack([1 - u[keep] - v[keep], u[keep], v[keep]], axis=1)
    for t, q, o in zip(tri[:20], p[:20], ours[:20], strict=True):
        grid = bary @ t
        assert np.linalg.norm(q - o) <= np.linalg.norm(grid - q, axis=1).min() + 1e-12


@pytest.mark.parametrize("name", ["003_cracker_box", "006_mustard_bottle"])
def test_model_points_lie_on_the_surface_and_never_change(name, surface_distance):
    a = load_object(name, prefer="procedural", max_texture_px=64)
    points = a.model.model_points_m
    assert points.shape == (2620, 3)
    d = surface_distance(a.model.vertices_m, a.model.faces, points)
    assert d.max() < 1e-12
    _clear_caches()
    b = load_object(name, prefer="procedural", max_texture_px=128)  # texture size is irrelevant
    np.testing.assert_array_equal(points, b.model.model_points_m)


def test_model_points_are_pinned():
    """Golden values: the sample depends only on the geometry and the object name (a SHA-256
    seed and PCG64's raw stream, both stable across numpy versions)."""
    expected_seed = int.from_bytes(hashlib.sha256(b"003_cracker_box").digest()[:8], "little")
    assert model_point_seed("003_cracker_box") == expected_seed
    points = load_object("003_cracker_box", prefer="procedural", max_texture_px=64)
    pinned = [
        [0.04969075711517775, -0.10243543169101205, -0.0359],
        [0.03432956224471427, -0.042155764800359354, -0.0359],
    ]
    np.testing.assert_allclose(points.model.model_points_m[:2], pinned, rtol=0, atol=1e-15)
    np.testing.assert_allclose(
        points.model.model_points_m[-1],
        [-0.05985767878840924, 0.040205266227243595, 0.0359],
        rtol=0,
        atol=1e-15,
    )


def test_surface_sample_is_area_uniform():
    box = trimesh.creation.box((0.3, 0.1, 0.02))
    points = sample_surface_points(np.asarray(box.vertices), np.asarray(box.faces), 60000, seed=7)
    # share of points on each pair of faces ~ share of area (binomial tolerance, 5 sigma)
    on_x = np.isclose(np.abs(points[:, 0]), 0.15).mean()
    on_y = np.isclose(np.abs(points[:, 1]), 0.05).mean()
    on_z = np.isclose(np.abs(points[:, 2]), 0.01).mean()
    area = np.array([0.1 * 0.02, 0.3 * 0.02, 0.3 * 0.1])
    expected = area / area.sum()
    sigma = np.sqrt(expected * (1 - expected) / len(points))
    np.testing.assert_array_less(np.abs([on_x, on_y, on_z] - expected), 5 * sigma)
    # uniform inside a face: the mean of the points on the +z face is its centre
    top = points[np.isclose(points[:, 2], 0.01)]
    np.testing.assert_allclose(top[:, :2].mean(axis=0), 0.0, atol=5 * 0.3 / np.sqrt(12 * len(top)))


def _trimesh_merged(vertices_m, faces):
    mesh = trimesh.Trimesh(vertices_m, faces, process=False)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64)


def _assert_same_bytes(ours, oracle):
    for a, b in zip(ours, oracle, strict=True):
        assert a.dtype == b.dtype and a.shape == b.shape
        assert a.tobytes() == b.tobytes()


def test_geometry_mesh_is_trimeshs_merge_vertices_bit_for_bit():
    """geometry_mesh (numpy, so loading a stand-in does not import trimesh) gives exactly what
    the trimesh call it replaces gives: the same vertices, in the same order, and faces; model
    points, and every dataset's model files, depend on both."""
    for info in list_objects():
        atlas = stand_in_mesh(info)
        _assert_same_bytes(
            geometry_mesh(atlas.vertices_m, atlas.faces),
            _trimesh_merged(atlas.vertices_m, atlas.faces),
        )
    rng = np.random.default_rng(5)
    # a coarse grid with sub-1e-8 m jitter (merged), some 1e-7 m offsets (kept apart), and
    # vertices that no face uses (dropped)
    vertices = rng.integers(-4, 5, (400, 3)) * 0.01 + rng.normal(0.0, 1e-10, (400, 3))
    vertices[::7] += 1e-7
    faces = rng.integers(0, 300, (250, 3))
    _assert_same_bytes(geometry_mesh(vertices, faces), _trimesh_merged(vertices, faces))
    no_faces = np.zeros((0, 3), dtype=np.int64)
    _assert_same_bytes(geometry_mesh(vertices, no_faces), _trimesh_merged(vertices, no_faces))


def test_geometry_mesh_of_real_meshes_is_trimeshs(shared_ycb_dir):
    for obj in sorted(shared_ycb_dir.glob("*/textured.obj"))[:2]:
        vertices, faces, _ = read_mesh_file(obj)
        _assert_same_bytes(geometry_mesh(vertices, faces), _trimesh_merged(vertices, faces))


# ------------------------------------------------------------------------------ real meshes


def _check_real(name: str, ycb_dir: Path, surface_distance, point_stride: int = 1) -> None:
    info = get_object_info(name)
    assets = load_object(name, assets_dir=ycb_dir, prefer="ycb", max_texture_px=512)
    assert assets.source == "ycb"
    assert assets.source_path == ycb_dir / name / "textured.obj"
    lo, hi = assets.mesh.bounds_m
    np.testing.assert_allclose(0.5 * (lo + hi), 0.0, atol=0.1e-3)  # measured: < 0.001 mm
    np.testing.assert_allclose(hi - lo, info.dimensions_m, atol=0.05e-3)
    assert assets.mesh.uv.min() >= 0.0 and assets.mesh.uv.max() <= 1.0
    assert max(assets.mesh.texture_rgb.shape[:2]) == 512
    # the aligned mesh is the original one moved by the manifest's (R, t)
    original = trimesh.load_mesh(ycb_dir / name / "textured.obj", process=False)
    T = info.nvdu_alignment.T_nvdu_orig
    np.testing.assert_allclose(
        assets.mesh.vertices_m, original.vertices @ T[:3, :3].T + T[:3, 3], atol=1e-12
    )
    np.testing.assert_array_equal(assets.mesh.uv, original.visual.uv)
    points = assets.model.model_points_m[::point_stride]
    d = surface_distance(assets.model.vertices_m, assets.model.faces, points)
    assert d.max() < 1e-12


@pytest.mark.parametrize("name", ["005_tomato_soup_can"])
def test_real_mesh_is_aligned(name, shared_ycb_dir, surface_distance):
    _check_real(name, shared_ycb_dir, surface_distance, point_stride=8)


@pytest.mark.slow
@pytest.mark.parametrize("name", FAST_YCB)
def test_all_real_meshes_are_aligned(name, shared_ycb_dir, surface_distance):
    _check_real(name, shared_ycb_dir, surface_distance)


def test_real_texture_is_the_file_downscaled(shared_ycb_dir):
    assets = load_object("009_gelatin_box", assets_dir=shared_ycb_dir, max_texture_px=256)
    bgr = cv2.imread(str(shared_ycb_dir / "009_gelatin_box" / "texture_map.jpg"))
    expected = cv2.resize(bgr, (256, 256), interpolation=cv2.INTER_AREA)[:, :, ::-1]
    np.testing.assert_array_equal(assets.mesh.texture_rgb, expected)


def test_real_uv_convention_row_is_one_minus_v(shared_ycb_dir):
    """Face-centre UVs land on painted texels with row = (1 - v) * H; the flipped reading lands
    on the atlas' black background about 40 % of the time (measured 0.40-0.47)."""
    mesh = load_object("003_cracker_box", assets_dir=shared_ycb_dir, max_texture_px=512).mesh
    uv = mesh.uv[mesh.faces].mean(axis=1)
    dark = lambda rgb: (rgb.astype(int).sum(axis=1) < 30).mean()  # noqa: E731
    assert dark(mesh.sample_texture(uv)) < 0.01
    assert dark(mesh.sample_texture(np.column_stack([uv[:, 0], 1 - uv[:, 1]]))) > 0.3


def test_google_16k_layout_and_lookup_order(shared_ycb_dir, tmp_path):
    name = "010_potted_meat_can"
    nested = tmp_path / "assets" / name / "google_16k"
    nested.mkdir(parents=True)
    for f in ("textured.obj", "textured.mtl", "texture_map.jpg"):
        shutil.copy(shared_ycb_dir / name / f, nested / f)
    cache = tmp_path / "cache"
    assert find_ycb_mesh(name, assets_dir=tmp_path / "assets", cache_dir=cache) == (
        nested / "textured.obj"
    )
    assets = load_object(name, assets_dir=tmp_path / "assets", max_texture_px=64)
    assert assets.source == "ycb" and assets.source_path == nested / "textured.obj"
    # without the assets folder nothing is installed: the stand-in
    assert load_object(name, cache_dir=cache, max_texture_px=64).source == "procedural"
    # the cache is searched after assets_dir
    (cache / "ycb").mkdir(parents=True)
    shutil.copytree(nested, cache / "ycb" / name)
    assert find_ycb_mesh(name, cache_dir=cache) == cache / "ycb" / name / "textured.obj"
    assert load_object(name, cache_dir=cache, max_texture_px=64).source == "ycb"
    assert load_object(name, cache_dir=cache, prefer="procedural").source == "procedural"


def _write_textured_cube_obj(folder: Path, size_m: float, texture: bool = True) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    cube = trimesh.creation.box((size_m,) * 3)
    lines = ["mtllib textured.mtl"] if texture else []
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in cube.vertices]
    lines += [f"vt {0.1 + 0.1 * (i % 8):.3f} {0.2 + 0.05 * i:.3f}" for i in range(8)]
    lines += ["usemtl material_0"] if texture else []
    lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in cube.faces]
    (folder / "textured.obj").write_text("\n".join(lines) + "\n")
    if texture:
        (folder / "textured.mtl").write_text("newmtl material_0\nmap_Kd texture_map.png \n")
        image = np.zeros((16, 32, 3), dtype=np.uint8)
        image[:, :, 2] = np.arange(32, dtype=np.uint8)[None] * 8
        cv2.imwrite(str(folder / "texture_map.png"), image)
    return folder / "textured.obj"


def test_a_mesh_that_does_not_fit_the_alignment_is_refused(tmp_path):
    _write_textured_cube_obj(tmp_path / "003_cracker_box", 0.05)
    with pytest.raises(DatasetFormatError, match=r"does not fit the registry entry '003_cracker"):
        load_object("003_cracker_box", assets_dir=tmp_path)


def test_prefer_ycb_without_a_mesh_says_how_to_install(tmp_path):
    with pytest.raises(
        AssetNotFoundError,
        match=r"no real mesh of '004_sugar_box' is installed \(looked for .*cache/ycb/004_sugar_"
        r"box/textured.obj\); install them with `roft-sim assets install --from /path/to/ycb",
    ):
        load_object("004_sugar_box", cache_dir=tmp_path / "cache", prefer="ycb")


def test_unknown_name_and_bad_arguments():
    with pytest.raises(UnknownObjectError, match=r"did you mean '006_mustard_bottle'\?"):
        load_object("006_mustard_botle")
    with pytest.raises(ConfigError, match=r"prefer must be"):
        load_object("003_cracker_box", prefer="real")  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"max_texture_px must be an integer in 8\.\.8192"):
        load_object("003_cracker_box", max_texture_px=4)
    with pytest.raises(AssetNotFoundError, match=r"assets directory '/nonexistent' does not exist"):
        load_object("003_cracker_box", assets_dir=Path("/nonexistent"))


# -------------------------------------------------------------------------------- mesh files


def test_textured_obj_file_keeps_its_frame_and_texture(tmp_path):
    path = _write_textured_cube_obj(tmp_path / "cube", 0.04)
    assets = load_object(str(path), max_texture_px=64)
    assert assets.source == "file" and assets.info is None
    assert assets.model.mesh_path == path.resolve()
    assert assets.model.name == "textured"
    np.testing.assert_allclose(assets.mesh.bounds_m, [[-0.02] * 3, [0.02] * 3])
    assert assets.mesh.texture_rgb.shape == (16, 32, 3)
    assert assets.mesh.texture_rgb[0, 31, 0] == 248  # BGR file -> RGB array


@pytest.mark.parametrize("suffix", [".stl", ".ply"])
def test_untextured_files_get_a_projected_procedural_texture(tmp_path, suffix, surface_distance):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    path = tmp_path / f"ball{suffix}"
    mesh.export(path)
    assets = load_object(path, max_texture_px=64, cache_dir=tmp_path / "cache")
    assert assets.source == "file"
    assert assets.mesh.uv.min() >= 0 and assets.mesh.uv.max() <= 1
    assert max(assets.mesh.texture_rgb.shape[:2]) == 64
    assert assets.mesh.texture_rgb.std() > 10
    assert list((tmp_path / "cache" / "procedural").glob("file-ball-*.npy"))
    d = surface_distance(mesh.vertices, mesh.faces, assets.model.model_points_m)
    assert d.max() < 1e-8  # STL stores float32


def test_mesh_files_in_millimetres_and_missing_files_are_refused(tmp_path):
    path = tmp_path / "big.stl"
    trimesh.creation.box((100.0, 50.0, 20.0)).export(path)
    with pytest.raises(DatasetFormatError, match=r"100 units across; roft_sim expects metres"):
        load_object(str(path))
    with pytest.raises(AssetNotFoundError, match=r"mesh file '.*missing.obj' does not exist"):
        load_object(str(tmp_path / "missing.obj"))
    bad = tmp_path / "broken.ply"
    bad.write_text("ply\nformat nonsense\n")
    with pytest.raises(DatasetFormatError, match=r"broken.ply' cannot be read"):
        load_object(str(bad))
