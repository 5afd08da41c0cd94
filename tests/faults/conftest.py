"""Fixtures of the fault and stream tests."""

from __future__ import annotations

import pytest
from fault_sequences import make_sequence

from roft_sim.datasets.base import InMemorySequence


@pytest.fixture
def tiny_sequence() -> InMemorySequence:
    return make_sequence()
