"""Hypothesis profiles for tracker property tests (imports hypothesis only).

- ``roft-sim-ci`` (:data:`CI_PROFILE`): derandomised, 60 examples, no deadline, no example
  database: the same examples on every CI run.
- ``thorough`` (:data:`THOROUGH_PROFILE`): 2000 random examples, no deadline: a long search on
  demand (``pytest --hypothesis-profile=thorough``).

Both switch off the health checks of :data:`TRACKER_HEALTH_CHECKS`. The pytest plugin registers
them when hypothesis is in use; :func:`tracker_settings` gives per-test settings that scale with
the active profile.
"""

from __future__ import annotations

from typing import Any

from hypothesis import HealthCheck, settings
from hypothesis.errors import InvalidArgument

__all__ = [
    "CI_PROFILE",
    "THOROUGH_PROFILE",
    "TRACKER_HEALTH_CHECKS",
    "register_hypothesis_profiles",
    "tracker_settings",
]

CI_PROFILE = "roft-sim-ci"
"""Derandomised, 60 examples, no deadline."""
THOROUGH_PROFILE = "thorough"
"""2000 random examples, no deadline."""

TRACKER_HEALTH_CHECKS = (
    HealthCheck.too_slow,
    HealthCheck.data_too_large,
    HealthCheck.function_scoped_fixture,
)
"""Health checks that tracker properties trip by nature: a run takes milliseconds, a schedule is
a lot of data, and the plugin's ``make_tracker`` is a function-scoped fixture (a stateless
factory: every call builds a fresh tracker, so sharing it across examples is safe)."""


def register_hypothesis_profiles() -> None:
    """Registers :data:`CI_PROFILE` and :data:`THOROUGH_PROFILE` unless a profile of that name
    exists already (a project's own ``thorough`` wins). Loads neither."""
    wanted: dict[str, dict[str, Any]] = {
        CI_PROFILE: {"max_examples": 60, "derandomize": True, "database": None},
        THOROUGH_PROFILE: {"max_examples": 2000},
    }
    for name, values in wanted.items():
        try:
            settings.get_profile(name)
        except InvalidArgument:
            settings.register_profile(
                name, deadline=None, suppress_health_check=list(TRACKER_HEALTH_CHECKS), **values
            )


def tracker_settings(*, fraction: float = 1.0, min_examples: int = 1) -> settings:
    """Settings for a tracker property test: no deadline, :data:`TRACKER_HEALTH_CHECKS` off, and
    ``fraction`` of the active profile's ``max_examples`` (at least ``min_examples``), so
    ``--hypothesis-profile=thorough`` scales every test up.

    Use it as a decorator below ``@given``'s neighbours, like ``@settings``; it reads the active
    profile when the test module is imported (after pytest has loaded ``--hypothesis-profile``).
    """
    if not fraction > 0:
        raise ValueError(f"fraction must be > 0, got {fraction}")
    assert settings.default is not None  # typed Optional; hypothesis sets it on import
    n = max(min_examples, int(round(settings.default.max_examples * fraction)))
    checks = list(TRACKER_HEALTH_CHECKS)
    return settings(max_examples=n, deadline=None, suppress_health_check=checks)
