"""The reference's held "DOPE" scoring policy and the start-of-sequence miss stretch."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from roft_sim.datasets.base import DetectorPoses
from roft_sim.errors import ConfigError
from roft_sim.harness.dope_calibration import held_detection_estimates
from roft_sim.records import PoseTrack
from roft_sim.sensors.pose_estimator import PoseEstimatorConfig, sample_pose_detections


def _reference_load_dope(values: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, int]:
    """The reference ``data_loader.load_dope`` (simulated inference) written out step by step on
    one scalar per frame: shift by 6 with edge padding, keep every 6th, repeat each 6 times,
    replace a missing value by the last valid one, drop the frames before the first valid."""
    n = len(values)
    shifted = np.concatenate([np.repeat(values[:1], 6), values])[:n]
    shifted_ok = np.concatenate([np.repeat(valid[:1], 6), valid])[:n]
    kept, kept_ok = shifted[::6], shifted_ok[::6]
    held = np.repeat(kept, 6)[:n].astype(float)
    held_ok = np.repeat(kept_ok, 6)[:n]
    last = np.nan
    for k in range(n):
        if held_ok[k]:
            last = held[k]
        held[k] = last
    first = int(np.flatnonzero(~np.isnan(held))[0])
    return held, first


@pytest.mark.parametrize("seed", range(5))
def test_held_detections_match_the_reference_policy(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(20, 120))
    valid = rng.random(n) < 0.6
    valid[int(rng.integers(0, n // 2)) // 6 * 6] = True  # at least one usable frame
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, 0, 3] = np.arange(n)  # the frame index, to see which detection is held
    T_held, ok = held_detection_estimates(DetectorPoses(T_cam_obj=T, valid=valid))
    expected, first = _reference_load_dope(np.arange(n, dtype=float), valid)
    assert not ok[:first].any() and ok[first:].all()
    np.testing.assert_array_equal(T_held[first:, 0, 3], expected[first:])


def test_held_detections_reject_bad_timing():
    det = DetectorPoses(T_cam_obj=np.broadcast_to(np.eye(4), (3, 4, 4)), valid=np.ones(3, bool))
    with pytest.raises(ConfigError, match="period_frames"):
        held_detection_estimates(det, period_frames=0)


def _track(n: int) -> PoseTrack:
    T = np.broadcast_to(np.eye(4), (n, 4, 4)).copy()
    T[:, 2, 3] = 0.6
    return PoseTrack(
        t_s=np.arange(n) / 30, T_cam_obj=T, v_obj_mps=np.zeros((n, 3)), w_radps=np.zeros((n, 3))
    )


def test_start_miss_stretch_has_the_configured_rate_and_mean_length():
    config = PoseEstimatorConfig(
        miss_probability=0.0, start_miss_probability=0.3, start_miss_mean_frames=40.0
    )
    lengths = []
    for seed in range(600):
        valid = sample_pose_detections(_track(400), config, np.random.default_rng(seed)).valid
        lengths.append(int(np.argmax(valid)))
    lengths_arr = np.array(lengths)
    stretched = lengths_arr[lengths_arr > 0]
    assert abs(len(stretched) / 600 - 0.3) < 0.06
    assert abs(stretched.mean() - 40.0) < 6.0


def test_start_miss_stretch_leaves_the_other_draws_unchanged():
    base = PoseEstimatorConfig()
    with_stretch = dataclasses.replace(base, start_miss_probability=1.0, start_miss_mean_frames=5)
    a = sample_pose_detections(_track(60), base, np.random.default_rng(3))
    b = sample_pose_detections(_track(60), with_stretch, np.random.default_rng(3))
    first = int(np.argmax(b.valid))
    assert first >= 1 and not b.valid[:first].any()
    np.testing.assert_array_equal(a.valid[first:], b.valid[first:])
    np.testing.assert_array_equal(a.T_cam_obj[first:], b.T_cam_obj[first:])


def test_start_miss_config_is_checked():
    with pytest.raises(ConfigError, match="start_miss_mean_frames"):
        PoseEstimatorConfig(start_miss_mean_frames=0.5)
    with pytest.raises(ConfigError, match="start_miss_probability"):
        PoseEstimatorConfig(start_miss_probability=1.5)


# ------------------------------------------------------- the per-object Table I calibration
def test_fast_ycb_objects_get_their_own_fit_unless_an_estimator_is_given():
    from roft_sim.sensors.networks import PoseSetConfig
    from roft_sim.sensors.pose_estimator import FAST_YCB_DOPE

    assert len(FAST_YCB_DOPE) == 6
    default = PoseSetConfig()
    for name, config in FAST_YCB_DOPE.items():
        assert default.estimator_for(name) == config != PoseEstimatorConfig()
    assert default.estimator_for("021_bleach_cleanser") == PoseEstimatorConfig()
    custom = PoseSetConfig(estimator=PoseEstimatorConfig(rotation_sigma_rad=0.2))
    assert custom.estimator_for("009_gelatin_box").rotation_sigma_rad == 0.2
    pooled = PoseSetConfig(calibration="none")
    assert pooled.estimator_for("009_gelatin_box") == PoseEstimatorConfig()
    with pytest.raises(ConfigError, match="calibration"):
        PoseSetConfig(calibration="paper")  # type: ignore[arg-type]


TABLE1_AUC_TOLERANCE = 3.0
"""Issue 15's goal: each object within 3 ADD-AUC points of Table I's DOPE column."""
ALL_AUC_TOLERANCE = 2.0
"""... and ALL within 2 points of 58.83 %."""


@pytest.mark.slow
@pytest.mark.shared_data
def test_held_dope_reproduces_table1_per_object_on_the_report_seeds(shared_ycb_dir):
    """The fit used trajectory seeds 0-9 of the fast-ycb preset's motion; this scores seeds
    100-109 (the EVALUATION split) with the real meshes' model points."""
    from roft_sim.assets import load_object
    from roft_sim.generation import preset_scenario_paths
    from roft_sim.harness.dope_calibration import REPORT_SEEDS, scenario_motion_tracks, score_dope
    from roft_sim.report.paper_reference import paper_tables
    from roft_sim.sensors.pose_estimator import FAST_YCB_DOPE

    paths = {p.stem: p for p in preset_scenario_paths("fast-ycb")}
    tracks = {n: scenario_motion_tracks(p, REPORT_SEEDS) for n, p in paths.items()}
    points = {
        n: load_object(n, assets_dir=shared_ycb_dir, prefer="ycb").model.model_points_m
        for n in paths
    }
    held = score_dope(FAST_YCB_DOPE, tracks, points).held
    paper = paper_tables().table1["DOPE"]["add_auc_pct"]
    reached = {n: round(held[n].add_auc_pct, 2) for n in [*paths, "ALL"]}
    print("held DOPE ADD-AUC, seeds 100-109:", reached)
    for name in paths:
        assert abs(reached[name] - paper[name]) <= TABLE1_AUC_TOLERANCE, (name, reached, paper)
    assert abs(reached["ALL"] - paper["ALL"]) <= ALL_AUC_TOLERANCE
    # gelatin box: the heavy outliers behind Table I's 34.4 cm
    assert held["009_gelatin_box"].rmse_t_cm > 20.0


def _preset_paths(*names: str):
    from roft_sim.generation import preset_scenario_paths

    return {p.stem: p for p in preset_scenario_paths("fast-ycb") if p.stem in names}


def test_faster_bursts_lose_more_from_ideal_to_held():
    """The held-minus-ideal loss of the same pooled estimator is set by the motion: bursts that
    all peak near the stated peaks lose more than the generator's default spread of bursts."""
    from roft_sim.assets import load_object
    from roft_sim.harness.dope_calibration import motion_held_loss

    paths = _preset_paths("003_cracker_box", "005_tomato_soup_can")
    points = {n: load_object(n, prefer="procedural").model.model_points_m[:256] for n in paths}

    def loss(fraction: float) -> float:
        rows = motion_held_loss(paths, points, range(3), fraction, frames=300)
        return rows.held["ALL"].add_auc_pct - rows.ideal["ALL"].add_auc_pct

    slow, fast = loss(0.3), loss(1.0)
    assert fast < slow - 3.0, (slow, fast)


def test_motion_fit_finds_the_fraction_of_a_known_loss():
    from roft_sim.harness.dope_calibration import fit_motion_speed_fraction

    calls: list[float] = []

    def loss(fraction: float) -> float:  # monotone: -15 at 0.3 .. -29 at 1.0
        calls.append(fraction)
        return -9.0 - 20.0 * fraction

    assert fit_motion_speed_fraction(loss, -9.0 - 20.0 * 0.62) == pytest.approx(0.62, abs=0.01)
    assert len(calls) == 2 + 7 and all(0.3 <= c <= 1.0 for c in calls)


def test_motion_fit_keeps_the_evaluated_fraction_nearest_the_target():
    """A noisy loss sends the bisection astray: the target is met at 0.8 (the second midpoint),
    but 0.7's loss (-23 less a 3-point dip) falls below it, so the bisection ends near 0.7;
    0.8 is returned."""
    from roft_sim.harness.dope_calibration import fit_motion_speed_fraction

    def loss(fraction: float) -> float:
        return -9.0 - 20.0 * fraction - (3.0 if abs(fraction - 0.7) < 1e-9 else 0.0)

    # midpoints 0.6, 0.8 (the target), 0.7 (below it: hi = 0.7), 0.65 ... 0.69375
    assert fit_motion_speed_fraction(loss, -25.0, bounds=(0.2, 1.0)) == 0.8


def test_motion_fit_refuses_an_unreachable_loss_and_bad_bounds():
    from roft_sim.harness.dope_calibration import fit_motion_speed_fraction

    with pytest.raises(ConfigError, match=r"-40.00 points is not reached.*-15.00 \.\. -29.00"):
        fit_motion_speed_fraction(lambda f: -9.0 - 20.0 * f, -40.0)
    with pytest.raises(ConfigError, match="bounds"):
        fit_motion_speed_fraction(lambda f: -f, -0.5, bounds=(0.8, 0.2))


def test_speed_fraction_override_needs_synthetic_motion(tmp_path):
    """The preset with its continuous profile instead of the bursty one."""
    from roft_sim.harness.dope_calibration import scenario_motion_tracks

    (preset,) = _preset_paths("003_cracker_box").values()
    text = preset.read_text()
    assert 'source = "bursty"' in text
    path = tmp_path / "continuous.toml"
    path.write_text(text.replace('source = "bursty"', 'source = "continuous"'))
    with pytest.raises(ConfigError, match="min_speed_fraction applies to synthetic"):
        scenario_motion_tracks(path, [0], min_speed_fraction=0.5)


MOTION_LOSS_TOLERANCE = 2.0
"""Points of ADD-AUC between the preset motion's held-minus-ideal loss on the report seeds and
the paper's (58.83 - 84.94)."""


@pytest.mark.slow
@pytest.mark.shared_data
def test_preset_motion_loses_the_papers_ideal_to_held_share_on_the_report_seeds(shared_ycb_dir):
    """The preset's min_speed_fraction was fitted on seeds 0-9 (``--fit-motion``); seeds
    100-109 must lose what the paper's DOPE loses from its ideal to its held row."""
    from roft_sim.assets import load_object
    from roft_sim.generation import preset_scenario_paths
    from roft_sim.harness.dope_calibration import REPORT_SEEDS, motion_held_loss
    from roft_sim.report.paper_reference import paper_tables

    paths = {p.stem: p for p in preset_scenario_paths("fast-ycb")}
    points = {
        n: load_object(n, assets_dir=shared_ycb_dir, prefer="ycb").model.model_points_m
        for n in paths
    }
    rows = motion_held_loss(paths, points, REPORT_SEEDS)
    table4 = paper_tables().table4
    paper = table4["DOPE"]["add_auc_pct"] - table4["DOPE (ideal)"]["add_auc_pct"]
    reached = rows.held["ALL"].add_auc_pct - rows.ideal["ALL"].add_auc_pct
    assert abs(reached - paper) <= MOTION_LOSS_TOLERANCE, (reached, paper)


def test_spread_prints_each_sequence_with_the_pooled_runs_draws(capsys):
    """One line per object: the held ADD-AUC of each track alone (from the pooled scoring's own
    draws for that object and track), then their mean and sample standard deviation."""
    from roft_sim.harness.dope_calibration import _print_spread, score_dope

    points = np.random.default_rng(1).uniform(-0.05, 0.05, (64, 3))
    tracks = {"a_object": [_track(60), _track(90)]}
    configs = {"a_object": PoseEstimatorConfig()}
    _print_spread(score_dope(configs, tracks, {"a_object": points}))
    line = capsys.readouterr().out.strip().splitlines()[-1]
    name, rest = line.split(": ")
    values = [float(v) for v in rest.split(";")[0].split()]
    mean, sd = (float(v) for v in rest.split(";")[1].split(","))
    assert name == "a_object" and len(values) == 2
    assert mean == pytest.approx(np.mean(values), abs=0.01)
    assert sd == pytest.approx(np.std(values, ddof=1), abs=0.01)
    # the first track alone, drawn as the pooled scoring draws object 0's track 0
    alone = score_dope(configs, {"a_object": tracks["a_object"][:1]}, {"a_object": points})
    assert values[0] == pytest.approx(alone.held["a_object"].add_auc_pct, abs=0.01)


def test_cli_help_and_bad_paths_exit_without_fitting(tmp_path, capsys):
    """``--help`` describes the script and a missing folder is refused before any fit starts."""
    from roft_sim.harness.dope_calibration import cli

    with pytest.raises(SystemExit) as help_exit:
        cli(["--help"])
    assert help_exit.value.code == 0
    assert "--fit-motion" in capsys.readouterr().out
    with pytest.raises(SystemExit) as bad_exit:
        cli([str(tmp_path / "missing")])
    assert bad_exit.value.code == 2
    assert "is not a directory" in capsys.readouterr().err
