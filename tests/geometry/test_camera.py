"""Pinhole projection against OpenCV's projectPoints, back-projection round trips."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from roft_sim.errors import ConfigError
from roft_sim.geometry import (
    CameraIntrinsics,
    backproject_depth,
    backproject_pixels,
    project_points,
)

CAM = CameraIntrinsics(
    fx_px=600.0, fy_px=610.0, cx_px=300.5, cy_px=250.25, width_px=640, height_px=480
)


def test_projection_matches_opencv():
    rng = np.random.default_rng(5)
    p = rng.uniform([-0.3, -0.3, 0.4], [0.3, 0.3, 1.2], size=(100, 3))
    cv_uv, _ = cv2.projectPoints(p, np.zeros(3), np.zeros(3), CAM.K, None)
    np.testing.assert_allclose(project_points(CAM, p), cv_uv[:, 0, :], atol=1e-9)


def test_backprojection_roundtrip_and_behind_camera_is_nan():
    rng = np.random.default_rng(6)
    uv = rng.uniform([0, 0], [640, 480], size=(50, 2))
    z = rng.uniform(0.3, 2.0, size=50)
    np.testing.assert_allclose(project_points(CAM, backproject_pixels(CAM, uv, z)), uv, atol=1e-9)
    assert np.isnan(project_points(CAM, [0.0, 0.0, -1.0])).all()


def test_backproject_depth_grid_and_shape_check():
    depth = np.full(CAM.shape, 2.0, dtype=np.float32)
    pts = backproject_depth(CAM, depth)
    assert pts.shape == (480, 640, 3)
    np.testing.assert_allclose(
        pts[250, 300], [(300 - 300.5) / 600 * 2, (250 - 250.25) / 610 * 2, 2.0]
    )
    with pytest.raises(ValueError, match="does not match"):
        backproject_depth(CAM, np.zeros((10, 10)))


def test_resized_intrinsics_map_pixel_edges():
    small = CAM.resized(320, 240)
    # the image's left edge (u = -0.5) and a point projected both ways agree
    p = np.array([0.05, -0.02, 0.8])
    uv = project_points(CAM, p)
    uv_small = project_points(small, p)
    np.testing.assert_allclose((uv + 0.5) / 2, uv_small + 0.5, atol=1e-12)


def test_intrinsics_validation_and_K():
    with pytest.raises(ConfigError, match="focal lengths must be positive"):
        CameraIntrinsics(fx_px=0, fy_px=1, cx_px=0, cy_px=0, width_px=1, height_px=1)
    with pytest.raises(ConfigError, match="resolution"):
        CameraIntrinsics(fx_px=1, fy_px=1, cx_px=0, cy_px=0, width_px=0, height_px=1)
    assert CameraIntrinsics.from_matrix(CAM.K, 640, 480) == CAM
    assert CAM.fovy_rad == pytest.approx(2 * np.arctan(240 / 610))
