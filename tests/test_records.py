"""Records: shape validation, flow lookup, object-model diameter."""

from __future__ import annotations

import numpy as np
import pytest

from roft_sim.records import Estimate, FlowField, ObjectModel, PoseTrack


def _model(points: np.ndarray) -> ObjectModel:
    return ObjectModel(
        name="x", vertices_m=points, faces=np.zeros((0, 3), np.int64), model_points_m=points
    )


def test_diameter_of_a_box_and_of_flat_or_collinear_point_sets():
    corners = np.array([[x, y, z] for x in (0, 0.1) for y in (0, 0.2) for z in (0, 0.3)])
    rng = np.random.default_rng(0)
    inside = rng.uniform(0, 1, (200, 3)) * [0.1, 0.2, 0.3]
    assert _model(np.vstack([corners, inside])).diameter_m == pytest.approx(np.sqrt(0.14))
    flat = np.c_[rng.uniform(0, 1, (50, 2)), np.zeros(50)]
    flat[:2] = [[0, 0, 0], [1, 1, 0]]
    assert _model(flat).diameter_m == pytest.approx(np.sqrt(2))
    line = np.outer(np.linspace(0, 1, 10), [0.3, 0.4, 0.0])
    assert _model(line).diameter_m == pytest.approx(0.5)


def test_flow_field_block_nearest_lookup_and_dense():
    f = np.zeros((2, 3, 2), np.float32)
    f[1, 2] = [1.5, -2.0]
    flow = FlowField(flow_px=f, from_k=0, to_k=1, grid_px=4)
    np.testing.assert_array_equal(
        flow.sample(np.array([9, 0]), np.array([7, 0])), [[1.5, -2.0], [0, 0]]
    )
    assert flow.dense(8, 10).shape == (8, 10, 2)
    np.testing.assert_array_equal(
        flow.dense(8, 12)[4:, 8:], np.broadcast_to([1.5, -2.0], (4, 4, 2))
    )
    with pytest.raises(ValueError, match="does not cover"):
        flow.dense(9, 12)
    valid = np.ones((2, 3), bool)
    valid[1, 2] = False
    masked = FlowField(flow_px=f, from_k=0, to_k=1, grid_px=4, valid=valid)
    assert np.isnan(masked.sample(np.array([9]), np.array([7]))).all()


def test_records_reject_wrong_shapes():
    with pytest.raises(ValueError, match=r"T_cam_obj must have shape \(4, 4\)"):
        Estimate(k=0, T_cam_obj=np.eye(3), v_obj_mps=np.zeros(3), w_radps=np.zeros(3))
    with pytest.raises(ValueError, match=r"flow_px must have shape"):
        FlowField(flow_px=np.zeros((2, 2)), from_k=0, to_k=1)
    with pytest.raises(ValueError, match=r"v_obj_mps must have shape \(3, 3\)"):
        PoseTrack(
            t_s=np.zeros(3),
            T_cam_obj=np.zeros((3, 4, 4)),
            v_obj_mps=np.zeros((2, 3)),
            w_radps=np.zeros((3, 3)),
        )
    assert not Estimate.invalid(4).valid
