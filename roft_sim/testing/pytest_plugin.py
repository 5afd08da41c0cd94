"""The roft_sim pytest plugin: fixtures and options for property tests of trackers.

Installed with roft-sim under the entry point ``pytest11`` (``roft_sim =
"roft_sim.testing.pytest_plugin"``), so every pytest run in an environment with roft-sim sees
it; it imports only pytest at start-up (no numpy, MuJoCo, hypothesis or OpenGL probing) and
does nothing until a test asks for one of its fixtures. Disable it with ``-p no:roft_sim``.

Fixtures:

- ``analytic_sequence`` (session): the renderer-free analytic box, 24 frames at 64x48 with exact
  depth, masks, flow and a ``gt`` pose set; ``analytic_sequence_factory`` (session) builds
  others (``factory(n_frames=..., width_px=..., height_px=..., motion=...)``, memoised).
- ``rendered_sequence`` (session): a tiny MuJoCo-rendered sequence (the ``cracker_box`` CI
  scenario, 8 frames at 64x48, Fast-YCB layout with a ``dope`` pose set, detector masks, ``gt``
  and ``nvof_1_slow`` flow), rendered once per session into a temporary folder; skips, with the
  reason, when no offscreen OpenGL backend works. ``rendered_sequence_factory`` (session) renders
  other scenarios, frame counts and resolutions (each once per session).
- ``tracker_under_test``: the :class:`~roft_sim.trackers.TrackerSpec` to test: the tracker named
  by ``--roft-sim-tracker NAME`` or the ini option ``roft_sim_tracker``; override the fixture in
  a ``conftest.py`` to return your own spec (no entry point needed).
- ``tracker_config``: its configuration (``--roft-sim-tracker-config FILE.toml``, else the
  spec's defaults).
- ``make_tracker``: ``make_tracker(sequence, config=None)`` builds a fresh tracker of
  ``tracker_under_test`` for a sequence (:func:`roft_sim.testing.streams.tracker_for`).

Hypothesis profiles ``roft-sim-ci`` (derandomised, 60 examples, no deadline) and ``thorough``
(2000 examples) are registered when hypothesis is in use, so ``pytest
--hypothesis-profile=roft-sim-ci`` and ``--hypothesis-profile=thorough`` work in any project.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any, cast

import pytest

_TRACKER_OPTION = "--roft-sim-tracker"
_CONFIG_OPTION = "--roft-sim-tracker-config"
_TRACKER_INI = "roft_sim_tracker"


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("roft-sim", "roft_sim tracker property tests")
    group.addoption(
        _TRACKER_OPTION,
        default=None,
        metavar="NAME",
        help="registered tracker served by the tracker_under_test fixture (roft-sim trackers "
        "lists them); overrides the roft_sim_tracker ini option",
    )
    group.addoption(
        _CONFIG_OPTION,
        default=None,
        metavar="FILE",
        help="TOML settings of the tracker under test (default: its defaults)",
    )
    parser.addini(_TRACKER_INI, "registered tracker served by the tracker_under_test fixture")


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    # Before hypothesis's own pytest_configure loads --hypothesis-profile; hypothesis is imported
    # only when the run uses it (the option is given, or a conftest imported it already).
    wants_profile = bool(config.getoption("--hypothesis-profile", default=None))
    if wants_profile or "hypothesis" in sys.modules:
        try:
            from roft_sim.testing.profiles import register_hypothesis_profiles
        except ImportError:  # hypothesis is not installed: nothing to register
            return
        register_hypothesis_profiles()


@pytest.fixture(scope="session")
def analytic_sequence_factory() -> Callable[..., Any]:
    """``factory(n_frames=24, width_px=64, height_px=48, motion=None, fps=30)`` -> the analytic
    box :class:`~roft_sim.datasets.base.InMemorySequence` (memoised; do not modify it)."""
    from roft_sim.testing.fixtures import analytic_sequence

    return analytic_sequence


@pytest.fixture(scope="session")
def analytic_sequence(analytic_sequence_factory: Callable[..., Any]) -> Any:
    """The analytic box: 24 frames at 64x48, 30 fps, exact depth, masks, flow, ``gt`` poses."""
    return analytic_sequence_factory()


@pytest.fixture(scope="session")
def rendered_sequence_factory(tmp_path_factory: pytest.TempPathFactory) -> Callable[..., Any]:
    """``factory(scenario="cracker_box", frames=8, resolution=(64, 48), seed=None)`` -> a
    MuJoCo-rendered sequence, rendered once per session and argument set. Skips the test, with
    the reason, when no offscreen OpenGL backend works."""
    from roft_sim.render.gl_backend import probe_gl_backend, select_gl_backend

    # The backend must be chosen before MuJoCo is imported (test infrastructure, like a
    # conftest: it may read the environment).
    backend = select_gl_backend(os.environ)
    problem = probe_gl_backend(backend) if backend else probe_gl_backend()
    cache: dict[tuple[Any, ...], Any] = {}

    def factory(
        scenario: str = "cracker_box",
        frames: int = 8,
        resolution: tuple[int, int] = (64, 48),
        seed: int | None = None,
    ) -> Any:
        if backend is None or problem is not None:
            pytest.skip(f"no offscreen OpenGL backend to render with: {problem}")
        key = (scenario, frames, tuple(resolution), seed)
        if key not in cache:
            from roft_sim.testing.fixtures import render_tiny_sequence

            name = f"{scenario}_{frames}f_{resolution[0]}x{resolution[1]}_s{seed}"
            cache[key] = render_tiny_sequence(
                tmp_path_factory.mktemp(name),
                scenario=scenario,
                frames=frames,
                resolution=cast(tuple[int, int], tuple(resolution)),
                seed=seed,
                gl_backend=backend,
            )
        return cache[key]

    return factory


@pytest.fixture(scope="session")
def rendered_sequence(rendered_sequence_factory: Callable[..., Any]) -> Any:
    """The ``cracker_box`` CI scenario, 8 frames at 64x48, rendered once per session."""
    return rendered_sequence_factory()


@pytest.fixture
def tracker_under_test(pytestconfig: pytest.Config) -> Any:
    """The :class:`~roft_sim.trackers.TrackerSpec` named by ``--roft-sim-tracker`` or the ini
    option ``roft_sim_tracker``. Override this fixture to test an unregistered tracker."""
    name = pytestconfig.getoption(_TRACKER_OPTION) or pytestconfig.getini(_TRACKER_INI)
    if not name:
        pytest.fail(
            "tracker_under_test: no tracker chosen; pass --roft-sim-tracker NAME, set "
            "roft_sim_tracker = NAME in the [tool.pytest.ini_options] table, or override the "
            "tracker_under_test fixture in conftest.py to return your TrackerSpec",
            pytrace=False,
        )
    from roft_sim.trackers import get_tracker_spec

    return get_tracker_spec(str(name))


@pytest.fixture
def tracker_config(pytestconfig: pytest.Config, tracker_under_test: Any) -> Any:
    """Settings of the tracker under test: ``--roft-sim-tracker-config FILE`` or its defaults."""
    from roft_sim.trackers import load_tracker_config

    return load_tracker_config(tracker_under_test, pytestconfig.getoption(_CONFIG_OPTION))


@pytest.fixture
def make_tracker(tracker_under_test: Any, tracker_config: Any) -> Callable[..., Any]:
    """``make_tracker(sequence, config=None, *, seed=0)`` -> a fresh tracker of
    ``tracker_under_test`` for ``sequence`` (with ``tracker_config`` unless ``config`` is
    given; the analytic box's depth renderer is injected for analytic sequences)."""
    from roft_sim.testing.streams import tracker_for

    def make(sequence: Any, config: Any = None, *, seed: int = 0) -> Any:
        return tracker_for(
            tracker_under_test,
            sequence,
            config if config is not None else tracker_config,
            seed=seed,
        )

    return make
