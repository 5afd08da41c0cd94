"""Delivery faults: duplicates, stale re-deliveries and reordering between network and tracker.

They act on the list of deliveries of one stream, in delivery order, after the delays, and in
the order they are listed (where it matters: a duplicate of a reordered result is reordered
too only if ``reorder`` comes first). :class:`~roft_sim.faults.loss.Blackout` with
``on = "arrival"`` is also a delivery fault.

``deliver(events, rng, n_runs)`` returns the new delivery list (sorted by arrival frame, then
delivery order) and the detections it removed (id -> reason). All random draws are made per
network run (``n_runs`` values), so a run's fate does not depend on the other runs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar, Literal

import numpy as np

from roft_sim.faults.checks import check_int_range, check_probability
from roft_sim.faults.events import DeliveryEvent
from roft_sim.faults.loss import Blackout

__all__ = ["Duplicate", "Stale", "Reorder", "apply_blackout_on_arrival", "sort_deliveries"]

Keyed = list[tuple[DeliveryEvent, float]]


def sort_deliveries(keyed: Keyed) -> list[DeliveryEvent]:
    """Events sorted by arrival frame, then by key (stable)."""
    return [e for e, _ in sorted(keyed, key=lambda ek: (ek[0].arrival_k, ek[1]))]


@dataclass(frozen=True, slots=True, kw_only=True)
class Duplicate:
    """With probability ``p``, a result is delivered a second time, ``min_after_frames ..
    max_after_frames`` frames after its first delivery (same ``detection_id``)."""

    kind: Literal["duplicate"] = "duplicate"
    p: float = 0.1
    """Probability per result [-]."""
    min_after_frames: int = 0
    """Earliest second delivery, frames after the first [frames] (0 = the same frame, right
    after it)."""
    max_after_frames: int = 0
    """Latest second delivery [frames]."""
    stage: ClassVar[Literal["delivery"]] = "delivery"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        check_int_range(
            "min_after_frames",
            self.min_after_frames,
            "max_after_frames",
            self.max_after_frames,
            minimum=0,
        )

    def deliver(
        self, events: list[DeliveryEvent], rng: np.random.Generator, n_runs: int
    ) -> tuple[list[DeliveryEvent], dict[int, str]]:
        hit = rng.random(n_runs) < self.p
        after = rng.integers(self.min_after_frames, self.max_after_frames, n_runs, endpoint=True)
        m = len(events)
        keyed: Keyed = [(e, float(i)) for i, e in enumerate(events)]
        for i, e in enumerate(events):
            if e.copy != "duplicate" and hit[e.detection_id]:
                a = int(after[e.detection_id])
                copy = dataclasses.replace(e, arrival_k=e.arrival_k + a, copy="duplicate")
                # Same frame: right after the original; later frame: after that frame's others.
                keyed.append((copy, i + 0.5 if a == 0 else m + i))
        return sort_deliveries(keyed), {}

    def describe(self) -> str:
        when = (
            "same frame"
            if self.max_after_frames == 0
            else f"{self.min_after_frames}..{self.max_after_frames} frames later"
        )
        return f"duplicate ({when}), p={self.p:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class Stale:
    """With probability ``p``, a result is replaced by the previous delivery of its stream: the
    old detection (its id, capture frame and content) arrives again in its place, and the new
    one is lost (a network that re-sends its last output)."""

    kind: Literal["stale"] = "stale"
    p: float = 0.1
    """Probability per result [-]."""
    stage: ClassVar[Literal["delivery"]] = "delivery"

    def __post_init__(self) -> None:
        check_probability("p", self.p)

    def deliver(
        self, events: list[DeliveryEvent], rng: np.random.Generator, n_runs: int
    ) -> tuple[list[DeliveryEvent], dict[int, str]]:
        hit = rng.random(n_runs) < self.p
        out: list[DeliveryEvent] = []
        removed: dict[int, str] = {}
        for i, e in enumerate(events):
            if i > 0 and e.copy == "original" and hit[e.detection_id]:
                previous = out[-1]  # what the tracker received last (maybe itself stale)
                out.append(dataclasses.replace(previous, arrival_k=e.arrival_k, copy="stale"))
                removed[e.detection_id] = "superseded"
            else:
                out.append(e)
        return out, removed

    def describe(self) -> str:
        return f"stale re-delivery, p={self.p:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class Reorder:
    """With probability ``p``, a result is held back until ``past_events`` later results that
    are not held themselves have been delivered, and then delivered right after the last of
    them (at its frame): it arrives out of order. A held result that nothing overtakes before
    the stream ends keeps its place (so ``p = 1`` holds nothing back)."""

    kind: Literal["reorder"] = "reorder"
    p: float = 0.1
    """Probability per result [-]."""
    past_events: int = 1
    """How many later (not held) deliveries overtake it, >= 1."""
    stage: ClassVar[Literal["delivery"]] = "delivery"

    def __post_init__(self) -> None:
        check_probability("p", self.p)
        check_int_range("past_events", self.past_events, "past_events", self.past_events, minimum=1)

    def deliver(
        self, events: list[DeliveryEvent], rng: np.random.Generator, n_runs: int
    ) -> tuple[list[DeliveryEvent], dict[int, str]]:
        hit = rng.random(n_runs) < self.p
        out: list[DeliveryEvent] = []
        held: list[tuple[DeliveryEvent, int]] = []  # (result, overtakes still to come)
        for e in events:
            if e.copy == "original" and hit[e.detection_id]:
                held.append((e, self.past_events))
                continue
            out.append(e)
            held = [(h, left - 1) for h, left in held]
            out += [dataclasses.replace(h, arrival_k=e.arrival_k) for h, left in held if left == 0]
            held = [(h, left) for h, left in held if left > 0]
        # Not overtaken often enough before the end: delivered in order after everything else.
        for h, _ in held:
            last = out[-1].arrival_k if out else h.arrival_k
            out.append(dataclasses.replace(h, arrival_k=max(h.arrival_k, last)))
        return out, {}

    def describe(self) -> str:
        return f"reorder: held behind {self.past_events} later result(s), p={self.p:g}"


def apply_blackout_on_arrival(
    blackout: Blackout, events: list[DeliveryEvent]
) -> tuple[list[DeliveryEvent], dict[int, str]]:
    """Drops (or holds until the window ends) the deliveries arriving inside a window."""
    keyed: Keyed = []
    removed: dict[int, str] = {}
    for i, e in enumerate(events):
        end = blackout.window_end(e.arrival_k)
        if end == e.arrival_k:
            keyed.append((e, float(i)))
        elif blackout.mode == "hold":
            keyed.append((dataclasses.replace(e, arrival_k=end), float(i)))
        else:
            removed[e.detection_id] = "dropped"
    return sort_deliveries(keyed), removed
