"""`roft-sim run --tum`: TUM trajectories that evo reads, with evo's APE equal to our e_t."""

from __future__ import annotations

import json

import numpy as np
import pytest
from harness_cases import write_box_dataset

from roft_sim.cli import main

evo_file_interface = pytest.importorskip(
    "evo.tools.file_interface", reason="evo is not installed (pip install -e '.[dev]')"
)
evo_metrics = pytest.importorskip("evo.core.metrics")
evo_sync = pytest.importorskip("evo.core.sync")


def test_evo_reads_the_exports_and_its_ape_is_our_position_rmse(tmp_path):
    data = write_box_dataset(tmp_path / "data", names=("box_a",))
    out = tmp_path / "out"
    args = ["run", str(data), "--tracker", "detector-hold", "--flow", "none", "--masks", "none"]
    # failure policy: frames without a pose are left out of the RMSE, as they are of estimate.tum
    assert main([*args, "--invalid", "failure", "--tum", "--out", str(out), "--no-progress"]) == 0
    gt = evo_file_interface.read_tum_trajectory_file(str(out / "box_a" / "gt.tum"))
    est = evo_file_interface.read_tum_trajectory_file(str(out / "box_a" / "estimate.tum"))
    metrics = json.loads((out / "metrics.json").read_text())["box_a"]
    assert gt.num_poses == metrics["frames"] == 24
    assert est.num_poses == metrics["frames_rmse"] == 24 - metrics["frames_invalid"]
    np.testing.assert_allclose(gt.timestamps, np.arange(24) / 30.0)
    gt, est = evo_sync.associate_trajectories(gt, est)
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((gt, est))
    assert 100.0 * ape.get_statistic(evo_metrics.StatisticsType.rmse) == pytest.approx(
        metrics["rmse_t_cm"], rel=1e-12
    )
    rot = evo_metrics.APE(evo_metrics.PoseRelation.rotation_angle_deg)
    rot.process_data((gt, est))
    assert rot.get_statistic(evo_metrics.StatisticsType.rmse) == pytest.approx(
        metrics["rmse_a_deg"], rel=1e-6
    )
