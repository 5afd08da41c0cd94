"""SO(3) conversions against scipy and MuJoCo's mju_* functions (independent oracles)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from roft_sim import geometry as g
from roft_sim.geometry.so3 import (
    matrix_from_rotvec,
    so3_exp_and_left_jacobian,
    so3_left_jacobian,
)
from roft_sim.testing import assert_quat_close, assert_rotation_close
from roft_sim.testing.strategies import rotation_vectors, small_rotation_vectors, unit_quaternions


@given(unit_quaternions())
def test_matrix_from_quat_matches_scipy_and_mujoco(q):
    R = g.matrix_from_quat(q)
    np.testing.assert_allclose(
        R, Rotation.from_quat(g.quat_xyzw_from_wxyz(q)).as_matrix(), atol=1e-12
    )
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, q)
    np.testing.assert_allclose(R, mat.reshape(3, 3), atol=1e-12)


@given(unit_quaternions())
def test_quat_from_matrix_roundtrip_is_sign_invariant_and_canonical(q):
    q2 = g.quat_from_matrix(g.matrix_from_quat(q))
    assert q2[0] >= 0
    assert_quat_close(q2, q, atol_rad=1e-12)
    assert_quat_close(q2, -q, atol_rad=1e-12)
    mj = np.zeros(4)
    mujoco.mju_mat2Quat(mj, g.matrix_from_quat(q).ravel())
    assert_quat_close(q2, mj, atol_rad=1e-12)


@given(unit_quaternions(), unit_quaternions())
def test_quat_multiply_matches_mujoco_and_matrix_product(q1, q2):
    res = np.zeros(4)
    mujoco.mju_mulQuat(res, q1, q2)
    np.testing.assert_allclose(g.quat_multiply(q1, q2), res, atol=1e-12)
    assert_rotation_close(
        g.matrix_from_quat(g.quat_multiply(q1, q2)),
        g.matrix_from_quat(q1) @ g.matrix_from_quat(q2),
        atol_rad=1e-12,
    )


@given(unit_quaternions(), st.lists(st.floats(-3, 3), min_size=3, max_size=3))
def test_quat_rotate_matches_mujoco(q, p):
    res = np.zeros(3)
    mujoco.mju_rotVecQuat(res, np.array(p), q)
    np.testing.assert_allclose(g.quat_rotate(q, p), res, atol=1e-12)


@given(rotation_vectors())
def test_rotvec_conversions_match_scipy(r):
    q = g.quat_from_rotvec(r)
    assert_quat_close(q, g.quat_wxyz_from_xyzw(Rotation.from_rotvec(r).as_quat()), atol_rad=1e-12)
    np.testing.assert_allclose(
        g.matrix_from_rotvec(r), Rotation.from_rotvec(r).as_matrix(), atol=1e-12
    )
    r2 = g.rotvec_from_quat(q)
    angle = np.linalg.norm(r)
    if angle < np.pi - 1e-6:  # at pi, r and -r are the same rotation
        np.testing.assert_allclose(r2, r, atol=1e-12)
    assert_quat_close(g.quat_from_rotvec(r2), q, atol_rad=1e-12)


@given(small_rotation_vectors())
def test_small_rotations_keep_relative_precision(r):
    q = g.quat_from_rotvec(r)
    r2 = g.rotvec_from_quat(q)
    assert np.linalg.norm(r2 - r) <= 1e-10 * np.linalg.norm(r)
    # angle between identity and a tiny rotation is exact, where arccos would return 0
    assert g.quat_angle([1, 0, 0, 0], q) == pytest.approx(np.linalg.norm(r), rel=1e-10)


def test_mujoco_quat2vel_agrees_with_rotvec():
    rng = np.random.default_rng(0)
    for r in rng.normal(size=(50, 3)):
        q = g.quat_from_rotvec(r)
        res = np.zeros(3)
        mujoco.mju_quat2Vel(res, q, 1.0)
        assert_quat_close(g.quat_from_rotvec(res), q, atol_rad=1e-9)


@pytest.mark.parametrize("angle", [0.0, 1e-14, 1e-8, 0.5, np.pi - 1e-9, np.pi])
def test_geodesic_angle_exact_near_0_and_pi(angle):
    axis = np.array([0.3, -0.4, 0.866])
    axis /= np.linalg.norm(axis)
    R1 = Rotation.from_rotvec([0.2, 0.1, -0.3]).as_matrix()
    R2 = R1 @ g.matrix_from_rotvec(axis * angle)
    assert g.rotation_angle(R1, R2) == pytest.approx(angle, abs=1e-12, rel=1e-6)


@given(unit_quaternions())
def test_axis_angle_fast_ycb_rows_roundtrip(q):
    aa = g.axis_angle_from_quat(q)
    assert 0.0 <= aa[3] <= np.pi
    assert np.linalg.norm(aa[:3]) == pytest.approx(1.0)
    assert_quat_close(g.quat_from_axis_angle(aa), q, atol_rad=1e-12)
    sc = Rotation.from_quat(g.quat_xyzw_from_wxyz(q)).as_rotvec()
    assert_quat_close(g.quat_from_rotvec(sc), g.quat_from_axis_angle(aa), atol_rad=1e-12)


def test_axis_angle_identity_and_mujoco_oracle():
    np.testing.assert_array_equal(g.axis_angle_from_quat([1, 0, 0, 0]), [1, 0, 0, 0])
    np.testing.assert_array_equal(g.quat_from_axis_angle([0, 0, 0, 0]), [1, 0, 0, 0])
    res = np.zeros(4)
    mujoco.mju_axisAngle2Quat(res, np.array([0.0, 1.0, 0.0]), 2.0)
    assert_quat_close(g.quat_from_axis_angle([0, 1, 0, 2.0]), res)


def test_batched_shapes():
    q = g.as_quat_wxyz(np.random.default_rng(1).normal(size=(5, 7, 4)))
    assert g.matrix_from_quat(q).shape == (5, 7, 3, 3)
    assert g.quat_from_matrix(g.matrix_from_quat(q)).shape == (5, 7, 4)
    assert g.rotvec_from_quat(q).shape == (5, 7, 3)
    assert g.quat_angle(q, q[:1]).shape == (5, 7)
    assert g.skew(np.ones((2, 3))).shape == (2, 3, 3)


@pytest.mark.parametrize(
    ("bad", "match"),
    [([1, 0, 0], r"shape \(\.\.\., 4\)"), ([np.nan, 0, 0, 1], "NaN"), ([0, 0, 0, 0], "zero norm")],
)
def test_as_quat_rejects_bad_input(bad, match):
    with pytest.raises(ValueError, match=match):
        g.as_quat_wxyz(bad)


def test_as_quat_unit_check_without_normalising():
    with pytest.raises(ValueError, match="norm differs from 1"):
        g.as_quat_wxyz([1.01, 0, 0, 0], normalize=False)
    g.as_quat_wxyz([1 + 1e-8, 0, 0, 0], normalize=False)


def test_as_rotation_matrix_rejects_reflection_and_shear():
    with pytest.raises(ValueError, match="reflection"):
        g.as_rotation_matrix(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ValueError, match="orthonormal"):
        g.as_rotation_matrix([[1, 0.1, 0], [0, 1, 0], [0, 0, 1]])


def test_skew_is_cross_product():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(2, 3))
    np.testing.assert_allclose(g.skew(a) @ b, np.cross(a, b), atol=1e-15)


def test_xyzw_boundary_roundtrip():
    q = g.as_quat_wxyz([0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(g.quat_wxyz_from_xyzw(g.quat_xyzw_from_wxyz(q)), q)
    assert g.quat_xyzw_from_wxyz([1, 2, 3, 4]).tolist() == [2, 3, 4, 1]


@pytest.mark.parametrize("angle_rad", [0.0, 1e-9, 9e-7, 1.1e-6, 1e-3, 0.5, 3.0])
def test_scalar_exp_and_left_jacobian_equal_the_batch_functions_and_scipy(angle_rad):
    rng = np.random.default_rng(12)
    for _ in range(20):
        axis = rng.normal(size=3)
        r = axis / np.linalg.norm(axis) * angle_rad
        R, J = so3_exp_and_left_jacobian(r)
        np.testing.assert_allclose(R, Rotation.from_rotvec(r).as_matrix(), rtol=0, atol=1e-14)
        np.testing.assert_allclose(R, matrix_from_rotvec(r), rtol=0, atol=1e-14)
        np.testing.assert_allclose(J, so3_left_jacobian(r), rtol=0, atol=1e-14)


def test_single_rotation_paths_equal_the_batch_paths_bit_for_bit():
    """One quaternion or matrix takes a scalar path (a tenth of the time in ROFT's step); it
    must give the batch path's results exactly."""
    rng = np.random.default_rng(21)
    for i in range(300):
        q = rng.normal(size=4) * rng.uniform(0.1, 10.0)
        np.testing.assert_array_equal(g.matrix_from_quat(q), g.matrix_from_quat(q[None])[0])
        R = Rotation.random(random_state=i).as_matrix()
        np.testing.assert_array_equal(g.quat_from_matrix(R), g.quat_from_matrix(R[None])[0])
        p = rng.normal(size=4)
        assert g.quat_angle(q, p) == g.quat_angle(q[None], p[None])[0]
    with pytest.raises(ValueError, match="NaN"):
        g.matrix_from_quat([np.nan, 0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="zero norm"):
        g.quat_angle([0.0, 0.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0])
