"""Unit test of the example plugin (runs without installing it: pytest examples/tracker_plugin)."""

import numpy as np
from roft_sim_example_tracker import SPEC, ExtrapolateConfig

from roft_sim.geometry import CameraIntrinsics, transform_from_rt
from roft_sim.records import ObjectModel, Observation, PoseDetection
from roft_sim.trackers import TrackerContext, run_tracker


def test_constant_velocity_is_extrapolated_exactly():
    fps = 30
    ctx = TrackerContext(
        intrinsics=CameraIntrinsics(
            fx_px=100.0, fy_px=100.0, cx_px=15.5, cy_px=11.5, width_px=32, height_px=24
        ),
        fps=fps,
        object_model=ObjectModel(
            name="point",
            vertices_m=np.zeros((3, 3)),
            faces=np.zeros((1, 3), np.int64),
            model_points_m=np.zeros((1, 3)),
        ),
        rng=np.random.default_rng(0),
    )
    tracker = SPEC.factory(ExtrapolateConfig(), ctx)
    v = np.array([0.3, -0.1, 0.05])
    pose = lambda k: transform_from_rt(np.eye(3), [0.0, 0.0, 0.5] + v * k / fps)  # noqa: E731
    obs = [
        Observation(
            k=k,
            t_s=k / fps,
            rgb=None,
            depth_m=None,
            flow=None,
            poses=tuple(
                PoseDetection(capture_k=c, arrival_k=k, T_cam_obj=pose(c), detection_id=c)
                for c in (k - 6,)
                if c >= 0 and c % 6 == 0
            ),
        )
        for k in range(30)
    ]
    est = run_tracker(tracker, obs)
    assert not est[5].valid
    np.testing.assert_allclose(est[20].T_cam_obj, pose(20), atol=1e-12)
    np.testing.assert_allclose(est[20].v_obj_mps, v, atol=1e-12)
