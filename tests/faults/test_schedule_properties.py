"""Property tests of the pure fault schedule: the timing a tracker will see.

Oracles: the reference's delay simulation (roft_reference.md 2.1, 5.1), hand-computed
schedules, the binomial law for Bernoulli losses, the geometric law for Gilbert-Elliott burst
lengths, and recomputation with faults reordered or added.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy import stats

from roft_sim.errors import ConfigError
from roft_sim.faults import (
    BernoulliDropout,
    Blackout,
    BusyNetwork,
    ClockSkew,
    Duplicate,
    FaultConfig,
    FixedDelay,
    GilbertElliott,
    MaskStreamFaults,
    PoseStreamFaults,
    Rate,
    Reorder,
    RotationFlip,
    Stale,
    TranslationJump,
    UniformDelay,
    fault_rng,
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

frames = st.integers(0, 400)
seeds = st.integers(0, 2**32 - 1)


def pose_only(*faults, first_result="delayed") -> FaultConfig:
    return FaultConfig(pose=PoseStreamFaults(first_result=first_result, faults=tuple(faults)))


def timing(schedule, stream="pose"):
    """[(id, true capture, reported capture, arrival, copy)] in delivery order."""
    return [
        (e.detection_id, e.true_capture_k, e.reported_capture_k, e.arrival_k, e.copy)
        for e in schedule.deliveries(stream)
    ]


# ------------------------------------------------------------------ presets


@given(frames, seeds)
def test_none_every_frame_arrives_at_its_capture_frame(n, seed):
    s = schedule_detections(n, load_faults("none"), seed)
    for stream in ("pose", "mask"):
        events = s.deliveries(stream)
        assert [e.true_capture_k for e in events] == list(range(n))
        assert all(e.arrival_k == e.true_capture_k == e.reported_capture_k for e in events)
        assert all(r.fate == "delivered" for r in s.records(stream))
    assert not s.camera.dropped.any()


@given(frames, seeds)
def test_paper_matches_the_reference_delay_simulation(n, seed):
    s = schedule_detections(n, load_faults("paper"), seed)
    for stream in ("pose", "mask"):
        events = s.deliveries(stream)
        # only every 6th frame carries a result, and each result is of the frame 6 earlier
        assert all(e.arrival_k % 6 == 0 for e in events)
        for e in events:
            expected = 0 if e.true_capture_k == 0 else e.true_capture_k + 6
            assert e.arrival_k == expected
            assert e.reported_capture_k == e.true_capture_k
        # hand-computed: frame 0 -> 0; frame 6m -> 6m + 6 while it fits in the sequence
        expected_pairs = [(0, 0)] * (n > 0) + [(c, c + 6) for c in range(6, n - 6, 6)]
        assert [(e.true_capture_k, e.arrival_k) for e in events] == expected_pairs


def test_paper_reference_delivers_frame_zero_twice():
    s = schedule_detections(30, load_faults("paper-reference"), 0)
    assert timing(s)[:3] == [
        (0, 0, 0, 0, "original"),
        (0, 0, 0, 6, "repeat"),
        (1, 6, 6, 12, "original"),
    ]
    assert s.pose_records[0].arrivals == (0, 6)


@given(frames, seeds)
def test_busy_network_of_six_frames_is_the_paper_setting(n, seed):
    busy = pose_only(BusyNetwork(processing=FixedDelay(frames=6)))
    paper = pose_only(Rate(rate_hz=5), FixedDelay(frames=6))
    assert timing(schedule_detections(n, busy, seed)) == timing(schedule_detections(n, paper, seed))


# ------------------------------------------------------------------ delays


@given(st.integers(1, 200), seeds, timing_only_configs(), st.integers(0, 20))
def test_a_fixed_delay_shifts_every_arrival_by_exactly_d(n, seed, faults, d):
    # strip delivery faults and the first-result rule, whose effect depends on arrival frames
    base_faults = tuple(f for f in faults.pose.faults if f.stage != "delivery")
    base = pose_only(*base_faults)
    shifted = pose_only(*base_faults, FixedDelay(frames=d))
    long = n + 40  # no arrival falls off the end in either run
    a = schedule_detections(long, base, seed)
    b = schedule_detections(long, shifted, seed)
    a_events = [e for e in a.pose if e.arrival_k + d < long]
    assert [(e.detection_id, e.arrival_k + d) for e in a_events] == [
        (e.detection_id, e.arrival_k)
        for e in b.pose
        if e.detection_id in {x.detection_id for x in a_events}
    ]


@given(frames, seeds, st.integers(0, 10), st.integers(0, 10))
def test_fixed_delays_add_up_and_commute(n, seed, d1, d2):
    one = pose_only(Rate(period_frames=3), FixedDelay(frames=d1 + d2))
    two = pose_only(Rate(period_frames=3), FixedDelay(frames=d1), FixedDelay(frames=d2))
    swapped = pose_only(FixedDelay(frames=d2), Rate(period_frames=3), FixedDelay(frames=d1))
    t = timing(schedule_detections(n, one, seed))
    assert t == timing(schedule_detections(n, two, seed))
    assert t == timing(schedule_detections(n, swapped, seed))


@given(st.integers(50, 300), seeds, delay_distributions(), delay_distributions())
def test_random_delays_commute(n, seed, a, b):
    # each fault has its own generator, so listing them the other way round changes nothing
    ab = pose_only(Rate(period_frames=2), a, b)
    ba = pose_only(b, a, Rate(period_frames=2))
    if a.kind == b.kind:  # same kind: the generators are tied to occurrence, not to the value
        return
    assert timing(schedule_detections(n, ab, seed)) == timing(schedule_detections(n, ba, seed))


@given(seeds, st.integers(0, 10), st.integers(0, 10))
def test_uniform_delay_stays_in_its_range(seed, lo, span):
    fault = UniformDelay(min_frames=lo, max_frames=lo + span)
    s = schedule_detections(300, pose_only(fault), seed)
    delays = np.array([e.delay_frames for e in s.pose])
    assert delays.min() >= lo and delays.max() <= lo + span
    # every value appears over ~280 draws (P(one missing) < 11 * (10/11)^280 < 1e-10)
    assert len(set(delays.tolist())) == span + 1


# ------------------------------------------------------------------ losses


@given(st.floats(0.01, 0.99), seeds)
def test_bernoulli_dropout_rate_is_within_a_binomial_interval(p, seed):
    n = 1500
    s = schedule_detections(n, pose_only(BernoulliDropout(p=p)), seed)
    lost = sum(r.fate == "dropped" for r in s.pose_records)
    lo, hi = stats.binom.interval(0.9999, n, p)
    assert lo <= lost <= hi, f"{lost} of {n} lost, 99.99 % interval [{lo}, {hi}] for p={p}"


def _inert(loss):
    """The same kind of loss fault, losing nothing."""
    if isinstance(loss, BernoulliDropout):
        return BernoulliDropout(p=0.0)
    if isinstance(loss, GilbertElliott):
        return GilbertElliott(p_good_to_bad=0.0, loss_in_good=0.0)
    return Blackout(windows=())


@given(st.integers(1, 300), seeds, st.floats(0, 1), st.floats(0, 1))
def test_sweeping_a_dropout_rate_keeps_nested_losses(n, seed, p1, p2):
    # The draws of a fault depend on its kind and position, not on p: a larger p loses a
    # superset of the results a smaller p loses (smooth error-versus-dropout sweeps).
    lo, hi = sorted((p1, p2))
    lost = [
        {
            r.detection_id
            for r in schedule_detections(n, pose_only(BernoulliDropout(p=p)), seed).pose_records
            if r.fate == "dropped"
        }
        for p in (lo, hi)
    ]
    assert lost[0] <= lost[1]


def _runs(flags: np.ndarray, value: bool) -> list[int]:
    """Lengths of the maximal runs of ``value``, leaving out runs that touch either end."""
    hit = np.concatenate([[False], np.asarray(flags) == value, [False]]).astype(np.int8)
    edges = np.diff(hit)
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    inner = (starts > 0) & (stops < len(flags))
    return (stops - starts)[inner].tolist()


def test_runs_helper():
    flags = np.array([1, 1, 0, 1, 1, 1, 0, 0, 1, 0, 1], dtype=bool)
    assert _runs(flags, True) == [3, 1] and _runs(flags, False) == [1, 2, 1]


@given(st.floats(0.01, 0.3), st.floats(0.05, 0.9), seeds)
def test_gilbert_elliott_reproduces_its_mean_burst_length(p_gb, p_bg, seed):
    # With loss 1 in bad and 0 in good, bursts of losses are the bad sojourns: geometric with
    # mean 1 / p_bad_to_good (and good gaps with mean 1 / p_good_to_bad). Tolerance: 5 standard
    # errors of the sample mean of a geometric law, sd = sqrt(1 - p) / p (runs touching either
    # end are left out). The fault's drop mask over 50000 items, drawn with the generator the
    # schedule gives it (test_gilbert_elliott_schedule_is_its_drop_mask checks that link).
    n = 50000
    fault = GilbertElliott(p_good_to_bad=p_gb, p_bad_to_good=p_bg)
    rng = fault_rng(np.random.SeedSequence(seed), "pose", fault.kind, 0)
    lost = fault.dropped(np.arange(n), rng)
    for value, p in ((True, p_bg), (False, p_gb)):
        lengths = _runs(lost, value)
        assert len(lengths) >= 100, "too few bursts for a test"
        se = np.sqrt(1 - p) / p / np.sqrt(len(lengths))
        assert abs(np.mean(lengths) - 1 / p) <= 5 * se, (
            f"mean run {np.mean(lengths):.3f} vs {1 / p:.3f} (se {se:.3f}, {len(lengths)} runs)"
        )
    assert fault.mean_burst_length == pytest.approx(1 / p_bg)


def test_gilbert_elliott_schedule_is_its_drop_mask():
    fault = GilbertElliott(p_good_to_bad=0.1, p_bad_to_good=0.25)
    s = schedule_detections(3000, pose_only(Rate(period_frames=2), fault), 5)
    rng = fault_rng(np.random.SeedSequence(5), "pose", fault.kind, 0)
    expected = fault.dropped(np.arange(0, 3000, 2), rng)
    assert [r.fate == "dropped" for r in s.pose_records] == expected.tolist()
    lengths = _runs(expected, True)
    assert np.mean(lengths) == pytest.approx(4.0, rel=0.15)  # 1 / 0.25, ~ 140 bursts


def test_gilbert_elliott_states_match_a_step_by_step_markov_chain():
    # Oracle: the plain one-step-at-a-time simulation of the same chain; compare the
    # transition frequencies of the vectorised sojourn sampler with the configured ones.
    from roft_sim.faults.loss import gilbert_elliott_states

    states = gilbert_elliott_states(200000, 0.05, 0.3, np.random.default_rng(0))
    prev, nxt = states[:-1], states[1:]
    p_gb = np.mean(nxt[~prev])
    p_bg = np.mean(~nxt[prev])
    assert p_gb == pytest.approx(0.05, abs=0.003) and p_bg == pytest.approx(0.3, abs=0.01)
    assert states.mean() == pytest.approx(0.05 / 0.35, abs=0.01)


def test_gilbert_elliott_loss_rate_and_partial_losses():
    fault = GilbertElliott(p_good_to_bad=0.1, p_bad_to_good=0.3, loss_in_bad=0.8, loss_in_good=0.05)
    rng = fault_rng(np.random.SeedSequence(1), "pose", fault.kind, 0)
    rate = fault.dropped(np.arange(200000), rng).mean()
    assert fault.loss_rate == pytest.approx(0.25 * 0.8 + 0.75 * 0.05)
    assert rate == pytest.approx(fault.loss_rate, abs=0.01)


@given(frames, seeds, st.lists(loss_faults(), min_size=1, max_size=3), st.randoms())
def test_losses_are_a_union_so_their_order_does_not_matter(n, seed, losses, random):
    # Faults of one kind in one stream are told apart by their order (their generators are keyed
    # by kind and occurrence, so a swept p keeps the same draws): shuffle across kinds only.
    kinds = sorted({f.kind for f in losses})
    random.shuffle(kinds)
    shuffled = [f for kind in kinds for f in losses if f.kind == kind]
    a = schedule_detections(n, pose_only(Rate(period_frames=2), *losses), seed)
    b = schedule_detections(n, pose_only(*shuffled, Rate(period_frames=2)), seed)
    fates = lambda s: [r.fate for r in s.pose_records]  # noqa: E731
    assert fates(a) == fates(b)
    # and the union: a run is lost iff some loss fault alone loses it
    alone = []
    for i, f in enumerate(losses):
        # same kind earlier in the list: keep placeholders so f keeps its occurrence number
        before = [_inert(g) for g in losses[:i] if g.kind == f.kind]
        faults = pose_only(Rate(period_frames=2), *before, f)
        alone.append(schedule_detections(n, faults, seed).pose_records)
    for r in a.pose_records:
        assert (r.fate == "dropped") == any(x[r.detection_id].fate == "dropped" for x in alone)


def test_blackout_on_capture_and_on_arrival():
    cap = pose_only(FixedDelay(frames=3), Blackout(windows=((10, 20),), on="capture"))
    s = schedule_detections(40, cap, 0)
    assert {e.true_capture_k for e in s.pose}.isdisjoint(range(10, 20))
    arr = pose_only(FixedDelay(frames=3), Blackout(windows=((10, 20),), on="arrival"))
    s = schedule_detections(40, arr, 0)
    assert {e.arrival_k for e in s.pose}.isdisjoint(range(10, 20))
    assert s.pose_records[7].fate == "dropped"  # captured at 7, would arrive at 10
    held = pose_only(
        FixedDelay(frames=3), Blackout(windows=((10, 20), (20, 22)), on="arrival", mode="hold")
    )
    s = schedule_detections(40, held, 0)
    at_22 = [e.true_capture_k for e in s.arriving_at("pose", 22)]
    assert at_22 == list(range(7, 20))  # held through both windows, delivered in order


# ------------------------------------------------------------------ delivery


def test_duplicate_keeps_the_id_and_arrives_again():
    s = schedule_detections(30, pose_only(Rate(period_frames=5), Duplicate(p=1.0)), 0)
    assert timing(s)[:2] == [(0, 0, 0, 0, "original"), (0, 0, 0, 0, "duplicate")]
    late = pose_only(Duplicate(p=1.0, min_after_frames=2, max_after_frames=2))
    s = schedule_detections(10, late, 0)
    assert s.pose_records[3].arrivals == (3, 5)


def test_stale_result_replaces_the_new_one():
    s = schedule_detections(30, pose_only(Rate(period_frames=5), Stale(p=1.0)), 0)
    # every result after the first is replaced by the previous delivery, i.e. the first one
    assert [(e.detection_id, e.arrival_k, e.copy) for e in s.pose] == [(0, 0, "original")] + [
        (0, k, "stale") for k in (5, 10, 15, 20, 25)
    ]
    assert [r.fate for r in s.pose_records] == ["delivered"] + ["superseded"] * 5


def test_reorder_holds_results_behind_later_ones():
    # Hand-computed from the fault's own draws: with seed 1, p = 0.5 holds runs 0, 3, 4, 5, 6
    # of 8 (captures 0, 5, ..., 35, no delay).
    rng = fault_rng(np.random.SeedSequence(1), "pose", "reorder", 0)
    assert (rng.random(8) < 0.5).tolist() == [1, 0, 0, 1, 1, 1, 1, 0]
    s = schedule_detections(40, pose_only(Rate(period_frames=5), Reorder(p=0.5)), 1)
    # run 0 goes right after run 1; runs 3-6 wait for run 7 (the next one not held)
    assert [(e.true_capture_k, e.arrival_k) for e in s.pose] == [
        (5, 5), (0, 5), (10, 10), (35, 35), (15, 35), (20, 35), (25, 35), (30, 35)
    ]  # fmt: skip
    # seed 0 holds runs 2 and 5; with past_events = 2 each waits for two later results
    rng = fault_rng(np.random.SeedSequence(0), "pose", "reorder", 0)
    assert (rng.random(8) < 0.5).tolist() == [0, 0, 1, 0, 0, 1, 0, 0]
    s = schedule_detections(40, pose_only(Rate(period_frames=5), Reorder(p=0.5, past_events=2)), 0)
    assert [(e.true_capture_k, e.arrival_k) for e in s.pose] == [
        (0, 0), (5, 5), (15, 15), (20, 20), (10, 20), (30, 30), (35, 35), (25, 35)
    ]  # fmt: skip
    # p = 1: nothing is left to overtake, so nothing moves
    s = schedule_detections(40, pose_only(Rate(period_frames=5), Reorder(p=1.0)), 0)
    assert [e.arrival_k for e in s.pose] == list(range(0, 40, 5))


def test_delivery_order_matters_and_is_the_listed_order():
    # Documented (docs/faults.md): delivery faults apply in the listed order. Duplicating then
    # reordering also holds the duplicate back; reordering then duplicating does not.
    dup_then_reorder = pose_only(Rate(period_frames=5), Duplicate(p=1.0), Reorder(p=1.0))
    reorder_then_dup = pose_only(Rate(period_frames=5), Reorder(p=1.0), Duplicate(p=1.0))
    a = timing(schedule_detections(20, dup_then_reorder, 0))
    b = timing(schedule_detections(20, reorder_then_dup, 0))
    assert a != b
    assert sorted(a) == sorted(b)  # the same deliveries, in a different order


def test_content_faults_apply_in_listed_order():
    # A jump then a flip, or a flip then a jump: both recorded in the listed order.
    a = pose_only(TranslationJump(p=1.0), RotationFlip(p=1.0))
    b = pose_only(RotationFlip(p=1.0), TranslationJump(p=1.0))
    ka = [c.kind for c in schedule_detections(3, a, 0).pose[0].corruptions]
    kb = [c.kind for c in schedule_detections(3, b, 0).pose[0].corruptions]
    assert ka == ["translation_jump", "rotation_flip"]
    assert kb == ["rotation_flip", "translation_jump"]


# ------------------------------------------------------------------ stamps


@given(frames, seeds, st.floats(-3, 3), st.floats(0, 1.5))
def test_clock_skew_changes_only_the_reported_capture(n, seed, offset, sd):
    clean = pose_only(Rate(period_frames=3), FixedDelay(frames=2))
    skewed = pose_only(
        Rate(period_frames=3),
        FixedDelay(frames=2),
        ClockSkew(offset_frames=offset, noise_sd_frames=sd),
    )
    a = schedule_detections(n, clean, seed)
    b = schedule_detections(n, skewed, seed)
    assert [(e.true_capture_k, e.arrival_k) for e in a.pose] == [
        (e.true_capture_k, e.arrival_k) for e in b.pose
    ]
    for e in b.pose:
        assert e.reported_capture_k >= 0
        if sd == 0:
            assert e.reported_capture_k == max(0, round(e.true_capture_k + offset))


# ------------------------------------------------------------------ seeds and purity


@given(detection_schedules())
def test_same_seed_same_schedule(triple):
    faults, seed, schedule = triple
    again = schedule_detections(schedule.n_frames, faults, seed)
    assert timing(again) == timing(schedule) and timing(again, "mask") == timing(schedule, "mask")
    assert again.pose_records == schedule.pose_records
    assert again.mask_records == schedule.mask_records
    assert np.array_equal(again.camera.dropped, schedule.camera.dropped)
    assert again.camera.depth == schedule.camera.depth


def test_different_seeds_differ_and_fault_seed_overrides():
    faults = pose_only(BernoulliDropout(p=0.5))
    a = schedule_detections(200, faults, 1)
    b = schedule_detections(200, faults, 2)
    assert a.pose_records != b.pose_records
    pinned = dataclasses.replace(faults, seed=7)
    assert (
        schedule_detections(200, pinned, 1).pose_records
        == schedule_detections(200, pinned, 2).pose_records
    )
    seq = np.random.SeedSequence(1)
    assert schedule_detections(200, faults, seq).pose_records == a.pose_records


@given(frames, seeds, fault_configs(camera=False), loss_faults())
def test_adding_a_fault_leaves_the_others_draws_unchanged(n, seed, faults, extra):
    # Append a loss of a kind not yet in the stream: every run it does not drop keeps exactly
    # the timing and content it had.
    if any(f.kind == extra.kind for f in faults.pose.faults):
        return
    more = dataclasses.replace(
        faults, pose=dataclasses.replace(faults.pose, faults=faults.pose.faults + (extra,))
    )
    a = schedule_detections(n, faults, seed)
    b = schedule_detections(n, more, seed)
    for ra, rb in zip(a.pose_records, b.pose_records, strict=True):
        assert (ra.true_capture_k, ra.reported_capture_k, ra.corruptions) == (
            rb.true_capture_k,
            rb.reported_capture_k,
            rb.corruptions,
        )
    assert a.mask_records == b.mask_records  # another stream: untouched
    has_delivery = any(f.stage == "delivery" for f in faults.pose.faults)
    if not has_delivery:  # without delivery faults, survivors arrive exactly as before
        kept = {r.detection_id for r in b.pose_records if r.fate == "delivered"}
        assert [e for e in a.pose if e.detection_id in kept] == list(b.pose)


@given(detection_schedules())
def test_schedule_invariants(triple):
    faults, seed, s = triple
    n = s.n_frames
    for stream in ("pose", "mask"):
        events = s.deliveries(stream)
        records = s.records(stream)
        arrivals = [e.arrival_k for e in events]
        assert arrivals == sorted(arrivals) and all(0 <= a < n for a in arrivals)
        for e in events:
            assert e.arrival_k >= e.true_capture_k  # causality: a result after its frame
            r = records[e.detection_id]
            assert r.fate == "delivered" and r.true_capture_k == e.true_capture_k
            assert r.reported_capture_k == e.reported_capture_k
            assert e.corruptions == r.corruptions
        assert [r.detection_id for r in records] == list(range(len(records)))
        captures = [r.true_capture_k for r in records]
        assert captures == sorted(set(captures)) and all(0 <= c < n for c in captures)
        for r in records:
            assert (len(r.arrivals) > 0) == (r.fate == "delivered")
            assert (r.cause is not None) == (r.fate in ("dropped", "superseded"))
        for k in range(0, n, 7):
            assert s.arriving_at(stream, k) == tuple(e for e in events if e.arrival_k == k)
    prev = s.camera.previous_delivered
    for k in range(n):
        earlier = [j for j in range(k) if not s.camera.dropped[j]]
        assert prev[k] == (earlier[-1] if earlier else -1)


@given(frames, seeds, fault_configs(camera=False))
def test_ideal_detections_deliver_every_frame_at_its_own_frame(n, seed, faults):
    s = schedule_detections(n, faults, seed, ideal_detections=True)
    for stream in ("pose", "mask"):
        records = s.records(stream)
        assert [r.true_capture_k for r in records] == list(range(n))
        for e in s.deliveries(stream):
            assert e.arrival_k == e.true_capture_k == e.reported_capture_k
            assert e.copy == "original"
        # only losses remove anything (no rate, no delivery faults)
        for r in records:
            assert r.fate in ("delivered", "dropped")


def test_validity_marks_detector_misses():
    valid = np.ones(30, dtype=bool)
    valid[[0, 12]] = False
    s = schedule_detections(30, load_faults("paper"), 0, valid=valid)
    assert s.pose_records[0].fate == "missed" and s.pose_records[2].fate == "missed"
    assert [e.true_capture_k for e in s.pose] == [6, 18]  # 24 -> 30 is after the end
    lazy = schedule_detections(30, load_faults("paper"), 0, valid={"mask": lambda c: c != 6})
    assert lazy.mask_records[1].fate == "missed" and lazy.pose_records[1].fate == "delivered"


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"n_frames": -1}, "n_frames must be an integer >= 0"),
        ({"rng_seed": -3}, "seed must be an integer >= 0"),
        ({"valid": np.ones(5, dtype=bool)}, r"validity must be a \(30,\) bool array"),
        ({"valid": {"pos": None}}, "unknown streams"),
        ({"fps": 0}, "camera fps must be a positive integer"),
        ({"fps": 24}, r"pose.faults\[0\].*rate_hz = 5 does not divide the camera rate 24 fps"),
    ],
)
def test_schedule_errors_say_what_to_fix(kwargs, match):
    args = {"n_frames": 30, "faults": load_faults("paper"), "rng_seed": 0, **kwargs}
    with pytest.raises(ConfigError, match=match):
        schedule_detections(**args)


def test_mask_and_pose_streams_are_independent():
    faults = FaultConfig(
        pose=PoseStreamFaults(faults=(BernoulliDropout(p=0.5),)),
        mask=MaskStreamFaults(faults=(BernoulliDropout(p=0.5),)),
    )
    s = schedule_detections(200, faults, 0)
    assert [r.fate for r in s.pose_records] != [r.fate for r in s.mask_records]
