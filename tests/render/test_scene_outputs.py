"""The scene's ground truth reaches the datasets: BOP carries every distractor as one more
instance per image (pose, masks, info), Fast-YCB keeps the tracked object only, and the object's
visible-fraction statistics land in the metadata and in generate's summary."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from stand_ins import textured_mesh_file

from roft_sim.datasets import open_sequence
from roft_sim.datasets.bop import bop_obj_id
from roft_sim.datasets.image_files import PNG_COMPRESSION, encode_png_mask
from roft_sim.generation import (
    GenerationOptions,
    ScenarioOverrides,
    generate_dataset,
    shipped_scenarios_dir,
)
from roft_sim.scenario import ObjectConfig, load_scenario
from roft_sim.scene.config import DistractorConfig, HandConfig

pytestmark = pytest.mark.render


SEED = 4
"""A seed whose grasp the camera sees (the hand hides part of the object)."""


def _scenario(tmp_path):
    import trimesh

    can = textured_mesh_file(tmp_path, "can", trimesh.creation.cylinder(radius=0.034, height=0.1))
    scenario = load_scenario(shipped_scenarios_dir() / "ci" / "cracker_box.toml")
    scene = dataclasses.replace(
        scenario.scene,
        table=dataclasses.replace(scenario.scene.table, texture_px=64),
        background=dataclasses.replace(scenario.scene.background, texture_px=64),
        hand=HandConfig(enabled=True, side="random"),  # a hand the camera sees
        distractors=(DistractorConfig(name=str(can), position_m=(0.2, 1.2)),),
    )
    box = textured_mesh_file(tmp_path, "box", trimesh.creation.box(extents=(0.06, 0.16, 0.21)))
    scenario = dataclasses.replace(
        scenario, object=ObjectConfig(mesh=Path(box)), scene=scene, seed=SEED
    )
    return ScenarioOverrides(frames=3, resolution=(160, 120)).apply(scenario)


@pytest.mark.parametrize("fmt", ["bop", "fast-ycb"])
def test_distractors_and_visibility_reach_the_dataset(tmp_path, fmt):
    # a PNG level other than the default, which every PNG of a frame must follow
    options = GenerationOptions(format=fmt, progress=False, png_compression=PNG_COMPRESSION + 5)
    summary = generate_dataset([_scenario(tmp_path)], tmp_path / "out", options)
    (result,) = summary.sequences
    meta = json.loads((result.path / "metadata.json").read_text())
    stats = meta["ground_truth_visibility"]
    assert result.visibility == stats and summary.report()["sequences"][0]["visibility"] == stats
    # Oracle: the stored visible and full masks of the tracked object.
    seq = open_sequence(result.path)
    fractions = []
    for k in range(3):
        visible, full = seq.mask(k, "gt"), seq.mask(k, "gt_full")
        fractions.append(visible.sum() / (visible | full).sum())
    assert stats["mean"] == pytest.approx(np.mean(fractions), abs=1e-6)
    assert stats["min"] < 1.0  # the hand hides part of the object
    if fmt == "fast-ycb":
        return
    gt = json.loads((result.path / "scene_gt.json").read_text())
    info = json.loads((result.path / "scene_gt_info.json").read_text())
    for k in ("0", "1", "2"):
        assert [g["obj_id"] for g in gt[k]] == [seq.metadata()["format_options"]["obj_id"],
                                                 bop_obj_id("can")]  # fmt: skip
        assert len(info[k]) == 2 and info[k][1]["px_count_visib"] > 20
        for folder in ("mask_visib", "mask"):
            path = result.path / folder / f"{int(k):06d}_000001.png"
            # written at the writer's PNG level like every other PNG of the frame
            decoded = cv2.imread(str(path), cv2.IMREAD_UNCHANGED) > 0
            assert path.read_bytes() == encode_png_mask(decoded, level=PNG_COMPRESSION + 5)
    # The distractor rests on the table: its pose in the world is the same in every frame.
    cams = seq.camera_poses()
    poses = []
    for k in range(3):
        T = np.eye(4)
        T[:3, :3] = np.reshape(gt[str(k)][1]["cam_R_m2c"], (3, 3))
        T[:3, 3] = np.asarray(gt[str(k)][1]["cam_t_m2c"]) / 1000.0
        poses.append(cams[k] @ T)
    np.testing.assert_allclose(poses[0], poses[2], atol=1e-6)
