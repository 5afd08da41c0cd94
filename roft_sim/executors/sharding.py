"""Sharding: split a run's work units among N independent jobs (``--shard i/N``).

A cluster scheduler (a Slurm array job, a Kubernetes indexed job, N shell loops) starts the SAME
command N times with ``--shard 1/N`` ... ``--shard N/N``; each job runs only its units, into the
same output folder on a shared filesystem. No job talks to another, so the assignment must be a
pure function of the units and (i, N), identical on every machine and in every rerun:

1. every unit has a unique, stable sort key (generation: ``(sequence name, first frame)`` of the
   FULL plan, i.e. of every frame, not only of the frames still missing; sweeps: the cell id,
   a hash of the cell's resolved configuration);
2. the units are sorted by that key, and unit number ``p`` of the sorted list (0-based) of ``T``
   goes to shard ``p * N // T`` (``layout="blocks"``: N contiguous runs whose sizes differ by at
   most one; generation, so a shard's frame chunks are mostly of one sequence and a worker keeps
   its renderer) or to shard ``p mod N`` (``layout="round-robin"``; sweeps, so the slow and fast
   trackers' cells spread evenly).

What a shard finds already finished on disk it skips, so a failed shard is rerun by running the
same command again. Shards never finalize shared outputs (a generated sequence, a sweep summary):
a final run without ``--shard`` does, once every shard has finished.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal, TypeVar

from roft_sim.errors import ConfigError

__all__ = ["Shard", "parse_shard", "select_shard", "shard_positions", "SHARD_LAYOUTS"]

U = TypeVar("U")

SHARD_LAYOUTS = ("blocks", "round-robin")
"""How sorted units are dealt to shards (see the module doc)."""

_SHARD = re.compile(r"^\s*(-?\d+)\s*/\s*(-?\d+)\s*$")


@dataclass(frozen=True, slots=True)
class Shard:
    """Shard ``index`` (0-based) of ``count``; written ``i/N`` with 1-based ``i = index + 1``."""

    index: int
    """0-based shard number, ``0 <= index < count``."""
    count: int
    """Number of shards (>= 1)."""

    def __post_init__(self) -> None:
        if self.count < 1 or not 0 <= self.index < self.count:
            raise ConfigError(
                f"shard index {self.index} of {self.count}: need count >= 1 and 0 <= index < count"
            )

    def __str__(self) -> str:
        return f"{self.index + 1}/{self.count}"

    @classmethod
    def parse(cls, text: str) -> Shard:
        """``"i/N"`` as a user writes it (1-based: ``1/4`` ... ``4/4``) -> ``Shard(i - 1, N)``.

        Raises:
            ConfigError: not ``i/N`` with whole numbers ``1 <= i <= N``.
        """
        m = _SHARD.match(text)
        if m is None:
            raise ConfigError(
                f"--shard {text!r}: expected i/N with whole numbers 1 <= i <= N, e.g. 1/4 "
                "(shard 1 of 4)"
            )
        i, n = int(m.group(1)), int(m.group(2))
        if n < 1:
            raise ConfigError(f"--shard {text!r}: the number of shards N must be >= 1")
        if not 1 <= i <= n:
            raise ConfigError(
                f"--shard {text!r}: the shard number i must be in 1..{n} (1-based: the first "
                f"shard is 1/{n}, the last {n}/{n}; with a 0-based array index use $((ID + 1)))"
            )
        return cls(i - 1, n)


def parse_shard(text: str) -> Shard:
    """Same as :meth:`Shard.parse`."""
    return Shard.parse(text)


def shard_positions(
    total: int, shard: Shard, layout: Literal["blocks", "round-robin"] = "blocks"
) -> list[int]:
    """Positions ``p`` (in sorted order, 0-based) of the ``total`` units that ``shard`` gets.

    Raises:
        ConfigError: unknown layout.
    """
    if layout == "blocks":
        return [p for p in range(total) if p * shard.count // total == shard.index]
    if layout == "round-robin":
        return list(range(shard.index, total, shard.count))
    raise ConfigError(f"unknown shard layout {layout!r}; expected one of {SHARD_LAYOUTS}")


def select_shard(
    units: Sequence[U],
    shard: Shard | None,
    *,
    key: Callable[[U], Any],
    layout: Literal["blocks", "round-robin"] = "blocks",
) -> list[U]:
    """The units of ``shard`` (all of them when None), in their original order.

    Args:
        units: every unit of the run (the same list in every shard).
        shard: which shard.
        key: a unique, stable sort key per unit (the same on every machine: no ids of objects,
            no hashes salted per process).
        layout: ``blocks`` or ``round-robin`` (module doc).

    Raises:
        ValueError: two units share a key.
    """
    if shard is None:
        return list(units)
    keys = [key(u) for u in units]
    if len(set(keys)) != len(keys):
        raise ValueError("shard keys must be unique; two units share one")
    order = sorted(range(len(units)), key=keys.__getitem__)
    chosen = {order[p] for p in shard_positions(len(units), shard, layout)}
    return [u for j, u in enumerate(units) if j in chosen]
