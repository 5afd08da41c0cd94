"""Replicate intervals against scipy, paired verdicts and their calibration, the seeds a
difference needs, the Politis-White block length and the moving-block bootstrap."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal, stats

from roft_sim.metrics.auc import add_auc, add_auc_rows
from roft_sim.metrics.statistics import (
    BETTER,
    NO_DIFFERENCE,
    WORSE,
    Interval,
    block_bootstrap_interval,
    bootstrap_percentile_interval,
    mean_interval,
    mean_intervals,
    moving_block_indices,
    paired_comparison,
    politis_white_block_length,
    replicates_needed,
    verdict_word,
)


def test_interval_is_scipys_bca_widened_to_students_t() -> None:
    """Right-skewed replicates (one failure-like value): the upper bound is scipy's BCa bound
    (longer than t's on the skewed side), the lower bound t's (BCa is shorter there)."""
    x = np.array([2.1, 2.3, 2.2, 2.6, 2.4, 2.0, 2.5, 6.5])
    got = mean_interval(x, rng=np.random.default_rng(5), n_resamples=3000)
    bca = stats.bootstrap(
        (x,), np.mean, method="BCa", n_resamples=3000, rng=np.random.default_rng(5)
    ).confidence_interval
    t = stats.ttest_1samp(x, 0.0).confidence_interval(0.95)
    assert got.estimate == pytest.approx(x.mean())
    assert bca.high > t.high and bca.low > t.low  # the skew: BCa shifts up
    assert got.high == pytest.approx(bca.high, rel=1e-12)
    assert got.low == pytest.approx(t.low, rel=1e-12)
    assert got.n == 8 and got.text(".2f").startswith(f"{x.mean():.2f} [")


def test_degenerate_and_tiny_replicate_sets() -> None:
    rng = np.random.default_rng(0)
    constant = mean_interval([3.0, 3.0, 3.0], rng=rng)
    assert (constant.low, constant.estimate, constant.high) == (3.0, 3.0, 3.0)
    single = mean_interval([4.0, math.nan], rng=rng)  # NaN replicates are left out
    assert single.n == 1 and not single.has_interval and single.text() == "4.00 (n=1)"
    assert not single.excludes(0.0)
    assert math.isnan(mean_interval([], rng=rng).estimate)
    m, lo, hi = mean_intervals(np.ones((3, 1)), rng=rng)
    assert np.isnan(lo).all() and np.isnan(hi).all() and (m == 1).all()
    with pytest.raises(ValueError, match="finite"):
        mean_intervals([[1.0, np.inf]], rng=rng)


def test_verdict_word_knows_each_metrics_direction() -> None:
    up = Interval(estimate=2.0, low=0.5, high=3.5, n=10)
    down = Interval(estimate=-2.0, low=-3.5, high=-0.5, n=10)
    spans = Interval(estimate=0.4, low=-0.5, high=1.3, n=10)
    assert verdict_word(up, "higher") == BETTER and verdict_word(up, "lower") == WORSE
    assert verdict_word(down, "lower") == BETTER and verdict_word(down, "higher") == WORSE
    assert verdict_word(spans, "higher") == NO_DIFFERENCE
    rng = np.random.default_rng(1)
    a = np.array([80.0, 75.0, 90.0, 60.0, 70.0])
    add = paired_comparison(a, a - [2.0, 2.2, 1.9, 2.1, 2.05], "add_auc_pct", rng=rng)
    assert add.verdict == BETTER and add.difference.estimate == pytest.approx(2.05)
    e_t = paired_comparison([1.0, 1.1, 1.2, 0.9], [2.0, 2.2, 2.1, 1.9], "rmse_t_cm", rng=rng)
    assert e_t.verdict == BETTER and e_t.difference.high < 0
    with pytest.raises(ValueError, match="no direction"):
        paired_comparison([1.0], [2.0], "frames", rng=rng)
    with pytest.raises(ValueError, match="equal lengths"):
        paired_comparison([1.0], [2.0, 3.0], "rmse_t_cm", rng=rng)


def _cells(
    rng: np.random.Generator,
    reps: int,
    sequences: int,
    seeds: int,
    *,
    shift: float = 0.0,
    noise: float = 1.5,
    failure: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(reps, sequences x seeds) ADD-AUC [%] of a tracker A and of B, the same law shifted by
    ``shift``, on the same cells: a difficulty per sequence and an effect per fault draw (both
    shared by A and B), then each run's own noise (another seed stream: Gaussian, and with
    probability ``failure`` a lost track costing 25 points)."""
    difficulty = rng.normal(70.0, 8.0, (reps, sequences, 1))
    draw = rng.normal(0.0, 3.0, (reps, sequences, seeds))

    def run() -> np.ndarray:
        lost = rng.random((reps, sequences, seeds)) < failure
        own = rng.normal(0.0, noise, (reps, sequences, seeds)) - 25.0 * lost
        return (difficulty + draw + own).reshape(reps, -1)

    return run() + shift, run()


def _no_difference_rate(a: np.ndarray, b: np.ndarray, rng: np.random.Generator) -> float:
    m, lo, hi = mean_intervals(a - b, rng=rng, n_resamples=999)
    words = [
        verdict_word(Interval(estimate=x, low=low, high=high, n=a.shape[1]), "higher")
        for x, low, high in zip(m, lo, hi, strict=True)
    ]
    return float(np.mean([w == NO_DIFFERENCE for w in words]))


def test_a_tracker_against_itself_is_no_detectable_difference_in_95_percent() -> None:
    """200 repetitions of a tracker against itself with another seed stream (5 sequences x 4
    seeds, runs that now and then lose the track): at least 95 % are "no detectable
    difference". (The long-run rate of this law is about 97.5 %; a plain percentile bootstrap
    calls a difference far more often at so few replicates.)"""
    rng = np.random.default_rng(2026)
    a, b = _cells(rng, 200, 5, 4, failure=0.05)
    assert _no_difference_rate(a, b, rng) >= 0.95
    plain = stats.bootstrap((a[:, :6] - b[:, :6],), np.mean, axis=-1, method="percentile", rng=rng)
    lo, hi = plain.confidence_interval
    assert np.mean((lo <= 0) & (hi >= 0)) < 0.93  # what the t floor protects against


@pytest.mark.slow
def test_no_difference_rate_is_95_percent_on_a_gaussian_law() -> None:
    """On a Gaussian law, where Student's t is exact, the rate is the nominal 95 % (4000
    repetitions)."""
    rng = np.random.default_rng(7)
    a, b = _cells(rng, 4000, 5, 4)
    assert _no_difference_rate(a, b, rng) >= 0.945


def test_a_two_point_difference_is_found_with_the_recommended_seeds() -> None:
    """A pilot (5 sequences x 4 seeds) gives the paired sd; the seeds recommended for a 2-point
    ADD-AUC difference find the real 2-point difference in at least 75 % of 200 repetitions
    (80 % power at the pilot's upper sd bound), one seed in far fewer."""
    rng = np.random.default_rng(11)
    pilot_a, pilot_b = _cells(rng, 1, 5, 4, shift=2.0, noise=3.0)
    sd = float(np.std(pilot_a - pilot_b, ddof=1))
    needed = replicates_needed(sd, 2.0, pilot_pairs=20)
    assert needed is not None
    seeds = -(-needed // 5)
    a, b = _cells(rng, 200, 5, seeds, shift=2.0, noise=3.0)
    assert 1.0 - _no_difference_rate(a, b, rng) >= 0.75
    a, b = _cells(rng, 200, 5, 1, shift=2.0, noise=3.0)
    assert 1.0 - _no_difference_rate(a, b, rng) < 0.5


def test_replicates_needed_matches_the_paired_t_power() -> None:
    """sd 3, difference 2 (effect 0.67): the paired t test needs 20 pairs for 80 % power (the
    noncentral t gives >= 0.8 at the recommendation, < 0.8 one pair earlier)."""
    n = replicates_needed(3.0, 2.0)
    assert n == 20

    def power(k: int) -> float:
        q = stats.t.ppf(0.975, k - 1)
        return float(stats.nct.sf(q, k - 1, math.sqrt(k) * 2.0 / 3.0))

    assert power(n) >= 0.79 and power(n - 1) < 0.8
    # a pilot's sd is taken at its upper 80 % bound: more pairs, fewer the smaller the pilot
    assert (
        replicates_needed(3.0, 2.0, pilot_pairs=10)
        > replicates_needed(3.0, 2.0, pilot_pairs=100)
        > n
    )
    assert replicates_needed(3.0, 2.0, pilot_pairs=1) is None
    assert replicates_needed(0.0, 2.0) == 2
    assert replicates_needed(math.nan, 2.0) is None
    assert replicates_needed(3.0, 4.0) < n


def test_percentile_bootstrap_of_any_statistic() -> None:
    x = np.array([0.3, 0.1, 0.5, 0.9, 0.2, 0.4])
    got = bootstrap_percentile_interval(
        lambda i: float(np.median(x[i])), x.size, rng=np.random.default_rng(3)
    )
    assert got.estimate == pytest.approx(np.median(x))
    assert got.low <= got.estimate <= got.high and got.method == "percentile bootstrap"
    one = bootstrap_percentile_interval(lambda i: 1.0, 1, rng=np.random.default_rng(3))
    assert not one.has_interval


def _ar1(rng: np.random.Generator, n: int, phi: float) -> np.ndarray:
    out: np.ndarray = signal.lfilter([1.0], [1.0, -phi], rng.normal(size=n))
    return out


def test_politis_white_block_length_follows_the_ar1_theory() -> None:
    """For AR(1) with coefficient phi the optimal moving-block length is
    (6 phi^2 / (1 - phi^2)^2)^(1/3) N^(1/3); white noise gets blocks of about 1."""
    rng = np.random.default_rng(4)
    n = 5000
    for phi in (0.5, 0.8):
        theory = (6 * phi**2 / (1 - phi**2) ** 2) ** (1 / 3) * n ** (1 / 3)
        got = np.median([politis_white_block_length(_ar1(rng, n, phi)) for _ in range(5)])
        assert got == pytest.approx(theory, rel=0.25), phi
    assert politis_white_block_length(rng.normal(size=n)) <= 3
    assert politis_white_block_length([1.0, 2.0]) == 1


def test_moving_blocks_stay_inside_their_sequence() -> None:
    index = moving_block_indices([7, 5], 3, 50, np.random.default_rng(0))
    assert index.shape == (50, 12)
    assert ((index[:, :7] >= 0) & (index[:, :7] < 7)).all()
    assert ((index[:, 7:] >= 7) & (index[:, 7:] < 12)).all()
    steps = np.diff(index[:, :3], axis=1)  # the first block of each resample is consecutive
    assert (steps == 1).all()


def test_block_bootstrap_widens_the_interval_of_correlated_frames() -> None:
    """The mean of an AR(1) series with phi = 0.8: blocks of the Politis-White length give an
    interval about sqrt((1 + phi) / (1 - phi)) = 3 times the width of single-frame blocks."""
    rng = np.random.default_rng(8)
    x = _ar1(rng, 2000, 0.8)

    def mean(index: np.ndarray) -> np.ndarray:
        out: np.ndarray = x[index].mean(axis=1)
        return out

    block = politis_white_block_length(x)
    wide = block_bootstrap_interval(mean, [x.size], block, rng=rng, n_resamples=1000)
    narrow = block_bootstrap_interval(mean, [x.size], 1, rng=rng, n_resamples=1000)
    assert wide.estimate == pytest.approx(x.mean())
    ratio = (wide.high - wide.low) / (narrow.high - narrow.low)
    assert 2.0 < ratio < 4.0


def test_add_auc_rows_is_the_vocap_auc_of_each_row() -> None:
    rng = np.random.default_rng(9)
    for _ in range(50):
        d = np.round(rng.exponential(0.04, int(rng.integers(1, 40))), 3)
        d[rng.random(d.size) < 0.1] = np.inf
        # add_auc takes the reference's float32 accuracy steps (i / N rounded to float32): the
        # float64 closed form is within their rounding, far below the intervals it serves
        assert add_auc_rows(d[None, :])[0] == pytest.approx(add_auc(d), abs=1e-5)
    assert add_auc_rows(np.full((2, 3), np.inf)).tolist() == [0.0, 0.0]
