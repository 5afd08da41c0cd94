"""Rate, busy-network and delay models; composing configurations; the public strategies."""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

from roft_sim.errors import ConfigError
from roft_sim.faults import (
    BernoulliDropout,
    BusyNetwork,
    ClockSkew,
    EmpiricalDelay,
    FaultConfig,
    FixedDelay,
    LogNormalDelay,
    PoseStreamFaults,
    Rate,
    UniformDelay,
    compose_faults,
    load_faults,
    schedule_detections,
)
from roft_sim.testing.fault_strategies import (
    delay_distributions,
    detection_schedules,
    fault_configs,
    loss_faults,
    timing_only_configs,
)

seeds = st.integers(0, 2**32 - 1)


def pose_only(*faults) -> FaultConfig:
    return FaultConfig(pose=PoseStreamFaults(faults=tuple(faults)))


@pytest.mark.parametrize(
    ("rate", "fps", "expected"),
    [
        (Rate(rate_hz=5), 30, [0, 6, 12, 18]),
        (Rate(rate_hz=10), 30, [0, 3, 6, 9, 12, 15, 18, 21]),
        (Rate(period_frames=4, phase_frames=2), 30, [2, 6, 10, 14, 18, 22]),
        (Rate(rate_hz=30), 30, list(range(24))),
        (Rate(rate_hz=5), 60, [0, 12]),
    ],
)
def test_rate_capture_frames(rate, fps, expected):
    captures, delays = rate.sample(24, fps, np.random.default_rng(0))
    assert captures.tolist() == expected and not delays.any()


def test_busy_network_skips_frames_while_it_works():
    # processing 2, 5, 1, 3 frames: runs on 0, 2, 7, 8, then 11 ...
    busy = BusyNetwork(processing=EmpiricalDelay(frames=(2, 5, 1, 3), weights=None))
    rng = np.random.default_rng(0)
    draws = EmpiricalDelay(frames=(2, 5, 1, 3)).delays(np.random.default_rng(0), 30)
    captures, processing = busy.sample(30, 30, rng)
    expected = [0]
    for d in draws:
        nxt = expected[-1] + max(int(d), 1)
        if nxt >= 30:
            break
        expected.append(nxt)
    assert captures.tolist() == expected
    assert processing.tolist() == draws[: len(expected)].tolist()
    # a result arrives when the network is free again: the next run's capture frame
    s = schedule_detections(30, pose_only(busy), 0)
    run_caps = [r.true_capture_k for r in s.pose_records]
    for e in s.pose:
        i = run_caps.index(e.true_capture_k)
        if i + 1 < len(run_caps):
            assert e.arrival_k == run_caps[i + 1] or draws[i] == 0


def test_busy_network_with_zero_processing_runs_on_every_frame():
    captures, delays = BusyNetwork(processing=FixedDelay(frames=0)).sample(
        10, 30, np.random.default_rng(0)
    )
    assert captures.tolist() == list(range(10)) and not delays.any()


@given(seeds, st.floats(0.5, 20), st.floats(0, 1.2))
def test_lognormal_delay_is_the_ceiling_of_a_lognormal(seed, median, sigma):
    fault = LogNormalDelay(median_frames=median, sigma=sigma)
    d = fault.delays(np.random.default_rng(seed), 4000)
    z = np.random.default_rng(seed).standard_normal(4000)
    np.testing.assert_array_equal(d, np.ceil(median * np.exp(sigma * z) - 1e-9))
    # the median of ceil(X) is ceil(median of X) up to sampling error of one frame
    assert abs(np.median(d) - math.ceil(median - 1e-9)) <= 1 + 3 * sigma * median / np.sqrt(4000)


def test_lognormal_clips_and_degenerate_sigma():
    d = LogNormalDelay(median_frames=6.0, sigma=0.0).delays(np.random.default_rng(0), 50)
    assert (d == 6).all()
    d = LogNormalDelay(median_frames=6.0, sigma=2.0, min_frames=2, max_frames=9).delays(
        np.random.default_rng(0), 5000
    )
    assert d.min() == 2 and d.max() == 9


def test_empirical_delay_frequencies_follow_the_weights():
    fault = EmpiricalDelay(frames=(4, 6, 9), weights=(1.0, 2.0, 1.0))
    d = fault.delays(np.random.default_rng(2), 20000)
    counts = [np.sum(d == v) for v in (4, 6, 9)]
    chi2 = stats.chisquare(counts, f_exp=[5000, 10000, 5000])
    assert chi2.pvalue > 1e-4 and fault.mean_frames() == pytest.approx(6.25)


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: FixedDelay(frames=-1), "frames must be >= 0"),
        (lambda: UniformDelay(min_frames=5, max_frames=2), "swap them"),
        (lambda: LogNormalDelay(median_frames=0.0), "median_frames must be finite and > 0"),
        (lambda: EmpiricalDelay(frames=()), "at least one delay"),
        (lambda: EmpiricalDelay(frames=(1, 2), weights=(1.0,)), "one weight per delay"),
        (lambda: EmpiricalDelay(frames=(1,), weights=(0.0,)), "not all 0"),
        (lambda: Rate(), "exactly one of period_frames or rate_hz"),
        (lambda: Rate(rate_hz=5, period_frames=6), "exactly one"),
        (lambda: Rate(period_frames=0), "period_frames must be >= 1"),
        (lambda: ClockSkew(noise_sd_frames=-1.0), "noise_sd_frames must be finite"),
        (lambda: ClockSkew(drift=math.inf), "drift must be finite"),
    ],
)
def test_bad_timing_parameters(make, match):
    with pytest.raises(ConfigError, match=match):
        make()


# ------------------------------------------------------------------ composition


@settings(max_examples=25)
@given(fault_configs(camera=False), fault_configs(camera=False), fault_configs(camera=False))
def test_composition_is_associative(a, b, c):
    try:
        left = compose_faults(compose_faults(a, b), c)
    except ConfigError:
        with pytest.raises(ConfigError):
            compose_faults(a, compose_faults(b, c))
        return
    right = compose_faults(a, compose_faults(b, c))
    assert dataclasses.replace(left, name="x") == dataclasses.replace(right, name="x")


@given(
    st.integers(0, 200),
    seeds,
    st.lists(delay_distributions(), max_size=2),
    st.lists(loss_faults(), max_size=2),
    st.floats(-2, 2),
)
def test_composition_commutes_for_losses_delays_and_stamps(n, seed, delays, losses, offset):
    # Fragments whose faults commute give the same schedule in either order, provided no fault
    # kind appears in both (same-kind faults are told apart by their order).
    a = pose_only(Rate(rate_hz=10), *delays)
    b = pose_only(*losses, ClockSkew(offset_frames=offset))
    kinds_a = {f.kind for f in a.pose.faults}
    if kinds_a & {f.kind for f in b.pose.faults}:
        return
    ab = schedule_detections(n, compose_faults(a, b), seed)
    ba = schedule_detections(n, compose_faults(b, a), seed)
    assert ab.pose == ba.pose
    # the records agree up to the list position in the cause ("pose.faults[1] (dropout)")
    strip = lambda r: dataclasses.replace(r, cause=r.cause and re.sub(r"\[\d+\]", "", r.cause))  # noqa: E731
    assert [strip(r) for r in ab.pose_records] == [strip(r) for r in ba.pose_records]


def test_compose_presets_and_fragments(tmp_path):
    extra = tmp_path / "extra.toml"
    extra.write_text('[pose]\nfaults = [{ kind = "dropout", p = 0.5 }]\n')
    composed = load_faults(f"paper+{extra}")
    assert composed.name == f"paper+{extra}"
    assert composed.pose.faults[-1] == BernoulliDropout(p=0.5)
    assert composed.pose.first_result == "undelayed"
    with pytest.raises(ConfigError, match="at most one sampling fault.*set no network rate"):
        load_faults("paper+jitter")
    with pytest.raises(ConfigError, match="first_result differs"):
        compose_faults(load_faults("paper"), load_faults("paper-reference"))
    with pytest.raises(ConfigError, match="different seeds"):
        compose_faults(FaultConfig(seed=1), FaultConfig(seed=2))
    with pytest.raises(ConfigError, match="empty part"):
        load_faults("paper+")
    assert compose_faults() == FaultConfig(name="none")


# ------------------------------------------------------------------ public strategies


@given(detection_schedules(timing_only_configs(), max_frames=60))
def test_timing_only_strategy_has_no_content_or_camera_faults(triple):
    faults, _, schedule = triple
    for _, fault in faults.iter_faults():
        assert fault.stage in ("sampling", "delay", "loss", "delivery")
    assert all(not r.corruptions for r in schedule.pose_records + schedule.mask_records)


@settings(max_examples=25)
@given(fault_configs())
def test_generated_configs_round_trip_through_toml_mappings(faults):
    from roft_sim.config_files import jsonable
    from roft_sim.faults import fault_config_from_mapping

    data = jsonable(faults)
    assert fault_config_from_mapping(data) == faults
