"""Fixtures and oracles shared by the asset tests."""

from __future__ import annotations

import pytest

from roft_sim.assets.objects import _clear_caches
from roft_sim.testing.mesh_oracles import surface_distance_m


@pytest.fixture(autouse=True)
def _fresh_asset_caches():
    """Every test starts without in-process asset caches (so caching cannot hide a bug)."""
    _clear_caches()
    yield
    _clear_caches()


@pytest.fixture(scope="session")
def surface_distance():
    """The :func:`surface_distance_m` oracle."""
    return surface_distance_m
