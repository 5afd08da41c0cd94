"""`roft-sim bag export`: a sequence under faults as a ROS 2 bag, read back by two readers and
checked against the fault schedule of the run it mirrors."""

from __future__ import annotations

import dataclasses
import json
import re
from collections import Counter

import numpy as np
import pytest
from bag_readers import box_sequence, read_with_mcap_ros2, read_with_rosbags, write_box_dataset

from roft_sim.bags.export import export_options, export_sequence_bag
from roft_sim.bags.messages import (
    CAMERA_FRAME,
    GT_OBJECT_FRAME,
    array_from_image_msg,
    depth_m_from_image_msg,
    matrix_from_quat_msg,
    stamp_ns_from_frame,
    transform_from_pose_msg,
)
from roft_sim.cli import main
from roft_sim.datasets import open_sequence
from roft_sim.faults import load_faults
from roft_sim.harness.runner import make_observation_stream

FPS = 30
CHAOS_SEED = 10
"""A seed under which chaos on the test sequence reorders, duplicates and drops (asserted)."""


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("data")
    return write_box_dataset(root, names=("box",), n_frames=60, width=32, height=24) / "box"


@pytest.fixture(scope="module")
def chaos_bag(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("bags") / "chaos.mcap"
    args = ["bag", "export", str(dataset), "--faults", "chaos", "--seed", str(CHAOS_SEED)]
    assert main([*args, "--out", str(out), "--no-progress", "--json"]) == 0
    return out


@pytest.fixture(scope="module")
def chaos_schedule(dataset):
    sequence = open_sequence(dataset)
    options = export_options(load_faults("chaos"), seed=CHAOS_SEED)
    stream, _, _ = make_observation_stream(sequence, options, with_flow=False)
    return sequence, stream


@pytest.fixture(scope="module")
def readers(chaos_bag):
    return {"mcap_ros2": read_with_mcap_ros2(chaos_bag), "rosbags": read_with_rosbags(chaos_bag)}


def ns(k: int) -> int:
    return stamp_ns_from_frame(k, FPS)


def test_stamps_are_frame_times_in_integer_nanoseconds():
    assert [ns(k) for k in (0, 1, 2, 3, 30)] == [0, 33333333, 66666667, 100000000, 10**9]


@pytest.mark.parametrize("reader", ["mcap_ros2", "rosbags"])
def test_chaos_bag_logs_every_detection_at_its_scheduled_arrival(readers, chaos_schedule, reader):
    sequence, stream = chaos_schedule
    n = len(sequence)
    messages = readers[reader]
    for stream_name, topic in (("pose", "/detector/pose"), ("mask", "/segmenter/mask")):
        events = [e for e in stream.schedule.deliveries(stream_name) if e.arrival_k < n]
        expected = Counter((ns(e.reported_capture_k), ns(e.arrival_k)) for e in events)
        got = Counter((stamp, log) for t, _, log, stamp, _ in messages if t == topic)
        assert got == expected, topic
    # the schedule really is chaotic: late, duplicated, stamped out of order in log order
    poses = [(log, stamp) for t, _, log, stamp, _ in messages if t == "/detector/pose"]
    assert all(log >= stamp for log, stamp in poses) and any(log > stamp for log, stamp in poses)
    events = stream.schedule.deliveries("pose")
    assert any(e.copy != "original" for e in events)
    stamps_in_bag_order = [stamp for _, stamp in poses]
    assert stamps_in_bag_order != sorted(stamps_in_bag_order)  # reordered (within one arrival)


@pytest.mark.parametrize("reader", ["mcap_ros2", "rosbags"])
def test_chaos_bag_topics_types_and_camera_frames(readers, chaos_schedule, reader):
    sequence, stream = chaos_schedule
    n = len(sequence)
    dropped = stream.schedule.camera.dropped
    assert 0 < dropped.sum() < n
    delivered = [ns(k) for k in range(n) if not dropped[k]]
    messages = readers[reader]
    types = {t: dt for t, dt, *_ in messages}
    assert types == {
        "/camera/color/image_raw": "sensor_msgs/msg/Image",
        "/camera/color/camera_info": "sensor_msgs/msg/CameraInfo",
        "/camera/depth/image_rect": "sensor_msgs/msg/Image",
        "/camera/depth/camera_info": "sensor_msgs/msg/CameraInfo",
        "/detector/pose": "geometry_msgs/msg/PoseStamped",
        "/segmenter/mask": "sensor_msgs/msg/Image",
        "/tf": "tf2_msgs/msg/TFMessage",
        "/ground_truth/twist": "geometry_msgs/msg/TwistStamped",
    }
    for topic in types:
        rows = [(log, stamp) for t, _, log, stamp, _ in messages if t == topic]
        if topic.startswith("/camera/"):  # a dropped frame has no image and no camera info
            assert rows == [(s, s) for s in delivered], topic
        elif topic in ("/tf", "/ground_truth/twist"):
            assert rows == [(ns(k), ns(k)) for k in range(n)], topic
    logs = [log for _, _, log, _, _ in messages]
    assert logs == sorted(logs)


def test_both_readers_decode_the_same_content(readers, chaos_schedule):
    sequence, stream = chaos_schedule
    truth = sequence.ground_truth()
    a, b = readers["mcap_ros2"], readers["rosbags"]
    assert sorted((t, log, s) for t, _, log, s, _ in a) == sorted(
        (t, log, s) for t, _, log, s, _ in b
    )
    for messages in (a, b):
        by_topic: dict[str, list] = {}
        for topic, _, log, stamp, msg in messages:
            by_topic.setdefault(topic, []).append((log, stamp, msg))
        log, _, image = by_topic["/camera/color/image_raw"][0]
        k = round(log * FPS / 1e9)
        assert image.header.frame_id == CAMERA_FRAME and image.encoding == "rgb8"
        np.testing.assert_array_equal(array_from_image_msg(image), sequence.rgb(k))
        for log, stamp, pose in by_topic["/detector/pose"]:
            arrival = round(log * FPS / 1e9)
            observed = stream.observation(arrival).poses
            match = [p for p in observed if ns(p.capture_k) == stamp]
            assert match, (arrival, stamp)
            got = transform_from_pose_msg(pose.pose)
            assert min(np.abs(got - p.T_cam_obj).max() for p in match) < 1e-12
        log, _, mask = by_topic["/segmenter/mask"][0]
        assert mask.encoding == "mono8"
        assert set(np.unique(array_from_image_msg(mask))) <= {0, 255}
        for log, _, tf in by_topic["/tf"]:
            k = round(log * FPS / 1e9)
            (transform,) = tf.transforms
            assert transform.header.frame_id == CAMERA_FRAME
            assert transform.child_frame_id == GT_OBJECT_FRAME
            q = transform.transform.rotation
            R = matrix_from_quat_msg(q)
            np.testing.assert_allclose(R, truth.T_cam_obj[k, :3, :3], atol=1e-12)
            assert q.w >= 0
        for log, _, twist in by_topic["/ground_truth/twist"]:
            k = round(log * FPS / 1e9)
            v = twist.twist.linear
            np.testing.assert_array_equal([v.x, v.y, v.z], truth.v_obj_mps[k])


@pytest.mark.parametrize("encoding", ["32FC1", "16UC1"])
def test_depth_encodings_round_trip(tmp_path, encoding):
    base = box_sequence(n_frames=4, width=16, height=12)
    depths = [np.array(d) for d in base.depth_frames]
    for d in depths:
        d[:2, :3] = 0.0  # no return
        d[3, 4] = 70.0  # beyond 16UC1's 65.535 m: no return there
    sequence = dataclasses.replace(base, depth_frames=depths)
    options = export_options(load_faults("none"))
    out = tmp_path / f"{encoding}.mcap"
    export_sequence_bag(sequence, options, out, depth_encoding=encoding)
    for messages in (read_with_mcap_ros2(out), read_with_rosbags(out)):
        depths = [m for t, _, _, _, m in messages if t == "/camera/depth/image_rect"]
        assert len(depths) == len(sequence)
        for k, msg in enumerate(depths):
            expected = sequence.depth(k)
            assert msg.encoding == encoding and msg.header.frame_id == CAMERA_FRAME
            got = depth_m_from_image_msg(msg)
            if encoding == "32FC1":
                np.testing.assert_array_equal(got, expected)
                assert np.isnan(array_from_image_msg(msg)[expected == 0]).all()  # REP 118
            else:
                expected = np.where(expected > 65.535, 0, expected)
                np.testing.assert_allclose(got, expected, atol=0.5e-3 + 1e-7)
                assert (array_from_image_msg(msg)[expected == 0] == 0).all()
                assert array_from_image_msg(msg).dtype == np.uint16


def test_no_ground_truth_leaves_out_tf_and_twist(tmp_path):
    sequence = box_sequence(n_frames=3, width=16, height=12)
    out = tmp_path / "inputs.mcap"
    export_sequence_bag(sequence, export_options(load_faults("none")), out, ground_truth=False)
    topics = {t for t, *_ in read_with_rosbags(out)}
    assert "/tf" not in topics and "/ground_truth/twist" not in topics
    assert "/camera/color/image_raw" in topics


def test_export_refuses_an_existing_bag_without_overwrite(dataset, tmp_path, capsys):
    out = tmp_path / "a.mcap"
    out.write_bytes(b"keep")
    args = ["bag", "export", str(dataset), "--faults", "none", "--out", str(out), "--no-progress"]
    assert main(args) == 2
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert out.read_bytes() == b"keep"
    assert main([*args, "--overwrite", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["topics"]["/tf"]["messages"] == 60 and out.stat().st_size > 4


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"--out": "a.bag"}, "must end in .mcap"),
        ({"SEQUENCE": "missing"}, "missing"),
        ({"--faults": "no-such-preset"}, "no-such-preset"),
        ({"--poses": "nope"}, "no pose set 'nope'"),
    ],
)
def test_export_checks_its_inputs_before_writing(dataset, tmp_path, capsys, change, message):
    values = {"SEQUENCE": str(dataset), "--out": "a.mcap", "--faults": "none", "--poses": "auto"}
    values |= change
    args = ["bag", "export", values.pop("SEQUENCE"), "--no-progress"]
    for key, value in values.items():
        args += [key, str(tmp_path / value) if key == "--out" else value]
    assert main(args) == 2
    assert re.search(message, capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


def test_a_failed_export_leaves_no_file(tmp_path):
    sequence = box_sequence(n_frames=6, width=16, height=12)
    out = tmp_path / "half.mcap"

    def interrupt(_: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        export_sequence_bag(sequence, export_options(load_faults("none")), out, progress=interrupt)
    assert list(tmp_path.iterdir()) == []


def test_the_bag_follows_the_mcap_ros2_profile(chaos_bag):
    from mcap.reader import make_reader

    with open(chaos_bag, "rb") as stream:
        reader = make_reader(stream)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert header.profile == "ros2"
    assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
    for channel in summary.channels.values():
        assert channel.message_encoding == "cdr"
        assert channel.metadata == {"offered_qos_profiles": ""}  # the profile's required key
    assert metadata["roft_sim"]["faults"] == "chaos" and metadata["roft_sim"]["seed"] == "10"
    assert metadata["roft_sim"]["frames"] == "60" and metadata["roft_sim"]["fps"] == "30"
