"""ADD, ADD-S, position and rotation errors: hand cases and brute-force oracles."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial import distance
from scipy.spatial.transform import Rotation

from roft_sim.geometry import matrix_from_rotvec, transform_from_rt
from roft_sim.metrics import (
    add_distances,
    adds_distances,
    rotation_errors_rad,
    translation_errors_m,
)
from roft_sim.testing.strategies import rotation_vectors, translations


def _box_points(rng: np.random.Generator, m: int = 300) -> np.ndarray:
    return rng.uniform([-0.04, -0.08, -0.1], [0.04, 0.08, 0.1], size=(m, 3))


def _ring(n: int, radius_m: float, z_m: float = 0.0) -> np.ndarray:
    a = 2 * np.pi * np.arange(n) / n
    return np.stack([radius_m * np.cos(a), radius_m * np.sin(a), np.full(n, z_m)], 1)


def test_add_of_pure_translation_is_translation_norm():
    pts = _box_points(np.random.default_rng(0))
    T_gt = transform_from_rt(matrix_from_rotvec([0.3, -0.2, 0.5]), [0.1, 0.0, 0.7])
    T_est = T_gt.copy()
    T_est[:3, 3] += [0.03, -0.04, 0.0]
    np.testing.assert_allclose(add_distances(T_est[None], T_gt[None], pts), [0.05], atol=1e-15)


def test_add_of_rotation_about_symmetry_axis_of_a_ring():
    # Each ring point moves along a chord 2 r sin(theta / 2).
    r, theta = 0.05, 0.4
    pts = _ring(36, r)
    T_est = transform_from_rt(matrix_from_rotvec([0, 0, theta]), [0, 0, 0.5])
    T_gt = transform_from_rt(np.eye(3), [0, 0, 0.5])
    np.testing.assert_allclose(
        add_distances(T_est[None], T_gt[None], pts), [2 * r * np.sin(theta / 2)], rtol=1e-12
    )


def test_adds_of_symmetric_shape_is_zero_where_add_is_not():
    pts = np.concatenate([_ring(24, 0.033, z) for z in (-0.05, 0.0, 0.05)])  # a "can"
    step = 2 * np.pi / 24
    T_gt = transform_from_rt(matrix_from_rotvec([0.2, 0.1, -0.3]), [0.05, -0.02, 0.6])
    T_est = T_gt @ transform_from_rt(matrix_from_rotvec([0, 0, 5 * step]), np.zeros(3))
    assert adds_distances(T_est[None], T_gt[None], pts)[0] == pytest.approx(0.0, abs=1e-12)
    assert add_distances(T_est[None], T_gt[None], pts)[0] > 0.03


def _random_pose_pairs(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    R1 = Rotation.random(n, random_state=rng).as_matrix()
    R2 = Rotation.random(n, random_state=rng).as_matrix()
    t1 = rng.normal(0, 0.1, (n, 3)) + [0, 0, 0.7]
    t2 = t1 + rng.normal(0, 0.02, (n, 3))
    return transform_from_rt(R1, t1), transform_from_rt(R2, t2)


def test_add_and_adds_match_per_frame_brute_force():
    rng = np.random.default_rng(1)
    pts = _box_points(rng, 200)
    T_est, T_gt = _random_pose_pairs(rng, 7)
    add, adds = add_distances(T_est, T_gt, pts), adds_distances(T_est, T_gt, pts)
    for n in range(7):
        p_est = pts @ T_est[n, :3, :3].T + T_est[n, :3, 3]
        p_gt = pts @ T_gt[n, :3, :3].T + T_gt[n, :3, 3]
        assert add[n] == pytest.approx(np.linalg.norm(p_est - p_gt, axis=1).mean(), rel=1e-12)
        nearest = distance.cdist(p_gt, p_est).min(axis=1)  # GT point -> nearest estimate point
        assert adds[n] == pytest.approx(nearest.mean(), rel=1e-12)
        assert adds[n] <= add[n] + 1e-15


def test_add_chunking_gives_same_result(monkeypatch):
    import roft_sim.metrics.pose_errors as pe

    rng = np.random.default_rng(2)
    pts = _box_points(rng, 50)
    T_est, T_gt = _random_pose_pairs(rng, 11)
    full = add_distances(T_est, T_gt, pts)
    monkeypatch.setattr(pe, "_POINTS_PER_CHUNK", 120)  # 2 frames per chunk
    np.testing.assert_allclose(add_distances(T_est, T_gt, pts), full, rtol=1e-14)


def test_non_finite_estimate_is_a_failure_and_bad_input_raises():
    pts = _box_points(np.random.default_rng(3), 20)
    T = np.stack([np.eye(4), np.eye(4)])
    T_est = T.copy()
    T_est[1, 0, 3] = np.nan
    assert add_distances(T_est, T, pts).tolist() == [0.0, np.inf]
    assert adds_distances(T_est, T, pts).tolist() == [0.0, np.inf]
    assert np.isnan(translation_errors_m(T_est, T)[1]).all()
    assert np.isnan(rotation_errors_rad(T_est, T)[1])
    with pytest.raises(ValueError, match="ground-truth pose 1 is not finite"):
        add_distances(T, T_est, pts)
    with pytest.raises(ValueError, match=r"shape \(N, 4, 4\)"):
        add_distances(T, T[:1], pts)
    with pytest.raises(ValueError, match=r"model_points_m must have shape \(M, 3\)"):
        add_distances(T, T, pts[:, :2])


@given(rotation_vectors(), rotation_vectors(), translations(0.3))
def test_rotation_error_is_angle_of_R_gt_R_est_transpose(r_est, r_gt, t):
    R_est, R_gt = matrix_from_rotvec(r_est), matrix_from_rotvec(r_gt)
    expected = Rotation.from_matrix(R_gt @ R_est.T).magnitude()
    got = rotation_errors_rad(transform_from_rt(R_est, t)[None], transform_from_rt(R_gt, t)[None])[
        0
    ]
    assert got == pytest.approx(expected, abs=1e-9)
    assert translation_errors_m(
        transform_from_rt(R_est, t)[None], transform_from_rt(R_gt, 0 * t)[None]
    )[0] == pytest.approx(t, abs=1e-15)


@given(st.integers(0, 2**31 - 1))
def test_adds_never_exceeds_add(seed):
    rng = np.random.default_rng(seed)
    pts = _box_points(rng, 40)
    T_est, T_gt = _random_pose_pairs(rng, 3)
    assert (adds_distances(T_est, T_gt, pts) <= add_distances(T_est, T_gt, pts) + 1e-12).all()
