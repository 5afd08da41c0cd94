"""The ROFT tracker: pose synchronisation by replay, buffers, outlier rejection, ablations,
accuracy with ground-truth inputs, and well-formedness under random fault schedules."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from observation_schedules import (
    Delivery,
    build_observations,
    make_context,
    paper_schedule,
    run,
    scaled_examples,
)

from roft_sim.errors import ConfigError, PluginError
from roft_sim.geometry import (
    matrix_from_rotvec,
    transform_distance,
    transform_from_rt,
    v_o_from_v_obj,
)
from roft_sim.records import ESTIMATE_COVARIANCE_ORDER, Estimate, Observation
from roft_sim.trackers import create_tracker, get_tracker_spec, load_tracker_config
from roft_sim.trackers.roft import (
    ABLATIONS,
    RoftConfig,
    RoftTracker,
    VelocityKFConfig,
    ablation_config,
)
from roft_sim.trackers.roft.config import CovarianceScaleConfig, PoseGateConfig, PoseSyncConfig
from roft_sim.trackers.roft.mask_sync import PixelSet, metric_erosion_px

TINY = RoftConfig(velocity=VelocityKFConfig(subsampling_stride=5))
"""On 64x48 images the object has ~200 pixels: a smaller stride keeps the flow update alive."""


def _perturbed(seq, c: int, rng: np.random.Generator, wild: bool) -> np.ndarray:
    T = seq.gt.T_cam_obj[c].copy()
    dT = transform_from_rt(matrix_from_rotvec(rng.normal(0, 0.03, 3)), rng.normal(0, 0.005, 3))
    T = dT @ T
    if wild:
        T[:3, 3] += [0.15, -0.1, 0.2]
    return T


@st.composite
def pose_deliveries(draw, n_frames: int, max_delay: int = 15, wild_ok: bool = True):
    captures = sorted(draw(st.sets(st.integers(0, n_frames - 1), min_size=1, max_size=9)))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    out = []
    for i, c in enumerate(captures):
        delay = draw(st.integers(0, max_delay))
        wild = wild_ok and draw(st.integers(0, 4)) == 0
        out.append((c, delay, i, wild))
    order = draw(st.permutations(range(len(out))))
    return [out[i] for i in order], rng


def _assert_estimates_equal(a: Estimate, b: Estimate, atol: float = 1e-9) -> None:
    assert a.valid and b.valid
    np.testing.assert_allclose(a.T_cam_obj, b.T_cam_obj, rtol=0, atol=atol)
    np.testing.assert_allclose(a.v_obj_mps, b.v_obj_mps, rtol=0, atol=atol)
    np.testing.assert_allclose(a.w_radps, b.w_radps, rtol=0, atol=atol)
    np.testing.assert_allclose(a.covariance, b.covariance, rtol=0, atol=atol)


GATED = dataclasses.replace(
    TINY,
    gate=PoseGateConfig(
        enable=True, max_translation_m=0.03, max_rotation_deg=8.0, max_consecutive_rejections=1
    ),
)
"""With the pose gate at tight bounds, so that the perturbed test poses are gated often."""


@pytest.mark.parametrize("config", [TINY, GATED], ids=["reference", "gated"])
@settings(max_examples=scaled_examples(8))
@given(data=st.data())
def test_replay_makes_delayed_poses_exact(tiny_seq, config, data):
    """After every pose captured up to frame k has arrived, the estimate at k equals (1e-9) the
    estimate of a run in which every pose arrived at its capture frame: any delays 0-15,
    arrival orders, outliers (the depth test runs in both). With the pose gate too: its
    decisions depend only on the replayed beliefs and the rejection streak stored per frame."""
    seq = tiny_seq
    n = len(seq)
    schedule, rng = data.draw(pose_deliveries(n))
    poses = {i: _perturbed(seq, c, rng, wild) for c, _, i, wild in schedule}
    delayed = [Delivery(c, c + d, i, poses[i]) for c, d, i, _ in schedule if c + d < n]
    prompt = [Delivery(c, c, i, poses[i]) for c, _, i, _ in schedule]
    masks = paper_schedule(n, first_id=1000)
    tracker = RoftTracker(config, make_context(seq))
    est_delayed = run(tracker, build_observations(seq, poses=delayed, masks=masks))
    est_prompt = run(tracker, build_observations(seq, poses=prompt, masks=masks))
    for k in range(n):
        complete = all(c + d <= k for c, d, _, _ in schedule if c <= k)
        if complete and any(c <= k for c, _, _, _ in schedule):
            _assert_estimates_equal(est_delayed[k], est_prompt[k])


@settings(max_examples=scaled_examples(4))
@given(data=st.data())
def test_pose_arrivals_and_replays_leave_the_reported_twist_alone(tiny_seq, data):
    """Issue 14's saw-tooth hypothesis, "each replay disturbs the velocity state", cannot hold:
    with the same flow and masks, the reported spatial twist (v_o, w) is the same to the bit
    whatever poses arrive after the first, whenever, in any order, outliers included (every
    arrival replays the pose UKF); only the pose-dependent quantities change."""
    seq = tiny_seq
    n = len(seq)
    schedule, rng = data.draw(pose_deliveries(n))
    first = Delivery(0, 0, 500)
    later = [
        Delivery(c, c + d, i, _perturbed(seq, c, rng, wild))
        for c, d, i, wild in schedule
        if c + d < n
    ]
    masks = paper_schedule(n, first_id=1000)
    alone = _pose_run(seq, [first], masks=masks)
    with_poses = _pose_run(seq, [first, *later], masks=masks)
    for a, b in zip(alone, with_poses, strict=True):
        assert (a.spatial_twist is None) == (b.spatial_twist is None)
        if a.spatial_twist is not None:
            np.testing.assert_array_equal(a.spatial_twist, b.spatial_twist)
    if any(not wild and c + d < n for c, d, _, wild in schedule):  # a plausible pose counts
        assert any(
            not np.array_equal(a.T_cam_obj, b.T_cam_obj)
            for a, b in zip(alone, with_poses, strict=True)
        )


def test_arrival_order_within_the_horizon_does_not_matter(tiny_seq):
    seq = tiny_seq
    rng = np.random.default_rng(3)
    caps = [2, 5, 9, 14, 20]
    poses = {i: _perturbed(seq, c, rng, False) for i, c in enumerate(caps)}
    tracker = RoftTracker(TINY, make_context(seq))
    finals = []
    for arrivals in ([22, 22, 22, 22, 22], [30, 25, 22, 28, 24], [22, 30, 29, 28, 27]):
        d = [
            Delivery(c, a, i, poses[i]) for i, (c, a) in enumerate(zip(caps, arrivals, strict=True))
        ]
        finals.append(run(tracker, build_observations(seq, poses=d))[-1])
    _assert_estimates_equal(finals[0], finals[1])
    _assert_estimates_equal(finals[0], finals[2])


def _scaled_config(seq) -> RoftConfig:
    """Flow noise (W/1280)^2 px^2 and stride 5: the angular noise and pixel count of the
    reference's R = 1 px^2 and stride 35 on Fast-YCB's 1280x720 images."""
    s = (seq.intrinsics.width_px / 1280) ** 2
    return RoftConfig(velocity=VelocityKFConfig(cov_flow=(s, s), subsampling_stride=5))


def _pose_run(seq, deliveries, config=TINY, **kw):
    tracker = RoftTracker(config, make_context(seq))
    return run(tracker, build_observations(seq, poses=deliveries, **kw))


def test_poses_older_than_the_horizon_are_dropped_counted_and_change_nothing(tiny_seq):
    seq = tiny_seq
    config = dataclasses.replace(TINY, sync=PoseSyncConfig(horizon_frames=8))
    base = [Delivery(0, 0, 0), Delivery(12, 15, 1)]
    late = base + [Delivery(6, 20, 2)]  # 14 frames old at arrival > 8
    a = _pose_run(seq, base, config)
    b = _pose_run(seq, late, config)
    assert b[20].dropped_pose_ids == (2,) and b[20].diagnostics["poses_dropped_too_old"] == 1
    assert b[-1].diagnostics["total_poses_dropped_too_old"] == 1
    for k in range(len(seq)):
        _assert_estimates_equal(a[k], b[k], atol=0.0)


def test_duplicates_future_and_non_finite_poses_are_dropped(tiny_seq):
    seq = tiny_seq
    T_nan = np.full((4, 4), np.nan)
    base = [Delivery(0, 0, 0), Delivery(6, 12, 1)]
    bad = base + [Delivery(6, 14, 1), Delivery(30, 14, 7), Delivery(8, 14, 8, T_nan)]
    a, b = _pose_run(seq, base), _pose_run(seq, bad)
    assert set(b[14].dropped_pose_ids) == {1, 7, 8}
    d = b[14].diagnostics
    assert (
        d["poses_dropped_duplicate"],
        d["poses_dropped_future"],
        d["poses_dropped_invalid"],
    ) == (
        1,
        1,
        1,
    )
    for k in range(len(seq)):
        _assert_estimates_equal(a[k], b[k], atol=0.0)


def test_first_pose_initialises_and_an_earlier_one_arriving_later_reinitialises(tiny_seq):
    seq = tiny_seq
    prompt = _pose_run(seq, [Delivery(3, 3, 0), Delivery(10, 10, 1)])
    assert not prompt[2].valid and prompt[3].valid
    out_of_order = _pose_run(seq, [Delivery(10, 12, 1), Delivery(3, 16, 0)])
    assert not out_of_order[11].valid and out_of_order[12].valid
    for k in range(16, len(seq)):
        _assert_estimates_equal(prompt[k], out_of_order[k])


def test_reset_with_an_initial_estimate(tiny_seq):
    seq = tiny_seq
    tracker = RoftTracker(TINY, make_context(seq))
    initial = Estimate(
        k=0, T_cam_obj=seq.gt.T_cam_obj[0], v_obj_mps=seq.gt.v_obj_mps[0], w_radps=seq.gt.w_radps[0]
    )
    est = run(tracker, build_observations(seq, poses=[Delivery(4, 10, 0)]), initial=initial)
    assert all(e.valid for e in est)
    t_err, _ = transform_distance(est[0].T_cam_obj, seq.gt.T_cam_obj[0])
    assert t_err < 0.03
    # a pose captured before the initial estimate's frame cannot be replayed
    est = run(tracker, build_observations(seq, poses=[]), initial=initial)
    again = run(tracker, build_observations(seq, poses=[]), initial=initial)
    _assert_estimates_equal(est[-1], again[-1], atol=0.0)  # reset clears everything


def test_estimate_layout(tiny_seq):
    seq = tiny_seq
    unscaled = dataclasses.replace(TINY, covariance_scale=CovarianceScaleConfig(enable=False))
    tracker = RoftTracker(unscaled, make_context(seq))
    schedule = {"poses": paper_schedule(len(seq)), "masks": paper_schedule(len(seq), first_id=99)}
    est = run(tracker, build_observations(seq, **schedule))
    e = est[-1]
    P = tracker.pose_belief.P
    idx = {name: i for i, name in enumerate(ESTIMATE_COVARIANCE_ORDER)}
    np.testing.assert_array_equal(e.covariance[idx["t_x"] : idx["t_z"] + 1, 0:3], P[6:9, 6:9])
    np.testing.assert_array_equal(e.covariance[idx["r_x"], idx["r_x"]], P[9, 9])
    np.testing.assert_array_equal(e.covariance[idx["v_x"], idx["w_z"]], P[0, 5])
    # the default calibration: the velocity blocks are scaled by the factors the diagnostics
    # report, a positive semi-definite excess is added to the pose block; the estimates are
    # the same
    obs = build_observations(seq, **schedule)
    s = run(RoftTracker(TINY, make_context(seq)), obs)[-1]
    np.testing.assert_array_equal(s.T_cam_obj, e.T_cam_obj)
    np.testing.assert_array_equal(s.v_obj_mps, e.v_obj_mps)
    f = np.array([s.diagnostics[f"covariance_scale_{b}"] for b in "vw"], dtype=float)
    d = np.r_[np.ones(6), np.repeat(np.sqrt(np.maximum(f, 1.0)), 3)]
    np.testing.assert_allclose(s.covariance[6:], (e.covariance * np.outer(d, d))[6:], rtol=1e-12)
    assert np.linalg.eigvalsh(s.covariance[:6, :6] - e.covariance[:6, :6]).min() > -1e-15
    np.testing.assert_array_equal(e.spatial_twist, tracker.reported_twist)
    np.testing.assert_array_equal(e.v_obj_mps, tracker.pose_belief.x[0:3])
    assert not est[0].valid or est[0].k == 0
    # frame 0 has no flow: no twist is claimed (velocity.report_unmeasured_twist), then one
    assert est[0].spatial_twist is None
    assert all(x.spatial_twist is not None for x in est[1:])


def test_auto_motion_model_leaves_the_poses_to_the_constant_model(tiny_seq):
    """``velocity.motion_model = "auto"`` hands the pose UKF the constant model's interval mean:
    the poses and their covariances are the constant model's to the bit; only the reported
    twist mixes in the constant-acceleration model, whose weight the diagnostics report."""
    seq = tiny_seq
    schedule = {"poses": paper_schedule(len(seq)), "masks": paper_schedule(len(seq), first_id=99)}
    out = {}
    for model in ("constant", "auto"):
        cfg = dataclasses.replace(
            TINY, velocity=dataclasses.replace(TINY.velocity, motion_model=model)
        )
        out[model] = run(RoftTracker(cfg, make_context(seq)), build_observations(seq, **schedule))
    for c, a in zip(out["constant"], out["auto"], strict=True):
        np.testing.assert_array_equal(a.T_cam_obj, c.T_cam_obj)
        np.testing.assert_array_equal(a.covariance, c.covariance)
        assert 0.0 <= a.diagnostics["velocity_weight_accel_linear"] <= 1.0
        assert "velocity_weight_accel_linear" not in c.diagnostics


# ----------------------------------------------------------------- outlier rejection


def test_depth_test_rejects_a_wild_pose_and_keeps_good_ones(small_seq):
    seq = small_seq
    n = len(seq)
    wild = seq.gt.T_cam_obj[18].copy()
    wild[:3, 3] += [0.0, 0.0, 0.08]  # the depth test sees depth errors, not lateral shifts
    deliveries = [Delivery(c, c if c == 0 else c + 6, c) for c in range(0, n - 6, 6)]
    deliveries = [d if d.capture_k != 18 else Delivery(18, 24, 18, wild) for d in deliveries]
    masks = paper_schedule(n, first_id=1000)
    config = _scaled_config(seq)
    on = _pose_run(seq, deliveries, config, masks=masks)
    off = _pose_run(seq, deliveries, ablation_config("no_outlier_rejection", config), masks=masks)
    assert on[24].rejected_pose_ids == (18,) and 18 not in on[24].accepted_pose_ids
    assert off[24].accepted_pose_ids == (18,) and off[24].rejected_pose_ids == ()
    assert sum(len(e.rejected_pose_ids) for e in on) == 1  # no good pose rejected
    err_on = transform_distance(on[24].T_cam_obj, seq.gt.T_cam_obj[24])[0]
    err_off = transform_distance(off[24].T_cam_obj, seq.gt.T_cam_obj[24])[0]
    assert err_off > 2 * err_on


def test_roft_without_a_renderer_needs_outlier_rejection_off(tiny_seq):
    ctx = make_context(tiny_seq, renderer=False)
    with pytest.raises(PluginError, match="needs a depth renderer"):
        RoftTracker(RoftConfig(), ctx)
    RoftTracker(ablation_config("no_outlier_rejection"), ctx)
    with pytest.raises(PluginError, match="needs a depth renderer"):
        create_tracker(get_tracker_spec("roft"), ctx)


# ----------------------------------------------------------------- ablations


def test_ablation_configs_are_the_reference_scripts():
    nv = ablation_config("no_velocity")
    assert not nv.use_velocity and not nv.use_pose_resync and not nv.outlier_rejection.enable
    assert nv.pose.sigma_angular == (0.01,) * 3 and nv.pose.meas_cov_q == (0.01,) * 3
    npose = ablation_config("no_pose")
    assert not npose.use_pose and not npose.use_pose_resync and not npose.outlier_rejection.enable
    assert not ablation_config("no_mask_sync").mask.flow_aided
    assert not ablation_config("no_pose_sync").use_pose_resync
    assert ablation_config("full") == RoftConfig()
    assert set(ABLATIONS) >= {"no_pose_sync", "no_outlier_rejection", "no_mask_sync"}
    with pytest.raises(ConfigError, match="unknown ROFT ablation 'no_flow'"):
        ablation_config("no_flow")


def test_without_pose_sync_a_delayed_pose_is_fused_as_if_current(small_seq):
    seq = small_seq
    delayed = [Delivery(0, 0, 0), Delivery(6, 12, 1), Delivery(12, 18, 2)]
    as_current = [
        Delivery(d.arrival_k, d.arrival_k, d.detection_id, seq.gt.T_cam_obj[d.capture_k])
        for d in delayed
    ]
    masks = paper_schedule(len(seq), first_id=1000)
    cfg = ablation_config("no_pose_sync", TINY)
    a = _pose_run(seq, delayed, cfg, masks=masks)
    b = _pose_run(seq, as_current, TINY, masks=masks)
    for k in range(len(seq)):
        _assert_estimates_equal(a[k], b[k], atol=0.0)
    full = _pose_run(seq, delayed, TINY, masks=masks)
    assert not np.allclose(full[12].T_cam_obj, a[12].T_cam_obj)


def test_without_mask_sync_the_last_mask_is_used_as_delivered(small_seq):
    seq = small_seq
    masks = paper_schedule(len(seq), first_id=1000)
    obs = build_observations(seq, poses=paper_schedule(len(seq)), masks=masks)
    stale = RoftTracker(ablation_config("no_mask_sync", TINY), make_context(seq))
    synced = RoftTracker(TINY, make_context(seq))
    stale.reset(None)
    synced.reset(None)
    for o in obs[:17]:
        stale.step(o)
        synced.step(o)
    np.testing.assert_array_equal(stale.mask.to_mask(), seq.mask(6, "gt"))  # delivered at 12
    assert not np.array_equal(synced.mask.to_mask(), seq.mask(6, "gt"))
    iou = lambda m, g: (m & g).sum() / (m | g).sum()  # noqa: E731
    assert iou(synced.mask.to_mask(), seq.mask(16, "gt")) > iou(
        seq.mask(6, "gt"), seq.mask(16, "gt")
    )


def test_without_velocity_the_flow_does_not_reach_the_pose(tiny_seq):
    seq = tiny_seq
    poses = paper_schedule(len(seq))
    cfg = ablation_config("no_velocity", TINY)
    zero_flows = [
        None if f is None else dataclasses.replace(f, flow_px=np.zeros_like(f.flow_px))
        for f in (seq.flow(k, "gt") for k in range(len(seq)))
    ]
    masks = paper_schedule(len(seq), first_id=1000)
    a = _pose_run(seq, poses, cfg, masks=masks)
    b = _pose_run(seq, poses, cfg, masks=masks, flows=zero_flows)
    for k in range(len(seq)):
        _assert_estimates_equal(a[k], b[k], atol=0.0)
    assert not np.allclose(a[-1].spatial_twist, b[-1].spatial_twist)  # the KF still runs
    full = _pose_run(seq, poses, TINY, masks=masks)
    assert not np.allclose(full[-1].T_cam_obj, a[-1].T_cam_obj)


def test_without_pose_only_the_first_pose_is_used_to_start(tiny_seq):
    seq = tiny_seq
    cfg = ablation_config("no_pose", TINY)
    masks = paper_schedule(len(seq), first_id=1000)
    good = paper_schedule(len(seq))
    far = transform_from_rt(np.eye(3), [0.3, 0.0, 1.0])
    bad = [good[0]] + [dataclasses.replace(d, override=far) for d in good[1:]]
    a = _pose_run(seq, good, cfg, masks=masks)
    b = _pose_run(seq, bad, cfg, masks=masks)
    assert a[0].valid
    for k in range(len(seq)):
        _assert_estimates_equal(a[k], b[k], atol=0.0)
    assert set(a[12].dropped_pose_ids) == {1} and a[12].diagnostics["poses_dropped_not_fused"] == 1


# ----------------------------------------------------------------- accuracy


def _errors(est, seq, first=6):
    t, a, v, w = [], [], [], []
    gt = seq.gt
    for e in est[first:]:
        dt, da = transform_distance(e.T_cam_obj, gt.T_cam_obj[e.k])
        t.append(dt)
        a.append(da)
        v_o = v_o_from_v_obj(gt.v_obj_mps[e.k], gt.w_radps[e.k], gt.T_cam_obj[e.k, :3, 3])
        v.append(np.linalg.norm(e.spatial_twist[:3] - v_o))
        w.append(np.linalg.norm(e.spatial_twist[3:] - gt.w_radps[e.k]))
    rms = lambda x: float(np.sqrt(np.mean(np.square(x))))  # noqa: E731
    return rms(t), np.degrees(rms(a)), rms(v), np.degrees(rms(w))


def test_accuracy_with_ground_truth_flow_masks_and_poses(medium_seq):
    """320x240, paper schedule (pose and mask every 6 frames, 6 frames late), GT inputs, fast
    motion (RMS 1.4 m/s spatial velocity, 2.9 rad/s).

    Flow noise (320/1280)^2 px^2 and stride 5 stand for Fast-YCB's 1280x720 (see the velocity
    KF test). Measured RMS over frames 6-59: position 1.73 cm, rotation 7.5 deg; velocity KF
    22 cm/s and 26 deg/s. (ROFT's orientation comes mostly from integrating the flow's w, which
    lags half a frame, against a pose gain of about 0.08: the paper's "ROFT w/ GT segm. and
    pose" row has 2.5 cm and 10.6 deg.) Without pose sync: 4.05 cm, 8.8 deg.
    """
    seq = medium_seq
    n = len(seq)
    cfg = _scaled_config(seq)
    masks = paper_schedule(n, first_id=1000)
    est = _pose_run(seq, paper_schedule(n), cfg, masks=masks)
    t, a, v, w = _errors(est, seq)
    print(f"ROFT GT inputs: {t * 100:.2f} cm {a:.2f} deg, v_o {v * 100:.1f} cm/s, w {w:.1f} deg/s")
    assert t < 0.025 and a < 10.0 and v < 0.25 and w < 30.0
    nosync = _pose_run(seq, paper_schedule(n), ablation_config("no_pose_sync", cfg), masks=masks)
    t2, a2, _, _ = _errors(nosync, seq)
    print(f"without pose sync: {t2 * 100:.2f} cm {a2:.2f} deg")
    assert t2 > 1.5 * t and a2 > a


# ----------------------------------------------------------------- robustness


@st.composite
def fault_schedules(draw, n: int):
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    poses, masks = [], []
    pid = 0
    for c in range(n):
        if draw(st.integers(0, 3)) == 0:  # a network run
            delay = draw(st.integers(0, 25))  # beyond the 12-frame horizon sometimes
            kind = draw(st.sampled_from(["good", "good", "wild", "flip", "nan-free-far"]))
            T = _perturbed_fault(c, kind, rng)
            copies = draw(st.integers(1, 2))  # duplicates keep their id
            for j in range(copies):
                poses.append(Delivery(c, c + delay + j * draw(st.integers(0, 3)), pid, T))
            pid += 1
        if draw(st.integers(0, 3)) == 0:
            delay = draw(st.integers(0, 25))
            empty = draw(st.integers(0, 4)) == 0
            masks.append(Delivery(c, c + delay, 10_000 + c, "empty" if empty else None))
    dropped = draw(st.sets(st.integers(1, n - 1), max_size=6))
    no_flow = draw(st.sets(st.integers(1, n - 1), max_size=6))
    return poses, masks, dropped, no_flow


_FAULT_SEQ = {}


def _perturbed_fault(c, kind, rng):
    T = _FAULT_SEQ["seq"].gt.T_cam_obj[c].copy()
    if kind == "wild":
        T[:3, 3] += rng.normal(0, 0.3, 3)
    elif kind == "flip":
        T[:3, :3] = T[:3, :3] @ matrix_from_rotvec([np.pi, 0, 0])
    elif kind == "nan-free-far":
        T[:3, 3] = rng.normal(0, 50.0, 3)
    return T


def _check_well_formed(e: Estimate) -> None:
    if e.spatial_twist is not None:
        assert np.isfinite(e.spatial_twist).all()
    if not e.valid:
        return
    T = e.T_cam_obj
    assert np.isfinite(T).all() and np.isfinite(e.v_obj_mps).all() and np.isfinite(e.w_radps).all()
    R = T[:3, :3]
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-9)  # |q| = 1
    assert np.linalg.det(R) > 0
    P = e.covariance
    assert np.isfinite(P).all()
    np.testing.assert_array_equal(P, P.T)
    assert np.linalg.eigvalsh(P).min() > 0


@settings(max_examples=scaled_examples(10))
@given(data=st.data())
def test_well_formed_after_every_step_under_random_fault_schedules(tiny_seq, data):
    seq = tiny_seq
    _FAULT_SEQ["seq"] = seq
    n = len(seq)
    poses, masks, dropped, no_flow = data.draw(fault_schedules(n))
    empty = np.zeros(seq.intrinsics.shape, bool)
    masks = [
        dataclasses.replace(m, override=empty) if isinstance(m.override, str) else m for m in masks
    ]
    obs = build_observations(seq, poses=poses, masks=masks, dropped_frames=dropped)
    obs = [dataclasses.replace(o, flow=None) if o.k in no_flow else o for o in obs]
    config = dataclasses.replace(TINY, sync=PoseSyncConfig(horizon_frames=12))
    for cfg in (config, ablation_config("no_pose_sync", config)):
        tracker = RoftTracker(cfg, make_context(seq))
        tracker.reset(None)
        for o in obs:
            e = tracker.step(o)
            assert e.k == o.k
            _check_well_formed(e)


def test_velocity_measurement_uses_the_eroded_mask(small_seq):
    seq = small_seq
    masks = [Delivery(k, k, 1000 + k) for k in range(len(seq))]
    obs = build_observations(seq, masks=masks)
    used = {}
    for r in (0, 2):
        cfg = RoftConfig(velocity=VelocityKFConfig(mask_erosion_px=r, subsampling_stride=1))
        est = run(RoftTracker(cfg, make_context(seq)), obs)
        used[r] = np.array([e.diagnostics["flow_pixels"] for e in est[1:]])
    # 2 px off a ~40x30 px silhouette: roughly a quarter of the pixels go
    assert (used[2] < 0.85 * used[0]).all() and (used[2] > 0).all()


def test_observations_must_come_in_order(tiny_seq):
    tracker = RoftTracker(TINY, make_context(tiny_seq))
    obs = build_observations(tiny_seq)
    tracker.reset(None)
    tracker.step(obs[3])
    with pytest.raises(ValueError, match="increasing k; got k=2 after 3"):
        tracker.step(obs[2])


def test_observations_must_come_without_gaps(tiny_seq):
    """A skipped k (instead of a dropped-frame Observation) is a clear error, not a KeyError
    from the replay buffers."""
    obs = build_observations(tiny_seq, poses=[Delivery(0, 0, 0), Delivery(3, 6, 1)])
    tracker = RoftTracker(TINY, make_context(tiny_seq))
    tracker.reset(None)
    tracker.step(obs[0])
    tracker.step(obs[1])
    with pytest.raises(ValueError, match="without gaps in k; got k=3 after 1"):
        tracker.step(obs[3])


# ----------------------------------------------------------------- configuration


def test_config_loads_from_toml_with_nested_tables(tmp_path):
    path = tmp_path / "roft.toml"
    path.write_text(
        "use_pose_resync = false\n[velocity]\nsubsampling_stride = 7\n"
        "[outlier_rejection]\ngamma = 3.5\n[mask]\ncleanup = 'none'\n"
    )
    cfg = load_tracker_config(get_tracker_spec("roft"), path)
    assert isinstance(cfg, RoftConfig)
    assert (cfg.use_pose_resync, cfg.velocity.subsampling_stride, cfg.outlier_rejection.gamma) == (
        False,
        7,
        3.5,
    )
    assert cfg.mask.cleanup == "none" and cfg.pose == RoftConfig().pose


@pytest.mark.parametrize(
    "text, match",
    [
        (
            "[velocity]\nsubsampling_radius = 35\n",
            "unknown key 'subsampling_radius'.*subsampling_stride",
        ),
        ("[outlier_rejection]\ngamma = -1.0\n", "gamma must be > 0"),
        ("[pose]\nmeas_cov_q = [0.0, 1e-4, 1e-4]\n", "pose.meas_cov_q must be finite and > 0"),
        ("[mask]\ncleanup = 'erode'\n", "expected one of 'none', 'close'"),
        ("use_flow = false\n", "use_velocity = true needs use_flow = true"),
        ("[sync]\nhorizon_frames = -1\n", "horizon_frames must be in"),
        ("[gate]\nmin_rejection_span_s = -0.1\n", "min_rejection_span_s must be >= 0 seconds"),
        ("[pose]\ncoast_correlation_time_v_s = 0.0\n", "coast_correlation_time_v_s must be > 0"),
    ],
)
def test_bad_config_values_name_the_key_and_the_fix(tmp_path, text, match):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        load_tracker_config(get_tracker_spec("roft"), path)


def test_dropped_camera_frames_predict_without_measurement(tiny_seq):
    seq = tiny_seq
    masks = paper_schedule(len(seq), first_id=1000)
    obs = build_observations(
        seq, poses=paper_schedule(len(seq)), masks=masks, dropped_frames=[8, 9]
    )
    assert obs[10].flow is not None and obs[10].flow.from_k == 7
    tracker = RoftTracker(TINY, make_context(seq))
    est = run(tracker, obs)
    assert est[8].valid and est[8].diagnostics["flow_pixels"] == 0
    assert est[10].diagnostics["flow_pixels"] > 0  # the 2-frame flow 7 -> 10 is used
    assert isinstance(obs[8], Observation) and obs[8].camera_dropped


def test_without_flow_the_pose_coasts_with_decaying_velocities(tiny_seq):
    """Camera frames 12..39 dropped (no flow; no pose after frame 6): after t seconds without
    a velocity measurement the UKF's angular velocity is rho(t) times the last measured one,
    rho the Gaussian autocorrelation of ``pose.coast_correlation_time_w_s``, so the pose moves
    far less than a constant-velocity extrapolation carries it; with the correlation times off
    (the reference's model) the velocity stays."""
    seq = tiny_seq
    first = [Delivery(0, 0, 0), Delivery(6, 6, 1)]
    obs = build_observations(
        seq, poses=first, masks=[Delivery(0, 0, 1000)], dropped_frames=range(12, len(seq))
    )
    constant = dataclasses.replace(
        TINY.pose, coast_correlation_time_v_s=None, coast_correlation_time_w_s=None
    )
    moved = {}
    for name, pose in (("coast", TINY.pose), ("constant", constant)):
        est = run(RoftTracker(dataclasses.replace(TINY, pose=pose), make_context(seq)), obs)
        w = np.array([e.w_radps for e in est])
        assert est[11].diagnostics["flow_pixels"] > 0 and np.linalg.norm(w[11]) > 0.05
        if name == "coast":
            t = np.arange(1, len(seq) - 11) / seq.fps
            rho = np.exp(-(t**2) / (2 * pose.coast_correlation_time_w_s**2))
            np.testing.assert_allclose(w[12:], rho[:, None] * w[11], rtol=1e-9, atol=1e-12)
        else:
            np.testing.assert_allclose(w[12:], np.broadcast_to(w[11], w[12:].shape), atol=1e-12)
        moved[name] = transform_distance(est[11].T_cam_obj, est[-1].T_cam_obj)
    assert moved["coast"][1] < 0.5 * moved["constant"][1]


def test_metric_erosion_is_a_band_on_the_object_and_never_eats_the_mask():
    """5 mm at 0.5 m with fx = 500 px is 5 px; a 6x6 px mask keeps more than half of itself
    (radius 1 would leave 16 of 36 pixels, so the radius drops to 0)."""
    depth = np.full((200, 200), 0.5)
    big = np.zeros((200, 200), dtype=bool)
    big[50:150, 50:150] = True
    assert metric_erosion_px(PixelSet.from_mask(big), depth, 500.0, 0.005, 0.5) == 5
    assert metric_erosion_px(PixelSet.from_mask(big), 2 * depth, 500.0, 0.005, 0.5) == 2
    small = np.zeros((200, 200), dtype=bool)
    small[10:16, 10:16] = True
    assert metric_erosion_px(PixelSet.from_mask(small), depth, 500.0, 0.005, 0.5) == 0
    assert metric_erosion_px(PixelSet.from_mask(small), depth, 500.0, 0.005, 0.9) == 2


def test_stride_and_flow_noise_scale_with_the_resolution():
    cfg = VelocityKFConfig()
    assert cfg.stride(1280) == 35 and cfg.stride(640) == 9 and cfg.stride(320) == 2
    assert cfg.flow_variance_px2(640) == (0.25, 0.25)
    ref = VelocityKFConfig(noise_reference_width_px=None)
    assert ref.stride(320) == 35 and ref.flow_variance_px2(320) == (1.0, 1.0)


# ----------------------------------------------------------------- fresh-mask re-measurement
@pytest.mark.parametrize("remeasure", [True, False])
def test_fresh_mask_remeasures_the_buffered_twists(small_seq, remeasure):
    """Masks captured every 6 frames and delivered 6 late (poses on time): with
    ``velocity.remeasure_on_fresh_mask`` the velocity KF, the twists stored for the pose
    replays and the pose at every arrival frame equal (1e-9) those of a run in which each mask
    arrived at its capture frame (the flows since the capture are read on the fresh mask);
    without it the twists measured on the older mask stay."""
    seq = small_seq
    n = len(seq)
    captures = range(0, n, 6)
    poses = [Delivery(c, c, i) for i, c in enumerate(captures)]
    masks = {
        "delayed": paper_schedule(n, first_id=1000),
        "prompt": [Delivery(c, c, 1000 + i) for i, c in enumerate(captures)],
    }
    cfg = RoftConfig(velocity=VelocityKFConfig(remeasure_on_fresh_mask=remeasure))
    out = {}
    for name, schedule in masks.items():
        tracker = RoftTracker(cfg, make_context(seq))
        tracker.reset(None)
        rows = []
        for obs in build_observations(seq, poses=poses, masks=schedule):
            e = tracker.step(obs)
            rows.append((e, tracker.velocity_belief[0], e.diagnostics["remeasured_frames"]))
        out[name] = rows
    arrivals = [c + 6 for c in captures if c > 0 and c + 6 < n]
    assert arrivals
    for k in arrivals:
        (e_d, x_d, m_d), (e_p, x_p, _) = out["delayed"][k], out["prompt"][k]
        if remeasure:
            assert m_d == 5  # frames c+1 .. k-1
            np.testing.assert_allclose(x_d, x_p, rtol=0, atol=1e-9)
            _assert_estimates_equal(e_d, e_p)
        else:
            assert m_d == 0
            assert np.abs(x_d - x_p).max() > 1e-6
            assert np.abs(e_d.T_cam_obj - e_p.T_cam_obj).max() > 1e-9


def test_no_twist_is_claimed_before_the_first_flow_update(small_seq):
    """Frame 0 has no flow: the default reports no spatial twist there (the metric then leaves
    the frame out of the velocity RMSE); ``report_unmeasured_twist`` gives the reference's
    initial zero."""
    seq = small_seq
    obs = build_observations(seq, poses=paper_schedule(len(seq)), masks=paper_schedule(len(seq)))
    for report in (False, True):
        cfg = RoftConfig(velocity=VelocityKFConfig(report_unmeasured_twist=report))
        est = run(RoftTracker(cfg, make_context(seq)), obs[:3])
        if report:
            np.testing.assert_array_equal(est[0].spatial_twist, np.zeros(6))
        else:
            assert est[0].spatial_twist is None
        assert est[1].spatial_twist is not None and np.abs(est[1].spatial_twist).max() > 0
