"""Hypothesis strategies for whole observation streams: a scene x a fault schedule x a seed.

For property tests of trackers and filters under injected delays and faults::

    from hypothesis import given
    from roft_sim.testing.stream_strategies import faulted_streams, pose_timing_faults

    @given(faulted_streams(analytic_sequence, pose_timing_faults()))
    def test_replay_is_exact(stream):
        check_delay_invariance(lambda: tracker_for("roft", stream.sequence),
                               stream.observations()).raise_if_failed()

A drawn :class:`~roft_sim.testing.streams.FaultedStream` prints as its fault list and its
capture -> arrival timeline, so the shrunk counterexample hypothesis reports reads as a minimal
schedule. Fault configurations come from :mod:`roft_sim.testing.fault_strategies` (they shrink
towards fewer faults, smaller delays and probabilities), trajectories with speed bounds from
:mod:`roft_sim.testing.trajectory_strategies`, images from the renderer-free analytic scene
(:mod:`roft_sim.testing.analytic_scene`).

- :func:`analytic_motions`: smooth closed-form motions with peak speeds within bounds.
- :func:`analytic_sequences`: the analytic textured box rendered along such a motion (cached).
- :func:`trajectory_sequences`: the box rendered along a synthetic hand-like trajectory.
- :func:`pose_timing_faults`: configurations that vary only the pose stream's timing, losses,
  delivery (and optionally outliers): what a delay-correct tracker must handle exactly.
- :func:`faulted_streams`: a sequence, a fault configuration and a seed.
- :func:`tracker_settings`: hypothesis settings for tracker properties (no deadline).

Importing this module registers the hypothesis profiles ``roft-sim-ci`` and ``thorough``
(:mod:`roft_sim.testing.profiles`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import cast

import numpy as np
from hypothesis import event
from hypothesis import strategies as st
from numpy.typing import ArrayLike

from roft_sim.datasets.base import InMemorySequence
from roft_sim.datasets.base import Sequence as DatasetSequence
from roft_sim.faults import CameraFaults, FaultConfig, FlowFaults, MaskStreamFaults, load_faults
from roft_sim.geometry.camera import CameraIntrinsics
from roft_sim.records import PoseTrack
from roft_sim.testing.analytic_scene import (
    AnalyticBox,
    AnalyticMotion,
    analytic_box_sequence,
    default_intrinsics,
)
from roft_sim.testing.fault_strategies import camera_faults, flow_faults, pose_stream_faults
from roft_sim.testing.fixtures import analytic_sequence
from roft_sim.testing.profiles import (
    CI_PROFILE,
    THOROUGH_PROFILE,
    register_hypothesis_profiles,
    tracker_settings,
)
from roft_sim.testing.strategies import FiniteFloats
from roft_sim.testing.streams import FaultedStream
from roft_sim.testing.trajectory_strategies import synthetic_trajectories
from roft_sim.trajectories.base import Trajectory

__all__ = [
    "CI_PROFILE",
    "THOROUGH_PROFILE",
    "register_hypothesis_profiles",
    "tracker_settings",
    "analytic_motions",
    "analytic_sequences",
    "TrajectoryMotion",
    "trajectory_sequences",
    "pose_timing_faults",
    "faulted_streams",
]

register_hypothesis_profiles()

_finite: FiniteFloats = {"allow_nan": False, "allow_infinity": False}


@st.composite
def analytic_motions(
    draw: st.DrawFn,
    *,
    max_linear_speed_mps: float = 1.0,
    max_angular_speed_radps: float = 4.0,
    max_amplitude_m: float = 0.06,
) -> AnalyticMotion:
    """:class:`~roft_sim.testing.analytic_scene.AnalyticMotion` with peak speeds within bounds.

    Frequencies, phases and rotation axes are drawn; position amplitudes (at most
    ``max_amplitude_m`` [m] per axis, about the default centre 0.5 m in front of the camera) and
    rotation amplitudes are scaled down until the peak linear speed is at most
    ``max_linear_speed_mps`` and the peak angular speed at most ``max_angular_speed_radps``.
    Shrinks towards a still object.
    """
    if not (max_linear_speed_mps >= 0 and max_angular_speed_radps >= 0 and max_amplitude_m >= 0):
        raise ValueError("speed and amplitude bounds must be >= 0")
    amp = np.array(draw(st.tuples(*[st.floats(0.0, max_amplitude_m, **_finite)] * 3)))
    freq = np.array(draw(st.tuples(*[st.floats(0.2, 1.5, **_finite)] * 3)))
    phase = draw(st.tuples(*[st.floats(0.0, 2 * np.pi, **_finite)] * 3))
    peak_v = float(np.linalg.norm(amp * 2 * np.pi * freq))
    if peak_v > max_linear_speed_mps:
        amp = amp * (max_linear_speed_mps / peak_v)
    ramp = np.array(draw(st.tuples(*[st.floats(0.0, 1.0, **_finite)] * 2)))
    rfreq = np.array(draw(st.tuples(*[st.floats(0.2, 1.5, **_finite)] * 2)))
    rphase = draw(st.tuples(*[st.floats(0.0, 2 * np.pi, **_finite)] * 2))
    peak_w = float(np.sum(ramp * 2 * np.pi * rfreq))  # |w| <= |th1'| + |th2'|
    if peak_w > max_angular_speed_radps:
        ramp = ramp * (max_angular_speed_radps / peak_w)
    axis = st.tuples(*[st.floats(-1.0, 1.0, **_finite)] * 3).filter(
        lambda a: np.linalg.norm(a) > 0.1
    )
    return AnalyticMotion(
        amplitude_m=cast(tuple[float, float, float], tuple(float(a) for a in amp)),
        frequency_hz=cast(tuple[float, float, float], tuple(float(f) for f in freq)),
        phase_rad=phase,
        rotation_axes=(draw(axis), draw(axis)),
        rotation_amplitude_rad=cast(tuple[float, float], tuple(float(a) for a in ramp)),
        rotation_frequency_hz=cast(tuple[float, float], tuple(float(f) for f in rfreq)),
        rotation_phase_rad=rphase,
        initial_rotvec_rad=draw(st.tuples(*[st.floats(-1.0, 1.0, **_finite)] * 3)),
    )


@st.composite
def analytic_sequences(
    draw: st.DrawFn,
    *,
    n_frames: int | st.SearchStrategy[int] = 12,
    size_px: tuple[int, int] = (64, 48),
    motions: st.SearchStrategy[AnalyticMotion] | None = None,
) -> InMemorySequence:
    """The analytic box rendered along a drawn motion (exact depth, masks, flow and a ``gt``
    pose set), ``size_px = (width, height)``; rendered sequences are cached."""
    n = draw(n_frames) if isinstance(n_frames, st.SearchStrategy) else n_frames
    motion = draw(motions if motions is not None else analytic_motions())
    width, height = size_px
    return analytic_sequence(n_frames=int(n), width_px=width, height_px=height, motion=motion)


@dataclass(frozen=True, slots=True)
class TrajectoryMotion:
    """A placed :class:`~roft_sim.trajectories.base.Trajectory` as an analytic-scene motion:
    ``track(t)`` samples it at ``start_s + t``."""

    trajectory: Trajectory
    """The trajectory ``T_cam_obj(t)`` (camera frame)."""

    def track(self, t_s: ArrayLike) -> PoseTrack:
        """Exact poses and velocities at times ``t_s`` ``(N,)`` [s] from the trajectory's start."""
        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64))
        s = self.trajectory.sample(self.trajectory.start_s + t)
        return PoseTrack(t_s=t, T_cam_obj=s.T_ref_obj, v_obj_mps=s.v_mps, w_radps=s.w_radps)

    def __repr__(self) -> str:
        tr = self.trajectory
        return f"TrajectoryMotion({type(tr).__name__}, {tr.end_s - tr.start_s:.2f} s)"


@st.composite
def trajectory_sequences(
    draw: st.DrawFn,
    *,
    n_frames: int = 12,
    size_px: tuple[int, int] = (64, 48),
    max_linear_speed_mps: float = 1.0,
    max_angular_speed_dps: float = 300.0,
    fps: int = 30,
) -> InMemorySequence:
    """The analytic box rendered along a synthetic hand-like trajectory with bounded peak speeds
    (:func:`roft_sim.testing.trajectory_strategies.synthetic_trajectories`, placed in view of
    this camera). The first ``n_frames`` frames at ``fps``."""
    intrinsics: CameraIntrinsics = default_intrinsics(*size_px)
    box = AnalyticBox()
    radius = float(np.linalg.norm(box.half_extents_m))
    trajectory = draw(
        synthetic_trajectories(
            intrinsics=intrinsics,
            object_radius_m=radius,
            min_linear_speed_mps=min(0.05, max_linear_speed_mps),
            max_linear_speed_mps=max_linear_speed_mps,
            min_angular_speed_dps=min(10.0, max_angular_speed_dps),
            max_angular_speed_dps=max_angular_speed_dps,
            min_duration_s=max(1.0, n_frames / fps),
            max_duration_s=max(2.0, n_frames / fps),
        )
    )
    motion = TrajectoryMotion(trajectory)
    far = float(motion.track(np.arange(n_frames) / fps).T_cam_obj[:, 2, 3].max())
    return analytic_box_sequence(
        n_frames=n_frames,
        fps=fps,
        intrinsics=intrinsics,
        box=box,
        motion=motion,
        wall_depth_m=max(1.2, far + radius + 0.2),
        name="trajectory_box",
    )


@functools.cache
def _paper_masks() -> MaskStreamFaults:
    return load_faults("paper").mask


def pose_timing_faults(
    *,
    max_delay_frames: int = 15,
    outliers: bool = False,
    camera: bool = False,
    masks: MaskStreamFaults | None = None,
) -> st.SearchStrategy[FaultConfig]:
    """Fault configurations that vary the POSE stream only: rate or busy network, delays and
    jitter, losses (dropouts, bursts, blackouts), duplicates, stale results and reordering; no
    clock skew. A delay-correct tracker must give the zero-delay result on all of them.

    Args:
        max_delay_frames: largest delay of one delay fault [frames] (two may add up).
        outliers: also draw pose outliers (translation jumps, flips, wrong object).
        camera: also draw camera-frame drops, depth and flow faults.
        masks: the mask stream, held fixed (default: the ``paper`` preset's, 5 Hz, 6 frames
            late, the first mask undelayed).
    """
    mask_stream = masks if masks is not None else _paper_masks()
    return st.builds(
        FaultConfig,
        name=st.just("generated"),
        pose=pose_stream_faults(content=outliers, skew=False, max_delay_frames=max_delay_frames),
        mask=st.just(mask_stream),
        camera=camera_faults() if camera else st.just(CameraFaults()),
        flow=flow_faults() if camera else st.just(FlowFaults()),
    )


def _delay_bucket(delays: list[int]) -> str:
    if not delays:
        return "no pose delivered"
    worst = max(delays)
    for limit in (0, 6, 12, 30):
        if worst <= limit:
            return f"max pose delay <= {limit} frames"
    return "max pose delay > 30 frames"


@st.composite
def faulted_streams(
    draw: st.DrawFn,
    sequences: DatasetSequence | st.SearchStrategy[DatasetSequence],
    faults: st.SearchStrategy[FaultConfig] | None = None,
    *,
    seeds: st.SearchStrategy[int] | None = None,
    flow: str | None = "gt",
    pose_set: str | None = "gt",
    mask_set: str | None = "gt",
    include_rgb: bool = True,
) -> FaultedStream:
    """A :class:`~roft_sim.testing.streams.FaultedStream`: a sequence (fixed or drawn), a fault
    configuration (default: :func:`roft_sim.testing.fault_strategies.fault_configs`, every
    family) and a seed. Its ``repr`` is the timeline; it reports the largest pose delay as a
    hypothesis ``event`` (see ``--hypothesis-show-statistics``).

    Args:
        sequences: a sequence, or a strategy of them (e.g. :func:`analytic_sequences`).
        faults: a strategy of fault configurations.
        seeds: the seeds (default: any 32-bit integer; shrinks towards 0).
        flow, pose_set, mask_set, include_rgb: as in
            :class:`~roft_sim.testing.streams.FaultedStream`.
    """
    sequence = draw(sequences) if isinstance(sequences, st.SearchStrategy) else sequences
    if faults is None:
        from roft_sim.testing.fault_strategies import fault_configs

        faults = fault_configs()
    config = draw(faults)
    seed = draw(seeds if seeds is not None else st.integers(0, 2**32 - 1))
    stream = FaultedStream(
        sequence=sequence,
        faults=config,
        seed=seed,
        flow=flow,
        pose_set=pose_set,
        mask_set=mask_set,
        include_rgb=include_rgb,
    )
    schedule = stream.schedule
    event(_delay_bucket([e.delay_frames for e in schedule.deliveries("pose")]))
    return stream
