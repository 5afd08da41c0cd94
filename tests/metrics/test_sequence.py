"""Sequence metrics: RMSE of known errors, velocity conversion, invalid frames, ALL vs MEAN."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.geometry import matrix_from_rotvec, transform_from_rt, v_o_from_v_obj
from roft_sim.metrics import (
    add_auc,
    evaluate_estimates,
    evaluate_sequence,
    pool_metrics,
)
from roft_sim.records import Estimate, PoseTrack

PTS = np.array([[0.05, 0, 0], [-0.05, 0, 0], [0, 0.05, 0], [0, -0.05, 0], [0, 0, 0.05]])


def _gt(n: int, seed: int = 0) -> PoseTrack:
    rng = np.random.default_rng(seed)
    R = np.stack([matrix_from_rotvec(rng.normal(0, 1, 3)) for _ in range(n)])
    t = rng.normal(0, 0.1, (n, 3)) + [0, 0, 0.7]
    return PoseTrack(
        t_s=np.arange(n) / 30.0,
        T_cam_obj=transform_from_rt(R, t),
        v_obj_mps=rng.normal(0, 0.3, (n, 3)),
        w_radps=rng.normal(0, 2.0, (n, 3)),
    )


def test_rmse_of_known_translation_and_rotation_errors():
    gt = _gt(2)
    T_est = gt.T_cam_obj.copy()
    T_est[0, :3, 3] += [0.03, 0.04, 0.0]  # 5 cm
    T_est[0, :3, :3] = matrix_from_rotvec([0, 0, np.deg2rad(10)]) @ T_est[0, :3, :3]
    T_est[1, :3, :3] = matrix_from_rotvec([np.deg2rad(20), 0, 0]) @ T_est[1, :3, :3]
    m = evaluate_sequence(T_est, gt.T_cam_obj, PTS)
    assert m.rmse_t_cm == pytest.approx(np.sqrt(25 / 2))
    assert m.rmse_t_axes_cm == pytest.approx((np.sqrt(9 / 2), np.sqrt(16 / 2), 0.0))
    assert m.rmse_a_deg == pytest.approx(np.sqrt((100 + 400) / 2))
    assert m.frames == 2 and m.frames_rmse == 2
    assert np.isnan(m.rmse_v_cmps) and m.frames_velocity == 0
    np.testing.assert_allclose(m.a_err_deg, [10, 20])


def test_velocity_from_spatial_twist_uses_ground_truth_position():
    # Hand case: v_o = 0, w = (0, 0, 1) rad/s, t_gt = (1, 0, 0) m -> v = w x t = (0, 1, 0) m/s.
    T_gt = transform_from_rt(np.eye(3), [1.0, 0, 0])[None]
    T_est = transform_from_rt(np.eye(3), [0.5, 0.2, 0])[None]  # a wrong ESTIMATED position
    m = evaluate_sequence(
        T_est,
        T_gt,
        PTS,
        v_obj_gt=[[0, 1.0, 0]],
        w_gt=[[0, 0, 1.0]],
        spatial_twist_est=[[0, 0, 0, 0, 0, 1.0]],
    )
    assert m.rmse_v_cmps == pytest.approx(0.0, abs=1e-12)
    assert m.rmse_w_dps == pytest.approx(0.0, abs=1e-12)


def test_velocity_errors_in_cm_per_s_and_deg_per_s():
    gt = _gt(50, seed=1)
    dv = np.array([0.01, -0.02, 0.0])  # 2.236 cm/s
    dw = np.array([0.0, 0.0, np.deg2rad(3.0)])
    twist = np.concatenate(
        [
            v_o_from_v_obj(gt.v_obj_mps + dv, gt.w_radps + dw, gt.T_cam_obj[:, :3, 3]),
            gt.w_radps + dw,
        ],
        1,
    )
    # The twist is built with the GT position, so converting it back gives v_obj + dv exactly.
    m_direct = evaluate_sequence(
        gt.T_cam_obj,
        gt.T_cam_obj,
        PTS,
        v_obj_gt=gt.v_obj_mps,
        w_gt=gt.w_radps,
        v_obj_est=gt.v_obj_mps + dv,
        w_est=gt.w_radps + dw,
    )
    assert m_direct.rmse_v_cmps == pytest.approx(np.linalg.norm(dv) * 100)
    assert m_direct.rmse_w_dps == pytest.approx(3.0)
    # The twist takes precedence over v_obj_est / w_est (zeros here).
    m_twist = evaluate_sequence(
        gt.T_cam_obj,
        gt.T_cam_obj,
        PTS,
        v_obj_gt=gt.v_obj_mps,
        w_gt=gt.w_radps,
        spatial_twist_est=twist,
        v_obj_est=np.zeros((50, 3)),
        w_est=np.zeros((50, 3)),
    )
    assert m_twist.rmse_v_cmps == pytest.approx(np.linalg.norm(dv) * 100)
    assert m_twist.rmse_w_dps == pytest.approx(3.0)


def test_a_frame_without_a_twist_is_scored_with_its_own_velocity():
    """The reference scores every row of velocity_estimate.txt: a frame whose estimate carries no
    spatial twist (ROFT's frame 0, before its velocity filter has seen flow) holds the estimate's
    v_obj - w x t_gt there, which it turns back into v_obj; here v_obj = w = 0, so that frame's
    error is the ground truth's whole velocity (recomputed by hand below)."""
    gt = _gt(4, seed=7)
    twists = np.concatenate([gt.v_o_mps + 0.002, gt.w_radps - 0.01], 1)
    ests = [
        Estimate(
            k=k,
            T_cam_obj=gt.T_cam_obj[k],
            v_obj_mps=np.zeros(3),
            w_radps=np.zeros(3),
            spatial_twist=None if k == 0 else twists[k],
        )
        for k in range(4)
    ]
    m = evaluate_estimates(ests, gt, PTS, velocity="auto")
    assert m.frames_velocity == 4
    v = np.zeros((4, 3))
    w = np.zeros((4, 3))
    for k in range(1, 4):
        w[k] = twists[k, 3:]
        v[k] = twists[k, :3] + np.cross(w[k], gt.T_cam_obj[k, :3, 3])
    e_v = np.linalg.norm((gt.v_obj_mps - v) * 100.0, axis=1)
    e_w = np.linalg.norm((gt.w_radps - w) * 180.0 / np.pi, axis=1)
    assert e_v[0] > 10 * e_v[1:].max()  # frame 0 weighs in
    assert m.rmse_v_cmps == pytest.approx(np.sqrt(np.mean(e_v**2)), rel=1e-12)
    assert m.rmse_w_dps == pytest.approx(np.sqrt(np.mean(e_w**2)), rel=1e-12)
    # evaluate_sequence leaves a NaN twist row out when no v_obj / w is given
    twist_rows = np.vstack([np.full(6, np.nan), twists[1:]])
    bare = evaluate_sequence(
        gt.T_cam_obj, gt.T_cam_obj, PTS, v_obj_gt=gt.v_obj_mps, w_gt=gt.w_radps,
        spatial_twist_est=twist_rows,
    )  # fmt: skip
    assert bare.frames_velocity == 3
    assert bare.rmse_v_cmps == pytest.approx(np.sqrt(np.mean(e_v[1:] ** 2)), rel=1e-12)


def test_velocity_without_ground_truth_is_an_error():
    gt = _gt(3)
    with pytest.raises(ValueError, match="without v_obj_gt"):
        evaluate_sequence(gt.T_cam_obj, gt.T_cam_obj, PTS, v_obj_est=np.zeros((3, 3)))


def test_invalid_frame_policies():
    gt = _gt(4, seed=2)
    T_est = gt.T_cam_obj.copy()
    T_est[:, :3, 3] += [0.01, 0, 0]  # 1 cm everywhere
    T_est[0] = np.eye(4)  # the invalid frame holds the identity pose
    valid = np.array([False, True, True, True])
    common = dict(v_obj_gt=gt.v_obj_mps, w_gt=gt.w_radps, v_obj_est=gt.v_obj_mps, w_est=gt.w_radps)

    fail = evaluate_sequence(T_est, gt.T_cam_obj, PTS, valid=valid, **common)
    assert fail.frames == 4 and fail.frames_invalid == 1 and fail.frames_rmse == 3
    assert fail.add_m[0] == np.inf
    assert fail.add_auc_pct == pytest.approx(add_auc([np.inf, 0.01, 0.01, 0.01]))
    assert fail.rmse_t_cm == pytest.approx(1.0)
    assert fail.frames_velocity == 3

    excl = evaluate_sequence(T_est, gt.T_cam_obj, PTS, valid=valid, invalid="exclude", **common)
    assert excl.frames == 3 and excl.frame_index.tolist() == [1, 2, 3]
    assert excl.add_auc_pct == pytest.approx(add_auc([0.01] * 3))
    assert excl.rmse_t_cm == pytest.approx(1.0)

    given = evaluate_sequence(T_est, gt.T_cam_obj, PTS, valid=valid, invalid="as_given", **common)
    assert given.frames_rmse == 4
    assert given.rmse_t_cm > 10  # the identity pose is ~70 cm away

    with pytest.raises(ValueError, match="'failure', 'exclude', 'as_given' or 'hold'"):
        evaluate_sequence(T_est, gt.T_cam_obj, PTS, invalid="drop")  # type: ignore[arg-type]


def _reference_dope_hold(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference's DOPE treatment once the stream is delayed and subsampled
    (``data_loader.load_dope``, ``simulate_inference``), transcribed: start at the first row
    whose x, y, z are all non-zero, then replace every missing (zero) row by the previous one.
    Returns the rows and the frame index of each."""
    i_0 = 0
    for i in range(rows.shape[0]):
        if rows[i, 0] != 0.0 and rows[i, 1] != 0.0 and rows[i, 2] != 0.0:
            i_0 = i
            break
    data = rows[i_0:].copy()
    for i in range(1, data.shape[0]):
        if data[i, 0] == 0.0 and data[i, 1] == 0.0 and data[i, 2] == 0.0:
            data[i, :] = data[i - 1, :]
    return data, np.arange(i_0, rows.shape[0])


def test_hold_policy_matches_the_reference_dope_treatment():
    gt = _gt(9, seed=4)
    rng = np.random.default_rng(1)
    T_est = gt.T_cam_obj.copy()
    T_est[:, :3, 3] += rng.normal(0, 0.01, (9, 3))
    valid = np.array([False, False, True, True, False, False, True, False, True])
    T_est[~valid] = np.eye(4)  # what an invalid estimate holds
    v_est = rng.normal(0, 0.2, (9, 3))
    m = evaluate_sequence(
        T_est,
        gt.T_cam_obj,
        PTS,
        valid=valid,
        invalid="hold",
        v_obj_gt=gt.v_obj_mps,
        w_gt=gt.w_radps,
        v_obj_est=v_est,
        w_est=gt.w_radps,
    )
    rows = np.zeros((9, 6))
    rows[valid, :3] = T_est[valid, :3, 3]
    rows[valid, 3:] = v_est[valid]
    held, frames = _reference_dope_hold(rows)
    assert m.frame_index.tolist() == frames.tolist() == list(range(2, 9))
    assert m.frames_invalid == 5
    t_err = held[:, :3] - gt.T_cam_obj[frames, :3, 3]
    assert m.rmse_t_cm == pytest.approx(100 * np.sqrt(np.mean(np.sum(t_err**2, axis=1))))
    v_err = held[:, 3:] - gt.v_obj_mps[frames]
    assert m.rmse_v_cmps == pytest.approx(100 * np.sqrt(np.mean(np.sum(v_err**2, axis=1))))
    assert np.isfinite(m.add_m).all()  # nothing is a failure under hold
    none_valid = evaluate_sequence(
        T_est, gt.T_cam_obj, PTS, valid=np.zeros(9, bool), invalid="hold"
    )
    assert none_valid.frames == 0


def test_pool_all_pools_frames_and_mean_averages_entries():
    a, b = _gt(2, 3), _gt(6, 4)

    def shifted(gt: PoseTrack, d_m: float) -> np.ndarray:
        T = gt.T_cam_obj.copy()
        T[:, :3, 3] += [d_m, 0, 0]
        return T

    ma = evaluate_sequence(shifted(a, 0.08), a.T_cam_obj, PTS, step_times_s=[0.01, 0.02])
    mb = evaluate_sequence(shifted(b, 0.01), b.T_cam_obj, PTS, step_times_s=[0.03] * 6)
    pooled = pool_metrics({"a": ma, "b": mb})
    assert list(pooled) == ["ALL", "MEAN", "a", "b"]
    ALL, MEAN = pooled["ALL"], pooled["MEAN"]
    assert ALL.frames == 8 and MEAN.frames == 8
    assert ALL.add_auc_pct == pytest.approx(add_auc([0.08] * 2 + [0.01] * 6))
    assert MEAN.add_auc_pct == pytest.approx((ma.add_auc_pct + mb.add_auc_pct) / 2)
    assert ALL.rmse_t_cm == pytest.approx(np.sqrt((2 * 64 + 6 * 1) / 8))
    assert MEAN.rmse_t_cm == pytest.approx((8 + 1) / 2)
    assert ALL.add_auc_pct != pytest.approx(MEAN.add_auc_pct)
    assert ALL.step_time is not None and ALL.step_time.steps == 8
    assert ALL.step_time.median_ms == pytest.approx(30.0)
    assert set(ALL.summary()) >= {
        "add_auc_pct",
        "rmse_t_cm",
        "rmse_a_deg",
        "rmse_v_cmps",
        "rmse_w_dps",
        "frames",
    }
    assert ALL.summary()["rmse_v_cmps"] is None  # NaN -> null in JSON
    with pytest.raises(ValueError, match="reserved"):
        pool_metrics({"ALL": ma})


def test_evaluate_estimates_matches_arrays_and_checks_alignment():
    gt = _gt(5, seed=5)
    twists = np.concatenate([gt.v_o_mps, gt.w_radps], 1) + 0.01
    ests = [
        Estimate(
            k=k,
            T_cam_obj=gt.T_cam_obj[k],
            v_obj_mps=np.zeros(3),
            w_radps=np.zeros(3),
            spatial_twist=twists[k],
            valid=k > 0,
        )
        for k in range(5)
    ]
    m = evaluate_estimates(ests, gt, PTS)
    ref = evaluate_sequence(
        gt.T_cam_obj,
        gt.T_cam_obj,
        PTS,
        v_obj_gt=gt.v_obj_mps,
        w_gt=gt.w_radps,
        spatial_twist_est=twists,
        valid=[False, True, True, True, True],
    )
    assert m.summary() == ref.summary()
    m_vobj = evaluate_estimates(ests, gt, PTS, velocity="v_obj")
    assert m_vobj.rmse_v_cmps > m.rmse_v_cmps  # zero v_obj estimates are far off
    with pytest.raises(ValueError, match="one estimate per ground-truth frame"):
        evaluate_estimates(ests[1:], gt, PTS)
    no_twist = [Estimate.invalid(k) for k in range(5)]
    with pytest.raises(ValueError, match="carry no spatial_twist"):
        evaluate_estimates(no_twist, gt, PTS, velocity="spatial_twist")


def test_evaluate_estimates_of_an_empty_sequence_gives_nan_metrics():
    # evaluate_sequence scores N = 0 as NaN metrics; evaluate_estimates must not crash on it
    gt = PoseTrack(
        t_s=np.zeros(0),
        T_cam_obj=np.zeros((0, 4, 4)),
        v_obj_mps=np.zeros((0, 3)),
        w_radps=np.zeros((0, 3)),
    )
    m = evaluate_estimates([], gt, PTS)
    assert m.frames == 0 and np.isnan(m.add_auc_pct) and np.isnan(m.rmse_v_cmps)
