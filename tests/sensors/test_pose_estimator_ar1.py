"""The pose estimator's AR(1) error process against scipy's ``lfilter`` (the oracle, and what it
was computed with before generation workers stopped importing scipy.signal)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from roft_sim.sensors.pose_estimator import _ar1


@pytest.mark.parametrize("rho", [0.3, 0.9, 0.999, -0.7])
@pytest.mark.parametrize("n", [1, 2, 57, 880])
def test_ar1_is_bit_identical_to_lfilter(rho, n):
    got = _ar1(np.random.default_rng(n), n, 6, rho)
    x = np.random.default_rng(n).standard_normal((n, 6))
    c = np.sqrt(1.0 - rho * rho)
    x[0] /= c
    want = lfilter([c], [1.0, -rho], x, axis=0)
    assert got.shape == (n, 6) and got.dtype == np.float64 and got.flags.c_contiguous
    assert got.tobytes() == want.tobytes()


def test_ar1_without_correlation_is_the_white_draw():
    np.testing.assert_array_equal(
        _ar1(np.random.default_rng(2), 5, 3, 0.0),
        np.random.default_rng(2).standard_normal((5, 3)),
    )
