"""The robust start (``init = "robust"``): the first pose detection that fails the
depth-rendering test is held back from any tracker, and the run says so."""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np
import pytest
from harness_cases import ECHO_SPEC, box_sequence

from roft_sim.datasets.base import DetectorPoses, InMemorySequence
from roft_sim.errors import ConfigError
from roft_sim.faults import load_faults
from roft_sim.harness import RunOptions, run_sequence
from roft_sim.harness.options import InitPolicy
from roft_sim.harness.robust_start import RobustStartConfig
from roft_sim.harness.runner import SequenceRun
from roft_sim.testing.analytic_scene import AnalyticBoxDepthRenderer

FAR_OFF_M = np.array([0.0, 0.0, 0.3])
"""How far the first detection is off (behind the object: its depth contradicts the measured
surface)."""


@pytest.fixture(scope="module")
def bad_first_detection() -> InMemorySequence:
    seq = box_sequence(n_frames=24, width=96, height=72)
    poses = seq.detector_poses("dope")
    T = poses.T_cam_obj.copy()
    T[0, :3, 3] += FAR_OFF_M
    return dataclasses.replace(
        seq, detector_pose_sets={"dope": DetectorPoses(T_cam_obj=T, valid=poses.valid)}
    )


def _run(seq: InMemorySequence, init: InitPolicy, **kw: Any) -> SequenceRun:
    options = RunOptions(
        tracker="echo", flow="stored:gt", faults=load_faults("paper"), init=init, **kw
    )
    return run_sequence(
        seq,
        options,
        spec=ECHO_SPEC,
        depth_renderer_factory=lambda model: AnalyticBoxDepthRenderer(),
    )


def test_far_off_first_detection_is_held_back_and_logged(
    bad_first_detection: InMemorySequence, caplog: pytest.LogCaptureFixture
) -> None:
    detector = bad_first_detection.detector_poses("dope").T_cam_obj
    plain = _run(bad_first_detection, "first-detection")
    np.testing.assert_array_equal(plain.estimates[0].T_cam_obj, detector[0])
    with caplog.at_level(logging.INFO, logger="roft_sim.harness.robust_start"):
        robust = _run(bad_first_detection, "robust")
    # paper schedule: captures 0, 6, 12, 18; capture 6 arrives at frame 12
    assert not robust.estimates[0].valid and not robust.estimates[11].valid
    np.testing.assert_array_equal(robust.estimates[12].T_cam_obj, detector[6])
    assert "waited until frame 12" in str(robust.inputs["init"])
    assert "held back" in caplog.text and "pixels agree" in caplog.text
    assert robust.depth_renderer_built


def test_a_good_first_detection_starts_at_once() -> None:
    seq = box_sequence(n_frames=24, width=96, height=72)
    run = _run(seq, "robust")
    assert run.estimates[0].valid
    np.testing.assert_array_equal(
        run.estimates[0].T_cam_obj, seq.detector_poses("dope").T_cam_obj[0]
    )
    assert str(run.inputs["init"]).startswith("robust: first detection accepted at frame 0")


def test_the_wait_is_bounded(bad_first_detection: InMemorySequence) -> None:
    # with no wait allowed, the detection after the first rejected one is taken unchecked
    config = RobustStartConfig(max_wait_s=0.0, min_consistent_fraction=1.0, min_pixels=10**6)
    run = _run(bad_first_detection, "robust", robust_start=config)
    assert not run.estimates[11].valid and run.estimates[12].valid
    summary = str(run.inputs["init"])
    assert "held back" in summary and "no detection passed" in summary


def test_config_is_checked() -> None:
    with pytest.raises(ConfigError, match="depth_tolerance_m"):
        RobustStartConfig(depth_tolerance_m=0.0)
    with pytest.raises(ConfigError, match="unknown init policy"):
        RunOptions(tracker="echo", init="later")  # type: ignore[arg-type]
