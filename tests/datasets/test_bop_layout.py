"""BOP scene folders numbered as bop_toolkit expects, with a map to the sequence names, and
``models_info.json`` diameters as bop_toolkit computes them."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from dataset_fixtures import plate_sequence

from roft_sim.datasets import list_sequences, open_sequence, write_sequence
from roft_sim.datasets.bop import SCENE_NAMES_FILE, bop_scene_folder, model_diameter_m
from roft_sim.errors import ConfigError
from roft_sim.records import ObjectModel


def _calc_pts_diameter(pts: np.ndarray) -> float:
    """bop_toolkit ``misc.calc_pts_diameter``, transcribed: the largest distance between any
    two points, by brute force."""
    diameter = -1.0
    for pt_id in range(pts.shape[0]):
        pt_dup = np.tile(np.array([pts[pt_id, :]]), [pts.shape[0] - pt_id, 1])
        pts_diff = pt_dup - pts[pt_id:, :]
        max_dist = np.sqrt((pts_diff * pts_diff).sum(axis=1)).max()
        if max_dist > diameter:
            diameter = max_dist
    return float(diameter)


def test_scenes_are_numbered_and_mapped_to_their_names(tmp_path: Path):
    for name in ("plate_b", "plate_a"):
        write_sequence(plate_sequence(n_frames=2, name=name), "bop", tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir() if p.is_dir()) == ["000001", "000002"]
    names = json.loads((tmp_path / SCENE_NAMES_FILE).read_text())
    assert names == {"000001": "plate_b", "000002": "plate_a"}
    found = list_sequences(tmp_path)
    assert [p.name for p in found] == ["000001", "000002"]
    assert [open_sequence(p).name for p in found] == ["plate_b", "plate_a"]  # names kept
    # the same name maps to the same scene again (resume), a given id is used, a clash refused
    assert bop_scene_folder(tmp_path, "plate_a") == "000002"
    assert bop_scene_folder(tmp_path, "plate_c", 7) == "000007"
    with pytest.raises(ConfigError, match="000001 .* is taken"):
        bop_scene_folder(tmp_path, "plate_d", 1)
    assert bop_scene_folder(tmp_path, "000042") == "000042"  # numeric names are their folder


def test_models_info_diameter_is_bop_toolkits_over_the_mesh_vertices(tmp_path: Path):
    rng = np.random.default_rng(3)
    vertices = rng.normal(0.0, 0.05, (300, 3)) * [1.0, 0.5, 2.0]
    points = vertices[rng.choice(300, 40, replace=False)] * 0.97  # sampled inside the surface
    model = ObjectModel(
        name="blob",
        vertices_m=vertices,
        faces=np.array([[0, 1, 2]], dtype=np.int64),
        model_points_m=points,
    )
    seq = dataclasses.replace(plate_sequence(n_frames=2, name="blob"), model=model)
    scene = write_sequence(seq, "bop", tmp_path)
    info = json.loads((scene / "models" / "models_info.json").read_text())
    (entry,) = info.values()
    # bop_toolkit loads the ply in mm and runs calc_pts_diameter on its vertices
    expected_mm = _calc_pts_diameter(vertices * 1000.0)
    assert entry["diameter"] == pytest.approx(expected_mm, rel=1e-12)
    assert entry["diameter"] > _calc_pts_diameter(points * 1000.0) + 1.0  # not from the points
    assert model_diameter_m(vertices) == pytest.approx(expected_mm / 1000.0, rel=1e-12)
    flat = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0.1, 0.2, 0], [0.05, 0.1, 0]])
    assert model_diameter_m(flat) == pytest.approx(np.hypot(0.1, 0.2), rel=1e-12)
