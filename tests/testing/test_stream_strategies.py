"""The stream strategies: speed bounds hold, pose-only fault families vary only the pose
stream, and a failing property shrinks to a minimal schedule printed as a timeline."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import Phase, find, given, settings
from hypothesis import strategies as st

from roft_sim.faults import load_faults
from roft_sim.testing import FaultedStream, pose_delays
from roft_sim.testing.fault_strategies import fault_configs
from roft_sim.testing.fixtures import analytic_sequence
from roft_sim.testing.profiles import CI_PROFILE, THOROUGH_PROFILE, tracker_settings
from roft_sim.testing.stream_strategies import (
    analytic_motions,
    analytic_sequences,
    faulted_streams,
    pose_timing_faults,
    trajectory_sequences,
)

SEQ = analytic_sequence(n_frames=16, width_px=32, height_px=24)
_SEARCH = settings(
    max_examples=300, derandomize=True, database=None, deadline=None,
    phases=[Phase.generate, Phase.shrink],
)  # fmt: skip


@settings(max_examples=20, deadline=None)
@given(analytic_motions(max_linear_speed_mps=0.3, max_angular_speed_radps=1.5))
def test_analytic_motions_stay_within_their_speed_bounds(motion):
    track = motion.track(np.linspace(0.0, 10.0, 2001))
    assert np.linalg.norm(track.v_obj_mps, axis=1).max() <= 0.3 + 1e-9
    assert np.linalg.norm(track.w_radps, axis=1).max() <= 1.5 + 1e-9


@settings(max_examples=5, deadline=None)
@given(analytic_sequences(n_frames=st.integers(2, 6), size_px=(32, 24)))
def test_analytic_sequences_render_the_drawn_motion(seq):
    assert 2 <= len(seq) <= 6 and seq.intrinsics.shape == (24, 32)
    assert seq.detector_poses("gt").T_cam_obj.shape == (len(seq), 4, 4)


@settings(max_examples=5, deadline=None)
@given(trajectory_sequences(n_frames=10, size_px=(48, 36), max_linear_speed_mps=0.4,
                            max_angular_speed_dps=90.0))  # fmt: skip
def test_trajectory_sequences_keep_the_speed_bounds_and_the_object_in_view(seq):
    gt = seq.ground_truth()
    assert np.linalg.norm(gt.v_obj_mps, axis=1).max() <= 0.4 * (1 + 1e-6)
    assert np.degrees(np.linalg.norm(gt.w_radps, axis=1).max()) <= 90.0 * (1 + 1e-6)
    assert all(seq.mask(k, "gt").sum() > 10 for k in range(len(seq)))


@settings(max_examples=30, deadline=None)
@given(faulted_streams(SEQ, pose_timing_faults()))
def test_pose_timing_faults_vary_the_pose_stream_only(stream):
    paper = load_faults("paper")
    assert stream.faults.mask == paper.mask
    assert stream.faults.camera.faults == () and stream.faults.flow.faults == ()
    kinds = {f.kind for f in stream.faults.pose.faults}
    assert "clock_skew" not in kinds
    assert not kinds & {"translation_jump", "rotation_flip", "wrong_object"}


def test_a_failing_property_shrinks_to_a_short_schedule_printed_as_a_timeline():
    """Find a schedule that delivers some pose 8 or more frames late, from configurations of
    every fault family: the shrunk example keeps a few pose faults and nothing else, and prints
    as a capture -> arrival timeline. (Shrinking cannot always drop a no-op fault: every fault
    draws from a generator keyed by its kind and occurrence, so removing one changes the draws
    of the next of its kind.)"""
    found = find(
        faulted_streams(SEQ, fault_configs()),
        lambda s: max(pose_delays(s.observations()), default=0) >= 8,
        settings=_SEARCH,
    )
    assert 1 <= len(found.faults.pose.faults) <= 3
    assert found.faults.mask.faults == () and found.faults.camera.faults == ()
    assert found.faults.flow.faults == ()
    text = repr(found)
    assert "pose.faults[0]:" in text and "pose run" in text
    longest = re.search(r"^pose: .* delay \d+\.\.(\d+) frames", text, re.MULTILINE)
    assert longest is not None and int(longest.group(1)) >= 8


def test_hypothesis_reports_the_failing_stream_as_its_timeline():
    @settings(max_examples=50, derandomize=True, database=None, phases=[Phase.generate])
    @given(faulted_streams(SEQ, pose_timing_faults(max_delay_frames=6)))
    def no_pose_is_late(stream):
        assert max(pose_delays(stream.observations()), default=0) == 0

    with pytest.raises(AssertionError) as failure:
        no_pose_is_late()
    notes = "\n".join(getattr(failure.value, "__notes__", []))
    assert "FaultedStream(sequence='analytic_box' (16 frames)" in notes
    assert "capture reported  arrival(s)" in notes


def test_profiles_are_registered_and_tracker_settings_scale_with_the_active_one():
    ci = settings.get_profile(CI_PROFILE)
    assert ci.derandomize and ci.database is None and ci.deadline is None
    assert settings.get_profile(THOROUGH_PROFILE).max_examples >= 2000
    half = tracker_settings(fraction=0.5)
    assert half.max_examples == max(1, round(settings.default.max_examples / 2))
    assert half.deadline is None
    with pytest.raises(ValueError, match="fraction must be > 0"):
        tracker_settings(fraction=0)


def test_faulted_stream_equality_of_draws_is_by_seed_and_config():
    a = FaultedStream(sequence=SEQ, faults=load_faults("chaos"), seed=4)
    b = FaultedStream(sequence=SEQ, faults=load_faults("chaos"), seed=4)
    assert repr(a) == repr(b)
