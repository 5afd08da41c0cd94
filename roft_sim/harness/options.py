"""What one harness run does: the tracker, the inputs it gets, the faults, the seed.

:class:`RunOptions` is the resolved configuration of ``roft-sim run`` (and of every cell of a
sweep): which tracker with which settings, under which fault configuration, fed from which
detector pose set, mask set and flow source, started how, with which seed. It is written to
``run.json`` beside the results (``jsonable(options)``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

from roft_sim.errors import ConfigError
from roft_sim.faults import FaultConfig, load_faults
from roft_sim.harness.robust_start import RobustStartConfig
from roft_sim.metrics import INVALID_POLICIES, InvalidPolicy

__all__ = [
    "RunOptions",
    "InitPolicy",
    "AUTO",
    "GT_SET",
    "NO_SET",
    "INIT_POLICIES",
    "PAPER_INVALID",
    "default_invalid_policy",
]

AUTO = "auto"
"""Pick the input automatically (see each field of :class:`RunOptions`)."""
GT_SET = "gt"
"""The ground-truth pose or mask set: an ablation input, fed by the harness."""
NO_SET = "none"
"""No input of that kind (no pose detections, no masks, no flow)."""

PAPER_INVALID: InvalidPolicy = "hold"
"""The invalid-estimate policy of the ``paper`` fault preset: the reference's (docs/metrics.md)."""


def default_invalid_policy(faults_name: str) -> InvalidPolicy:
    """The default invalid-estimate policy under a fault configuration: :data:`PAPER_INVALID`
    under the ``paper`` preset (the reference's setting), ``failure`` (ours) otherwise."""
    return PAPER_INVALID if faults_name == "paper" else "failure"


InitPolicy = Literal["first-detection", "robust", "gt"]
INIT_POLICIES: tuple[str, ...] = get_args(InitPolicy)


@dataclass(frozen=True, slots=True, kw_only=True)
class RunOptions:
    """The resolved configuration of one run of one tracker (every sequence gets the same)."""

    tracker: str
    """Registry name of the tracker (``roft-sim trackers``)."""
    tracker_config: Any = None
    """An instance of the tracker's config dataclass; None = its defaults."""
    faults: FaultConfig = field(default_factory=lambda: load_faults("paper"))
    """The fault configuration (a preset such as ``paper`` or a fault file, loaded)."""
    flow: str = AUTO
    """Flow source spec (``gt``, ``gt+noise``, ``dis[:preset]``, ``bm``, ``nvof-like:<inner>``,
    ``stored:<set>``), ``none`` for no flow, or ``auto``: the sequence's stored
    ``nvof_1_slow`` set, else its first stored set other than ``gt``, else ``dis``."""
    poses: str = AUTO
    """Detector pose set: a set name of the sequence, ``gt`` (ground-truth poses as
    detections: the "GT pose" ablation; taken from the sequence's ground truth when it stores no
    ``gt`` set), ``none``, ``auto`` (``dope`` when present, else the first set other than
    ``gt``), or ``redraw:<k>`` (the DOPE-like estimator drawn again with seed k on the ground
    truth: :mod:`roft_sim.harness.pose_sets`)."""
    masks: str = AUTO
    """Mask set: a set name, ``gt`` (ground-truth visible masks: the "GT segm." ablation),
    ``none``, or ``auto`` (the first detector set)."""
    init: InitPolicy = "first-detection"
    """``first-detection``: the tracker starts from the first pose that arrives (the reference's
    behaviour); ``robust``: from the first pose that passes the depth-rendering test against
    the measured depth (earlier ones are held back, :mod:`roft_sim.harness.robust_start`);
    ``gt``: ``reset`` gets the ground-truth pose and velocity of frame 0."""
    robust_start: RobustStartConfig = field(default_factory=RobustStartConfig)
    """Settings of the ``robust`` start's consistency test (unused by the other policies)."""
    seed: int = 0
    """The run's seed; each sequence derives its own ``SeedSequence`` from it and its name."""
    include_rgb: bool = True
    """Hand rgb images to the tracker (False saves reading them for trackers that ignore them;
    a flow source that needs rgb, e.g. DIS, reads them itself)."""
    invalid: InvalidPolicy = "failure"
    """How frames without a tracker pose (``Estimate.valid`` False) are scored
    (docs/metrics.md): ``failure``, ``exclude``, ``as_given`` or ``hold`` (the reference's
    treatment of its DOPE row; ``roft-sim run`` picks it under the ``paper`` faults)."""

    def __post_init__(self) -> None:
        if not self.tracker:
            raise ConfigError("no tracker given; pass --tracker NAME (see roft-sim trackers)")
        if self.init not in INIT_POLICIES:
            raise ConfigError(
                f"unknown init policy {self.init!r}; expected one of {', '.join(INIT_POLICIES)}"
            )
        if self.invalid not in INVALID_POLICIES:
            raise ConfigError(
                f"unknown invalid-estimate policy {self.invalid!r}; expected one of "
                f"{', '.join(INVALID_POLICIES)}"
            )
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ConfigError(f"seed must be an integer >= 0, got {self.seed!r}")
        for name in ("flow", "poses", "masks"):
            value = getattr(self, name)
            if not isinstance(value, str) or not value.strip():
                raise ConfigError(f"{name} must be a non-empty string, got {value!r}")

    def replace(self, **changes: Any) -> RunOptions:
        """A copy with ``changes`` applied (validated again)."""
        return dataclasses.replace(self, **changes)
