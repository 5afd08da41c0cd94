"""The ROFT tracker: mask synchronisation, velocity KF, pose UKF, pose synchronisation, outlier
rejection (reference report section 1.3 for the order of operations).

Per camera frame k:

1. the mask synchroniser advances to k (propagating with F_k, or warping a delayed mask that
   arrived);
2. the velocity KF predicts and corrects with F_k measured on the mask and depth of frame k-1;
   its mean is frame k's velocity measurement for the UKF (the reference feeds it every frame,
   also when the KF skipped its correction; a dropped camera frame gives none);
3. the depth samples the outlier test needs are taken from frame k (mask and depth);
4. arriving poses are filed under their capture frame c (the current frame when pose sync is
   off); the UKF restarts from the belief stored at c-1 and replays predict/correct over the
   buffered velocity measurements and poses up to k, storing the belief at EVERY frame (the
   reference keeps only alternate poses in the long-term chain, its quirk 5.4a, and skips frames
   after a missed pose, quirk 5.4b: neither is reproduced). A pose correction computes both
   candidates (with and without the pose) and keeps the pose only if the depth test passes.

The replayed result equals, to rounding, the result of a run in which every pose arrived
without delay. Poses older than the horizon, from the future, duplicated (same detection_id) or
non-finite are dropped and reported. The filter starts from ``reset(initial)`` or, without one,
from the earliest-captured pose received (re-initialised if an even earlier one arrives within
the horizon), so the result does not depend on the order of arrival.
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from roft_sim.errors import PluginError
from roft_sim.geometry.se3 import transform_from_pq
from roft_sim.geometry.so3 import quat_from_matrix
from roft_sim.records import (
    Estimate,
    Observation,
    PoseDetection,
)
from roft_sim.trackers.base import TrackerContext
from roft_sim.trackers.roft.config import RoftConfig
from roft_sim.trackers.roft.covariance_scale import (
    BlockScales,
    detector_noise_prior,
    normalised_innovation_squared,
    persistent_twist_samples,
    pose_excess_after,
    pose_innovation,
    restart_pose_excess,
    scaled_estimate_covariance,
    twist_difference,
    twist_noise,
)
from roft_sim.trackers.roft.innovation_gate import (
    InnovationSpread,
    adaptive_gate_test,
    initial_spread,
    squared_innovations,
)
from roft_sim.trackers.roft.mask_sync import (
    MaskStep,
    MaskSynchroniser,
    PixelSet,
)
from roft_sim.trackers.roft.outlier_rejection import (
    DepthOutlierTest,
    DepthSamples,
    depth_samples,
)
from roft_sim.trackers.roft.pose_ukf import (
    PoseBelief,
    PoseUKF,
    belief_from_estimate,
    estimate_from_belief,
    gate_rejects,
)
from roft_sim.trackers.roft.velocity_selector import SelectingVelocityKF
from roft_sim.trackers.roft.velocity_stage import TwistMeasurement, VelocityStage, VelocityStep

F64 = NDArray[np.float64]

__all__ = ["RoftTracker"]


@dataclass(frozen=True, slots=True)
class _Frame:
    """What the replay needs from one processed camera frame."""

    dt_s: float
    """Time since the previous frame [s] (the UKF prediction step)."""
    twist: F64 | None
    """(6,) velocity measurement (v_o, w) for the UKF, or None."""
    twist_cov: F64 | None
    """(6, 6) the velocity KF's covariance added to the UKF's twist noise, or None."""
    samples: DepthSamples | None
    """Measured depth samples for the outlier test of poses captured at this frame."""


@dataclass(frozen=True, slots=True)
class _RejectionStreak:
    """The poses the gate rejected in a row (in capture order) and the capture frame of the
    first of them."""

    count: int = 0
    first_capture_k: int = -1

    def after_rejecting(self, capture_k: int) -> _RejectionStreak:
        """The streak with one more pose, captured at ``capture_k``, rejected."""
        first = self.first_capture_k if self.count else capture_k
        return _RejectionStreak(self.count + 1, first)

    def span_s(self, capture_k: int, fps: float) -> float:
        """Seconds from the first rejected pose's capture to ``capture_k`` (0 without one)."""
        return (capture_k - self.first_capture_k) / fps if self.count else 0.0


_NO_STREAK = _RejectionStreak()


@dataclass(frozen=True, slots=True)
class _Pose:
    detection_id: int
    capture_k: int
    p_m: F64
    q_wxyz: F64


class _StageClock:
    """Seconds between successive laps, by stage name (``time.perf_counter``)."""

    def __init__(self) -> None:
        self.times: dict[str, float] = {}
        self._last = time.perf_counter()

    def lap(self, stage: str) -> None:
        """Adds the time since the last lap to ``stage``."""
        now = time.perf_counter()
        self.times[stage] = self.times.get(stage, 0.0) + now - self._last
        self._last = now

    def move(self, source: str, stage: str, seconds: float) -> None:
        """Books ``seconds`` of ``source``'s time as ``stage`` (a part timed inside it)."""
        self.times[source] -= seconds
        self.times[stage] = self.times.get(stage, 0.0) + seconds


_NO_TWIST = TwistMeasurement(None, None)


class RoftTracker:
    """ROFT (Piga et al. 2022) re-implemented in numpy; see docs/roft.md.

    Satisfies :class:`roft_sim.trackers.Tracker`. Build it with
    ``create_tracker(get_tracker_spec("roft"), context, config)``.
    """

    def __init__(self, config: RoftConfig, context: TrackerContext):
        self._config = config
        self._context = context
        self._intrinsics = context.intrinsics
        self._horizon = config.sync.horizon_frames
        self._ukf = PoseUKF(config.pose)
        self._outlier_test: DepthOutlierTest | None = None
        self._uses_outlier_test = config.use_pose and config.outlier_rejection.enable
        if self._uses_outlier_test:
            if context.depth_renderer is None:
                raise PluginError(
                    "ROFT's outlier rejection needs a depth renderer in the TrackerContext; "
                    "inject one or set outlier_rejection.enable = false"
                )
            self._outlier_test = DepthOutlierTest(
                context.depth_renderer, context.intrinsics, config.outlier_rejection
            )
        self._mask_sync = MaskSynchroniser(config.mask, context.intrinsics.shape, self._horizon)
        self._velocity = VelocityStage(
            config.velocity, context.intrinsics, context.fps, self._horizon
        )
        self.stage_times_s: dict[str, float] = {}
        """Seconds each stage of the last step took: ``mask_sync``, ``velocity``,
        ``remeasure`` (re-measuring a delayed mask's frames, part of the velocity stage),
        ``pose`` (this frame's UKF predict and correct), ``replay`` (the UKF re-run over the
        frames before it from a delayed pose's capture frame) and ``render`` (the outlier
        test's depth renders, inside ``pose`` and ``replay``)."""
        self.reset(None)

    @property
    def config(self) -> RoftConfig:
        return self._config

    def reset(self, initial: Estimate | None) -> None:
        """Starts a new sequence.

        Args:
            initial: the pose and velocity at frame ``initial.k`` (usually the first frame the
                tracker will see, e.g. its ground truth); its covariance, if given, is the
                initial covariance. When ``initial.k`` is the first observed frame, that frame
                is corrected without a prediction; when it is earlier, the filter predicts over
                one frame. None means "initialise from the earliest pose received".
        """
        self._mask_sync.reset()
        self._velocity.reset()
        self._frames: dict[int, _Frame] = {}
        self._beliefs: dict[int, PoseBelief] = {}
        # frame -> the poses gated in a row after it
        self._gate_streaks: dict[int, _RejectionStreak] = {}
        # frame -> the adaptive gate's innovation spread after it
        self._gate_spreads: dict[int, InnovationSpread] = {}
        self._scales: dict[int, BlockScales] = {}  # frame -> variance scales after it
        self._poses: dict[int, list[_Pose]] = {}
        self._known_ids: dict[int, int] = {}  # detection_id -> capture frame
        self._decisions: dict[int, bool] = {}  # detection_id -> accepted
        self._gated: set[int] = set()  # detection_ids rejected by the gate (vs depth test)
        # detection_ids that re-initialised an unconfirmed track, or by the depth override
        self._reinitialising: set[int] = set()
        self._init_pose: _Pose | None = None
        self._initial = initial
        self._no_predict_frame: int | None = None
        self._first_k: int | None = None
        self._last_k: int | None = None
        self._last_t: float | None = None
        self._mask: PixelSet | None = None
        self._totals: Counter[str] = Counter()
        # the first frame whose stored twist a fresh mask's re-measurement changed
        self._twists_changed_from: int | None = None

    def _file_poses(
        self, k: int, poses: tuple[PoseDetection, ...]
    ) -> tuple[list[_Pose], Counter[str], list[int]]:
        """Validates and files arriving poses under their (effective) capture frame.

        Returns:
            The poses filed, the count of dropped ones per reason, and the dropped ids.
        """
        dropped: Counter[str] = Counter()
        dropped_ids: list[int] = []
        new: list[_Pose] = []
        start = self._first_k
        for det in poses:
            c = det.capture_k if self._config.use_pose_resync else k
            T = np.asarray(det.T_cam_obj, dtype=np.float64)
            reason = None
            if not np.isfinite(T).all():
                reason = "invalid"
            elif c > k:
                reason = "future"
            elif c < k - self._horizon:
                reason = "too_old"
            elif start is not None and c < start:
                reason = "before_start"
            elif det.detection_id in self._known_ids:
                reason = "duplicate"
            if reason is not None:
                dropped[reason] += 1
                dropped_ids.append(det.detection_id)
                continue
            q = quat_from_matrix(T[:3, :3])
            pose = _Pose(det.detection_id, c, T[:3, 3].copy(), q)
            self._poses.setdefault(c, []).append(pose)
            self._known_ids[det.detection_id] = c
            new.append(pose)
            if not self._config.use_pose:  # kept only to initialise the filter
                dropped["not_fused"] += 1
                dropped_ids.append(det.detection_id)
        return new, dropped, dropped_ids

    # ------------------------------------------------------------------ the filter
    def _earliest_pose(self) -> _Pose | None:
        if not self._poses:
            return None
        c = min(self._poses)
        return min(self._poses[c], key=lambda p: p.detection_id)

    def _replay_start(self, k: int, new: list[_Pose]) -> tuple[int, PoseBelief] | None:
        """First frame to recompute and the belief before it; None while not initialised.

        Poses in the buffer are ordered by (capture frame, detection_id); without an initial
        estimate the first of them initialises the filter at its capture frame (the belief at
        c-1 is its pose with zero velocity and the initial covariance), and an earlier one that
        arrives later re-initialises it there.
        """
        if self._initial is not None:
            if not self._beliefs:
                first = self._first_k if self._first_k is not None else k
                if self._initial.k > first:
                    raise ValueError(
                        f"the initial estimate describes frame {self._initial.k}, after the first "
                        f"observed frame {first}; give the estimate of frame {first} or earlier"
                    )
                # stored where the replay restarts (before `first`); when it describes `first`
                # itself, frame `first` is corrected without a prediction (see _advance)
                self._beliefs[first - 1] = self._initial_belief_from_estimate(self._initial)
                self._scales[first - 1] = self._start_scales()
                self._no_predict_frame = first if self._initial.k == first else None
        else:
            earliest = self._earliest_pose()
            init = self._init_pose
            if earliest is not None and (
                init is None
                or (earliest.capture_k, earliest.detection_id) < (init.capture_k, init.detection_id)
            ):
                self._init_pose = earliest
                c = earliest.capture_k
                prior = self._ukf.initial_belief(earliest.p_m, earliest.q_wxyz)
                for j in [j for j in self._beliefs if j >= c - 1]:
                    del self._beliefs[j]
                    self._gate_streaks.pop(j, None)
                    self._gate_spreads.pop(j, None)
                    self._scales.pop(j, None)
                self._beliefs[c - 1] = prior
                self._scales[c - 1] = self._start_scales()
                return c, prior
            if init is None:
                return None
        start = min([p.capture_k for p in new] + [k])
        return start, self._beliefs[start - 1]

    def _initial_belief_from_estimate(self, initial: Estimate) -> PoseBelief:
        return belief_from_estimate(self._ukf, initial)

    def _correct_with_pose(
        self,
        predicted: PoseBelief,
        twist: F64 | None,
        pose: _Pose,
        frame: _Frame,
        first: bool,
        streak: _RejectionStreak,
        spread: InnovationSpread,
    ) -> tuple[PoseBelief, _RejectionStreak, InnovationSpread]:
        """One pose correction (with the frame's velocity on the first pose of the frame),
        behind the gate and the depth outlier test unless the pose initialised the filter.

        Returns:
            The corrected belief, the poses gated in a row after this one and the adaptive
            gate's innovation spread after it.
        """
        twist_cov = frame.twist_cov if twist is not None else None
        if pose is self._init_pose:
            self._decisions[pose.detection_id] = True
            return (
                self._ukf.correct(
                    predicted,
                    twist=twist,
                    twist_cov=twist_cov,
                    p_meas_m=pose.p_m,
                    q_meas_wxyz=pose.q_wxyz,
                ),
                _NO_STREAK,
                spread,
            )
        without_pose = (
            self._ukf.correct(predicted, twist=twist, twist_cov=twist_cov) if first else predicted
        )
        gate = self._config.gate
        if gate.enable and gate.adaptive:
            squared = squared_innovations(predicted.x[6:9], predicted.q, pose.p_m, pose.q_wxyz)
            P = predicted.P
            variance = (float(np.trace(P[6:9, 6:9])) / 3, float(np.trace(P[9:12, 9:12])) / 3)
            passes, after = adaptive_gate_test(gate, spread, squared, variance, pose.capture_k)
            confirmed = spread.passed > 0
            span_s = streak.span_s(pose.capture_k, self._context.fps)
            may_reject = (
                streak.count < gate.max_consecutive_rejections or span_s < gate.min_rejection_span_s
            )
            gated = not passes and confirmed and may_reject
            spread = after
            self._reinitialising.discard(pose.detection_id)
            override = self._depth_override(pose, without_pose, frame) if gated else None
            if override is not None or (not passes and not confirmed):
                self._decisions[pose.detection_id] = True
                self._gated.discard(pose.detection_id)
                self._reinitialising.add(pose.detection_id)
                keep = override == "position"
                return self._reinitialised_at(without_pose, pose, keep), _NO_STREAK, spread
        else:
            gated = gate_rejects(gate, predicted, pose.p_m, pose.q_wxyz, streak.count)
        if gated:
            self._decisions[pose.detection_id] = False
            self._gated.add(pose.detection_id)
            return without_pose, streak.after_rejecting(pose.capture_k), spread
        self._gated.discard(pose.detection_id)
        with_pose = self._ukf.correct(
            predicted,
            twist=twist,
            twist_cov=twist_cov,
            p_meas_m=pose.p_m,
            q_meas_wxyz=pose.q_wxyz,
        )
        test = self._outlier_test
        if test is None:
            self._decisions[pose.detection_id] = True
            return with_pose, _NO_STREAK, spread
        reject = test.reject(
            transform_from_pq(with_pose.x[6:9], with_pose.q),
            transform_from_pq(without_pose.x[6:9], without_pose.q),
            frame.samples,
        )
        self._decisions[pose.detection_id] = not reject
        return (without_pose if reject else with_pose), _NO_STREAK, spread

    def _depth_override(
        self, pose: _Pose, track: PoseBelief, frame: _Frame
    ) -> Literal["pose", "position"] | None:
        """``gate.depth_override_coverage``: whether the depth at the pose's capture frame
        shows the track, not the gated pose, off, and what of the pose to take.

        The track is off when the pose's render covers at least that fraction of the mask's
        depth samples, the track's (``track``) less than half as many, and the track's mean
        depth error is more than the depth test's ``gamma`` times the pose's (inf where its
        render covers no sample). Then ``"pose"`` when the pose's orientation also fits the
        depth ``gamma`` times better than the track's orientation at the pose's position,
        else ``"position"`` (the orientation stays the track's: a flip of a near-symmetric
        object fits the depth as well as the track's orientation, and the depth gives no
        reason to take it). None: no override."""
        coverage = self._config.gate.depth_override_coverage
        test = self._outlier_test
        samples = frame.samples
        if coverage is None or test is None or samples is None or len(samples) == 0:
            return None
        T_pose = transform_from_pq(pose.p_m, pose.q_wxyz)
        T_track = transform_from_pq(track.x[6:9], track.q)
        T_moved = transform_from_pq(pose.p_m, track.q)
        error, covered = test.errors_and_coverage(np.stack([T_pose, T_track, T_moved]), samples)
        gamma = self._config.outlier_rejection.gamma
        if not (
            covered[0] >= coverage and covered[1] < 0.5 * covered[0] and gamma * error[0] < error[1]
        ):
            return None
        return "pose" if gamma * error[0] < error[2] else "position"

    def _reinitialised_at(
        self, belief: PoseBelief, pose: _Pose, keep_orientation: bool = False
    ) -> PoseBelief:
        """``belief`` with its pose replaced by ``pose`` and the pose block of its covariance
        by the configured initial one (no cross-covariance with the velocities, which are
        kept with their covariance): an unconfirmed track's failing pose and the depth
        override. ``keep_orientation``: the position only; the orientation and its variance
        stay ``belief``'s."""
        fresh = self._ukf.initial_belief(pose.p_m, pose.q_wxyz)
        P = np.zeros_like(belief.P)
        P[0:6, 0:6] = belief.P[0:6, 0:6]
        P[6:12, 6:12] = fresh.P[6:12, 6:12]
        q = fresh.q
        if keep_orientation:
            P[9:12, 9:12] = belief.P[9:12, 9:12]
            q = belief.q
        x = np.concatenate([belief.x[0:6], fresh.x[6:9]])
        return PoseBelief(x=x, q=q, P=P)

    def _advance(self, j: int, prior: PoseBelief) -> PoseBelief:
        """Predict from j-1 to j and correct with everything known about frame j (also stores
        the gate's rejection streak after j, so that a replay from any frame restores it)."""
        frame = self._frames[j]
        # the initial estimate, when it describes frame j itself, needs no prediction
        no_predict = j == self._no_predict_frame
        twist = frame.twist if self._config.use_velocity else None
        belief = (
            prior if no_predict else self._ukf.predict(prior, frame.dt_s, coast_s=self._coast_s(j))
        )
        twist_cov = frame.twist_cov if twist is not None else None
        streak = self._gate_streaks.get(j - 1, _NO_STREAK)
        spread = self._gate_spreads.get(j - 1) or initial_spread(self._config.gate)
        scales = self._scales.get(j - 1) or self._start_scales()
        if not no_predict:
            scales = dataclasses.replace(scales, since_pose_s=scales.since_pose_s + frame.dt_s)
        if twist is not None:
            scales = self._with_twist_change(scales, j, twist, twist_cov)
        poses = sorted(self._poses.get(j, []), key=lambda p: p.detection_id)
        if not self._config.use_pose or not poses:
            belief = self._ukf.correct(belief, twist=twist, twist_cov=twist_cov)
        else:
            for i, pose in enumerate(poses):
                before = belief
                belief, streak, spread = self._correct_with_pose(
                    belief, twist if i == 0 else None, pose, frame, i == 0, streak, spread
                )
                fused = self._decisions.get(pose.detection_id)
                if pose is self._init_pose or pose.detection_id in self._reinitialising:
                    scales = self._restarted(scales, belief)
                elif fused:
                    scales = self._with_pose_nis(scales, before, pose)
        self._gate_streaks[j] = streak
        self._gate_spreads[j] = spread
        self._scales[j] = scales
        return belief

    def _coast_s(self, j: int) -> float:
        """Seconds without a velocity measurement at frame j: the time steps of j and of the
        frames before it that have no twist, back to the last one that has (over the frames
        kept, ``sync.horizon_frames``); 0 when j has one or the flow is not used."""
        if not self._config.use_velocity:
            return 0.0
        coast = 0.0
        while j in self._frames and self._frames[j].twist is None:
            coast += self._frames[j].dt_s
            j -= 1
        return coast

    # ------------------------------------------------------------------ reported covariance
    def _pose_noise(self) -> F64:
        """(6, 6) the configured pose noise ``diag(meas_cov_x, meas_cov_q)``."""
        pc = self._config.pose
        return np.diag(np.concatenate([pc.meas_cov_x, pc.meas_cov_q]))

    def _start_scales(self) -> BlockScales:
        """The scales before the first frame: the pose-noise factors start from the
        detector-noise prior (the adaptive gate's prior spread)."""
        t, r = detector_noise_prior(initial_spread(self._config.gate), self._config.pose)
        return BlockScales.initial(t, r)

    def _restarted(self, scales: BlockScales, belief: PoseBelief) -> BlockScales:
        """``scales`` after a pose (re)initialised the filter (``belief``, after it): the
        excess becomes that detection's estimated noise minus the filter's pose covariance,
        and the time since a pose 0."""
        factors = scales.pose_noise_factors(self._config.covariance_scale)
        excess = restart_pose_excess(belief.P[6:12, 6:12], self._pose_noise(), factors)
        return dataclasses.replace(scales, pose_excess=excess, since_pose_s=0.0)

    def _with_twist_change(
        self, scales: BlockScales, j: int, twist: F64, twist_cov: F64 | None
    ) -> BlockScales:
        """``scales`` with the velocity blocks updated by the change of the twist measurement
        from the previous twist (:meth:`_previous_twist_frame`) to frame j, normalised by the
        two measurements' noise (none without a previous twist)."""
        cfg = self._config.covariance_scale
        previous = self._previous_twist_frame(j)
        if not cfg.enable or previous is None or previous.twist is None:
            return scales
        pose_cfg = self._config.pose
        d, S = twist_difference(
            twist,
            twist_noise(pose_cfg, twist_cov),
            previous.twist,
            twist_noise(pose_cfg, previous.twist_cov),
        )
        memory = cfg.memory_measurements
        return dataclasses.replace(
            scales,
            v=scales.v.updated(normalised_innovation_squared(d[:3], S[:3, :3]), 3, memory),
            w=scales.w.updated(normalised_innovation_squared(d[3:], S[3:, 3:]), 3, memory),
        )

    def _previous_twist_frame(self, j: int) -> _Frame | None:
        """The frame the twist of frame j is compared with: the last frame before j that had a
        twist, at most ``sync.horizon_frames`` back, so that dropped camera frames and frames
        without flow do not starve the twist-change statistic; None when there is none. The
        frames are kept that far behind the oldest replayable one (:meth:`_prune`), so a replay
        finds the same frame as the undelayed run did."""
        previous = self._frames.get(j - 1)
        for i in range(j - 2, j - 1 - self._horizon, -1):
            if previous is not None and previous.twist is not None:
                break
            previous = self._frames.get(i)
        return previous

    def _with_pose_nis(self, scales: BlockScales, before: PoseBelief, pose: _Pose) -> BlockScales:
        """``scales`` with the pose blocks updated by a fused pose's innovation at ``before``
        (the belief before that pose's correction)."""
        cfg = self._config.covariance_scale
        if not cfg.enable:
            return scales
        nu, _ = pose_innovation(before, pose.p_m, pose.q_wxyz, self._config.pose)
        memory = cfg.memory_measurements
        # the pose noise the innovation is explained by is the configured one: the rest is the
        # twist's (the estimated noise would explain every innovation while the detector prior
        # is not yet forgotten, leaving the twist no sample)
        v_var, w_var = persistent_twist_samples(
            nu, before.P[6:12, 6:12], scales.pose_excess, self._pose_noise(), scales.since_pose_s
        )
        scales = dataclasses.replace(
            scales,
            v_persistent=scales.v_persistent.updated(v_var, 1, memory),
            w_persistent=scales.w_persistent.updated(w_var, 1, memory),
            since_pose_s=0.0,
        )
        # covariance matching of the pose noise: E[nu nu^T] = P + excess + R_true
        P = before.P[6:12, 6:12]
        R = self._pose_noise()
        excess = scales.pose_excess
        samples = []
        for block in (slice(0, 3), slice(3, 6)):
            # a sample of the noise's variance per dimension, in units of the configured one;
            # never negative (a prediction far more uncertain than its innovation says nothing
            # about the noise, it must not cancel the evidence of the other samples)
            spread = float(nu[block] @ nu[block]) - float(
                np.trace(P[block, block] + excess[block, block])
            )
            samples.append(max(spread, 0.0) / (float(np.trace(R[block, block])) / 3.0))
        t_scale = scales.t.updated(samples[0], 3, memory)
        r_scale = scales.r.updated(samples[1], 3, memory)
        # the configured pose noise is a floor: the excess stays positive semi-definite
        scales = dataclasses.replace(scales, t=t_scale, r=r_scale)
        return dataclasses.replace(
            scales,
            pose_excess=pose_excess_after(excess, P, R, scales.pose_noise_factors(cfg)),
        )

    def _reported(self, estimate: Estimate) -> Estimate:
        """The estimate with its covariance scaled by the variance scales of its frame."""
        cfg = self._config.covariance_scale
        scales = self._scales.get(estimate.k)
        if not cfg.enable or scales is None or estimate.covariance is None:
            return estimate
        cov = scaled_estimate_covariance(np.asarray(estimate.covariance), scales, cfg)
        factors = dict(zip(("t", "r", "v", "w"), scales.factors().tolist(), strict=True))
        diagnostics = {
            **estimate.diagnostics,
            **{f"covariance_scale_{name}": f for name, f in factors.items()},
        }
        return dataclasses.replace(estimate, covariance=cov, diagnostics=diagnostics)

    # ------------------------------------------------------------------ the protocol
    def step(self, observation: Observation) -> Estimate:
        """Consumes camera frame ``observation.k`` and returns the estimate for it.

        The stages run once each, in the paper's order: mask synchronisation, the velocity KF
        (with the re-measurement of a delayed mask's frames), the pose UKF with the replay of
        delayed poses (outlier rejection inside); their times are in :attr:`stage_times_s`.
        """
        obs = observation
        k = obs.k
        clock = _StageClock()
        dt = self._frame_interval_s(obs)
        mask_step = self._synchronise_mask(obs)
        pixels = mask_step.pixels if mask_step is not None else None
        clock.lap("mask_sync")
        velocity = self._measure_velocity(obs, mask_step)
        clock.lap("velocity")
        if velocity is not None:
            clock.move("velocity", "remeasure", velocity.remeasure_s)
        samples = None
        if self._uses_outlier_test and pixels is not None and obs.depth_m is not None:
            samples = depth_samples(pixels, obs.depth_m, self._config.outlier_rejection)
        twist = velocity.measurement if velocity is not None else _NO_TWIST
        self._frames[k] = _Frame(
            dt_s=float(dt), twist=twist.twist, twist_cov=twist.covariance, samples=samples
        )
        new, dropped, dropped_ids = self._file_poses(k, obs.poses)
        estimate_belief, replay = self._replay(k, new, clock)
        self._prune(k)
        accepted, rejected, gated = self._count_decisions(new, dropped)
        diagnostics: dict[str, float | int | str] = {
            "flow_pixels": velocity.pixels_used if velocity is not None else 0,
            "mask_pixels": len(pixels) if pixels is not None else 0,
            "replayed_frames": replay,
            "remeasured_frames": len(velocity.revised) if velocity is not None else 0,
            "poses_gated": gated,
            **{f"mask_{name}": n for name, n in (mask_step.counts if mask_step else {}).items()},
            **{f"poses_dropped_{reason}": n for reason, n in dropped.items()},
            **{f"total_{name}": n for name, n in self._totals.items()},
        }
        kf = self._velocity.filter
        if isinstance(kf, SelectingVelocityKF):
            diagnostics["velocity_weight_accel_linear"] = float(kf.weights_accel[0])
            diagnostics["velocity_weight_accel_angular"] = float(kf.weights_accel[1])
        spatial_twist = None
        if self._config.use_flow and (
            kf.updates > 0 or self._config.velocity.report_unmeasured_twist
        ):
            spatial_twist = kf.x_frame.copy()
        self.stage_times_s = clock.times
        if estimate_belief is None:
            return Estimate.invalid(
                k,
                spatial_twist=spatial_twist,
                dropped_pose_ids=tuple(dropped_ids),
                diagnostics=diagnostics,
            )
        return self._reported(
            estimate_from_belief(
                k,
                estimate_belief,
                spatial_twist=spatial_twist,
                accepted_pose_ids=accepted,
                rejected_pose_ids=rejected,
                dropped_pose_ids=tuple(dropped_ids),
                diagnostics=diagnostics,
            )
        )

    def _synchronise_mask(self, obs: Observation) -> MaskStep | None:
        """The mask stage: advances the synchroniser to frame ``obs.k`` (None when neither the
        flow nor the outlier test uses masks)."""
        if not (self._config.use_flow or self._uses_outlier_test):
            self._mask = None
            return None
        flow = obs.flow if self._config.use_flow else None
        step = self._mask_sync.step(obs.k, flow, obs.masks)
        self._mask = step.pixels
        return step

    def _measure_velocity(
        self, obs: Observation, mask_step: MaskStep | None
    ) -> VelocityStep | None:
        """The velocity stage (None without flow): frame k's twist measurement, and the
        revisions of earlier frames' twists a fresh mask's re-measurement made (stored here
        for the pose replay)."""
        if not self._config.use_flow:
            return None
        pixels = mask_step.pixels if mask_step is not None else None
        history = mask_step.history if mask_step is not None else ()
        velocity = self._velocity.step(obs, pixels, history)
        if velocity.revised:
            self._twists_changed_from = min(velocity.revised)
        for j, revised in velocity.revised.items():
            if j in self._frames:
                self._frames[j] = dataclasses.replace(
                    self._frames[j], twist=revised.twist, twist_cov=revised.covariance
                )
        return velocity

    def _frame_interval_s(self, obs: Observation) -> float:
        """Checks that frame ``obs.k`` follows the last one and returns the time since it [s]
        (from the time stamps; from the frame count when a stamp is missing or not increasing)."""
        k = obs.k
        if self._last_k is not None and k <= self._last_k:
            raise ValueError(
                f"observations must come in increasing k; got k={k} after {self._last_k}"
            )
        if self._last_k is not None and k != self._last_k + 1:
            raise ValueError(
                f"observations must come without gaps in k; got k={k} after {self._last_k}. A "
                "dropped camera frame must still be stepped, as an Observation with depth_m None"
            )
        if self._first_k is None:
            self._first_k = k
        fps = self._context.fps
        dt = obs.t_s - self._last_t if self._last_t is not None else 1.0 / fps
        if not (np.isfinite(dt) and dt > 0):
            dt = (k - (self._last_k if self._last_k is not None else k - 1)) / fps
        self._last_k, self._last_t = k, obs.t_s
        return float(dt)

    def _replay(
        self, k: int, new: list[_Pose], clock: _StageClock
    ) -> tuple[PoseBelief | None, int]:
        """Re-runs the pose filter from the earliest frame a new pose changes (or advances it
        by frame k alone), storing every belief; returns frame k's belief (None before the
        first pose) and the number of frames run. Times the frames before k as ``replay``,
        frame k as ``pose`` and the outlier test's renders as ``render``."""
        start = self._replay_start(k, new)
        changed = self._twists_changed_from  # stored twists a re-measurement replaced
        self._twists_changed_from = None
        if start is None:
            clock.lap("pose")
            return None, 0
        j0, belief = start
        if changed is not None and changed < j0:
            first = max(changed, min(self._beliefs) + 1)  # beliefs are stored from init - 1
            if first < j0:
                j0, belief = first, self._beliefs[first - 1]
        render_before = self._outlier_test.render_s if self._outlier_test is not None else 0.0
        for j in range(j0, k + 1):
            if j == k:
                clock.lap("replay")
            belief = self._advance(j, belief)
            self._beliefs[j] = belief
        clock.lap("pose")
        if self._outlier_test is not None:
            clock.times["render"] = self._outlier_test.render_s - render_before
        return belief, k + 1 - j0

    def _count_decisions(
        self, new: list[_Pose], dropped: Counter[str]
    ) -> tuple[tuple[int, ...], tuple[int, ...], int]:
        """Adds this frame's dropped, rejected and gated poses to the totals; returns the ids
        of the new poses accepted and rejected, and how many of the rejected the gate refused."""
        for reason, n in dropped.items():
            self._totals[f"poses_dropped_{reason}"] += n
        accepted = tuple(p.detection_id for p in new if self._decisions.get(p.detection_id))
        rejected = tuple(
            p.detection_id for p in new if self._decisions.get(p.detection_id) is False
        )
        self._totals["poses_rejected"] += len(rejected)
        gated = sum(1 for i in rejected if i in self._gated)
        self._totals["poses_gated"] += gated
        return accepted, rejected, gated

    def _prune(self, k: int) -> None:
        """Forgets what no pose within the horizon can need any more."""
        oldest = k - self._horizon
        # a replayed frame may look up to a horizon further back (_previous_twist_frame)
        for j in [j for j in self._frames if j < oldest - self._horizon]:
            del self._frames[j]
        self._velocity.prune(oldest)
        for j in [j for j in self._beliefs if j < oldest - 1]:
            del self._beliefs[j]
        for j in [j for j in self._gate_streaks if j < oldest - 1]:
            del self._gate_streaks[j]
        for j in [j for j in self._gate_spreads if j < oldest - 1]:
            del self._gate_spreads[j]
        for j in [j for j in self._scales if j < oldest - 1]:
            del self._scales[j]
        for c in [c for c in self._poses if c < oldest]:
            for pose in self._poses.pop(c):
                self._known_ids.pop(pose.detection_id, None)
                self._decisions.pop(pose.detection_id, None)
                self._gated.discard(pose.detection_id)
                self._reinitialising.discard(pose.detection_id)

    @property
    def pose_belief(self) -> PoseBelief | None:
        """The UKF belief at the last processed frame (None before initialisation)."""
        if self._last_k is None:
            return None
        return self._beliefs.get(self._last_k)

    @property
    def mask(self) -> PixelSet | None:
        """The synchronised mask of the last processed frame (None before any mask)."""
        return self._mask

    @property
    def velocity_belief(self) -> tuple[F64, F64]:
        """The velocity KF's interval-mean twist (6,) (v_o [m/s], w [rad/s], camera frame) and
        its covariance (6, 6): the pose UKF's velocity measurement."""
        return self._velocity.filter.x.copy(), self._velocity.filter.P.copy()

    @property
    def reported_twist(self) -> F64:
        """The velocity filter's twist (6,) (v_o [m/s], w [rad/s], camera frame) at the last
        frame: ``Estimate.spatial_twist`` once a flow has been used (the interval mean for
        ``velocity.motion_model = "constant"``, the models' mix for ``auto``)."""
        return self._velocity.filter.x_frame.copy()
