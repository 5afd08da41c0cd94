"""Timing faults of a detection stream: when the network runs, how late its results arrive, and
what time stamp they carry.

All times are integer camera frames (``1 / fps`` seconds each). A result that becomes ready
between two camera frames is seen at the next one, so continuous delay distributions are rounded
UP (``ceil``) to whole frames.

Stages (see :mod:`roft_sim.faults.schedule` for the full order):

- ``sampling``: :class:`Rate` (every n-th frame) or :class:`BusyNetwork` (a network that skips the
  frames that come while it works). At most one per stream; none = every frame.
- ``stamp``: :class:`ClockSkew` corrupts the REPORTED capture frame only.
- ``delay``: :class:`FixedDelay`, :class:`UniformDelay`, :class:`LogNormalDelay`,
  :class:`EmpiricalDelay`. Several delays in one stream ADD UP (per detection).

Each draw takes an explicit ``rng`` and returns one value per network run (indexed by run), so
the result of a fault does not depend on which other faults are configured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.faults.checks import (
    check_int_range,
    check_non_negative_int,
    check_positive_finite,
)

I64 = NDArray[np.int64]
F64 = NDArray[np.float64]

__all__ = [
    "Rate",
    "BusyNetwork",
    "FixedDelay",
    "UniformDelay",
    "LogNormalDelay",
    "EmpiricalDelay",
    "DelayDistribution",
    "ClockSkew",
]


# ---------------------------------------------------------------- delay distributions


@dataclass(frozen=True, slots=True, kw_only=True)
class FixedDelay:
    """Every result arrives exactly ``frames`` camera frames after its capture frame."""

    kind: Literal["delay"] = "delay"
    frames: int = 0
    """Delay [camera frames], >= 0 (6 frames = 200 ms at 30 fps)."""
    stage: ClassVar[Literal["delay"]] = "delay"

    def __post_init__(self) -> None:
        check_non_negative_int("frames", self.frames)

    def delays(self, rng: np.random.Generator, n: int) -> I64:
        """(n,) int64 delays [frames] (``rng`` unused: fixed)."""
        return np.full(n, self.frames, dtype=np.int64)

    def mean_frames(self) -> float:
        """Expected delay [frames]."""
        return float(self.frames)

    def describe(self) -> str:
        return f"delay {self.frames} frames"


@dataclass(frozen=True, slots=True, kw_only=True)
class UniformDelay:
    """Delay drawn uniformly from the integers ``min_frames .. max_frames`` (inclusive)."""

    kind: Literal["uniform_delay"] = "uniform_delay"
    min_frames: int = 0
    """Smallest delay [frames], >= 0."""
    max_frames: int = 0
    """Largest delay [frames], >= min_frames."""
    stage: ClassVar[Literal["delay"]] = "delay"

    def __post_init__(self) -> None:
        check_int_range("min_frames", self.min_frames, "max_frames", self.max_frames, minimum=0)

    def delays(self, rng: np.random.Generator, n: int) -> I64:
        """(n,) int64 delays [frames]."""
        return rng.integers(self.min_frames, self.max_frames, size=n, endpoint=True).astype(
            np.int64
        )

    def mean_frames(self) -> float:
        return 0.5 * (self.min_frames + self.max_frames)

    def describe(self) -> str:
        return f"delay uniform {self.min_frames}..{self.max_frames} frames"


@dataclass(frozen=True, slots=True, kw_only=True)
class LogNormalDelay:
    """Log-normal delay: ``ceil(median_frames * exp(sigma * N(0, 1)))``, clipped to
    ``[min_frames, max_frames]``.

    A heavy right tail: most results come near the median, a few very late (a network that
    sometimes stalls).
    """

    kind: Literal["lognormal_delay"] = "lognormal_delay"
    median_frames: float = 6.0
    """Median of the continuous delay [frames], > 0."""
    sigma: float = 0.3
    """Standard deviation of the log of the delay [-], >= 0 (0 = fixed at ceil(median))."""
    min_frames: int = 0
    """Lower clip [frames]."""
    max_frames: int | None = None
    """Upper clip [frames]; None = no clip."""
    stage: ClassVar[Literal["delay"]] = "delay"

    def __post_init__(self) -> None:
        check_positive_finite("median_frames", self.median_frames)
        check_positive_finite("sigma", self.sigma, allow_zero=True)
        check_non_negative_int("min_frames", self.min_frames)
        if self.max_frames is not None:
            check_int_range("min_frames", self.min_frames, "max_frames", self.max_frames, minimum=0)

    def delays(self, rng: np.random.Generator, n: int) -> I64:
        """(n,) int64 delays [frames]."""
        continuous = self.median_frames * np.exp(self.sigma * rng.standard_normal(n))
        # ceil of a value within float noise of an integer is that integer (median 6, sigma 0)
        d = np.ceil(continuous - 1e-9).astype(np.int64)
        hi = np.iinfo(np.int64).max if self.max_frames is None else self.max_frames
        return np.clip(d, self.min_frames, hi)

    def mean_frames(self) -> float:
        """Mean of the continuous (unrounded, unclipped) delay [frames]."""
        return self.median_frames * math.exp(0.5 * self.sigma**2)

    def describe(self) -> str:
        clip = f", clipped to [{self.min_frames}, {self.max_frames}]" if self.max_frames else ""
        return f"delay log-normal median {self.median_frames:g} frames sigma {self.sigma:g}{clip}"


@dataclass(frozen=True, slots=True, kw_only=True)
class EmpiricalDelay:
    """Delay drawn from a measured histogram: ``frames[i]`` with probability ``weights[i]``."""

    kind: Literal["empirical_delay"] = "empirical_delay"
    frames: tuple[int, ...] = (0,)
    """Possible delays [frames], each >= 0 (e.g. measured network latencies, rounded up)."""
    weights: tuple[float, ...] | None = None
    """Relative frequency of each delay (normalised here); None = all equally likely."""
    stage: ClassVar[Literal["delay"]] = "delay"

    def __post_init__(self) -> None:
        if not self.frames:
            raise ConfigError("frames must list at least one delay, e.g. frames = [5, 6, 6, 7]")
        for i, f in enumerate(self.frames):
            check_non_negative_int(f"frames[{i}]", f)
        if self.weights is not None:
            if len(self.weights) != len(self.frames):
                raise ConfigError(
                    f"weights has {len(self.weights)} entries for {len(self.frames)} frames; "
                    "give one weight per delay or leave weights out"
                )
            w = np.asarray(self.weights, dtype=np.float64)
            if not (np.isfinite(w).all() and (w >= 0).all() and w.sum() > 0):
                raise ConfigError(f"weights must be finite, >= 0 and not all 0, got {self.weights}")

    def _p(self) -> F64 | None:
        if self.weights is None:
            return None
        w = np.asarray(self.weights, dtype=np.float64)
        return w / float(w.sum())

    def delays(self, rng: np.random.Generator, n: int) -> I64:
        """(n,) int64 delays [frames]."""
        return rng.choice(np.asarray(self.frames, dtype=np.int64), size=n, p=self._p())

    def mean_frames(self) -> float:
        p = self._p()
        f = np.asarray(self.frames, dtype=np.float64)
        return float(f.mean() if p is None else (f * p).sum())

    def describe(self) -> str:
        return f"delay empirical over {list(self.frames)} frames"


DelayDistribution = FixedDelay | UniformDelay | LogNormalDelay | EmpiricalDelay
"""Any delay model; also the processing-time model of :class:`BusyNetwork`."""


# ---------------------------------------------------------------- sampling


@dataclass(frozen=True, slots=True, kw_only=True)
class Rate:
    """The network runs on every ``period_frames``-th camera frame, starting at ``phase_frames``.

    Give either ``period_frames`` or ``rate_hz`` (an integer that divides the camera rate: 5 Hz on
    a 30 fps camera is every 6th frame).
    """

    kind: Literal["rate"] = "rate"
    period_frames: int | None = None
    """Frames between two network runs, >= 1."""
    rate_hz: int | None = None
    """Network rate [Hz]; must divide the camera fps (checked when the stream is built)."""
    phase_frames: int = 0
    """First frame the network runs on, >= 0."""
    stage: ClassVar[Literal["sampling"]] = "sampling"

    def __post_init__(self) -> None:
        if (self.period_frames is None) == (self.rate_hz is None):
            raise ConfigError(
                "rate needs exactly one of period_frames or rate_hz, got "
                f"period_frames={self.period_frames}, rate_hz={self.rate_hz}; "
                "e.g. rate_hz = 5 (every 6th frame at 30 fps)"
            )
        if self.period_frames is not None and self.period_frames < 1:
            raise ConfigError(f"period_frames must be >= 1, got {self.period_frames}")
        if self.rate_hz is not None and self.rate_hz < 1:
            raise ConfigError(f"rate_hz must be >= 1, got {self.rate_hz}")
        check_non_negative_int("phase_frames", self.phase_frames)

    def period(self, fps: int) -> int:
        """Frames between runs at camera rate ``fps`` [Hz].

        Raises:
            ConfigError: ``rate_hz`` does not divide ``fps``.
        """
        if self.period_frames is not None:
            return self.period_frames
        rate_hz = int(self.rate_hz or 0)  # __post_init__ guarantees one of the two is set
        if fps % rate_hz:
            divisors = [d for d in range(1, fps + 1) if fps % d == 0]
            raise ConfigError(
                f"rate_hz = {rate_hz} does not divide the camera rate {fps} fps; use one of "
                f"{divisors} or give period_frames instead"
            )
        return fps // rate_hz

    def sample(self, n_frames: int, fps: int, rng: np.random.Generator) -> tuple[I64, I64]:
        """Capture frames ``(R,)`` of the network runs and their processing delays ``(R,)`` (0)."""
        captures = np.arange(self.phase_frames, n_frames, self.period(fps), dtype=np.int64)
        return captures, np.zeros_like(captures)

    def describe(self) -> str:
        what = (
            f"every {self.period_frames} frames"
            if self.period_frames is not None
            else f"{self.rate_hz} Hz"
        )
        return f"runs at {what}" + (f" from frame {self.phase_frames}" if self.phase_frames else "")


@dataclass(frozen=True, slots=True, kw_only=True)
class BusyNetwork:
    """A network that takes ``processing`` frames per result and skips frames while busy.

    It starts on frame ``phase_frames``; the result of the run on frame c is ready ``d`` frames
    later (``d`` drawn from ``processing``), and the network then takes the newest frame, c + d
    (c + 1 if d = 0). The processing time is part of the result's delay (further ``delay``
    faults add transport latency on top). ``processing = {kind = "delay", frames = 6}`` gives
    exactly the reference setting: runs on 0, 6, 12, ..., each result 6 frames late.
    """

    kind: Literal["busy"] = "busy"
    processing: DelayDistribution
    """Processing time per run [frames] (any delay model)."""
    phase_frames: int = 0
    """First frame the network runs on, >= 0."""
    stage: ClassVar[Literal["sampling"]] = "sampling"

    def __post_init__(self) -> None:
        check_non_negative_int("phase_frames", self.phase_frames)

    def sample(self, n_frames: int, fps: int, rng: np.random.Generator) -> tuple[I64, I64]:
        """Capture frames ``(R,)`` of the runs and their processing times ``(R,)`` [frames]."""
        # At most n_frames runs; draw them all at once so the draws never depend on n_frames'
        # position in a loop (same rng -> same processing time for run i).
        processing = self.processing.delays(rng, max(n_frames, 1))
        captures: list[int] = []
        c = self.phase_frames
        i = 0
        while c < n_frames:
            captures.append(c)
            c += max(int(processing[i]), 1)
            i += 1
        return np.asarray(captures, dtype=np.int64), processing[:i].copy()

    def describe(self) -> str:
        return f"busy network, processing {self.processing.describe().removeprefix('delay ')}"


# ---------------------------------------------------------------- stamp


@dataclass(frozen=True, slots=True, kw_only=True)
class ClockSkew:
    """Time-stamp error between the network's clock and the camera's: changes the REPORTED
    capture frame, never the true one or the arrival.

    ``reported = round(true + offset_frames + drift * true + N(0, noise_sd_frames))``, clipped
    at 0. Several skews in one stream add up before the rounding.
    """

    kind: Literal["clock_skew"] = "clock_skew"
    offset_frames: float = 0.0
    """Constant clock offset [frames] (positive: the network claims a later frame)."""
    drift: float = 0.0
    """Relative clock-rate error [-] (0.01: the network's clock runs 1 % fast)."""
    noise_sd_frames: float = 0.0
    """Standard deviation of per-result time-stamp noise [frames], >= 0."""
    stage: ClassVar[Literal["stamp"]] = "stamp"

    def __post_init__(self) -> None:
        for name in ("offset_frames", "drift"):
            if not math.isfinite(getattr(self, name)):
                raise ConfigError(f"{name} must be finite, got {getattr(self, name)!r}")
        check_positive_finite("noise_sd_frames", self.noise_sd_frames, allow_zero=True)

    def offsets(self, capture_k: I64, rng: np.random.Generator) -> F64:
        """(R,) time-stamp errors [frames, float] for runs captured at ``capture_k`` ``(R,)``."""
        noise = rng.standard_normal(capture_k.shape[0]) * self.noise_sd_frames
        return self.offset_frames + self.drift * capture_k.astype(np.float64) + noise

    def describe(self) -> str:
        return (
            f"clock skew offset {self.offset_frames:g} frames, drift {self.drift:g}, "
            f"noise sd {self.noise_sd_frames:g} frames"
        )
