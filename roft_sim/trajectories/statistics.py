"""Motion distributions: speed and acceleration percentiles of captured and synthetic motion, and
the fit of the continuous profile to captured hand-object motion.

The captured reference is hand-held motion from the shared captures (``../shared/trajectories``):
the TUM VI rooms (a hand-held rig; 10 Hz low-pass, 2 s drift removal) and the CMU 02 hands
relative to the pelvis (10 Hz low-pass). They are split as every tuned part of the project is:
TUNING = TUM room1 and BVH 02_05, EVALUATION = TUM room2 and room4 and BVH 02_06. Each capture
file weighs the same in a pooled distribution (each BVH hand half of its file), whatever its
length, and every distribution is sampled at 30 Hz (the camera rate), bridged tracking gaps left
out.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.trajectories.base import Trajectory, sample_at_rate
from roft_sim.trajectories.captured import (
    CapturedMotionConfig,
    CapturedTrajectory,
    build_captured_trajectory,
)
from roft_sim.trajectories.continuous import ContinuousMotionConfig
from roft_sim.trajectories.placement import PlacementConfig
from roft_sim.trajectories.synthetic import SyntheticMotionConfig

F64 = NDArray[np.float64]

__all__ = [
    "Percentiles",
    "MotionDistribution",
    "CapturedSource",
    "HandMotionSplit",
    "HAND_MOTION_SPLITS",
    "SPLIT_SEEDS",
    "STATS_RATE_HZ",
    "motion_distribution",
    "captured_sources",
    "captured_distribution",
    "synthetic_distribution",
    "fit_continuous_motion",
    "fit_error",
    "format_distribution_table",
]

_log = logging.getLogger(__name__)

STATS_RATE_HZ = 30.0
"""Rate at which every distribution is sampled [Hz] (the camera rate)."""

HandMotionSplit = Literal["tuning", "evaluation"]

_DEG = 180.0 / np.pi


@dataclass(frozen=True, slots=True, kw_only=True)
class Percentiles:
    """Median, 95th percentile and maximum of a non-negative quantity."""

    p50: float
    """Median."""
    p95: float
    """95th percentile."""
    max: float
    """Largest value."""

    def as_array(self) -> F64:
        """(3,) ``[p50, p95, max]``."""
        return np.array([self.p50, self.p95, self.max])


def _weighted_percentiles(values: F64, weights: F64) -> Percentiles:
    order = np.argsort(values)
    v, w = values[order], weights[order]
    cdf = (np.cumsum(w) - 0.5 * w) / w.sum()
    p50, p95 = np.interp([0.5, 0.95], cdf, v)
    return Percentiles(p50=float(p50), p95=float(p95), max=float(v[-1]))


@dataclass(frozen=True, slots=True, kw_only=True)
class MotionDistribution:
    """Speed and acceleration percentiles of one motion or a pool of motions."""

    name: str
    """What was measured (for tables)."""
    linear_speed_mps: Percentiles
    """Speed of the object origin [m/s]."""
    angular_speed_dps: Percentiles
    """Angular speed [deg/s]."""
    linear_acceleration_mps2: Percentiles
    """Norm of the object origin's acceleration [m/s^2]."""
    angular_acceleration_dps2: Percentiles
    """Norm of the angular acceleration [deg/s^2]."""
    num_samples: int
    """Samples pooled."""

    def rows(self) -> list[tuple[str, Percentiles]]:
        """``(label with unit, percentiles)`` in table order."""
        return [
            ("linear speed [m/s]", self.linear_speed_mps),
            ("angular speed [deg/s]", self.angular_speed_dps),
            ("linear accel. [m/s^2]", self.linear_acceleration_mps2),
            ("angular accel. [deg/s^2]", self.angular_acceleration_dps2),
        ]

    def as_array(self) -> F64:
        """(4, 3) rows of :meth:`rows` by ``[p50, p95, max]``."""
        return np.stack([p.as_array() for _, p in self.rows()])

    def report(self) -> dict[str, object]:
        """JSON-ready: the name, the sample count and each row's percentiles."""
        keys = (
            "linear_speed_mps",
            "angular_speed_dps",
            "linear_acceleration_mps2",
            "angular_acceleration_dps2",
        )
        out: dict[str, object] = {"name": self.name, "num_samples": self.num_samples}
        for key, (_, p) in zip(keys, self.rows(), strict=True):
            out[key] = {"p50": p.p50, "p95": p.p95, "max": p.max}
        return out


def motion_distribution(
    name: str,
    parts: Sequence[tuple[Trajectory, float]],
    *,
    rate_hz: float = STATS_RATE_HZ,
) -> MotionDistribution:
    """Pooled percentiles of several trajectories, each sampled at ``rate_hz`` and weighted.

    Args:
        name: label of the distribution.
        parts: ``(trajectory, weight)``; a trajectory's samples share its weight equally (so a
            long capture does not outweigh a short one). Samples of a
            :class:`CapturedTrajectory` inside its bridged gaps are left out.
        rate_hz: sampling rate [Hz].

    Raises:
        ValueError: no part, a non-positive weight, or a part without samples.
    """
    if not parts:
        raise ValueError("a motion distribution needs at least one trajectory")
    columns: list[list[F64]] = [[], [], [], []]
    weights: list[F64] = []
    for trajectory, weight in parts:
        if not weight > 0:
            raise ValueError(f"weights must be positive, got {weight}")
        s = sample_at_rate(trajectory, rate_hz)
        keep = np.ones(len(s), dtype=bool)
        if isinstance(trajectory, CapturedTrajectory):
            for lo, hi in trajectory.bridged_intervals_s:
                keep &= ~((s.t_s >= lo) & (s.t_s <= hi))
        if not keep.any():
            raise ValueError(f"{name}: a trajectory has no sample outside its gaps")
        for column, values in zip(
            columns,
            (s.v_mps, s.w_radps * _DEG, s.a_mps2, s.alpha_radps2 * _DEG),
            strict=True,
        ):
            column.append(np.linalg.norm(values, axis=-1)[keep])
        weights.append(np.full(int(keep.sum()), weight / keep.sum()))
    w = np.concatenate(weights)
    lin, ang, acc, alpha = (_weighted_percentiles(np.concatenate(c), w) for c in columns)
    return MotionDistribution(
        name=name,
        linear_speed_mps=lin,
        angular_speed_dps=ang,
        linear_acceleration_mps2=acc,
        angular_acceleration_dps2=alpha,
        num_samples=int(w.size),
    )


@dataclass(frozen=True, slots=True, kw_only=True)
class CapturedSource:
    """One captured hand motion of the reference pool."""

    name: str
    """Short name (``tum-room1``, ``bvh-002_05-L``)."""
    config: CapturedMotionConfig
    """How it is read and cleaned (path relative to the trajectories folder)."""
    weight: float
    """Its weight in the pooled distribution (1 per file, shared by a file's hands)."""


HAND_MOTION_SPLITS: dict[str, tuple[str, ...]] = {
    "tuning": ("tum:room1", "bvh:002_05"),
    "evaluation": ("tum:room2", "tum:room4", "bvh:002_06"),
}
"""The captures of each split (the project-wide TUNING / EVALUATION split)."""
SPLIT_SEEDS: dict[str, tuple[int, ...]] = {
    "tuning": tuple(range(10)),
    "evaluation": tuple(range(100, 110)),
}
"""The synthetic-motion seeds of each split (the project-wide TUNING / EVALUATION split)."""

LOWPASS_HZ = 10.0
"""Low-pass cut-off of every captured reference motion [Hz]."""
TUM_DRIFT_WINDOW_S = 2.0
"""Drift-removal window of the TUM VI rooms [s] (the operator walks)."""


def captured_sources(split: HandMotionSplit, trajectories_dir: Path) -> list[CapturedSource]:
    """The captured hand motions of ``split`` under ``trajectories_dir`` (the shared
    ``trajectories/`` folder: ``tum/dataset-roomN_512_16.txt``, ``bvh/002_0N.bvh``).

    Raises:
        ConfigError: unknown split, or a file of the split is missing.
    """
    if split not in HAND_MOTION_SPLITS:
        raise ConfigError(
            f"unknown split {split!r}; expected one of {', '.join(HAND_MOTION_SPLITS)}"
        )
    placement = PlacementConfig(min_in_view_fraction=0.0)
    sources: list[CapturedSource] = []
    for entry in HAND_MOTION_SPLITS[split]:
        fmt, name = entry.split(":")
        if fmt == "tum":
            path = trajectories_dir / "tum" / f"dataset-{name}_512_16.txt"
            configs = [
                (
                    f"tum-{name}",
                    CapturedMotionConfig(
                        path=path,
                        format="tum",
                        lowpass_hz=LOWPASS_HZ,
                        remove_drift_window_s=TUM_DRIFT_WINDOW_S,
                        placement=placement,
                    ),
                    1.0,
                )
            ]
        else:
            path = trajectories_dir / "bvh" / f"{name}.bvh"
            configs = [
                (
                    f"bvh-{name}-{side}",
                    CapturedMotionConfig(
                        path=path,
                        format="bvh",
                        joint=f"CC_Base_{side}_Hand",
                        relative_to="CC_Base_Pelvis",
                        lowpass_hz=LOWPASS_HZ,
                        placement=placement,
                    ),
                    0.5,
                )
                for side in ("L", "R")
            ]
        if not path.is_file():
            raise ConfigError(
                f"captured motion {str(path)!r} of the {split} split is missing; point "
                "--trajectories at the shared trajectories folder (with tum/ and bvh/)"
            )
        sources += [CapturedSource(name=n, config=c, weight=w) for n, c, w in configs]
    return sources


def captured_distribution(
    split: HandMotionSplit, trajectories_dir: Path, intrinsics: CameraIntrinsics
) -> MotionDistribution:
    """The pooled distribution of the captured hand motion of ``split``."""
    parts: list[tuple[Trajectory, float]] = []
    for source in captured_sources(split, trajectories_dir):
        trajectory = build_captured_trajectory(source.config, intrinsics)
        parts.append((trajectory, source.weight))
    return motion_distribution(f"captured ({split})", parts)


def synthetic_distribution(
    name: str,
    config: ContinuousMotionConfig | SyntheticMotionConfig,
    seeds: Sequence[int],
    intrinsics: CameraIntrinsics,
    *,
    object_radius_m: float = 0.1,
) -> MotionDistribution:
    """The pooled distribution of a synthetic profile over ``seeds`` (equal weights).

    Args:
        name: label.
        config: a :class:`ContinuousMotionConfig` or
            :class:`~roft_sim.trajectories.synthetic.SyntheticMotionConfig`; its seed is
            replaced by each of ``seeds``.
        seeds: the generator seeds pooled.
        intrinsics: the camera the motion is placed for.
        object_radius_m: object radius for the in-view margin [m].
    """
    from roft_sim.trajectories.build import build_trajectory

    parts: list[tuple[Trajectory, float]] = []
    for seed in seeds:
        cfg = replace(config, seed=int(seed))
        parts.append((build_trajectory(cfg, intrinsics, object_radius_m=object_radius_m), 1.0))
    return motion_distribution(name, parts)


def _log_ratio(target: ArrayLike, actual: ArrayLike) -> float:
    """Mean log ratio: the scale that best maps ``actual`` onto ``target`` in log space."""
    return float(np.exp(np.mean(np.log(np.asarray(target) / np.asarray(actual)))))


def fit_error(target: MotionDistribution, fitted: MotionDistribution) -> float:
    """Root-mean-square log ratio over the twelve percentiles (0 = identical; 0.1 = about 10 %
    off on average)."""
    ratio = np.log(fitted.as_array() / target.as_array())
    return float(np.sqrt(np.mean(ratio * ratio)))


TEMPO_VARIATIONS: tuple[float, ...] = (0.0, 0.3, 0.5, 0.7, 0.85)
"""Clock swings tried by :func:`fit_continuous_motion`."""


def _fit_scales(
    target: MotionDistribution,
    cfg: ContinuousMotionConfig,
    seeds: Sequence[int],
    intrinsics: CameraIntrinsics,
    min_median_angular_speed_dps: float,
    iterations: int,
) -> tuple[ContinuousMotionConfig, MotionDistribution]:
    t = target.as_array()
    dist = synthetic_distribution("continuous (fit)", cfg, seeds, intrinsics)
    for _ in range(iterations):
        s = dist.as_array()
        speed_w = max(_log_ratio(t[1], s[1]), min_median_angular_speed_dps / s[1, 0])
        speed_v = _log_ratio(t[0], s[0])
        freq_w = _log_ratio(t[3], s[3] * speed_w)
        freq_v = _log_ratio(t[2], s[2] * speed_v)
        cfg = replace(
            cfg,
            angular_speed_rms_dps=cfg.angular_speed_rms_dps * speed_w,
            linear_speed_rms_mps=cfg.linear_speed_rms_mps * speed_v,
            angular_frequency_hz=(
                cfg.angular_frequency_hz[0] * freq_w,
                cfg.angular_frequency_hz[1] * freq_w,
            ),
            linear_frequency_hz=(
                cfg.linear_frequency_hz[0] * freq_v,
                cfg.linear_frequency_hz[1] * freq_v,
            ),
        )
        dist = synthetic_distribution("continuous (fit)", cfg, seeds, intrinsics)
    return cfg, dist


def fit_continuous_motion(
    target: MotionDistribution,
    intrinsics: CameraIntrinsics,
    *,
    start: ContinuousMotionConfig | None = None,
    seeds: Sequence[int] = SPLIT_SEEDS["tuning"],
    min_median_angular_speed_dps: float = 80.0,
    iterations: int = 3,
    tempo_variations: Sequence[float] = TEMPO_VARIATIONS,
) -> tuple[ContinuousMotionConfig, MotionDistribution]:
    """Fits the continuous profile's speed, frequency and tempo scales to ``target``.

    Speed percentiles scale with the root-mean-square speed and acceleration percentiles with
    speed times frequency, so each iteration sets the speed scale to the mean log ratio of the
    target's speed percentiles (p50, p95, max) to the profile's, then the frequency band's scale
    to the mean log ratio of the accelerations, for the angular and the linear part apart; the
    angular speed scale is raised where needed to keep the median at
    ``min_median_angular_speed_dps``. The clock's swing (the width of the distributions) is
    picked from ``tempo_variations`` by the smallest :func:`fit_error`.

    Args:
        target: the captured distribution to match (the TUNING split's).
        intrinsics: camera for the placement.
        start: the profile to start from (default: the shipped defaults).
        seeds: generator seeds pooled at each iteration (TUNING seeds 0-9).
        min_median_angular_speed_dps: floor of the median angular speed [deg/s].
        iterations: fixed-point iterations per swing (the view box's soft bound and the
            rotation's cross terms make the scalings not exactly linear).
        tempo_variations: the clock swings tried.

    Returns:
        The fitted config (duration 30 s, seed 0) and its distribution over ``seeds``.
    """
    base = replace(start if start is not None else ContinuousMotionConfig(), duration_s=30.0)
    best: tuple[float, ContinuousMotionConfig, MotionDistribution] | None = None
    for variation in tempo_variations:
        cfg, dist = _fit_scales(
            target,
            replace(base, tempo_variation=float(variation)),
            seeds,
            intrinsics,
            min_median_angular_speed_dps,
            iterations,
        )
        error = fit_error(target, dist)
        _log.info("tempo_variation %.2f: fit error %.3f", variation, error)
        if best is None or error < best[0]:
            best = (error, cfg, dist)
    assert best is not None  # tempo_variations is not empty
    return best[1], best[2]


def format_distribution_table(distributions: Sequence[MotionDistribution]) -> str:
    """A text table: one row per quantity, ``p50 / p95 / max`` of each distribution side by
    side."""
    width = max(24, *(len(d.name) + 2 for d in distributions))
    head = f"{'':26}" + "".join(f"{d.name:>{width}}" for d in distributions)
    sub = f"{'':26}" + "".join(f"{'p50 / p95 / max':>{width}}" for _ in distributions)
    lines = [head, sub]
    for i, (label, _) in enumerate(distributions[0].rows()):
        fmt = ".2f" if "m/s" in label else ".0f"
        cells = []
        for d in distributions:
            p = d.rows()[i][1]
            cells.append(f"{p.p50:{fmt}} / {p.p95:{fmt}} / {p.max:{fmt}}".rjust(width))
        lines.append(f"{label:26}" + "".join(cells))
    return "\n".join(lines)
