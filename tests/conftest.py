"""Shared pytest configuration.

- ``slow`` tests run only with ``--run-slow``.
- ``render`` tests are skipped, with the reason, when no offscreen OpenGL backend works.
- Fixtures ``shared_ycb_dir`` and ``shared_trajectories_dir`` point at ``../shared/`` beside the
  repository and skip with the reason when it is absent. Override with ``--shared-dir``.
- Hypothesis profiles: the ones ``roft_sim.testing.profiles`` ships to users, so the suite runs
  under what it ships: ``roft-sim-ci`` by default (derandomised, 60 examples) and ``thorough``
  (2000 examples) with ``--hypothesis-profile=thorough``.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

from roft_sim.testing.profiles import CI_PROFILE, register_hypothesis_profiles

REPO_ROOT = Path(__file__).resolve().parent.parent

register_hypothesis_profiles()
settings.load_profile(CI_PROFILE)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--run-slow", action="store_true", help="also run tests marked slow")
    parser.addoption(
        "--update-golden",
        action="store_true",
        help="rewrite the golden renderer images in tests/golden/<backend>/ instead of comparing",
    )
    parser.addoption(
        "--shared-dir",
        default=str(REPO_ROOT.parent / "shared"),
        help="folder with ycb/ and trajectories/ test data (default: ../shared beside the repo)",
    )


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not config.getoption("--run-slow"):
        skip_slow = pytest.mark.skip(reason="slow test: run with --run-slow")
        for item in items:
            if "slow" in item.keywords:
                item.add_marker(skip_slow)
    if any("render" in item.keywords for item in items):
        from roft_sim.render.gl_backend import probe_gl_backend

        problem = probe_gl_backend()
        if problem is not None:
            skip_render = pytest.mark.skip(reason=f"no offscreen OpenGL backend: {problem}")
            for item in items:
                if "render" in item.keywords:
                    item.add_marker(skip_render)


def _shared_subdir(config: pytest.Config, name: str) -> Path:
    path = Path(config.getoption("--shared-dir")) / name
    if not path.is_dir():
        pytest.skip(f"test data {path} is absent (it lives in ../shared/{name} beside the repo)")
    return path


@pytest.fixture(scope="session")
def shared_ycb_dir(pytestconfig: pytest.Config) -> Path:
    """``../shared/ycb``: six real YCB google_16k meshes (skips when absent)."""
    return _shared_subdir(pytestconfig, "ycb")


@pytest.fixture(scope="session")
def shared_trajectories_dir(pytestconfig: pytest.Config) -> Path:
    """``../shared/trajectories``: TUM and BVH captured motion (skips when absent)."""
    return _shared_subdir(pytestconfig, "trajectories")


def pytest_configure(config: pytest.Config) -> None:
    # MuJoCo reads MUJOCO_GL at import; choose before any test imports it.
    from roft_sim.render.gl_backend import select_gl_backend

    select_gl_backend(os.environ)
