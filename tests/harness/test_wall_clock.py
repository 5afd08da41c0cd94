"""``--clock wall``: a tracker in its own thread against a real clock, drop and queue policies,
deadline scoring, the outputs and the CLI options."""

from __future__ import annotations

import json
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import pytest
from harness_cases import EchoConfig, EchoTracker, box_sequence, write_box_dataset

from roft_sim.cli import main
from roft_sim.errors import ConfigError, PluginError
from roft_sim.faults import load_faults
from roft_sim.harness import RunOptions, WallClock, evaluate_run, run_sequence
from roft_sim.records import Estimate, Observation
from roft_sim.trackers import TrackerContext, TrackerSpec

FRAMES = 24  # 0.8 s at 30 fps
SLOW_STEP_S = 0.05  # a step slower than the 33 ms frame period


@dataclass(frozen=True, slots=True, kw_only=True)
class SleepyConfig:
    """Settings of :class:`SleepyTracker`."""

    sleep_s: float = 0.0
    """Time each step on a frame with images takes (frames without images are free)."""
    fail_at_k: int = -1
    """Frame at which ``step`` returns an estimate for the wrong frame (-1: never)."""
    log: list[tuple[int, bool, int | None, tuple[int, ...], str]] = field(default_factory=list)
    """Per step: ``(k, has images, flow.from_k, pose ids, thread name)``."""


class SleepyTracker(EchoTracker):
    """An :class:`EchoTracker` that takes ``sleep_s`` per frame with images and logs its input."""

    def __init__(self, config: SleepyConfig, context: TrackerContext) -> None:
        super().__init__(EchoConfig(), context)
        self.sleepy = config

    def step(self, observation: Observation) -> Estimate:
        has_images = observation.depth_m is not None
        self.sleepy.log.append(
            (
                observation.k,
                has_images,
                None if observation.flow is None else observation.flow.from_k,
                tuple(d.detection_id for d in observation.poses),
                threading.current_thread().name,
            )
        )
        if has_images and self.sleepy.sleep_s > 0:
            time.sleep(self.sleepy.sleep_s)
        estimate = super().step(observation)
        if observation.k == self.sleepy.fail_at_k:
            return Estimate.invalid(observation.k + 1)
        return estimate


SLEEPY_SPEC = TrackerSpec(
    name="sleepy",
    description="test tracker: echo that sleeps on frames with images",
    config_type=SleepyConfig,
    factory=SleepyTracker,
)


@pytest.fixture(scope="module")
def seq():
    return box_sequence(n_frames=FRAMES)


def _run(seq, clock: WallClock | None, **config):
    tracker_config = SleepyConfig(**config)
    options = RunOptions(
        tracker="sleepy",
        tracker_config=tracker_config,
        flow="gt",
        faults=load_faults("paper"),
    )
    return run_sequence(seq, options, spec=SLEEPY_SPEC, clock=clock), tracker_config.log


def _pose_ids(log) -> list[int]:
    return sorted(i for *_, ids, _ in log for i in ids)


def test_slow_tracker_under_drop_loses_frames_but_no_detection(seq):
    sim, sim_log = _run(seq, None)
    run, log = _run(seq, WallClock(when_busy="drop"), sleep_s=SLOW_STEP_S)
    timeline = run.wall_clock
    assert timeline is not None
    stats = evaluate_run(run).figures
    # every frame stepped once, in order, in the tracker's own thread
    assert [k for k, *_ in log] == list(range(FRAMES))
    assert {name for *_, name in log} == {"roft-sim-tracker"}
    # a 50 ms step at 30 fps cannot see every frame: the frames it missed come without images
    dropped = timeline.dropped_busy
    assert stats["frames_dropped_busy"] == int(dropped.sum()) > 0
    assert [has for _, has, *_ in log] == (~dropped).tolist()
    assert stats["deadline_misses"] >= stats["frames_dropped_busy"]
    assert stats["queue_max"] is None
    # every detection still arrives, at its own frame
    assert _pose_ids(log) == _pose_ids(sim_log)
    # a frame seen after missed ones carries the flow from the last frame the tracker saw
    seen = [(k, from_k) for k, has, from_k, *_ in log if has]
    for previous, (k, from_k) in zip([-1] + [k for k, _ in seen[:-1]], seen, strict=True):
        assert from_k == (None if previous < 0 else previous), k
    assert stats["latency_max_ms"] < 1e3 * (2 * SLOW_STEP_S + 2 / 30)  # bounded, unlike queue
    assert len(sim.estimates) == len(run.estimates) == FRAMES


def test_slow_tracker_under_queue_lags_more_and_more(seq):
    sim, sim_log = _run(seq, None)
    # no prefetch: the loader builds each frame while the clock runs
    run, log = _run(seq, WallClock(when_busy="queue", prefetch_mib=0), sleep_s=SLOW_STEP_S)
    timeline = run.wall_clock
    assert timeline is not None
    stats = evaluate_run(run).figures
    # it sees exactly what it sees in simulated time, late
    assert [entry[:4] for entry in log] == [entry[:4] for entry in sim_log]
    for own, lockstep in zip(timeline.tracker_estimates, sim.estimates, strict=True):
        np.testing.assert_array_equal(own.T_cam_obj, lockstep.T_cam_obj)
    assert stats["frames_dropped_busy"] == 0
    latency_s = timeline.delivered_s - timeline.release_s
    # each frame waits ~17 ms longer than the one before (50 ms steps, 33 ms apart)
    assert latency_s[-1] - latency_s[0] > 0.5 * (FRAMES - 1) * (SLOW_STEP_S - 1 / 30)
    assert stats["queue_max"] >= 3
    assert stats["deadline_misses"] >= FRAMES // 2
    # the scored estimate of a frame is an older frame's, the newest delivered by its deadline
    held = timeline.held_index()
    assert (held < np.arange(FRAMES)).sum() >= FRAMES // 2
    for k, j in enumerate(held):
        if j >= 0:
            assert timeline.delivered_s[j] <= (k + 1) / 30
            np.testing.assert_array_equal(
                run.estimates[k].T_cam_obj, timeline.tracker_estimates[j].T_cam_obj
            )
            assert run.estimates[k].k == k and run.estimates[k].diagnostics["held_from_k"] == j
        else:
            assert not run.estimates[k].valid


def test_fast_tracker_misses_no_deadline(seq):
    # 3x slower clock: 100 ms per frame for a step of well under a millisecond
    short = box_sequence(n_frames=8)
    run, log = _run(short, WallClock(time_scale=3.0, when_busy="drop"))
    figures = evaluate_run(run).figures
    assert figures["deadline_misses"] == 0 and figures["frames_dropped_busy"] == 0
    assert figures["estimate_age_max_frames"] == 0
    assert figures["clock"] == {"mode": "wall", "time_scale": 3.0, "when_busy": "drop"}
    assert run.wall_clock is not None
    # times are on the run's clock: frame k released near k / 30 s, not 3 k / 30 s
    np.testing.assert_allclose(run.wall_clock.release_s, np.arange(8) / 30, atol=0.05)
    assert [k for k, *_ in log] == list(range(8))


def test_a_protocol_error_in_the_tracker_thread_is_raised_by_the_run(seq):
    with pytest.raises(PluginError, match="estimate for frame 4 when stepped with frame 3"):
        _run(seq, WallClock(time_scale=0.25), fail_at_k=3)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"time_scale": 0.0}, "finite and > 0"),
        ({"time_scale": -1.0}, "finite and > 0"),
        ({"time_scale": float("nan")}, "finite and > 0"),
        ({"time_scale": float("inf")}, "finite and > 0"),
        ({"when_busy": "wait"}, "unknown when-busy policy"),
        ({"prefetch_mib": -1}, "prefetch_mib must be an integer >= 0"),
    ],
)
def test_bad_clock_settings(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        WallClock(**kwargs)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_box_dataset(tmp_path_factory.mktemp("data"), n_frames=12)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--clock", "wall", "--time-scale", "0"], "time scale must be finite and > 0, got 0.0"),
        (["--clock", "wall", "--time-scale", "-2"], "time scale must be finite and > 0"),
        (["--clock", "wall", "--time-scale", "nan"], "time scale must be finite and > 0"),
        (["--clock", "wall", "--time-scale", "inf"], "time scale must be finite and > 0"),
        (["--clock", "wall", "--time-scale", "fast"], "invalid float value: 'fast'"),
        (["--clock", "wall", "--when-busy", "wait"], "invalid choice: 'wait'"),
        (["--clock", "lockstep"], "invalid choice: 'lockstep'"),
        (["--when-busy", "queue"], "--when-busy only apply to a real clock; add --clock wall"),
        (["--time-scale", "2"], "--time-scale only apply to a real clock"),
    ],
)
def test_bad_clock_options_are_usage_errors(dataset, tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    args = ["run", str(dataset), "--tracker", "detector-hold", "--flow", "none", "--out", str(out)]
    assert main([*args, *extra]) == 2
    assert message in capsys.readouterr().err
    assert not out.exists()


def test_cli_wall_run_writes_timing_metrics_and_table(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    args = ["run", str(dataset), "--tracker", "detector-hold", "--flow", "none", "--out", str(out)]
    clock = ["--clock", "wall", "--when-busy", "queue", "--time-scale", "0.5", "--no-progress"]
    assert main([*args, *clock]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert "latency ms (p50)" in lines[0] and "queue max" in lines[0]
    assert [line.split()[0] for line in lines[2:6]] == ["box_a", "box_b", "ALL", "MEAN"]
    assert any(line.startswith("clock: wall, time scale 0.5, frames queued") for line in lines)
    record = {"mode": "wall", "time_scale": 0.5, "when_busy": "queue"}
    assert json.loads((out / "run.json").read_text())["clock"] == record
    metrics = json.loads((out / "metrics.json").read_text())
    for name in ("ALL", "MEAN", "box_a", "box_b"):
        entry = metrics[name]
        assert entry["clock"] == record
        assert entry["latency_p50_ms"] > 0 and entry["frames_dropped_busy"] == 0
        assert entry["queue_max"] >= 0 and entry["release_lag_max_ms"] is not None
    with np.load(out / "box_a" / "wall_clock.npz") as z:
        assert z["delivered_s"].shape == (12,) and str(z["when_busy"]) == "queue"
        assert (z["delivered_s"] >= z["started_s"]).all()
        assert (z["started_s"] >= z["release_s"]).all()
    assert (out / "box_a" / "tracker_estimates.npz").is_file()


def test_sim_clock_is_recorded_and_writes_no_timing(dataset, tmp_path):
    out = tmp_path / "out"
    args = ["run", str(dataset), "--tracker", "detector-hold", "--flow", "none", "--out", str(out)]
    assert main(args) == 0
    assert json.loads((out / "run.json").read_text())["clock"] == {"mode": "sim"}
    metrics = json.loads((out / "metrics.json").read_text())
    assert "latency_p50_ms" not in metrics["box_a"] and "clock" not in metrics["ALL"]
    assert not (out / "box_a" / "wall_clock.npz").exists()
