"""Camera ego-motion: exact velocities (finite differences) and the static default."""

from __future__ import annotations

import numpy as np

from roft_sim.geometry import rotvec_from_matrix, so3_left_jacobian
from roft_sim.scene.camera_motion import camera_poses
from roft_sim.scene.config import CameraSwayConfig


def test_static_camera_is_the_identity():
    poses = camera_poses(None, np.array([0.0, 1.0]))
    np.testing.assert_array_equal(poses.T_world_cam, np.broadcast_to(np.eye(4), (2, 4, 4)))
    assert not poses.v_world_mps.any() and not poses.w_world_radps.any()


def test_sway_velocities_are_the_derivatives_of_the_poses():
    config = CameraSwayConfig(
        amplitude_m=(0.05, 0.02, 0.03), amplitude_rad=(0.2, 0.3, 0.1), frequency_hz=0.7
    )
    t = np.linspace(0.05, 3.0, 23)
    h = 1e-5
    poses = camera_poses(config, t)
    plus, minus = camera_poses(config, t + h), camera_poses(config, t - h)
    v_fd = (plus.T_world_cam[:, :3, 3] - minus.T_world_cam[:, :3, 3]) / (2 * h)
    R_p, R_m = plus.T_world_cam[:, :3, :3], minus.T_world_cam[:, :3, :3]
    w_fd = rotvec_from_matrix(R_p @ np.swapaxes(R_m, 1, 2)) / (2 * h)
    np.testing.assert_allclose(poses.v_world_mps, v_fd, atol=1e-8)
    np.testing.assert_allclose(poses.w_world_radps, w_fd, atol=1e-7)
    assert np.abs(poses.w_world_radps).max() > 0.1


def test_left_jacobian_matches_its_series_on_both_branches():
    from roft_sim.geometry import skew

    for scale in (1e-7, 1e-3):  # below and above the small-angle switch
        r = scale * np.array([1.0, -2.0, 3.0])
        K = skew(r)
        theta2 = float(r @ r)
        series = np.eye(3) + (0.5 - theta2 / 24) * K + (1 / 6 - theta2 / 120) * (K @ K)
        np.testing.assert_allclose(so3_left_jacobian(r), series, atol=1e-13)
    np.testing.assert_allclose(so3_left_jacobian(np.zeros(3)), np.eye(3))
