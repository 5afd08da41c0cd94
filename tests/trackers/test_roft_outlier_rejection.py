"""The depth outlier test: error definition, resolution rule, decisions and the gamma switch."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.geometry import CameraIntrinsics, transform_from_rt
from roft_sim.trackers.roft.config import OutlierRejectionConfig
from roft_sim.trackers.roft.mask_sync import PixelSet
from roft_sim.trackers.roft.outlier_rejection import (
    DepthOutlierTest,
    depth_samples,
    render_divider,
)

CAM = CameraIntrinsics(fx_px=80.0, fy_px=80.0, cx_px=19.5, cy_px=15.5, width_px=40, height_px=32)


class PlaneRenderer:
    """Renders the 'object' as a fronto-parallel plane at the pose's z over the left half of the
    image (0 elsewhere); records the cameras it was asked for."""

    def __init__(self):
        self.cameras = []

    def render_depth(self, T_cam_obj, intrinsics):
        self.cameras.append(intrinsics)
        out = np.zeros((len(T_cam_obj),) + intrinsics.shape, np.float32)
        out[:, :, : intrinsics.width_px // 2] = np.asarray(T_cam_obj)[:, 2, 3][:, None, None]
        return out


def _samples(depth, cfg=None):
    mask = np.ones(CAM.shape, bool)
    return depth_samples(PixelSet.from_mask(mask), depth, cfg or OutlierRejectionConfig())


def test_error_is_the_mean_absolute_depth_difference_where_rendered():
    depth = np.full(CAM.shape, 0.5, np.float32)
    depth[:, 5] = 0.0  # no measurement: not counted
    depth[:, 6] = 3.0  # beyond 2 m: not counted
    test = DepthOutlierTest(PlaneRenderer(), CAM, OutlierRejectionConfig())
    T = np.stack([transform_from_rt(np.eye(3), [0, 0, z]) for z in (0.6, 0.5)])
    e = test.errors(T, _samples(depth))
    # every 2nd pixel of the row-major list = even columns; rendered on columns 0..19
    np.testing.assert_allclose(e, [0.1, 0.0], atol=1e-6)
    no_render = DepthOutlierTest(PlaneRenderer(), CAM, OutlierRejectionConfig())
    assert no_render.errors(T, _samples(np.zeros(CAM.shape, np.float32))).tolist() == [
        np.inf,
        np.inf,
    ]


def test_render_resolution_follows_the_reference_rule():
    cfg = OutlierRejectionConfig()
    assert render_divider(CAM, cfg) == 4
    assert render_divider(CAM.resized(640, 480), cfg) == 2
    assert render_divider(CAM, OutlierRejectionConfig(render_divider=3)) == 3
    renderer = PlaneRenderer()
    test = DepthOutlierTest(renderer, CAM, cfg)
    test.errors(np.eye(4)[None], _samples(np.ones(CAM.shape, np.float32)))
    assert renderer.cameras[0] == CAM.resized(10, 8) == test.render_intrinsics


@pytest.mark.parametrize(
    "z_with, z_without, gamma, rejected",
    [(0.8, 0.52, 2.0, True), (0.53, 0.52, 2.0, False), (0.8, 0.52, 20.0, False)],
)
def test_decision_is_a_ratio_test(z_with, z_without, gamma, rejected):
    depth = np.full(CAM.shape, 0.5, np.float32)
    test = DepthOutlierTest(PlaneRenderer(), CAM, OutlierRejectionConfig(gamma=gamma))
    A = transform_from_rt(np.eye(3), [0, 0, z_with])
    B = transform_from_rt(np.eye(3), [0, 0, z_without])
    assert test.reject(A, B, _samples(depth)) is rejected


def test_missing_data_keeps_the_pose():
    test = DepthOutlierTest(PlaneRenderer(), CAM, OutlierRejectionConfig())
    A = transform_from_rt(np.eye(3), [0, 0, 1.5])
    B = transform_from_rt(np.eye(3), [0, 0, 0.5])
    assert not test.reject(A, B, None)
    empty = depth_samples(PixelSet.empty(CAM.shape), np.ones(CAM.shape), OutlierRejectionConfig())
    assert not test.reject(A, B, empty)

    # the candidate with the pose sees no object where the mask is, the other does: reject
    class Offside(PlaneRenderer):
        def render_depth(self, T_cam_obj, intrinsics):
            out = super().render_depth(T_cam_obj, intrinsics)
            out[0] = 0.0
            return out

    assert DepthOutlierTest(Offside(), CAM, OutlierRejectionConfig()).reject(
        A, B, _samples(np.full(CAM.shape, 0.5, np.float32))
    )


def test_a_renderer_returning_the_wrong_shape_is_an_error():
    class Wrong(PlaneRenderer):
        def render_depth(self, T_cam_obj, intrinsics):
            return np.zeros((1, 3, 3), np.float32)

    test = DepthOutlierTest(Wrong(), CAM, OutlierRejectionConfig())
    with pytest.raises(ValueError, match="depth renderer returned shape"):
        test.errors(np.eye(4)[None], _samples(np.ones(CAM.shape, np.float32)))
