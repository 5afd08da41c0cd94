"""Hypothesis strategies for fault configurations and schedules (public test toolkit).

Use them to property-test a tracker under generated fault schedules::

    from hypothesis import given
    from roft_sim.testing.fault_strategies import fault_configs

    @given(fault_configs(content=False), st.integers(0, 2**32 - 1))
    def test_tracker_survives(faults, seed):
        stream = ObservationStream(sequence, faults, seed=seed, flow_source=None)
        ...

Every strategy builds valid configs by construction (rates divide 30 fps, probabilities in
[0, 1], ranges ordered) and shrinks towards fewer faults, smaller delays and smaller
probabilities, so a failing example reads as a short fault list; print it as a timeline with
:func:`roft_sim.faults.format_timeline`.
"""

from __future__ import annotations

import functools
from typing import Any, TypeVar

from hypothesis import strategies as st

from roft_sim.faults import (
    BernoulliDropout,
    Blackout,
    BusyNetwork,
    CameraFaults,
    ClockSkew,
    DepthHoles,
    DepthNoise,
    DetectionSchedule,
    Duplicate,
    EmpiricalDelay,
    EmptyMask,
    FaultConfig,
    FirstResult,
    FixedDelay,
    FlowFaults,
    FlowHoles,
    FlowNoise,
    FlowReversed,
    GilbertElliott,
    LogNormalDelay,
    MaskMorphology,
    MaskShift,
    MaskStreamFaults,
    PoseStreamFaults,
    Rate,
    Reorder,
    RotationFlip,
    SpuriousBlobs,
    Stale,
    TranslationJump,
    UniformDelay,
    WrongFrameMask,
    WrongObject,
    schedule_detections,
)

__all__ = [
    "probabilities",
    "delay_distributions",
    "sampling_faults",
    "loss_faults",
    "stamp_faults",
    "delivery_faults",
    "pose_outlier_faults",
    "mask_corruption_faults",
    "pose_stream_faults",
    "mask_stream_faults",
    "camera_faults",
    "flow_faults",
    "fault_configs",
    "timing_only_configs",
    "detection_schedules",
]

_DIVISORS_OF_30 = (1, 2, 3, 5, 6, 10, 15, 30)

# The strategy builders below are memoised (@functools.cache): strategies are immutable, and
# _stream_faults draws from them once per example, so building them anew each time (and letting
# hypothesis validate them again) tripled the cost of drawing a fault configuration.


@functools.cache
def probabilities(max_p: float = 1.0) -> st.SearchStrategy[float]:
    """Probabilities in [0, max_p] (shrink towards 0)."""
    return st.floats(0.0, max_p, allow_nan=False, allow_infinity=False)


@functools.cache
def delay_distributions(max_frames: int = 15) -> st.SearchStrategy:
    """Any delay model with delays in [0, max_frames] frames."""
    fixed = st.builds(FixedDelay, frames=st.integers(0, max_frames))
    uniform = st.tuples(st.integers(0, max_frames), st.integers(0, max_frames)).map(
        lambda ab: UniformDelay(min_frames=min(ab), max_frames=max(ab))
    )
    lognormal = st.builds(
        LogNormalDelay,
        median_frames=st.floats(0.5, max(0.5, float(max_frames))),
        sigma=st.floats(0.0, 1.0),
        max_frames=st.just(max_frames),
    )
    empirical = st.lists(st.integers(0, max_frames), min_size=1, max_size=5).map(
        lambda f: EmpiricalDelay(frames=tuple(f))
    )
    return st.one_of(fixed, uniform, lognormal, empirical)


@functools.cache
def sampling_faults(max_period_frames: int = 10) -> st.SearchStrategy:
    """A ``rate`` (period or a divisor of 30 Hz) or a ``busy`` network."""
    by_period = st.builds(
        Rate,
        period_frames=st.integers(1, max_period_frames),
        phase_frames=st.integers(0, 5),
    )
    by_hz = st.builds(Rate, rate_hz=st.sampled_from(_DIVISORS_OF_30))
    busy = st.builds(BusyNetwork, processing=delay_distributions(max_period_frames))
    return st.one_of(by_period, by_hz, busy)


@functools.cache
def _windows() -> st.SearchStrategy[tuple[tuple[int, int], ...]]:
    window = st.tuples(st.integers(0, 200), st.integers(1, 30)).map(lambda s: (s[0], s[0] + s[1]))
    return st.lists(window, max_size=3).map(tuple)


@functools.cache
def loss_faults() -> st.SearchStrategy:
    """Bernoulli, Gilbert-Elliott or capture-blackout losses."""
    return st.one_of(
        st.builds(BernoulliDropout, p=probabilities(0.6)),
        st.builds(
            GilbertElliott,
            p_good_to_bad=probabilities(0.5),
            p_bad_to_good=st.floats(0.05, 1.0),
            loss_in_bad=probabilities(),
            loss_in_good=probabilities(0.2),
        ),
        st.builds(Blackout, windows=_windows(), on=st.just("capture")),
    )


@functools.cache
def stamp_faults() -> st.SearchStrategy:
    """Clock skew: offset, drift and time-stamp noise."""
    return st.builds(
        ClockSkew,
        offset_frames=st.floats(-3.0, 3.0),
        drift=st.floats(-0.02, 0.02),
        noise_sd_frames=st.floats(0.0, 2.0),
    )


@functools.cache
def delivery_faults() -> st.SearchStrategy:
    """Duplicates, stale results, reordering and arrival blackouts (drop or hold)."""
    after = st.tuples(st.integers(0, 5), st.integers(0, 5)).map(sorted)
    return st.one_of(
        st.builds(
            lambda p, ab: Duplicate(p=p, min_after_frames=ab[0], max_after_frames=ab[1]),
            probabilities(0.5),
            after,
        ),
        st.builds(Stale, p=probabilities(0.5)),
        st.builds(Reorder, p=probabilities(0.5), past_events=st.integers(1, 3)),
        st.builds(
            Blackout,
            windows=_windows(),
            on=st.just("arrival"),
            mode=st.sampled_from(["drop", "hold"]),
        ),
    )


@functools.cache
def pose_outlier_faults() -> st.SearchStrategy:
    """Translation jumps, rotation flips and wrong-object poses."""
    return st.one_of(
        st.builds(TranslationJump, p=probabilities(0.5)),
        st.builds(RotationFlip, p=probabilities(0.5)),
        st.builds(WrongObject, p=probabilities(0.5)),
    )


@functools.cache
def mask_corruption_faults() -> st.SearchStrategy:
    """Mask shifts, erosion/dilation, empty masks, blobs and wrong-frame masks (small sizes,
    for tiny test images)."""
    return st.one_of(
        st.builds(MaskShift, p=probabilities(0.5), min_px=st.just(1), max_px=st.integers(1, 8)),
        st.builds(MaskMorphology, p=probabilities(0.5), min_radius_px=st.integers(-3, 0),
                  max_radius_px=st.integers(0, 3)),
        st.builds(EmptyMask, p=probabilities(0.5)),
        st.builds(SpuriousBlobs, p=probabilities(0.5), min_radius_px=st.just(1),
                  max_radius_px=st.integers(1, 6)),
        st.builds(WrongFrameMask, p=probabilities(0.5), max_offset_frames=st.integers(1, 8)),
    )  # fmt: skip


_StreamFaults = TypeVar("_StreamFaults", PoseStreamFaults, MaskStreamFaults)


@st.composite
def _stream_faults(
    draw: st.DrawFn,
    cls: type[_StreamFaults],
    content: st.SearchStrategy[Any] | None,
    *,
    timing: bool,
    loss: bool,
    delivery: bool,
    skew: bool,
    max_delay_frames: int,
) -> _StreamFaults:
    faults: list[Any] = []
    if timing:
        sampling = draw(st.none() | sampling_faults())
        if sampling is not None:
            faults.append(sampling)
        faults += draw(st.lists(delay_distributions(max_delay_frames), max_size=2))
    if loss:
        faults += draw(st.lists(loss_faults(), max_size=2))
    if content is not None:
        faults += draw(st.lists(content, max_size=2))
    if skew:
        faults += draw(st.lists(stamp_faults(), max_size=1))
    if delivery:
        faults += draw(st.lists(delivery_faults(), max_size=3))
    first: FirstResult = draw(st.sampled_from(["delayed", "undelayed", "undelayed_and_delayed"]))
    return cls(first_result=first, faults=tuple(faults))


def pose_stream_faults(
    *,
    timing: bool = True,
    loss: bool = True,
    content: bool = True,
    delivery: bool = True,
    skew: bool = True,
    max_delay_frames: int = 15,
) -> st.SearchStrategy[PoseStreamFaults]:
    """A pose stream with any combination of the enabled fault families."""
    return _stream_faults(
        PoseStreamFaults,
        pose_outlier_faults() if content else None,
        timing=timing,
        loss=loss,
        delivery=delivery,
        skew=skew,
        max_delay_frames=max_delay_frames,
    )


def mask_stream_faults(
    *,
    timing: bool = True,
    loss: bool = True,
    content: bool = True,
    delivery: bool = True,
    skew: bool = True,
    max_delay_frames: int = 15,
) -> st.SearchStrategy[MaskStreamFaults]:
    """A mask stream with any combination of the enabled fault families."""
    return _stream_faults(
        MaskStreamFaults,
        mask_corruption_faults() if content else None,
        timing=timing,
        loss=loss,
        delivery=delivery,
        skew=skew,
        max_delay_frames=max_delay_frames,
    )


@functools.cache
def camera_faults() -> st.SearchStrategy[CameraFaults]:
    """Dropped camera frames, depth holes and depth noise (small sizes)."""
    fault = st.one_of(
        st.builds(BernoulliDropout, p=probabilities(0.5)),
        st.builds(GilbertElliott, p_good_to_bad=probabilities(0.3),
                  p_bad_to_good=st.floats(0.2, 1.0)),
        st.builds(Blackout, windows=_windows()),
        st.builds(DepthHoles, p=probabilities(), burst_frames=st.integers(1, 5),
                  min_radius_px=st.just(1), max_radius_px=st.integers(1, 6)),
        st.builds(DepthNoise, p=probabilities(), burst_frames=st.integers(1, 5),
                  sd_m=st.floats(1e-4, 0.05)),
    )  # fmt: skip
    return st.lists(fault, max_size=3).map(lambda f: CameraFaults(faults=tuple(f)))


@functools.cache
def flow_faults() -> st.SearchStrategy[FlowFaults]:
    """Flow noise, holes and sign flips."""
    fault = st.one_of(
        st.builds(FlowNoise, p=probabilities(), sd_px=st.floats(0.01, 5.0)),
        st.builds(FlowHoles, p=probabilities(), min_radius_px=st.just(1),
                  max_radius_px=st.integers(1, 6)),
        st.builds(FlowReversed, p=probabilities(), burst_frames=st.integers(1, 4)),
    )  # fmt: skip
    return st.lists(fault, max_size=3).map(lambda f: FlowFaults(faults=tuple(f)))


def fault_configs(
    *,
    timing: bool = True,
    loss: bool = True,
    content: bool = True,
    delivery: bool = True,
    skew: bool = True,
    camera: bool = True,
    max_delay_frames: int = 15,
) -> st.SearchStrategy[FaultConfig]:
    """Complete fault configurations with the enabled families (all by default)."""
    flags: dict[str, Any] = {
        "timing": timing,
        "loss": loss,
        "content": content,
        "delivery": delivery,
        "skew": skew,
        "max_delay_frames": max_delay_frames,
    }
    no_camera = st.just(CameraFaults())
    no_flow = st.just(FlowFaults())
    return st.builds(
        FaultConfig,
        name=st.just("generated"),
        pose=pose_stream_faults(**flags),
        mask=mask_stream_faults(**flags),
        camera=camera_faults() if camera else no_camera,
        flow=flow_faults() if camera else no_flow,
    )


def timing_only_configs(max_delay_frames: int = 15) -> st.SearchStrategy[FaultConfig]:
    """Rates, delays, losses and delivery faults, no content or camera faults: schedules a
    correct tracker must handle exactly (delay invariance, order invariance)."""
    return fault_configs(content=False, skew=False, camera=False, max_delay_frames=max_delay_frames)


@st.composite
def detection_schedules(
    draw: st.DrawFn,
    configs: st.SearchStrategy[FaultConfig] | None = None,
    *,
    max_frames: int = 120,
    fps: int = 30,
) -> tuple[FaultConfig, int, DetectionSchedule]:
    """``(faults, seed, schedule)`` triples: a config, a seed and its schedule over up to
    ``max_frames`` frames (every frame counted as detected)."""
    faults = draw(configs if configs is not None else fault_configs())
    seed = draw(st.integers(0, 2**32 - 1))
    n_frames = draw(st.integers(0, max_frames))
    return faults, seed, schedule_detections(n_frames, faults, seed, fps=fps)
