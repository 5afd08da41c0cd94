"""Fixtures of the property suite (settings and budgets: property_settings.py)."""

from __future__ import annotations

import pytest

from roft_sim.datasets.base import InMemorySequence
from roft_sim.testing.fixtures import analytic_sequence


@pytest.fixture(scope="session")
def roft_seq() -> InMemorySequence:
    """64x48, 24 frames of the analytic box in fast motion (peaks near 0.5 m/s, 4 rad/s)."""
    return analytic_sequence(n_frames=24, width_px=64, height_px=48)
