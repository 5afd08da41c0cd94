"""The DOPE-like defaults, scored on GENERATED Fast-YCB-like sequences as the reference scores
"DOPE (ideal)" (every detected frame, no delay, misses left out, ADD with the dataset's own
model points, "ALL" pools the frames), land on the paper's Table IV row.

This is the sensors' calibration (tests/sensors/test_pose_estimator_calibration.py) repeated
end to end: the six ``--preset fast-ycb`` scenarios (their own trajectories, objects, distances
and visibility from the rendered masks) go through ``generate_dataset`` and are read back with
``open_sequence``. Images are rendered small (160x90; the estimator's errors do not depend on the
resolution, only the visible fractions do, through the masks) and without flow or segmenter sets
(each network has its own random stream, so the pose set is the same with or without them).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from roft_sim.datasets import open_sequence
from roft_sim.generation import (
    PRESETS,
    GenerationOptions,
    ScenarioOverrides,
    generate_dataset,
    preset_scenario_paths,
)
from roft_sim.metrics import evaluate_sequence, pool_metrics
from roft_sim.scenario import load_scenario

pytestmark = [pytest.mark.render, pytest.mark.slow]

TARGET = {"add_auc_pct": 84.94, "rmse_t_cm": 8.7, "rmse_a_deg": 16.277}
"""ROFT paper, Table IV, "DOPE [23] (ideal)"."""
TOLERANCE = {"add_auc_pct": 2.5, "rmse_t_cm": 1.8, "rmse_a_deg": 2.7}
"""Accepted |reached - target|. The sensors' calibration accepts (1.5, 1.0, 1.5), about three
standard deviations over seeds at 3000 frames per object; these sequences have 880 frames per
object, so the spread is sqrt(3000 / 880) = 1.85 times larger and the same three standard
deviations are 1.85 times those values (rounded up). Reached with the seeds of the preset
scenarios: ADD-AUC 83.40 %, 9.48 cm, 15.88 deg (differences 1.54, 0.78, 0.40)."""


def _generate_preset(out):
    scenarios = []
    for path in preset_scenario_paths("fast-ycb"):
        s = load_scenario(path)
        networks = dataclasses.replace(
            s.networks,
            flow_sets=(),
            mask=dataclasses.replace(s.networks.mask, enabled=False),
            # the pooled "DOPE (ideal)" defaults, not the per-object Table I fit
            # (tests/harness/test_dope_calibration.py checks that one)
            pose=dataclasses.replace(s.networks.pose, calibration="none"),
        )
        scenarios.append(dataclasses.replace(s, networks=networks))
    return generate_dataset(
        scenarios,
        out,
        GenerationOptions(format="hdf5", progress=False),
        overrides=ScenarioOverrides(resolution=(160, 90)),
        sequence_naming=PRESETS["fast-ycb"].sequence_names,
        preset="fast-ycb",
    )


def test_dope_like_defaults_on_generated_fast_ycb_land_on_the_paper_row(tmp_path):
    summary = _generate_preset(tmp_path)
    assert summary.finished and summary.frames_generated == 6 * 880
    per_object = {}
    detected = 0
    for result in summary.sequences:
        seq = open_sequence(result.path)
        gt = seq.ground_truth()
        det = seq.detector_poses("dope")
        points = seq.object_model().model_points_m
        per_object[result.name] = evaluate_sequence(
            det.T_cam_obj, gt.T_cam_obj, points, valid=det.valid, invalid="exclude"
        )
        detected += int(det.valid.sum())
    pooled = pool_metrics(per_object)["ALL"]
    reached = {k: getattr(pooled, k) for k in TARGET}
    print("DOPE (ideal) on generated Fast-YCB:", {k: round(v, 3) for k, v in reached.items()})
    print("detected fraction:", detected / (6 * 880))
    for key, target in TARGET.items():
        assert abs(reached[key] - target) <= TOLERANCE[key], (key, reached[key], target)
    assert 0.9 < detected / (6 * 880) < 0.995  # ~2 % misses plus out-of-view frames
    assert np.isfinite(pooled.add_auc_pct)
