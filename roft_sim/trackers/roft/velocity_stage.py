"""The velocity stage of a ROFT step: the flow F_k read on the previous frame's mask, the
velocity KF, and the re-measurement of the frames a delayed mask covers.

Per delivered camera frame k (paper Fig. 2, reference report section 1.3):

1. the flow F_k is read on the mask of frame k-1 (eroded, :meth:`VelocityStage._eroded_mask`)
   with the depth of k-1 (and, with ``velocity.depth_rate``, the depth of k), and the velocity
   KF predicts and corrects with it (:func:`flow_measurement`, :class:`VelocityKF`);
2. the KF's interval-mean twist and its covariance are frame k's velocity measurement for the
   pose UKF (none when the KF could not update and ``skip_stale_velocity`` is on);
3. frame k's synchronised mask, eroded, and its depth are kept for the next frame's flow.

``velocity.remeasure_on_fresh_mask``: when a delayed mask captured at c arrives at k, the
frames c+1 .. k-1 are measured again, each flow on that mask warped to the frame before it
(the warps come from the mask synchroniser, which made them anyway), the KF is replayed from its
state after c, and their twists are handed back as revisions, so that the pose UKF's replay
reads every twist on the freshest mask evidence. Only the image inputs (depth and flow
references, no copies) and the KF's state after each frame are kept for that, for
``sync.horizon_frames`` frames.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import FlowField, Observation
from roft_sim.trackers.roft.config import VelocityKFConfig
from roft_sim.trackers.roft.mask_sync import PixelSet, erode_pixels, metric_erosion
from roft_sim.trackers.roft.velocity_kf import flow_measurement
from roft_sim.trackers.roft.velocity_selector import VelocityFilter, make_velocity_filter

F64 = NDArray[np.float64]

__all__ = ["TwistMeasurement", "VelocityStage", "VelocityStep"]


@dataclass(frozen=True, slots=True)
class TwistMeasurement:
    """The pose UKF's velocity measurement of one frame."""

    twist: F64 | None
    """(6,) the interval-mean spatial twist (v_o [m/s], w [rad/s]), camera frame, or None (no
    measurement this frame)."""
    covariance: F64 | None
    """(6, 6) the velocity KF's covariance, added to the UKF's twist noise, or None."""


_NO_TWIST = TwistMeasurement(None, None)


@dataclass(frozen=True, slots=True)
class VelocityStep:
    """What the velocity stage produced at one frame."""

    measurement: TwistMeasurement
    """Frame k's velocity measurement."""
    pixels_used: int
    """Flow pixels the KF update used (0: no update)."""
    revised: dict[int, TwistMeasurement] = field(default_factory=dict)
    """Frames before k whose measurement a fresh mask's re-measurement replaced."""
    remeasure_s: float = 0.0
    """Seconds the re-measurement took [s] (the tracker's stage timing)."""


@dataclass(frozen=True, slots=True)
class _FlowMask:
    """A delivered camera frame as the next flow measurement reads it."""

    k: int
    t_s: float
    pixels: PixelSet | None
    """Its synchronised mask, eroded (``velocity.mask_erosion_px`` or the metric rule)."""
    depth_m: NDArray[np.floating]
    """(H, W) its z-depth [m]."""


@dataclass(frozen=True, slots=True)
class _Inputs:
    """The inputs of one delivered frame's KF update (kept for a re-measurement)."""

    t_s: float
    depth_m: NDArray[np.floating]
    """(H, W) z-depth [m] (a reference to the observation's image, not a copy)."""
    flow: FlowField | None
    """F_k as delivered."""


class VelocityStage:
    """The flow-based velocity KF over the camera stream, with fresh-mask re-measurement."""

    def __init__(
        self,
        config: VelocityKFConfig,
        intrinsics: CameraIntrinsics,
        fps: int,
        horizon_frames: int,
    ):
        self._config = config
        self._intrinsics = intrinsics
        self._fps = fps
        self._horizon = horizon_frames
        self._stride = config.stride(intrinsics.width_px)
        self._filter = make_velocity_filter(config, intrinsics.width_px)
        self.reset()

    def reset(self) -> None:
        self._filter.reset()
        self._previous: _FlowMask | None = None
        self._inputs: dict[int, _Inputs] = {}
        self._states: dict[int, VelocityFilter] = {}

    @property
    def filter(self) -> VelocityFilter:
        """The velocity filter after the last frame."""
        return self._filter

    def step(
        self,
        observation: Observation,
        mask: PixelSet | None,
        history: tuple[tuple[int, PixelSet], ...] = (),
    ) -> VelocityStep:
        """Frame ``observation.k``: re-measures the frames a mask arriving now covers
        (``history``: that mask at its capture frame and warped to each frame since, from
        :class:`~roft_sim.trackers.roft.mask_sync.MaskStep`), then updates the KF with F_k
        and keeps frame k's ``mask`` for the next frame."""
        revised: dict[int, TwistMeasurement] = {}
        start = time.perf_counter()
        if self._config.remeasure_on_fresh_mask and history:
            revised = self._remeasure(observation.k, history)
        remeasure_s = time.perf_counter() - start
        if observation.depth_m is None:  # dropped camera frame: no measurement at all
            return VelocityStep(_NO_TWIST, 0, revised, remeasure_s)
        k, t_s, depth_m = observation.k, observation.t_s, observation.depth_m
        used = self._update(self._filter, self._previous, k, t_s, observation.flow, depth_m)
        self._previous = self._flow_mask(k, t_s, mask, depth_m)
        if self._config.remeasure_on_fresh_mask:
            self._inputs[k] = _Inputs(t_s, depth_m, observation.flow)
            self._states[k] = self._filter.copy()
        return VelocityStep(self._measurement(self._filter, used > 0), used, revised, remeasure_s)

    def prune(self, oldest_k: int) -> None:
        """Forgets the inputs and states of frames before ``oldest_k`` (no mask captured
        before it can arrive any more)."""
        for j in [j for j in self._inputs if j < oldest_k]:
            del self._inputs[j]
            self._states.pop(j, None)

    def _update(
        self,
        kf: VelocityFilter,
        prev: _FlowMask | None,
        k: int,
        t_s: float,
        flow: FlowField | None,
        depth_m: NDArray[np.floating],
    ) -> int:
        """Predicts and corrects ``kf`` with F_k read on ``prev`` (the mask and depth of the
        frame before k) and, with ``velocity.depth_rate``, the depth ``depth_m`` (H, W) [m] of
        frame k; returns the pixels used (0 when the filter did not update)."""
        if (
            prev is None
            or prev.pixels is None
            or flow is None
            or flow.from_k != prev.k
            or flow.to_k != k
            or not t_s - prev.t_s > 0
        ):
            return 0
        dt = t_s - prev.t_s
        meas = flow_measurement(
            prev.pixels,
            prev.depth_m,
            flow,
            self._intrinsics,
            dt,
            self._config,
            stride=self._stride,
            linearization_twist=kf.x if kf.updates > 0 else None,
            next_depth_m=depth_m,
        )
        if kf.step(meas, frames=dt * self._fps, t_s=t_s, dt_s=dt):
            return len(meas)
        return 0

    def _flow_mask(
        self, k: int, t_s: float, pixels: PixelSet | None, depth_m: NDArray[np.floating]
    ) -> _FlowMask:
        """Frame k as the next flow measurement reads it: its mask eroded by
        ``velocity.mask_erosion_px`` (or the metric rule) and its depth."""
        cfg = self._config
        if pixels is not None and cfg.mask_erosion_px is None:
            _, pixels = metric_erosion(
                pixels,
                depth_m,
                self._intrinsics.fx_px,
                cfg.mask_erosion_m,
                cfg.mask_erosion_max_removed,
            )
        elif pixels is not None and cfg.mask_erosion_px:
            pixels = erode_pixels(pixels, cfg.mask_erosion_px)
        return _FlowMask(k, t_s, pixels, depth_m)

    def _measurement(self, kf: VelocityFilter, updated: bool) -> TwistMeasurement:
        """The UKF's velocity measurement after an update of ``kf`` (none when the KF did not
        update and stale twists are skipped)."""
        cfg = self._config
        if not updated and cfg.skip_stale_velocity:
            return _NO_TWIST
        cov = kf.P.copy() if cfg.twist_covariance_to_ukf else None
        return TwistMeasurement(kf.x.copy(), cov)

    def _remeasure(
        self, k: int, history: tuple[tuple[int, PixelSet], ...]
    ) -> dict[int, TwistMeasurement]:
        """A mask captured at c arrived at k: replays the KF over the frames c+1 .. k-1 with
        each flow read on that mask warped to the frame before, and leaves the warped mask of
        k-1 for frame k's own update. Returns the re-measured frames' measurements."""
        c = history[0][0]
        if c >= k or c not in self._states or c not in self._inputs:
            return {}
        warped = dict(history)

        def mask_at(j: int) -> PixelSet:
            return warped[max(i for i in warped if i <= j)]

        kf = self._states[c].copy()
        prev = self._flow_mask(c, self._inputs[c].t_s, mask_at(c), self._inputs[c].depth_m)
        revised: dict[int, TwistMeasurement] = {}
        for j in range(c + 1, k):
            inputs = self._inputs.get(j)
            if inputs is None:  # a dropped camera frame: the filter did not run
                continue
            used = self._update(kf, prev, j, inputs.t_s, inputs.flow, inputs.depth_m)
            prev = self._flow_mask(j, inputs.t_s, mask_at(j), inputs.depth_m)
            self._states[j] = kf.copy()
            revised[j] = self._measurement(kf, used > 0)
        if k - 1 in self._inputs:
            self._filter = kf
            self._previous = prev
        return revised
