"""The message layer of roft_sim.bags: embedded definitions, stamps, the quaternion boundary."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bag_readers import read_with_rosbags  # noqa: F401  (skips without the bags extra)

from roft_sim.bags.messages import (
    frame_from_stamp_ns,
    matrix_from_quat_msg,
    pose_stamped_msg,
    stamp_ns_from_frame,
    transform_from_pose_msg,
)
from roft_sim.bags.msgdefs import MESSAGE_DEFINITIONS, dependencies, schema_text
from roft_sim.geometry.so3 import matrix_from_rotvec


@pytest.mark.parametrize("store", ["ROS2_HUMBLE", "ROS2_JAZZY"])
def test_embedded_definitions_are_the_ros2_ones(store):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    reference = get_typestore(getattr(Stores, store)).fielddefs
    for name in MESSAGE_DEFINITIONS:
        parsed = get_types_from_msg(schema_text(name), name)
        assert set(parsed) == {name, *dependencies(name)}
        for typ, fields in parsed.items():
            assert fields == reference[typ], typ


def test_schema_lists_each_dependency_once_after_a_separator():
    text = schema_text("sensor_msgs/msg/CameraInfo")
    assert text.startswith("std_msgs/Header header\n")
    blocks = text.split("=" * 80 + "\n")[1:]
    assert [b.splitlines()[0] for b in blocks] == [
        "MSG: std_msgs/Header",
        "MSG: builtin_interfaces/Time",
        "MSG: sensor_msgs/RegionOfInterest",
    ]


def test_stamps_round_trip_to_frames():
    for fps in (15, 30, 60, 90):
        ks = [0, 1, 2, 7, 29, 1000, 123456]
        assert [frame_from_stamp_ns(stamp_ns_from_frame(k, fps), fps) for k in ks] == ks
    assert stamp_ns_from_frame(2, 30) == 66_666_667  # nearest nanosecond


def test_quaternions_cross_the_boundary_scalar_last():
    T = np.eye(4)
    T[:3, :3] = matrix_from_rotvec([0.0, 0.0, math.pi / 2])
    T[:3, 3] = [0.1, -0.2, 0.7]
    q = pose_stamped_msg(0, T)["pose"]["orientation"]
    assert [q["x"], q["y"], q["z"]] == pytest.approx([0.0, 0.0, math.sqrt(0.5)], abs=1e-15)
    assert q["w"] == pytest.approx(math.sqrt(0.5), abs=1e-15)

    class Msg:  # a decoded message: attributes, not keys
        def __init__(self, d):
            for k, v in d.items():
                setattr(self, k, Msg(v) if isinstance(v, dict) else v)

    pose = Msg(pose_stamped_msg(0, T)["pose"])
    np.testing.assert_allclose(transform_from_pose_msg(pose), T, atol=1e-15)
    with pytest.raises(ValueError, match="zero norm"):
        matrix_from_quat_msg(Msg({"x": 0.0, "y": 0.0, "z": 0.0, "w": 0.0}))
