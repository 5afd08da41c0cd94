"""ADD-AUC: hand-computed VOCap cases and two independent implementations on random data.

The accuracies ``i / N`` are float32, as the ROFT reference's evaluation computes them, so a
number differs from its exact (float64) value by up to ~1e-5 percentage points: the hand cases
allow that, the literal transcription rounds the same way and matches to 1e-9."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from roft_sim.metrics import accuracy_curve, add_auc


def vocap_matlab_literal(distances: list[float]) -> float:
    """A literal, loop-by-loop transcription of YCB_Video_toolbox ``VOCap`` (1-based indices)
    and its caller: ``D(D > 0.1) = inf; d = sort(D); accuracy = cumsum(ones(1, n)) / n``, the
    accuracies rounded to float32 as hsp-iit/roft's Python port computes them."""
    D = [math.inf if (x > 0.1 or math.isnan(x)) else x for x in distances]
    d = sorted(D)
    n = len(d)
    accuracy = [float(np.float32(i + 1) / np.float32(n)) for i in range(n)]
    rec = [d[i] for i in range(n) if math.isfinite(d[i])]
    prec = [accuracy[i] for i in range(n) if math.isfinite(d[i])]
    if not rec:
        return 0.0
    mrec = [None, 0.0, *rec, 0.1]  # index 0 unused: MATLAB is 1-based
    mpre = [None, 0.0, *prec, prec[-1]]
    for i in range(2, len(mpre)):
        mpre[i] = max(mpre[i], mpre[i - 1])
    ap = 0.0
    for i in range(2, len(mrec)):
        if mrec[i] != mrec[i - 1]:
            ap += (mrec[i] - mrec[i - 1]) * mpre[i]
    return ap * 10 * 100


def vocap_closed_form(distances: list[float]) -> float:
    """The same number from a formula over DISTINCT values: the interval ending at value v gets
    the accuracy (#{e < v} + 1) / N (the first of the tied entries), the last interval up to
    0.1 gets n_finite / N."""
    e = np.array([x if x <= 0.1 else np.inf for x in distances], dtype=float)
    e[np.isnan(e)] = np.inf
    n = e.size
    finite = np.sort(e[np.isfinite(e)])
    if finite.size == 0:
        return 0.0
    total, prev = 0.0, 0.0
    for v in np.unique(finite):
        total += (v - prev) * (np.count_nonzero(finite < v) + 1) / n
        prev = v
    total += (0.1 - prev) * finite.size / n
    return total / 0.1 * 100


def exact_integral(distances: list[float]) -> float:
    """The exact area under A(tau) = #{e <= tau} / N on [0, 0.1], in %: each frame with
    e <= 0.1 contributes (0.1 - e) / N."""
    e = np.array(distances, dtype=float)
    ok = np.isfinite(e) & (e <= 0.1)
    return float(np.sum(0.1 - e[ok]) / e.size / 0.1 * 100)


def test_hand_computed_three_frames():
    # N = 3; 0.2 m > 0.1 m is a failure. mrec = [0, .02, .05, .1], mpre = [0, 1/3, 2/3, 2/3]:
    # 0.02 * 1/3 + 0.03 * 2/3 + 0.05 * 2/3 = 0.06 -> x10 -> 0.6 -> 60 %.
    assert add_auc([0.02, 0.05, 0.2]) == pytest.approx(60.0, abs=1e-5)  # float32 1/3, 2/3


def test_hand_computed_tie_takes_accuracy_of_first_tied_entry():
    # mrec = [0, .05, .05, .1], mpre = [0, .5, 1, 1]; index 3 (tie) is skipped:
    # 0.05 * 0.5 + 0.05 * 1 = 0.075 -> 75 % (the exact integral would be 50 %).
    assert add_auc([0.05, 0.05]) == pytest.approx(75.0, abs=1e-12)  # 1/2 and 1: exact
    assert exact_integral([0.05, 0.05]) == pytest.approx(50.0)


def test_distance_exactly_at_threshold_is_kept_and_nan_is_failure():
    assert add_auc([0.1]) == pytest.approx(100.0)  # right-endpoint quirk: 0.1 * 1 / 0.1
    # NaN counts in N as a failure: [0.02, 0.05, NaN] equals [0.02, 0.05, 0.2] (60 %).
    assert add_auc([0.02, np.nan, 0.05]) == pytest.approx(60.0)
    assert add_auc([0.02, np.inf, 0.05]) == pytest.approx(60.0)


def test_edge_cases():
    assert add_auc([0.0, 0.0, 0.0]) == pytest.approx(100.0)
    assert add_auc([0.5, np.inf]) == 0.0
    assert math.isnan(add_auc([]))
    with pytest.raises(ValueError, match="shape"):
        add_auc(np.zeros((2, 2)))
    with pytest.raises(ValueError, match=">= 0"):
        add_auc([-0.01])
    with pytest.raises(ValueError, match="max_threshold_m"):
        add_auc([0.01], max_threshold_m=0.0)


def test_max_threshold_scales_consistently():
    d = np.array([0.01, 0.03, 0.07])
    assert add_auc(d * 2, max_threshold_m=0.2) == pytest.approx(add_auc(d))


_values = st.one_of(
    st.floats(0.0, 0.15, allow_nan=False),
    st.sampled_from([0.0, 0.01, 0.025, 0.05, 0.1, 0.1000001, np.inf, np.nan]),  # ties, edges
)


@given(st.lists(_values, min_size=1, max_size=60))
def test_matches_literal_matlab_transcription_and_closed_form(distances):
    ours = add_auc(distances)
    assert ours == pytest.approx(vocap_matlab_literal(distances), abs=1e-9)
    assert ours == pytest.approx(vocap_closed_form(distances), abs=1e-5)  # float64 accuracies


@given(st.lists(st.floats(0.0, 0.15, allow_nan=False), min_size=1, max_size=60))
def test_upward_bias_over_exact_integral_is_bounded(distances):
    # VOCap is a right-endpoint sum: 0 <= VOCap - exact <= max finite d / (0.1 N) (in %).
    ours, exact = add_auc(distances), exact_integral(distances)
    d = np.array(distances)
    finite = d[d <= 0.1]
    bound = (finite.max() if finite.size else 0.0) / (0.1 * d.size) * 100
    assert -1e-5 <= ours - exact <= bound + 1e-5  # float32 accuracies


def test_accuracy_curve_counts_failures_in_n():
    acc = accuracy_curve([0.01, 0.02, np.nan, np.inf], [0.0, 0.01, 0.015, 0.02, 1.0])
    np.testing.assert_allclose(acc, [0.0, 0.25, 0.25, 0.5, 0.5])
