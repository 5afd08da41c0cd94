"""The observation stream on a tiny in-memory sequence (32x24): what a tracker sees."""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest
from fault_sequences import StrideFlowSource, make_sequence
from hypothesis import given, settings
from hypothesis import strategies as st

from roft_sim.errors import ConfigError, RoftSimError
from roft_sim.faults import (
    BernoulliDropout,
    Blackout,
    CameraFaults,
    DepthNoise,
    FaultConfig,
    FlowFaults,
    FlowReversed,
    MaskShift,
    MaskStreamFaults,
    ObservationStream,
    PoseStreamFaults,
    RotationFlip,
    TranslationJump,
    load_faults,
)
from roft_sim.records import Observation
from roft_sim.testing.fault_strategies import fault_configs


def fingerprint(sequence) -> str:
    h = hashlib.sha256()
    for k in range(len(sequence)):
        h.update(sequence.rgb(k).tobytes())
        h.update(sequence.depth(k).tobytes())
        for mask_set in sequence.mask_sets():
            m = sequence.mask(k, mask_set)
            h.update(b"none" if m is None else m.tobytes())
    h.update(sequence.detector_poses("dope").T_cam_obj.tobytes())
    h.update(sequence.detector_poses("dope").valid.tobytes())
    h.update(sequence.ground_truth().T_cam_obj.tobytes())
    return h.hexdigest()


def observation_digest(obs: Observation) -> tuple:
    def arr(a):
        return None if a is None else hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()

    return (
        obs.k,
        obs.t_s,
        arr(obs.rgb),
        arr(obs.depth_m),
        None if obs.flow is None else (obs.flow.from_k, obs.flow.to_k, arr(obs.flow.flow_px)),
        tuple((p.detection_id, p.capture_k, p.arrival_k, arr(p.T_cam_obj)) for p in obs.poses),
        tuple((m.detection_id, m.capture_k, m.arrival_k, arr(m.mask)) for m in obs.masks),
    )


def test_none_preset_delivers_the_detector_output_of_every_frame(tiny_sequence):
    stream = ObservationStream(
        tiny_sequence, load_faults("none"), seed=0, flow_source=StrideFlowSource()
    )
    observations = list(stream)
    assert [o.k for o in observations] == list(range(40))
    detector = tiny_sequence.detector_poses("dope").T_cam_obj
    gt = tiny_sequence.ground_truth().T_cam_obj
    for o in observations:
        assert o.t_s == pytest.approx(o.k / 30)
        assert o.rgb[0, 0, 0] == o.k and o.depth_m[0, 0] == pytest.approx(0.5 + o.k / 1000)
        (pose,) = o.poses
        (mask,) = o.masks
        assert pose.capture_k == pose.arrival_k == mask.capture_k == mask.arrival_k == o.k
        np.testing.assert_array_equal(pose.T_cam_obj, detector[o.k])
        assert not np.allclose(pose.T_cam_obj, gt[o.k])  # the detector, never ground truth
        np.testing.assert_array_equal(mask.mask, tiny_sequence.mask(o.k, "mrcnn"))
        assert (o.flow is None) == (o.k == 0)
        if o.flow is not None:
            assert (o.flow.from_k, o.flow.to_k) == (o.k - 1, o.k)


def test_paper_preset_observations(tiny_sequence):
    stream = ObservationStream(tiny_sequence, load_faults("paper"), seed=3, flow_source=None)
    carrying = {o.k: o for o in stream if o.poses or o.masks}
    assert sorted(carrying) == [0, 12, 18, 24, 30, 36]
    assert carrying[0].poses[0].capture_k == 0
    for k in (12, 18, 24, 30, 36):
        (pose,), (mask,) = carrying[k].poses, carrying[k].masks
        assert pose.capture_k == mask.capture_k == k - 6 and pose.arrival_k == k
        np.testing.assert_array_equal(mask.mask, tiny_sequence.mask(k - 6, "mrcnn"))


def test_dropped_camera_frames_have_no_images_and_the_next_flow_spans_two_frames(tiny_sequence):
    faults = FaultConfig(camera=CameraFaults(faults=(Blackout(windows=((5, 6), (20, 22))),)))
    source = StrideFlowSource()
    stream = ObservationStream(tiny_sequence, faults, seed=0, flow_source=source)
    obs = list(stream)
    for k in (5, 20, 21):
        assert obs[k].camera_dropped and obs[k].rgb is None and obs[k].depth_m is None
        assert obs[k].flow is None
        assert len(obs[k].poses) == 1  # detections still arrive on a dropped camera frame
    assert (obs[6].flow.from_k, obs[6].flow.to_k, obs[6].flow.stride) == (4, 6, 2)
    assert obs[6].flow.flow_px[0, 0, 0] == 2.0  # the source's stride-2 flow
    assert (obs[22].flow.from_k, obs[22].flow.stride) == (19, 3)
    assert (4, 6) in source.calls and (5, 6) not in source.calls and (4, 5) not in source.calls
    assert stream.ledger.camera.dropped_by[5] == "camera.faults[0] (blackout)"


def test_masks_and_poses_carry_reported_capture_and_arrival():
    seq = make_sequence(60)
    stream = ObservationStream(seq, load_faults("reorder"), seed=2, flow_source=None)
    seen = 0
    for o in stream:
        for p in o.poses:
            record = stream.ledger.record("pose", p.detection_id)
            assert p.arrival_k == o.k and o.k in record.arrivals
            assert p.capture_k == record.reported_capture_k
            np.testing.assert_array_equal(
                p.T_cam_obj, seq.detector_poses("dope").T_cam_obj[record.true_capture_k]
            )
            seen += 1
        for m in o.masks:
            record = stream.ledger.record("mask", m.detection_id)
            assert m.arrival_k == o.k and m.capture_k == record.reported_capture_k
            np.testing.assert_array_equal(m.mask, seq.mask(record.true_capture_k, "mrcnn"))
    assert seen > 10
    skewed = [r for r in stream.ledger.pose if r.reported_capture_k != r.true_capture_k]
    assert skewed, "the reorder preset's time-stamp noise should skew some captures"


def test_ledger_marks_exactly_the_injected_outliers():
    seq = make_sequence(120)
    faults = FaultConfig(
        pose=PoseStreamFaults(faults=(TranslationJump(p=0.2), RotationFlip(p=0.1))),
        mask=MaskStreamFaults(faults=(MaskShift(p=0.3, min_px=1, max_px=3),)),
    )
    stream = ObservationStream(seq, faults, seed=11, flow_source=None)
    detector = seq.detector_poses("dope").T_cam_obj
    changed_poses, changed_masks = set(), set()
    for o in stream:
        for p in o.poses:
            if not np.array_equal(p.T_cam_obj, detector[p.capture_k]):
                changed_poses.add(p.detection_id)
        for m in o.masks:
            if not np.array_equal(m.mask, seq.mask(m.capture_k, "mrcnn")):
                changed_masks.add(m.detection_id)
    assert changed_poses == stream.ledger.outlier_ids() and len(changed_poses) > 10
    assert changed_masks == stream.ledger.corrupted_mask_ids() and len(changed_masks) > 10
    summary = stream.ledger.summary()
    assert summary["pose"]["outliers"] == len(changed_poses)
    assert summary["pose"]["fates"] == {"delivered": 120}


def test_detector_misses_produce_no_detection():
    seq = make_sequence(30, pose_miss=(3, 12), mask_miss=(4, 12))
    stream = ObservationStream(seq, load_faults("none"), seed=0, flow_source=None)
    obs = list(stream)
    assert not obs[3].poses and obs[3].masks and not obs[4].masks and obs[4].poses
    assert not obs[12].poses and not obs[12].masks
    assert stream.ledger.record("pose", 3).fate == "missed"
    assert stream.ledger.record("mask", 4).fate == "missed"
    paper = ObservationStream(seq, load_faults("paper"), seed=0, flow_source=None)
    assert paper.ledger.record("pose", 2).fate == "missed"  # frame 12, would arrive at 18
    assert not list(paper)[18].poses


def test_ideal_detections_ignore_rate_and_delay():
    seq = make_sequence(30)
    ideal = ObservationStream(
        seq, load_faults("paper"), seed=0, flow_source=None, ideal_detections=True
    )
    for o in ideal:
        assert [p.capture_k for p in o.poses] == [o.k] == [m.capture_k for m in o.masks]


def test_the_same_seed_gives_the_same_stream_and_another_seed_another():
    seq = make_sequence(40)
    faults = load_faults("chaos")
    run = lambda seed: [  # noqa: E731
        observation_digest(o)
        for o in ObservationStream(seq, faults, seed=seed, flow_source=StrideFlowSource())
    ]
    assert run(5) == run(5)
    assert run(5) != run(6)


@settings(max_examples=15)
@given(fault_configs(), st.integers(0, 2**32 - 1))
def test_the_stream_is_a_pure_function_of_its_inputs(faults, seed):
    seq = make_sequence(24)
    before = fingerprint(seq)
    source = StrideFlowSource()
    first = [
        observation_digest(o) for o in ObservationStream(seq, faults, seed=seed, flow_source=source)
    ]
    assert fingerprint(seq) == before  # the sequence (and its ground truth) never changes
    # random access gives the same frames as iteration, in any order
    stream = ObservationStream(seq, faults, seed=seed, flow_source=source)
    for k in reversed(range(len(seq))):
        assert observation_digest(stream.observation(k)) == first[k]
    for o in stream:
        if o.depth_m is not None:
            assert o.depth_m.dtype == np.float32 and not o.depth_m.flags.writeable
        for m in o.masks:
            assert m.mask.dtype == np.bool_ and m.mask.shape == (24, 32)
        for p in o.poses:
            assert np.isfinite(p.T_cam_obj).all()
            np.testing.assert_allclose(p.T_cam_obj[:3, :3] @ p.T_cam_obj[:3, :3].T, np.eye(3),
                                       atol=1e-9)  # fmt: skip


def test_observations_cannot_be_used_to_write_into_the_sequence(tiny_sequence):
    o = ObservationStream(tiny_sequence, load_faults("none"), seed=0, flow_source=None).observation(
        3
    )
    with pytest.raises(ValueError, match="read-only"):
        o.rgb[0, 0, 0] = 99
    with pytest.raises(ValueError, match="read-only"):
        o.depth_m[0, 0] = 9.0


def test_depth_and_flow_faults_reach_the_observation(tiny_sequence):
    faults = FaultConfig(
        camera=CameraFaults(faults=(DepthNoise(p=1.0, burst_frames=1, sd_m=0.05),)),
        flow=FlowFaults(faults=(FlowReversed(p=1.0),)),
    )
    o = ObservationStream(
        tiny_sequence, faults, seed=0, flow_source=StrideFlowSource()
    ).observation(7)
    assert np.std(o.depth_m - tiny_sequence.depth(7)) == pytest.approx(0.05, rel=0.3)
    assert o.flow.flow_px[0, 0, 0] == -1.0


def test_backward_flow_mode_asks_the_source_for_the_reverse_pair(tiny_sequence):
    faults = FaultConfig(flow=FlowFaults(faults=(FlowReversed(p=1.0, mode="backward"),)))
    source = StrideFlowSource()
    o = ObservationStream(tiny_sequence, faults, seed=0, flow_source=source).observation(7)
    assert source.calls == [(7, 6)]
    assert (o.flow.from_k, o.flow.to_k) == (6, 7) and o.flow.flow_px[0, 0, 0] == -1.0


def test_flow_source_that_returns_the_wrong_pair_is_an_error(tiny_sequence):
    class Wrong(StrideFlowSource):
        def flow(self, sequence, from_k, to_k):
            return super().flow(sequence, from_k, to_k + 1)

    stream = ObservationStream(tiny_sequence, load_faults("none"), seed=0, flow_source=Wrong())
    with pytest.raises(RoftSimError, match=r"returned the flow 2->4 when asked for 2->3"):
        stream.observation(3)


def test_stream_options_and_errors(tiny_sequence):
    with pytest.raises(ConfigError, match=r"no pose set 'posecnn'; available: \['dope'\]"):
        ObservationStream(tiny_sequence, load_faults("none"), seed=0, flow_source=None,
                          pose_set="posecnn")  # fmt: skip
    with pytest.raises(ConfigError, match=r"no mask set 'x'; available: \['gt', 'mrcnn'\]"):
        ObservationStream(tiny_sequence, load_faults("none"), seed=0, flow_source=None,
                          mask_set="x")  # fmt: skip
    only_gt = dataclasses.replace(tiny_sequence, detector_masks={})
    with pytest.raises(ConfigError, match="no detector mask set.*mask_set='gt'"):
        ObservationStream(only_gt, load_faults("none"), seed=0, flow_source=None)
    gt_masks = ObservationStream(only_gt, load_faults("none"), seed=0, flow_source=None,
                                 mask_set="gt")  # fmt: skip
    np.testing.assert_array_equal(gt_masks.observation(2).masks[0].mask, only_gt.gt_masks[2])
    bare = ObservationStream(tiny_sequence, load_faults("none"), seed=0, flow_source=None,
                             pose_set=None, mask_set=None, include_rgb=False)  # fmt: skip
    o = bare.observation(1)
    assert o.poses == () and o.masks == () and o.rgb is None and o.depth_m is not None
    at_24 = dataclasses.replace(tiny_sequence, fps=24)
    with pytest.raises(ConfigError, match="rate_hz = 5 does not divide the camera rate 24"):
        ObservationStream(at_24, load_faults("paper"), seed=0, flow_source=None)
    with pytest.raises(IndexError, match="frame 40 out of range"):
        bare.observation(40)


def test_dropout_of_detections_in_the_stream():
    seq = make_sequence(200)
    faults = FaultConfig(pose=PoseStreamFaults(faults=(BernoulliDropout(p=0.3),)))
    stream = ObservationStream(seq, faults, seed=1, include_rgb=False, flow_source=None,
                               mask_set=None)  # fmt: skip
    delivered = sum(len(o.poses) for o in stream)
    dropped = stream.ledger.summary()["pose"]["fates"]["dropped"]
    assert delivered + dropped == 200 and 30 < dropped < 90


def test_auto_mask_set_never_picks_a_ground_truth_set(tiny_sequence):
    # Fast-YCB and BOP sequences list "gt" and "gt_full" (the amodal ground-truth silhouette)
    # before the detector sets: "auto" must skip both, or ground truth reaches the tracker.
    full = [None if m is None else m.copy() for m in tiny_sequence.gt_masks]
    seq = dataclasses.replace(
        tiny_sequence, detector_masks={"gt_full": full, **tiny_sequence.detector_masks}
    )
    assert seq.mask_sets() == ("gt", "gt_full", "mrcnn")
    stream = ObservationStream(seq, load_faults("none"), seed=0, flow_source=None)
    assert stream.mask_set == "mrcnn"
    only_gt = dataclasses.replace(tiny_sequence, detector_masks={"gt_full": full})
    with pytest.raises(ConfigError, match="no detector mask set"):
        ObservationStream(only_gt, load_faults("none"), seed=0, flow_source=None)
