"""Robust start (``init = "robust"``): a tracker starts from the first pose detection that agrees
with the measured depth, whatever the tracker.

The simulated DOPE's first detection is sometimes far off (45 cm in one sequence) or missing,
and a tracker that starts from it carries the error for many frames. With ``init = "robust"``
the harness holds back, before the first accepted one, every pose detection that fails the
depth-rendering test: the object's depth is rendered at the detected pose (the same injected
renderer ROFT's outlier test uses) and compared with the depth the camera measured on the
detection's capture frame (as the tracker received it). A pixel is consistent when the measured
depth is within ``depth_tolerance_m`` of the rendered one, contradicting when the measured
surface lies farther than that BEHIND the rendered object (the object cannot be there); nearer
surfaces are occluders (a hand) and count for neither. A detection passes with at least
``min_pixels`` consistent or contradicting pixels and a consistent fraction of at least
``min_consistent_fraction``. After ``max_wait_s`` without a passing detection the next one is
taken as it is (the start never waits forever). Once a detection is accepted, everything
reaches the tracker untouched.

Trackers see only fewer pose detections (masks, flow and images are unchanged), so the rule
works for every tracker without its cooperation. What happened is logged and summarised in the
run's ``inputs["init"]`` (written to ``run.json`` and ``cell.json``).
"""

from __future__ import annotations

import dataclasses
import logging
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import ConfigError
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import DepthRenderer, Observation, PoseDetection

F32 = NDArray[np.float32]

__all__ = ["RobustStartConfig", "RobustStartGate", "DepthCheck"]

_log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class RobustStartConfig:
    """Settings of the robust start's depth-rendering test."""

    depth_tolerance_m: float = 0.02
    """A measured depth within this of the rendered object's is consistent [m] (RealSense-like
    noise at 0.4-0.9 m is a few mm; 2 cm also absorbs small pose errors)."""
    min_consistent_fraction: float = 0.5
    """Least share of consistent pixels among consistent and contradicting ones."""
    min_pixels: int = 20
    """Least number of consistent or contradicting pixels (at the test's resolution) for a
    verdict; fewer (object hidden or out of view) fails the test."""
    test_width_px: int = 160
    """The test runs at about this image width (the camera resolution divided by
    ``max(1, round(width / test_width_px))``, for speed)."""
    max_wait_s: float = 2.0
    """After this long [s] without a passing detection, the next detection is accepted as it
    is."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.depth_tolerance_m) and self.depth_tolerance_m > 0):
            raise ConfigError(
                f"depth_tolerance_m must be a positive number of metres, got "
                f"{self.depth_tolerance_m}; e.g. 0.02"
            )
        if not 0.0 < self.min_consistent_fraction <= 1.0:
            raise ConfigError(
                f"min_consistent_fraction must lie in (0, 1], got {self.min_consistent_fraction}"
            )
        if self.min_pixels < 1 or self.test_width_px < 1:
            raise ConfigError(
                f"min_pixels and test_width_px must be >= 1, got {self.min_pixels} and "
                f"{self.test_width_px}"
            )
        if not (np.isfinite(self.max_wait_s) and self.max_wait_s >= 0):
            raise ConfigError(f"max_wait_s must be >= 0 [s], got {self.max_wait_s}")


@dataclass(frozen=True, slots=True, kw_only=True)
class DepthCheck:
    """The verdict of the depth-rendering test on one detection."""

    passed: bool
    """Whether the detection agrees with the measured depth."""
    consistent: int
    """Pixels whose measured depth matches the rendered object."""
    contradicting: int
    """Pixels whose measured surface lies behind the rendered object."""
    reason: str
    """Why, in words (for the log)."""


def _decimated(depth_m: F32, divider: int) -> F32:
    """Every ``divider``-th pixel, from the middle of each block: ``(H // d, W // d)``."""
    h, w = depth_m.shape[0] // divider, depth_m.shape[1] // divider
    start = divider // 2
    return np.ascontiguousarray(depth_m[start::divider, start::divider][:h, :w])


@dataclass(slots=True, kw_only=True)
class RobustStartGate:
    """Filters the pose detections of a run's observations until one passes the depth test.

    Call :meth:`filter` on every observation in frame order, before the tracker sees it.
    """

    config: RobustStartConfig
    """The test's settings."""
    renderer: DepthRenderer
    """Renders the object's depth at a pose (the tracker context's renderer)."""
    intrinsics: CameraIntrinsics
    """The camera."""
    fps: int
    """Camera rate [Hz] (for ``max_wait_s``)."""
    started_k: int | None = None
    """Frame at which a detection was accepted (None = still waiting)."""
    accepted: PoseDetection | None = None
    """The accepted detection."""
    rejected: list[tuple[int, PoseDetection, str]] = field(default_factory=list)
    """``(frame, detection, reason)`` of every detection held back."""
    accept_reason: str = ""
    """Why the accepted detection was taken."""
    _first_arrival_k: int | None = None
    _depths: OrderedDict[int, F32] = field(default_factory=OrderedDict)

    @property
    def divider(self) -> int:
        """The camera resolution's divider for the test."""
        return max(1, round(self.intrinsics.width_px / self.config.test_width_px))

    @property
    def small_intrinsics(self) -> CameraIntrinsics:
        """The camera at the test's resolution."""
        d = self.divider
        return self.intrinsics.resized(
            self.intrinsics.width_px // d, self.intrinsics.height_px // d
        )

    def check(self, detection: PoseDetection) -> DepthCheck:
        """The depth-rendering test of ``detection`` against the depth measured on its capture
        frame (as received; a frame the tracker never got fails)."""
        measured = self._depths.get(detection.capture_k)
        if measured is None:
            return DepthCheck(
                passed=False,
                consistent=0,
                contradicting=0,
                reason=f"no depth image of its capture frame {detection.capture_k} was received",
            )
        rendered = self.renderer.render_depth(detection.T_cam_obj[None], self.small_intrinsics)[0]
        tol = self.config.depth_tolerance_m
        seen = (rendered > 0) & (measured > 0)
        residual = measured[seen].astype(np.float64) - rendered[seen].astype(np.float64)
        consistent = int(np.count_nonzero(np.abs(residual) <= tol))
        contradicting = int(np.count_nonzero(residual > tol))
        total = consistent + contradicting
        if total < self.config.min_pixels:
            return DepthCheck(
                passed=False,
                consistent=consistent,
                contradicting=contradicting,
                reason=f"only {total} pixels to compare (< {self.config.min_pixels}): the object "
                "would be out of view or hidden",
            )
        fraction = consistent / total
        passed = fraction >= self.config.min_consistent_fraction
        verdict = ">=" if passed else "<"
        return DepthCheck(
            passed=passed,
            consistent=consistent,
            contradicting=contradicting,
            reason=f"{100 * fraction:.0f} % of {total} pixels agree with the measured depth "
            f"({verdict} {100 * self.config.min_consistent_fraction:.0f} %)",
        )

    def filter(self, observation: Observation) -> Observation:
        """``observation`` with the pose detections that may not start the tracker removed."""
        if self.started_k is not None:
            return observation
        if observation.depth_m is not None:
            self._depths[observation.k] = _decimated(observation.depth_m, self.divider)
            horizon = int(np.ceil(self.config.max_wait_s * self.fps)) + 60
            while self._depths and next(iter(self._depths)) < observation.k - horizon:
                self._depths.popitem(last=False)
        if not observation.poses:
            return observation
        if self._first_arrival_k is None:
            self._first_arrival_k = observation.k
        waited_s = (observation.k - self._first_arrival_k) / self.fps
        kept: list[PoseDetection] = []
        for detection in sorted(observation.poses, key=lambda d: d.capture_k):
            if self.started_k is not None:
                kept.append(detection)
                continue
            if waited_s >= self.config.max_wait_s and self.rejected:
                self._accept(observation.k, detection, f"no detection passed in {waited_s:.2f} s")
                kept.append(detection)
                continue
            verdict = self.check(detection)
            if verdict.passed:
                self._accept(observation.k, detection, verdict.reason)
                kept.append(detection)
            else:
                self.rejected.append((observation.k, detection, verdict.reason))
                _log.info(
                    "robust start: frame %d: pose captured on frame %d held back: %s",
                    observation.k,
                    detection.capture_k,
                    verdict.reason,
                )
        if len(kept) == len(observation.poses):
            return observation
        return dataclasses.replace(observation, poses=tuple(kept))

    def _accept(self, k: int, detection: PoseDetection, reason: str) -> None:
        self.started_k = k
        self.accepted = detection
        self.accept_reason = reason
        self._depths.clear()
        if self.rejected:
            _log.info(
                "robust start: initialisation waited until frame %d (%d detection(s) held back); "
                "started from the pose captured on frame %d: %s",
                k,
                len(self.rejected),
                detection.capture_k,
                reason,
            )

    def summary(self) -> str:
        """One line for ``run.json``: when the tracker could start and why it waited."""
        if self.started_k is None or self.accepted is None:
            held = f"; {len(self.rejected)} held back" if self.rejected else ""
            return f"robust: no detection accepted{held}"
        if not self.rejected:
            return (
                f"robust: first detection accepted at frame {self.started_k} (captured on "
                f"frame {self.accepted.capture_k})"
            )
        first_k, first, reason = self.rejected[0]
        return (
            f"robust: waited until frame {self.started_k} (pose captured on frame "
            f"{self.accepted.capture_k}: {self.accept_reason}); {len(self.rejected)} "
            f"detection(s) held back, the first at frame {first_k} (captured on frame "
            f"{first.capture_k}): {reason}"
        )
