"""OpenCV <-> MuJoCo camera conversion, checked against what MuJoCo itself compiles and renders."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from stand_ins import OFF_CENTRE_CAMERA, SMALL_CAMERA

from roft_sim.geometry import (
    CameraIntrinsics,
    matrix_from_rotvec,
    project_points,
    transform_from_rt,
)
from roft_sim.render.camera import (
    QUAT_CV_MJ,
    R_CV_MJ,
    intrinsics_from_mujoco_camera,
    mujoco_camera_params,
    mujoco_camera_pose_from_opencv,
    opencv_pose_from_mujoco_camera,
)

CAMERAS = [
    SMALL_CAMERA,
    OFF_CENTRE_CAMERA,
    CameraIntrinsics(
        fx_px=1229.4285612615463,
        fy_px=1229.4285612615463,
        cx_px=640.0,
        cy_px=360.0,
        width_px=1280,
        height_px=720,
    ),
]


def _camera_model(intrinsics: CameraIntrinsics, T_world_cam: np.ndarray) -> mujoco.MjModel:
    spec = mujoco.MjSpec()
    spec.stat.extent = 1.0
    spec.visual.map.znear = 0.05
    spec.worldbody.add_geom(size=[0.01, 0, 0], pos=[0, 0, 3])
    rig = spec.worldbody.add_body(pos=T_world_cam[:3, 3].tolist(), mocap=True)
    from roft_sim.geometry import quat_from_matrix

    rig.quat = quat_from_matrix(T_world_cam[:3, :3]).tolist()
    cam = rig.add_camera(name="cam", quat=list(QUAT_CV_MJ))
    p = mujoco_camera_params(intrinsics)
    cam.resolution = list(p.resolution)
    cam.sensor_size = list(p.sensor_size_m)
    cam.focal_pixel = list(p.focal_pixel)
    cam.principal_pixel = list(p.principal_pixel)
    return spec.compile()


@pytest.mark.parametrize("intrinsics", CAMERAS, ids=["small", "off_centre", "fast_ycb"])
def test_compiled_camera_gives_back_the_intrinsics(intrinsics):
    model = _camera_model(intrinsics, np.eye(4))
    back = intrinsics_from_mujoco_camera(
        model.cam_resolution[0], model.cam_sensorsize[0], model.cam_intrinsic[0]
    )
    assert (back.width_px, back.height_px) == (intrinsics.width_px, intrinsics.height_px)
    # MuJoCo stores intrinsics as float32: about 1e-7 relative.
    np.testing.assert_allclose(back.K, intrinsics.K, rtol=0, atol=2e-4)


@pytest.mark.parametrize("intrinsics", CAMERAS, ids=["small", "off_centre", "fast_ycb"])
def test_mujoco_frustum_edges_are_the_image_borders(intrinsics):
    """MuJoCo's own frustum (mjv_updateScene) must put the image borders at u = -0.5 and
    u = W - 0.5 (pixel centres at integers), for any principal point."""
    model = _camera_model(intrinsics, np.eye(4))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    scene = mujoco.MjvScene(model, maxgeom=10)
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FIXED
    cam.fixedcamid = 0
    mujoco.mjv_updateScene(
        model, data, mujoco.MjvOption(), None, cam, mujoco.mjtCatBit.mjCAT_ALL.value, scene
    )
    gl = scene.camera[0]
    n = gl.frustum_near
    left, right = gl.frustum_center - gl.frustum_width, gl.frustum_center + gl.frustum_width
    k = intrinsics
    rtol = 1e-5
    np.testing.assert_allclose(left, n * (-0.5 - k.cx_px) / k.fx_px, rtol=rtol)
    np.testing.assert_allclose(right, n * (k.width_px - 0.5 - k.cx_px) / k.fx_px, rtol=rtol)
    # MuJoCo's y axis points up: the top image border is at +y.
    np.testing.assert_allclose(gl.frustum_top, n * (k.cy_px + 0.5) / k.fy_px, rtol=rtol)
    np.testing.assert_allclose(
        gl.frustum_bottom, -n * (k.height_px - 0.5 - k.cy_px) / k.fy_px, rtol=rtol
    )


def test_camera_pose_round_trips_through_mujoco():
    rng = np.random.default_rng(4)
    for _ in range(5):
        T_world_cam = transform_from_rt(
            matrix_from_rotvec(rng.normal(size=3)), rng.normal(scale=0.3, size=3)
        )
        model = _camera_model(SMALL_CAMERA, T_world_cam)
        data = mujoco.MjData(model)
        mujoco.mj_forward(model, data)
        T_back = opencv_pose_from_mujoco_camera(data.cam_xpos[0], data.cam_xmat[0])
        np.testing.assert_allclose(T_back, T_world_cam, atol=1e-9)
        np.testing.assert_allclose(
            mujoco_camera_pose_from_opencv(T_world_cam)[:3, :3],
            data.cam_xmat[0].reshape(3, 3),
            atol=1e-9,
        )


def test_opencv_forward_is_mujoco_minus_z():
    # A point on the OpenCV optical axis lies on the MuJoCo camera's -z axis; y down is -y_mj.
    np.testing.assert_allclose(R_CV_MJ.T @ np.array([0.0, 0.0, 1.0]), [0.0, 0.0, -1.0])
    np.testing.assert_allclose(R_CV_MJ.T @ np.array([0.0, 1.0, 0.0]), [0.0, -1.0, 0.0])
    uv = project_points(SMALL_CAMERA, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(uv, [SMALL_CAMERA.cx_px, SMALL_CAMERA.cy_px])
