"""Loss faults: which results (or camera frames) never reach the tracker.

Each loss fault returns a drop mask over ALL candidate items of its stream (the network runs of
a detection stream, or the camera frames), computed from its own ``rng`` alone. A stream drops
the union of the masks, so loss faults commute and compose associatively, and adding one leaves
the others' decisions unchanged.

- :class:`BernoulliDropout`: each item lost independently with probability ``p``.
- :class:`GilbertElliott`: two-state Markov bursts (the standard network-loss model).
- :class:`Blackout`: everything in given frame windows (by capture frame, or by arrival frame in
  the delivery stage, where lost results may also be held back instead).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.faults.checks import check_probability, check_windows

I64 = NDArray[np.int64]
Bool = NDArray[np.bool_]

__all__ = ["BernoulliDropout", "GilbertElliott", "Blackout", "gilbert_elliott_states"]


@dataclass(frozen=True, slots=True, kw_only=True)
class BernoulliDropout:
    """Each result (or camera frame) is lost independently with probability ``p``."""

    kind: Literal["dropout"] = "dropout"
    p: float = 0.1
    """Loss probability per item [-]."""
    stage: ClassVar[Literal["loss"]] = "loss"

    def __post_init__(self) -> None:
        check_probability("p", self.p)

    def dropped(self, capture_k: I64, rng: np.random.Generator) -> Bool:
        """(R,) bool: True for the lost items among ``capture_k`` ``(R,)`` (in capture order)."""
        return rng.random(len(capture_k)) < self.p

    def describe(self) -> str:
        return f"dropout p={self.p:g}"


def gilbert_elliott_states(
    n: int, p_good_to_bad: float, p_bad_to_good: float, rng: np.random.Generator
) -> Bool:
    """(n,) bool states of a two-state Markov chain, True = bad, started from its stationary law.

    Sojourns are drawn as geometric run lengths (exact for the chain, vectorised): a bad sojourn
    lasts ``Geom(p_bad_to_good)`` steps (mean ``1 / p_bad_to_good``), a good one
    ``Geom(p_good_to_bad)`` steps.
    """
    if n == 0:
        return np.zeros(0, dtype=bool)
    pi_bad = p_good_to_bad / (p_good_to_bad + p_bad_to_good)
    bad = bool(rng.random() < pi_bad)
    states = np.empty(n, dtype=bool)
    filled = 0
    while filled < n:
        # Draw a batch of alternating sojourns starting in the current state, about enough to
        # fill what is left (the mean cycle is 1/p_gb + 1/p_bg steps).
        cycle = 1.0 / max(p_good_to_bad, 1e-9) + 1.0 / p_bad_to_good
        m = int(min(max((n - filled) / cycle * 1.2, 16), 1 << 20))
        p_first, p_second = (
            (p_bad_to_good, p_good_to_bad) if bad else (p_good_to_bad, p_bad_to_good)
        )
        lengths = np.empty(2 * m, dtype=np.int64)
        lengths[0::2] = _geometric(rng, p_first, m)
        lengths[1::2] = _geometric(rng, p_second, m)
        need = n - filled
        ends = np.cumsum(np.minimum(lengths, need))
        used = int(np.searchsorted(ends, need)) + 1  # sojourns that reach the end (or all)
        used = min(used, 2 * m)
        flags = np.tile(np.array([bad, not bad]), m)[:used]
        run = np.repeat(flags, np.minimum(lengths[:used], need))[:need]
        states[filled : filled + run.shape[0]] = run
        filled += run.shape[0]
    return states


def _geometric(rng: np.random.Generator, p: float, m: int) -> I64:
    """(m,) run lengths >= 1 with success probability ``p``; p = 0 means "forever"."""
    if p <= 0.0:
        return np.full(m, np.iinfo(np.int32).max, dtype=np.int64)
    return rng.geometric(p, size=m).astype(np.int64)


@dataclass(frozen=True, slots=True, kw_only=True)
class GilbertElliott:
    """Gilbert-Elliott bursty loss: a good and a bad state, with loss probabilities
    ``loss_in_good`` and ``loss_in_bad``.

    The chain steps once per item (per network run, or per camera frame). With the defaults
    (lose everything in the bad state, nothing in the good one) a burst of losses is exactly one
    bad sojourn: mean burst length ``1 / p_bad_to_good`` items, mean loss rate
    ``p_good_to_bad / (p_good_to_bad + p_bad_to_good)``.
    """

    kind: Literal["burst_dropout"] = "burst_dropout"
    p_good_to_bad: float = 0.05
    """Probability per item of entering the bad state [-]."""
    p_bad_to_good: float = 0.5
    """Probability per item of leaving the bad state [-], > 0 (bursts must end)."""
    loss_in_bad: float = 1.0
    """Loss probability in the bad state [-]."""
    loss_in_good: float = 0.0
    """Loss probability in the good state [-]."""
    stage: ClassVar[Literal["loss"]] = "loss"

    def __post_init__(self) -> None:
        for name in ("p_good_to_bad", "p_bad_to_good", "loss_in_bad", "loss_in_good"):
            check_probability(name, getattr(self, name))
        if self.p_bad_to_good <= 0.0:
            raise ConfigError(
                "p_bad_to_good must be > 0, or a burst never ends; mean burst length is "
                "1 / p_bad_to_good items (e.g. 0.25 for bursts of 4)"
            )

    @property
    def mean_burst_length(self) -> float:
        """Mean number of consecutive items in the bad state, ``1 / p_bad_to_good``."""
        return 1.0 / self.p_bad_to_good

    @property
    def loss_rate(self) -> float:
        """Long-run fraction of items lost."""
        pi_bad = self.p_good_to_bad / (self.p_good_to_bad + self.p_bad_to_good)
        return pi_bad * self.loss_in_bad + (1.0 - pi_bad) * self.loss_in_good

    def dropped(self, capture_k: I64, rng: np.random.Generator) -> Bool:
        """(R,) bool: True for lost items; the chain steps over ``capture_k`` in order."""
        n = capture_k.shape[0]
        bad = gilbert_elliott_states(n, self.p_good_to_bad, self.p_bad_to_good, rng)
        u = rng.random(n)
        return np.where(bad, u < self.loss_in_bad, u < self.loss_in_good)

    def describe(self) -> str:
        return (
            f"burst dropout: mean burst {self.mean_burst_length:.3g} items, "
            f"loss rate {self.loss_rate:.3g}"
        )


@dataclass(frozen=True, slots=True, kw_only=True)
class Blackout:
    """Nothing gets through during the frame windows ``[start, stop)``.

    ``on = "capture"``: results captured in a window are lost (the network or the camera is
    down). ``on = "arrival"``: results that would ARRIVE in a window are lost (``mode = "drop"``)
    or held and delivered together at the window's end (``mode = "hold"``, a link that buffers).
    For camera frames, capture and arrival coincide and ``mode`` must be ``drop``.
    """

    kind: Literal["blackout"] = "blackout"
    windows: tuple[tuple[int, int], ...] = ()
    """Frame windows ``[start, stop)`` [frames]."""
    on: Literal["capture", "arrival"] = "capture"
    """Which frame of a result the windows apply to."""
    mode: Literal["drop", "hold"] = "drop"
    """What happens to a result arriving in a window (``hold`` needs ``on = "arrival"``)."""

    def __post_init__(self) -> None:
        check_windows("windows", self.windows)
        if self.mode == "hold" and self.on != "arrival":
            raise ConfigError(
                'mode = "hold" delays results that would arrive in a window, so it needs '
                'on = "arrival"; set on = "arrival" or mode = "drop"'
            )

    @property
    def stage(self) -> Literal["loss", "delivery"]:
        """``loss`` when on capture frames, ``delivery`` when on arrival frames."""
        return "loss" if self.on == "capture" else "delivery"

    def in_window(self, k: I64) -> Bool:
        """(R,) bool: True where frame ``k`` ``(R,)`` lies in a window."""
        out = np.zeros(k.shape, dtype=bool)
        for start, stop in self.windows:
            out |= (k >= start) & (k < stop)
        return out

    def window_end(self, k: int) -> int:
        """First frame >= ``k`` outside every window (``k`` itself if it is in none)."""
        moved = True
        while moved:
            moved = False
            for start, stop in self.windows:
                if start <= k < stop:
                    k, moved = stop, True
        return k

    def dropped(self, capture_k: I64, rng: np.random.Generator) -> Bool:
        """(R,) bool: True for items captured inside a window (``rng`` unused)."""
        return self.in_window(capture_k)

    def describe(self) -> str:
        spans = ", ".join(f"[{a}, {b})" for a, b in self.windows) or "none"
        verb = "held until the end" if self.mode == "hold" else "lost"
        return f"blackout on {self.on} frames {spans}: {verb}"
