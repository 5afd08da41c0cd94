"""The records of a fault schedule: what was injected, and what each detection went through.

- :class:`Corruption`: one content fault drawn for one detection (or one camera frame).
- :class:`DeliveryEvent`: one delivery of a detection to the tracker (a duplicated detection has
  several).
- :class:`DetectionRecord`: the fate of one network run (delivered, missed, dropped, ...), for
  the harness and the metrics. It names the true capture frame, which a tracker never sees.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Literal

from roft_sim.faults.content import MASK_CORRUPTION_KINDS, POSE_OUTLIER_KINDS

__all__ = [
    "StreamName",
    "Corruption",
    "DeliveryEvent",
    "DetectionRecord",
    "Fate",
    "CopyKind",
]

StreamName = Literal["pose", "mask"]
"""Detection streams."""
Fate = Literal["delivered", "missed", "dropped", "superseded", "after_end"]
"""What became of one network run:

- ``delivered``: at least one delivery reached the tracker within the sequence;
- ``missed``: the dataset's detector found nothing on that frame (no fault involved);
- ``dropped``: a loss fault (dropout, burst, blackout) removed it;
- ``superseded``: a stale re-delivery of an older result took its place;
- ``after_end``: its (delayed) arrival falls after the last camera frame.
"""
CopyKind = Literal["original", "duplicate", "stale", "repeat"]
"""Why a delivery happens: the detection's own delivery, a duplicate of it, a stale
re-delivery (in place of a newer result), or the reference's second delivery of the first result
(``first_result = "undelayed_and_delayed"``)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class Corruption:
    """One content fault drawn for one detection or camera frame."""

    source: str
    """Where the fault is configured, e.g. ``pose.faults[2]``."""
    kind: str
    """The fault's ``kind``, e.g. ``rotation_flip``."""
    params: Mapping[str, Any] = field(default_factory=dict)
    """The drawn parameters (e.g. ``{"axis": "z"}``), enough to reproduce the corruption."""

    def describe(self) -> str:
        """Compact text, e.g. ``rotation_flip(axis=z)``."""
        shown = {k: v for k, v in self.params.items() if k != "seed"}
        inner = ", ".join(f"{k}={_short(v)}" for k, v in shown.items())
        return f"{self.kind}({inner})" if inner else self.kind


def _short(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.3g}"
    if isinstance(v, tuple):
        return "(" + ", ".join(_short(x) for x in v) + ")"
    return str(v)


@dataclass(frozen=True, slots=True, kw_only=True)
class DeliveryEvent:
    """One delivery of a detection to the tracker."""

    stream: StreamName
    """``pose`` or ``mask``."""
    detection_id: int
    """Index of the network run within its stream (0, 1, 2, ... in capture order); kept by
    duplicates and re-deliveries. A network can know this number, so it is no ground truth."""
    true_capture_k: int
    """Camera frame the result was really computed on (ground truth: never shown to trackers)."""
    reported_capture_k: int
    """Camera frame the result claims (differs from the true one under clock skew)."""
    arrival_k: int
    """Camera frame at which it reaches the tracker."""
    copy: CopyKind = "original"
    """Why this delivery happens (see :data:`CopyKind`)."""
    corruptions: tuple[Corruption, ...] = ()
    """Content faults applied to this detection, in order."""

    @property
    def delay_frames(self) -> int:
        """``arrival_k - true_capture_k`` [frames]."""
        return self.arrival_k - self.true_capture_k

    @property
    def is_outlier(self) -> bool:
        """True when an outlier-pose fault changed this pose."""
        return any(c.kind in POSE_OUTLIER_KINDS for c in self.corruptions)

    @property
    def is_corrupted(self) -> bool:
        """True when any content fault changed this detection."""
        return bool(self.corruptions)


@dataclass(frozen=True, slots=True, kw_only=True)
class DetectionRecord:
    """The fate of one network run, for the harness and the metrics."""

    stream: StreamName
    """``pose`` or ``mask``."""
    detection_id: int
    """Index of the run in its stream (the ``detection_id`` of its deliveries)."""
    true_capture_k: int
    """Camera frame the network ran on."""
    reported_capture_k: int
    """Camera frame its result claims."""
    fate: Fate
    """What became of it (see :data:`Fate`)."""
    cause: str | None = None
    """The fault responsible for a ``dropped`` or ``superseded`` fate, e.g.
    ``pose.faults[1] (dropout)``; None otherwise."""
    arrivals: tuple[int, ...] = ()
    """Frames at which this detection reached the tracker (several with duplicates)."""
    copies: tuple[CopyKind, ...] = ()
    """The kind of each delivery in ``arrivals``."""
    corruptions: tuple[Corruption, ...] = ()
    """Content faults drawn for it (also recorded when it was never delivered)."""

    @property
    def is_outlier(self) -> bool:
        """True when an outlier-pose fault was injected into this pose."""
        return any(c.kind in POSE_OUTLIER_KINDS for c in self.corruptions)

    @property
    def is_mask_corrupted(self) -> bool:
        """True when a mask-corruption fault was injected into this mask."""
        return any(c.kind in MASK_CORRUPTION_KINDS for c in self.corruptions)

    @property
    def delivered(self) -> bool:
        return self.fate == "delivered"
