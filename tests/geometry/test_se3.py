"""SE(3) transforms and velocity conventions, with finite differences as the velocity oracle."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from scipy.spatial.transform import Rotation

from roft_sim import geometry as g
from roft_sim.testing import assert_pose_close
from roft_sim.testing.strategies import transforms, translations


@given(transforms(), transforms())
def test_invert_and_compose(T_a_b, T_b_c):
    assert_pose_close(g.invert_transform(T_a_b) @ T_a_b, np.eye(4), atol_m=1e-12, atol_rad=1e-12)
    T_a_c = T_a_b @ T_b_c
    p_c = np.array([0.1, -0.2, 0.3])
    np.testing.assert_allclose(
        g.transform_points(T_a_c, p_c),
        g.transform_points(T_a_b, g.transform_points(T_b_c, p_c)),
        atol=1e-12,
    )


@given(transforms())
def test_pq_roundtrip(T):
    p, q = g.pq_from_transform(T)
    assert_pose_close(g.transform_from_pq(p, q), T, atol_m=1e-15, atol_rad=1e-12)


def test_transform_points_batched_matches_loop():
    rng = np.random.default_rng(3)
    T = g.transform_from_pq(rng.normal(size=(4, 3)), rng.normal(size=(4, 4)))
    p = rng.normal(size=(4, 3))
    expected = np.stack([T[i, :3, :3] @ p[i] + T[i, :3, 3] for i in range(4)])
    np.testing.assert_allclose(g.transform_points(T, p), expected, atol=1e-14)
    np.testing.assert_allclose(
        g.transform_points(T[0], p), (T[0, :3, :3] @ p.T).T + T[0, :3, 3], atol=1e-14
    )


@given(translations(), translations(), translations())
def test_spatial_twist_roundtrip_and_point_velocity(v_obj, w, t):
    v_o = g.v_o_from_v_obj(v_obj, w, t)
    np.testing.assert_allclose(g.v_obj_from_v_o(v_o, w, t), v_obj, atol=1e-12)
    # the body point at the object origin moves with v_obj = v_o + w x t
    np.testing.assert_allclose(v_o + np.cross(w, t), v_obj, atol=1e-12)
    # the same conversion as a linear map of the twist (for covariances)
    moved = g.twist_at_point_matrix(t) @ np.concatenate([v_o, w])
    np.testing.assert_allclose(moved, np.concatenate([v_obj, w]), atol=1e-12)


def _pose_at(t, omega_world, v_world, T0):
    R = Rotation.from_rotvec(omega_world * t).as_matrix() @ T0[:3, :3]
    return g.transform_from_rt(R, T0[:3, 3] + v_world * t)


def test_relative_motion_matches_finite_differences():
    rng = np.random.default_rng(4)
    Tc0 = g.transform_from_pq(rng.normal(size=3), rng.normal(size=4))
    To0 = g.transform_from_pq(rng.normal(size=3), rng.normal(size=4))
    vc, wc, vo, wo = rng.normal(size=(4, 3))
    t, h = 0.3, 1e-6
    T_wc, T_wo = _pose_at(t, wc, vc, Tc0), _pose_at(t, wo, vo, To0)
    T_co, v, w = g.relative_motion(T_wc, vc, wc, T_wo, vo, wo)
    Tp = g.invert_transform(_pose_at(t + h, wc, vc, Tc0)) @ _pose_at(t + h, wo, vo, To0)
    Tm = g.invert_transform(_pose_at(t - h, wc, vc, Tc0)) @ _pose_at(t - h, wo, vo, To0)
    np.testing.assert_allclose(v, (Tp[:3, 3] - Tm[:3, 3]) / (2 * h), rtol=1e-6, atol=1e-8)
    dR = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h)
    W = dR @ T_co[:3, :3].T
    np.testing.assert_allclose(w, [W[2, 1], W[0, 2], W[1, 0]], rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize(
    ("bad", "match"),
    [
        (np.eye(3), r"\(\.\.\., 4, 4\)"),
        (np.full((4, 4), np.nan), "NaN"),
        (np.diag([1.0, 1, 1, 2]), "last row"),
        (np.diag([1.0, 1, -1, 1]), "reflection"),
    ],
)
def test_as_transform_rejects_bad_input(bad, match):
    with pytest.raises(ValueError, match=match):
        g.as_transform(bad)


def test_transform_distance():
    T1 = np.eye(4)
    T2 = g.transform_from_rt(g.matrix_from_rotvec([0, 0, 0.25]), [0.3, 0.4, 0.0])
    dt, da = g.transform_distance(T1, T2)
    assert dt == pytest.approx(0.5)
    assert da == pytest.approx(0.25)
