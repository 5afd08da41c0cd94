"""Fixtures of the tracker tests: small analytic box sequences, rendered once per session."""

from __future__ import annotations

import pytest

from roft_sim.datasets.base import InMemorySequence
from roft_sim.testing.analytic_scene import analytic_box_sequence, default_intrinsics


@pytest.fixture(scope="session")
def tiny_seq() -> InMemorySequence:
    """64x48, 40 frames: for property tests of the filter logic."""
    return analytic_box_sequence(n_frames=40, intrinsics=default_intrinsics(64, 48))


@pytest.fixture(scope="session")
def small_seq() -> InMemorySequence:
    """160x120, 48 frames."""
    return analytic_box_sequence(n_frames=48, intrinsics=default_intrinsics(160, 120))


@pytest.fixture(scope="session")
def medium_seq() -> InMemorySequence:
    """320x240, 60 frames: mask synchronisation and accuracy figures."""
    return analytic_box_sequence(n_frames=60, intrinsics=default_intrinsics(320, 240))
