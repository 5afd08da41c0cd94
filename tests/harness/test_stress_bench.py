"""The stress benchmark: the shipped stress file, its scenarios, the scoring and verdict, and a
small run that checks the ordering (slow)."""

from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from roft_sim.errors import ConfigError
from roft_sim.faults import fault_config_from_mapping, load_faults, random_fault_mix
from roft_sim.faults.config import list_fault_presets
from roft_sim.harness.cells import SweepCell
from roft_sim.harness.options import RunOptions
from roft_sim.harness.outputs import FRAME_ERRORS_FILE, save_frame_errors
from roft_sim.harness.stress import (
    DEFAULT_FLOW,
    StressResult,
    StressSequence,
    StressSize,
    Verdict,
    format_stress_report,
    load_stress_config,
    run_stress,
    score_stress,
    shipped_holdout_config,
    shipped_stress_config,
    stress_scenarios,
)
from roft_sim.metrics import IntervalVelocityErrors, evaluate_sequence
from roft_sim.trajectories import (
    CapturedMotionConfig,
    ContinuousMotionConfig,
    SyntheticMotionConfig,
)


def test_shipped_stress_file_covers_the_split_motions_and_flows() -> None:
    config = load_stress_config(shipped_stress_config())
    assert config.template.is_file()
    splits = {s.split for s in config.sequences}
    assert splits == {"tuning", "evaluation"}
    assert len(config.sequences) >= 6
    motions = {(s.motion, s.format) for s in config.sequences}
    assert {("captured", "tum"), ("captured", "bvh"), ("continuous", None), ("bursty", None)} <= (
        motions
    )
    for s in config.sequences:  # the project-wide split of captures, seeds and objects
        if s.split == "tuning":
            assert s.seed < 10 and s.object in ("003_cracker_box", "004_sugar_box")
            assert s.capture is None or "room1" in s.capture or "002_05" in s.capture
        else:
            assert 100 <= s.seed < 110 and s.object not in ("003_cracker_box", "004_sugar_box")
            assert s.capture is None or "room1" not in s.capture and "002_05" not in s.capture
    assert {"dis", "gt+noise:0.5", "gt+noise:1", "gt+noise:2"} <= set(config.flows)
    assert any(f.startswith("stored:nvof") for f in config.flows)
    assert {"roft", "roft-reference", "detector-hold", "pose-only-ukf", "naive-delay"} <= set(
        config.trackers
    )
    assert config.full.faults == ()  # every shipped preset
    medium = config.medium  # every sequence, the quick presets, the default flow only
    assert medium is not None and medium.sequences == () and medium.frames > config.quick.frames
    assert medium.faults == config.quick.faults and medium.flows == (DEFAULT_FLOW,)
    assert len(list_fault_presets()) >= 6


def test_shipped_holdout_file_uses_what_neither_split_uses() -> None:
    """The held-out file: every sequence HOLDOUT, none of the stress file's captured windows or
    joints, seeds or object-motion pairings, every shipped preset at the medium size."""
    stress = load_stress_config(shipped_stress_config())
    holdout = load_stress_config(shipped_holdout_config())
    assert holdout.template == stress.template and holdout.template.is_file()
    assert {s.split for s in holdout.sequences} == {"holdout"}
    assert len(holdout.sequences) >= 6
    assert {s.motion for s in holdout.sequences} == {"captured", "continuous", "bursty"}

    def window(s: StressSequence) -> tuple[object, ...]:
        return (s.capture, s.joint, s.start_s)

    used = {window(s) for s in stress.sequences if s.motion == "captured"}
    assert not used & {window(s) for s in holdout.sequences if s.motion == "captured"}
    assert not {s.seed for s in stress.sequences} & {s.seed for s in holdout.sequences}
    pairs = {(s.motion, s.capture, s.object) for s in stress.sequences}
    assert not pairs & {(s.motion, s.capture, s.object) for s in holdout.sequences}
    assert holdout.medium is not None and holdout.medium.faults == ()  # every preset
    assert holdout.trackers == stress.trackers and holdout.baselines == stress.baselines


def test_a_split_outside_the_three_is_refused() -> None:
    with pytest.raises(ConfigError, match="split 'test' is not one of tuning, evaluation"):
        StressSequence(name="x", split="test", motion="bursty", object="003_cracker_box", seed=0)  # type: ignore[arg-type]


def test_a_sequence_names_a_registry_object_or_a_mesh_file_not_both() -> None:
    with pytest.raises(ConfigError, match="exactly one of object = .* or mesh = .*got object=None"):
        StressSequence(name="x", split="holdout", motion="bursty", seed=0)
    with pytest.raises(ConfigError, match="exactly one of object"):
        StressSequence(
            name="x",
            split="holdout",
            motion="bursty",
            seed=0,
            object="003_cracker_box",
            mesh=Path("box.obj"),
        )


def test_a_mesh_sequence_resolves_against_the_stress_file(tmp_path: Path) -> None:
    """A user's own object: ``mesh = "<file>"`` relative to the stress file reaches the
    scenario's ``[object] mesh``; a registry sequence beside it keeps its name."""
    template = shipped_stress_config().parent.parent / "ci" / "mustard_hand_moving_camera.toml"
    (tmp_path / "sub").mkdir()
    config_file = tmp_path / "sub" / "mine.toml"
    config_file.write_text(
        f"""name = "mine"
trackers = ["roft", "detector-hold"]
subject = "roft"
baselines = ["detector-hold"]
flows = ["stored:nvof_1_slow"]
template = "{template}"

[[sequences]]
name = "own-object"
split = "holdout"
motion = "continuous"
mesh = "meshes/drill.obj"
seed = 5

[[sequences]]
name = "registry-object"
split = "holdout"
motion = "bursty"
object = "004_sugar_box"
seed = 6

[quick]
frames = 12
resolution = [160, 90]
seeds = [0]

[full]
frames = 12
resolution = [160, 90]
seeds = [0]
"""
    )
    config = load_stress_config(config_file)
    own, registry = config.sequences
    assert own.mesh == tmp_path / "sub" / "meshes" / "drill.obj" and own.object is None
    assert registry.object == "004_sugar_box" and registry.mesh is None
    scenarios, skipped = stress_scenarios(config, config.quick, tmp_path / "none")
    assert skipped == []
    assert scenarios[0].object.mesh == own.mesh and scenarios[0].object.name is None
    assert scenarios[1].object.name == "004_sugar_box" and scenarios[1].object.mesh is None


def test_scenarios_skip_captured_motion_without_the_shared_folder(tmp_path: Path) -> None:
    config = load_stress_config(shipped_stress_config())
    scenarios, skipped = stress_scenarios(config, config.full, tmp_path / "absent")
    captured = [s for s in config.sequences if s.motion == "captured"]
    assert len(skipped) == len(captured) and all("is absent" in n for n in skipped)
    assert len(scenarios) == len(config.sequences) - len(captured)
    for scenario in scenarios:
        assert scenario.intrinsics.width_px == 640 and scenario.n_frames == config.full.frames
        assert scenario.scene.hand.enabled and scenario.camera.motion is not None
        assert isinstance(scenario.trajectory, ContinuousMotionConfig | SyntheticMotionConfig)


def test_scenarios_replay_captured_motion(shared_trajectories_dir: Path) -> None:
    config = load_stress_config(shipped_stress_config())
    scenarios, skipped = stress_scenarios(config, config.quick, shared_trajectories_dir)
    assert skipped == [] and len(scenarios) == len(config.quick.sequences)
    captured = [s for s in scenarios if isinstance(s.trajectory, CapturedMotionConfig)]
    assert {s.name for s in captured} == {"tum-room1", "bvh-002_06"}


def test_verdict_line_names_the_failures() -> None:
    verdict = Verdict(split="evaluation", wins=["paper"], fails=["chaos: e_t 9 vs detector-hold 6"])
    line = verdict.line("roft", ["detector-hold", "pose-only-ukf"])
    assert line.startswith(
        "EVALUATION, all flows: roft beats detector-hold and pose-only-ukf on ADD-AUC"
    )
    assert "under 1/2 presets" in line and "fails: chaos: e_t 9" in line
    with pytest.raises(ConfigError, match="unknown sequences"):
        config = load_stress_config(shipped_stress_config())
        dataclasses.replace(config, quick=dataclasses.replace(config.quick, sequences=("x",)))


def _fake_cell(
    cells_dir: Path,
    tracker: str,
    flow: str,
    offset_m: float,
    faults: str = "paper",
    seed: int = 0,
    seed_shift_m: float = 0.0005,
) -> SweepCell:
    """A finished cell whose estimate is the ground truth shifted by ``offset_m`` (plus
    ``seed_shift_m`` per ``seed``, so that seeds are distinct replicates) along x and turned by
    that offset x 100 degrees about z."""
    offset_m += seed_shift_m * seed
    cell = SweepCell.create(
        label=tracker,
        fault_label=faults,
        parameter=None,
        value=None,
        sequence_path=str(cells_dir / "no-sequence"),
        sequence_name="bvh-002_06",
        options=RunOptions(tracker=tracker, flow=flow, seed=seed),
    )
    n = 20
    T_gt = np.tile(np.eye(4), (n, 1, 1))
    T_gt[:, 2, 3] = 0.6
    T_est = T_gt.copy()
    T_est[:, 0, 3] += offset_m
    angle_rad = np.radians(100.0 * offset_m)
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    T_est[:, :2, :2] = [[c, -s], [s, c]]
    points_m = np.array([[0.05, 0.0, 0.0], [0.0, 0.05, 0.0], [0.0, 0.0, 0.05]])
    (cells_dir / cell.cell_id).mkdir(parents=True)
    save_frame_errors(
        cells_dir / cell.cell_id / FRAME_ERRORS_FILE, evaluate_sequence(T_est, T_gt, points_m)
    )
    return cell


def _result(tmp_path, scores, split, baselines, flows) -> StressResult:
    """A one-sequence (``bvh-002_06`` in ``split``), one-preset (``paper``) result."""
    return StressResult(
        out_dir=tmp_path,
        size_name="test",
        trackers=("roft", *baselines),
        notes=(),
        splits={split: ["bvh-002_06"]},
        scores=scores,
        presets=("paper",),
        flows=flows,
    )


def test_verdict_on_the_default_inputs_comes_first_and_ignores_other_flows(
    tmp_path: Path,
) -> None:
    """ROFT wins on the default flow and loses badly on gt+noise:1: the default-input verdict
    (the issue's criterion) says it wins, the all-flows one that it fails, and the default
    line is the first verdict line of the report."""
    errors_m = {  # (tracker, flow) -> position error
        ("roft", DEFAULT_FLOW): 0.01,
        ("roft", "gt+noise:1"): 0.20,
        ("detector-hold", DEFAULT_FLOW): 0.03,
        ("detector-hold", "gt+noise:1"): 0.03,
        ("pose-only-ukf", DEFAULT_FLOW): 0.04,
        ("pose-only-ukf", "gt+noise:1"): 0.04,
    }
    seeds = range(4)
    cells = [_fake_cell(tmp_path, t, f, e, seed=s) for (t, f), e in errors_m.items() for s in seeds]
    baselines = ["detector-hold", "pose-only-ukf"]
    scores = score_stress(
        cells, tmp_path, {"bvh-002_06": "evaluation"}, subject="roft", baselines=baselines
    )
    default = scores.default_verdicts["evaluation"]
    assert (default.wins, default.fails) == (["paper"], [])
    assert (default.pairs, default.design) == (4, "1 sequence x 1 flow x 4 seeds")
    assert scores.verdicts["evaluation"].wins == []
    assert "paper: ADD-AUC" in scores.verdicts["evaluation"].fails[0]
    assert scores.verdicts["evaluation"].design == "1 sequence x 2 flows x 4 seeds"
    roft_default = scores.pooled_default[("evaluation", "roft", "paper")]
    offsets_cm = [1.0, 1.05, 1.1, 1.15]  # pooled ALL: the RMSE over every frame of the 4 seeds
    assert roft_default["rmse_t_cm"] == pytest.approx(np.sqrt(np.mean(np.square(offsets_cm))))
    result = _result(tmp_path, scores, "evaluation", baselines, (DEFAULT_FLOW, "gt+noise:1"))
    report = format_stress_report(result, subject="roft", baselines=baselines)
    verdict_lines = report.split("## Verdict")[1].strip().splitlines()
    assert verdict_lines[0] == (
        f"EVALUATION, default inputs ({DEFAULT_FLOW}): roft beats detector-hold and "
        "pose-only-ukf on ADD-AUC, e_t, e_a under 1/1 presets (paired 95 % intervals, at least "
        "4 replicates each: 1 sequence x 1 flow x 4 seeds)"
    )
    assert verdict_lines[1].startswith("EVALUATION, all flows: roft beats")
    # pooled over both flows the paired e_t difference is (+0 cm, +17 cm) per seed: the
    # interval of its mean spans 0, so the win is not called
    assert "under 0/1 presets" in verdict_lines[1] and "fails: paper:" in verdict_lines[1]
    assert "(no detectable difference)" in verdict_lines[1]
    seeds_needed = report.split("## Seeds needed")[1]
    assert f"EVALUATION, default inputs ({DEFAULT_FLOW}): seeds for a 2-point" in seeds_needed
    (advice,) = default.advice
    assert advice.preset == "paper" and advice.pairs == 4 and advice.seeds_matter
    assert advice.seeds is not None and advice.seeds >= 1
    assert f"paper: {advice.seeds} (paired sd " in seeds_needed
    assert f"### EVALUATION: default inputs ({DEFAULT_FLOW})" in report
    # the win shows the intervals it rests on: one row per baseline, every metric "better"
    evidence = report.split("### Paired differences behind the verdicts (roft - baseline")[1]
    win_rows = [
        row.split(" | ")
        for row in evidence.splitlines()
        if row.startswith(f"| EVALUATION | default inputs ({DEFAULT_FLOW}) | paper |")
    ]
    assert [(row[3], row[4]) for row in win_rows] == [(b, "4") for b in baselines]
    assert all(" | ".join(row).count("] (better)") == 3 for row in win_rows)
    add_auc = default.evidence[0][1].comparisons["add_auc_pct"].difference
    assert add_auc.low > 0 and f"{add_auc.text('+.2f')} (better)" in win_rows[0][5]


def test_a_verdict_on_one_replicate_calls_no_win_and_asks_for_seeds(tmp_path: Path) -> None:
    """One cell per tracker has no interval: the subject's far smaller error is no win, and
    the seed recommendation says it cannot be estimated."""
    baselines = ["detector-hold"]
    cells = [
        _fake_cell(tmp_path, t, DEFAULT_FLOW, e)
        for t, e in (("roft", 0.01), ("detector-hold", 0.05))
    ]
    scores = score_stress(
        cells, tmp_path, {"bvh-002_06": "evaluation"}, subject="roft", baselines=baselines
    )
    verdict = scores.default_verdicts["evaluation"]
    assert verdict.wins == [] and "(no detectable difference)" in verdict.fails[0]
    assert verdict.recommendation().endswith("paper: unknown (fewer than 2 pairs)")


def test_seeds_that_change_nothing_ask_for_sequences(tmp_path: Path) -> None:
    """Three seeds whose cells are identical (no randomness) are one replicate: the advice is
    to add sequences, not seeds."""
    errors_m = (("roft", 0.01), ("detector-hold", 0.05))
    cells = [
        _fake_cell(tmp_path, t, DEFAULT_FLOW, e, seed=s, seed_shift_m=0.0)
        for t, e in errors_m
        for s in (0, 1, 2)
    ]
    scores = score_stress(
        cells, tmp_path, {"bvh-002_06": "evaluation"}, subject="roft", baselines=["detector-hold"]
    )
    verdict = scores.default_verdicts["evaluation"]
    assert verdict.pairs == 1 and verdict.wins == []
    assert "paper: seeds change nothing here, add sequences" in verdict.recommendation()


@pytest.mark.slow
@pytest.mark.render
def test_small_benchmark_orders_roft_above_the_baselines(tmp_path: Path) -> None:
    """Two synthetic EVALUATION sequences (continuous and bursty), three presets, the default
    inputs, 120 frames: ROFT must beat holding the last detection and the pose-only UKF on
    ADD-AUC, e_t and e_a, pooled over the two sequences, under each preset.

    120 frames as in the medium size: in the first 60 frames of ``bursty-s104`` the ``bursts``
    preset leaves no tracker a valid estimate (every tracker scored 2.5-2.8 % ADD-AUC there), so
    a shorter run compares start-up rules, not trackers."""
    config = load_stress_config(shipped_stress_config())
    config = dataclasses.replace(
        config, trackers=("roft", "detector-hold", "pose-only-ukf"), baselines=config.baselines
    )
    size = StressSize(
        frames=120,
        resolution=(320, 180),
        seeds=(0,),
        sequences=("continuous-s103", "bursty-s104"),
        faults=("paper", "bursts", "camera-drops"),
        flows=("stored:nvof_1_slow",),
    )
    result = run_stress(config, size, tmp_path, trajectories_dir=tmp_path / "none")
    print(format_stress_report(result, subject="roft", baselines=list(config.baselines)))
    losses = []
    for preset in size.faults:
        roft = result.scores.pooled[("evaluation", "roft", preset)]
        for base in config.baselines:
            other = result.scores.pooled[("evaluation", base, preset)]
            add_roft, add_other = roft["add_auc_pct"], other["add_auc_pct"]
            if not add_roft > add_other:
                losses.append(f"{preset}: ADD-AUC roft {add_roft:.1f} <= {base} {add_other:.1f}")
            for key in ("rmse_t_cm", "rmse_a_deg"):
                if not roft[key] < other[key]:
                    losses.append(
                        f"{preset}: {key} roft {roft[key]:.2f} >= {base} {other[key]:.2f}"
                    )
    assert not losses, "; ".join(losses)


def test_holdout_split_gets_its_tables_and_verdict_after_evaluation(tmp_path: Path) -> None:
    baselines = ["detector-hold", "pose-only-ukf"]
    errors_m = {"roft": 0.01, "detector-hold": 0.03, "pose-only-ukf": 0.04}
    cells = [
        _fake_cell(tmp_path, t, DEFAULT_FLOW, e, seed=s)
        for t, e in errors_m.items()
        for s in (0, 1, 2)
    ]
    scores = score_stress(
        cells, tmp_path, {"bvh-002_06": "holdout"}, subject="roft", baselines=baselines
    )
    assert scores.default_verdicts["holdout"].wins == ["paper"]
    result = _result(tmp_path, scores, "holdout", baselines, (DEFAULT_FLOW,))
    report = format_stress_report(result, subject="roft", baselines=baselines)
    assert "## HOLDOUT split: bvh-002_06" in report
    assert "### HOLDOUT sequence bvh-002_06" in report
    assert "velocity from the exact interval motion" not in report  # not computed: no table
    verdict_lines = report.split("## Verdict")[1].strip().splitlines()
    assert verdict_lines[0].startswith(f"HOLDOUT, default inputs ({DEFAULT_FLOW}): roft beats")


def test_report_sets_the_exact_interval_motion_beside_each_split(tmp_path: Path) -> None:
    """``run_stress`` stores each sequence's interval-velocity figures; the report prints them
    per split, one row per sequence, NaN as '-'."""
    baselines = ["detector-hold", "pose-only-ukf"]
    cells = [_fake_cell(tmp_path, t, DEFAULT_FLOW, 0.01) for t in ("roft", *baselines)]
    scores = score_stress(
        cells, tmp_path, {"bvh-002_06": "evaluation"}, subject="roft", baselines=baselines
    )
    v = {"held": 5.11, "extrapolated": 4.12, "fitted": 3.05}  # cm/s
    w = {"held": 19.91, "extrapolated": 19.42, "fitted": float("nan")}  # deg/s
    figures = IntervalVelocityErrors(
        **{f"{k}_v_cmps": x for k, x in v.items()},
        **{f"{k}_w_dps": x for k, x in w.items()},
        frames=117,
    )
    result = dataclasses.replace(
        _result(tmp_path, scores, "evaluation", baselines, (DEFAULT_FLOW,)),
        interval_velocity={"bvh-002_06": figures},
    )
    report = format_stress_report(result, subject="roft", baselines=baselines)
    section = report.split("### EVALUATION: velocity from the exact interval motion")[1]
    row = next(line for line in section.splitlines() if line.startswith("| bvh-002_06 |"))
    assert row == "| bvh-002_06 | 5.11 | 4.12 | 3.05 | 19.91 | 19.42 | - |"


def test_random_mixes_run_as_fault_files_named_by_their_stem(tmp_path: Path) -> None:
    """``bench_robustness.py --random-mixes``: the mixes are written as fault files that load
    back to the drawn configuration, and the report and verdict name them ``mix-<seed>``."""
    spec = importlib.util.spec_from_file_location(
        "bench_robustness", Path(__file__).parents[2] / "benchmarks" / "bench_robustness.py"
    )
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    paths = bench.write_random_mixes(tmp_path / "mixes", range(7, 9))
    assert [Path(p).name for p in paths] == ["mix-7.toml", "mix-8.toml"]
    for seed, path in zip((7, 8), paths, strict=True):
        assert load_faults(path) == fault_config_from_mapping(random_fault_mix(seed))
    baselines = ["detector-hold", "pose-only-ukf"]
    errors_m = {"roft": 0.03, "detector-hold": 0.01, "pose-only-ukf": 0.04}
    cells = [_fake_cell(tmp_path, t, DEFAULT_FLOW, e, paths[0]) for t, e in errors_m.items()]
    scores = score_stress(
        cells, tmp_path, {"bvh-002_06": "holdout"}, subject="roft", baselines=baselines
    )
    result = dataclasses.replace(
        _result(tmp_path, scores, "holdout", baselines, (DEFAULT_FLOW,)), presets=(paths[0],)
    )
    report = format_stress_report(result, subject="roft", baselines=baselines)
    assert "| mix-7 | roft |" in report and str(tmp_path) not in report
    assert "under 0/1 presets (paired 95 % intervals, at least 1 replicate each: " in report
    assert "; fails: mix-7: ADD-AUC" in report
