"""The continuous hand-held profile, its fit to captured motion, and the hand-motion config."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from roft_sim.cli import main
from roft_sim.config_files import dataclass_from_mapping, load_toml
from roft_sim.errors import ConfigError
from roft_sim.generation.presets import preset_scenario_paths
from roft_sim.scenario import load_scenario
from roft_sim.testing.trajectory_strategies import finite_difference_errors
from roft_sim.trajectories import (
    FAST_YCB_CAMERA,
    CapturedTrajectory,
    ContinuousHandMotion,
    ContinuousMotionConfig,
    HandMotionConfig,
    SyntheticMotionConfig,
    ViewRegion,
    build_trajectory,
    resolve_hand_motion,
    sample_at_rate,
)
from roft_sim.trajectories.statistics import (
    captured_distribution,
    fit_continuous_motion,
    fit_error,
    synthetic_distribution,
)

TUNING_SEEDS = tuple(range(10))


def _hand_motion(path: Path) -> HandMotionConfig:
    """The ``[trajectory]`` of a shipped scenario file as written (``load_scenario`` resolves
    it into the motion it stands for)."""
    config = dataclass_from_mapping(HandMotionConfig, load_toml(path)["trajectory"], where="t")
    assert isinstance(config, HandMotionConfig)
    return config


EVALUATION_SEEDS = tuple(range(100, 110))


def _angular_speed_dps(config: ContinuousMotionConfig | SyntheticMotionConfig) -> np.ndarray:
    sample = sample_at_rate(build_trajectory(config, FAST_YCB_CAMERA), 30.0)
    speed_dps: np.ndarray = np.degrees(np.linalg.norm(sample.w_radps, axis=-1))
    return speed_dps


@pytest.mark.parametrize("seed", [0, 7, 101])
def test_derivatives_are_exact(seed: int) -> None:
    trajectory = build_trajectory(ContinuousMotionConfig(seed=seed), FAST_YCB_CAMERA)
    errors = finite_difference_errors(trajectory, np.linspace(0.01, 9.99, 400))
    for name, err in errors.items():
        assert err.max() < 1e-6, f"{name}: relative error {err.max():.2e}"


def test_same_seed_same_motion_and_other_seeds_differ() -> None:
    t = np.linspace(0.0, 10.0, 50)
    a = build_trajectory(ContinuousMotionConfig(seed=4), FAST_YCB_CAMERA).sample(t)
    b = build_trajectory(ContinuousMotionConfig(seed=4), FAST_YCB_CAMERA).sample(t)
    c = build_trajectory(ContinuousMotionConfig(seed=5), FAST_YCB_CAMERA).sample(t)
    np.testing.assert_array_equal(a.T_ref_obj, b.T_ref_obj)
    assert np.abs(a.T_ref_obj - c.T_ref_obj).max() > 1e-2


def test_object_centre_never_leaves_the_view_region() -> None:
    radius_m = 0.1
    config = ContinuousMotionConfig(seed=2, duration_s=60.0)
    region = ViewRegion.from_config(
        FAST_YCB_CAMERA, config.working_distance_m, config.in_view_margin, radius_m
    )
    trajectory = build_trajectory(config, FAST_YCB_CAMERA, object_radius_m=radius_m)
    assert isinstance(trajectory, ContinuousHandMotion)
    p = sample_at_rate(trajectory, 120.0).T_ref_obj[:, :3, 3]
    assert region.contains(p).all()


def test_keeps_turning_median_at_least_80_dps_and_no_rests() -> None:
    continuous = np.concatenate(
        [_angular_speed_dps(ContinuousMotionConfig(seed=s, duration_s=30.0)) for s in TUNING_SEEDS]
    )
    bursty = np.concatenate(
        [_angular_speed_dps(SyntheticMotionConfig(seed=s, duration_s=30.0)) for s in TUNING_SEEDS]
    )
    assert np.median(continuous) >= 80.0
    # "no rest": the bursty profile sits below 5 deg/s for a large share of the time
    assert np.mean(continuous < 5.0) < 0.01
    assert np.mean(bursty < 5.0) > 0.15


def test_config_errors_name_the_field() -> None:
    with pytest.raises(ConfigError, match="tempo_variation"):
        ContinuousMotionConfig(tempo_variation=1.0)
    with pytest.raises(ConfigError, match="angular_frequency_hz"):
        ContinuousMotionConfig(angular_frequency_hz=(1.0, 0.5))
    with pytest.raises(ConfigError, match="seed"):
        ContinuousMotionConfig(seed=-1)


def test_fitted_profile_matches_captured_motion_in_distribution(
    shared_trajectories_dir: Path,
) -> None:
    tuning = captured_distribution("tuning", shared_trajectories_dir, FAST_YCB_CAMERA)
    evaluation = captured_distribution("evaluation", shared_trajectories_dir, FAST_YCB_CAMERA)
    cont = ContinuousMotionConfig(duration_s=30.0)
    burst = SyntheticMotionConfig(duration_s=30.0)
    fit_tuning = fit_error(tuning, synthetic_distribution("c", cont, TUNING_SEEDS, FAST_YCB_CAMERA))
    fit_eval = fit_error(
        evaluation, synthetic_distribution("c", cont, EVALUATION_SEEDS, FAST_YCB_CAMERA)
    )
    bursty_eval = fit_error(
        evaluation, synthetic_distribution("b", burst, EVALUATION_SEEDS, FAST_YCB_CAMERA)
    )
    # measured: 0.37 (tuning), 0.39 (evaluation) against 1.09 for the bursty profile
    assert fit_tuning < 0.45
    assert fit_eval < 0.5
    assert bursty_eval > 2.0 * fit_eval


def test_the_defaults_are_as_good_as_a_refit(shared_trajectories_dir: Path) -> None:
    tuning = captured_distribution("tuning", shared_trajectories_dir, FAST_YCB_CAMERA)
    default = synthetic_distribution(
        "default", ContinuousMotionConfig(duration_s=30.0), TUNING_SEEDS, FAST_YCB_CAMERA
    )
    _, refit = fit_continuous_motion(tuning, FAST_YCB_CAMERA)
    assert refit.angular_speed_dps.p50 >= 80.0
    assert fit_error(tuning, default) <= fit_error(tuning, refit) + 0.03


def test_hand_motion_falls_back_to_the_continuous_profile(tmp_path: Path) -> None:
    config = _hand_motion(preset_scenario_paths("fast-ycb")[0])
    missing = dataclasses.replace(config, source="auto", trajectories_dir=tmp_path)
    resolved, reason = resolve_hand_motion(missing)
    assert resolved == config.continuous and "absent" in reason
    with pytest.raises(ConfigError, match="missing"):
        resolve_hand_motion(dataclasses.replace(missing, source="captured"))


def test_hand_motion_bursty_reproduces_the_earlier_motion_exactly() -> None:
    for path in preset_scenario_paths("fast-ycb"):
        config = _hand_motion(path)
        t = np.arange(880) / 30.0
        old = build_trajectory(config.bursty, FAST_YCB_CAMERA, object_radius_m=0.1).sample(t)
        new = build_trajectory(
            dataclasses.replace(config, source="bursty"), FAST_YCB_CAMERA, object_radius_m=0.1
        ).sample(t)
        np.testing.assert_array_equal(old.T_ref_obj, new.T_ref_obj)
        np.testing.assert_array_equal(old.w_radps, new.w_radps)


def test_fast_ycb_preset_auto_source_replays_captured_motion_when_present(
    shared_trajectories_dir: Path,
) -> None:
    for path in preset_scenario_paths("fast-ycb"):
        scenario = load_scenario(path)
        config = dataclasses.replace(
            _hand_motion(path), source="auto", trajectories_dir=shared_trajectories_dir
        )
        trajectory = build_trajectory(config, scenario.intrinsics, object_radius_m=0.1)
        assert isinstance(trajectory, CapturedTrajectory)
        assert trajectory.end_s >= (scenario.n_frames - 1) / scenario.fps
        assert trajectory.in_view_fraction > 0.85


def test_load_scenario_resolves_the_hand_motion(tmp_path: Path) -> None:
    text = preset_scenario_paths("fast-ycb")[0].read_text()
    assert text.count('source = "bursty"\n') == 1
    path = tmp_path / "scenario.toml"
    for replacement, expected in (
        ('source = "auto"\ntrajectories_dir = "absent"\n', ContinuousMotionConfig),
        ('source = "continuous"\n', ContinuousMotionConfig),
        ('source = "bursty"\n', SyntheticMotionConfig),
    ):
        path.write_text(text.replace('source = "bursty"\n', replacement))
        assert isinstance(load_scenario(path).trajectory, expected)


def test_cli_hand_motion_stats_side_by_side(
    shared_trajectories_dir: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["-q", "trajectory", "stats", "--hand-motion", "--split", "tuning"]
    assert main([*argv, "--trajectories", str(shared_trajectories_dir)]) == 0
    out = capsys.readouterr().out
    assert "captured (tuning)" in out and "continuous (seeds 0-9)" in out and "bursty" in out
    assert "angular accel. [deg/s^2]" in out
    assert main([*argv, "--trajectories", str(shared_trajectories_dir), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["tuning"]["continuous"]["angular_speed_dps"]["p50"] >= 80.0


def test_cli_continuous_profile_and_refusals(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["-q", "trajectory", "stats", "--synthetic", "--profile", "continuous", "--json"]
    assert main(argv) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["config"]["kind"] == "continuous"
    assert report["angular_speed_dps"]["median"] > 60.0
    missing = str(tmp_path / "x")
    assert main(["trajectory", "stats", "--hand-motion", "--trajectories", missing]) == 2
    assert main(["trajectory", "stats", "--synthetic", "--split", "tuning"]) == 2
