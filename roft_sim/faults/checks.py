"""Checks shared by the fault configs: each raises ConfigError saying what and how to fix it."""

from __future__ import annotations

import math

from roft_sim.errors import ConfigError

__all__ = [
    "check_probability",
    "check_non_negative_int",
    "check_int_range",
    "check_positive_finite",
    "check_windows",
]


def check_probability(name: str, p: float) -> None:
    """``p`` must be a probability in [0, 1]."""
    if not (math.isfinite(p) and 0.0 <= p <= 1.0):
        raise ConfigError(f"{name} must be a probability in [0, 1], got {p!r}")


def check_non_negative_int(name: str, value: int) -> None:
    """``value`` must be an integer >= 0."""
    if value < 0:
        raise ConfigError(f"{name} must be >= 0, got {value}")


def check_int_range(lo_name: str, lo: int, hi_name: str, hi: int, *, minimum: int | None) -> None:
    """``minimum <= lo <= hi`` (``minimum`` None: no lower bound)."""
    if minimum is not None and lo < minimum:
        raise ConfigError(f"{lo_name} must be >= {minimum}, got {lo}")
    if hi < lo:
        raise ConfigError(
            f"{hi_name} ({hi}) must be >= {lo_name} ({lo}); swap them or raise {hi_name}"
        )


def check_positive_finite(name: str, value: float, *, allow_zero: bool = False) -> None:
    """``value`` must be finite and > 0 (or >= 0 with ``allow_zero``)."""
    ok = math.isfinite(value) and (value >= 0.0 if allow_zero else value > 0.0)
    if not ok:
        bound = ">= 0" if allow_zero else "> 0"
        raise ConfigError(f"{name} must be finite and {bound}, got {value!r}")


def check_windows(name: str, windows: tuple[tuple[int, int], ...]) -> None:
    """Frame windows ``[start, stop)`` with ``0 <= start < stop``."""
    for i, (start, stop) in enumerate(windows):
        if start < 0 or stop <= start:
            raise ConfigError(
                f"{name}[{i}] = [{start}, {stop}] is not a frame window [start, stop) with "
                f"0 <= start < stop; e.g. [30, 45] blacks out frames 30 to 44"
            )
