"""The toolkit on a MuJoCo-rendered sequence (the plugin's session fixture): real dataset
layout, a simulated DOPE pose set with misses, detector masks, stored NVOF-like flow, and ROFT's
depth test through the MuJoCo depth renderer. Skipped without an offscreen OpenGL backend."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from roft_sim.testing import assert_well_formed, check_delay_invariance, check_determinism
from roft_sim.testing.stream_strategies import faulted_streams, pose_timing_faults
from roft_sim.testing.streams import tracker_for
from roft_sim.trackers import run_tracker
from roft_sim.trackers.roft import RoftConfig, VelocityKFConfig

pytestmark = pytest.mark.render

CONFIG = RoftConfig(velocity=VelocityKFConfig(subsampling_stride=5))


def test_rendered_fixture_is_a_small_fast_ycb_sequence(rendered_sequence):
    seq = rendered_sequence
    assert len(seq) == 8 and seq.intrinsics.shape == (48, 64)
    assert "dope" in seq.pose_sets() and "nvof_1_slow" in seq.flow_sets()
    assert any(s not in ("gt", "gt_full") for s in seq.mask_sets())


@settings(max_examples=4, deadline=None, suppress_health_check=list(HealthCheck))
@given(data=st.data())
def test_roft_on_a_rendered_sequence_replays_exactly_and_deterministically(rendered_sequence, data):
    seq = rendered_sequence
    masks = next(s for s in seq.mask_sets() if s not in ("gt", "gt_full"))
    stream = data.draw(
        faulted_streams(
            seq,
            pose_timing_faults(max_delay_frames=3, outliers=True),
            flow="stored:nvof_1_slow",
            pose_set="dope",
            mask_set=masks,
        ),
        label="stream",
    )
    observations = stream.observations()
    make = lambda: tracker_for("roft", seq, CONFIG)  # noqa: E731 - MuJoCo depth renderer
    determinism = check_determinism(make, observations).raise_if_failed()
    assert determinism.frames_checked == len(seq)
    check_delay_invariance(make, observations).raise_if_failed()
    assert_well_formed(run_tracker(make(), observations), observations)
