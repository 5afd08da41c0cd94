"""The two independent readers the bag tests check every bag with, and the sequences they use.

- :func:`read_with_mcap_ros2`: ``mcap_ros2.reader.read_ros2_messages`` (the writer's library);
- :func:`read_with_rosbags`: ``rosbags.highlevel.AnyReader``, which parses the bag's embedded
  ``.msg`` definitions with its own parser and decodes CDR with its own code.

Both give ``(topic, datatype, log_time_ns, stamp_ns, message)`` tuples in log-time order.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path
from typing import Any

import pytest

pytest.importorskip("mcap_ros2", reason="needs the bags extra: pip install -e '.[bags]'")
pytest.importorskip("rosbags", reason="needs the bags extra: pip install -e '.[bags]'")

# the hand-made sequences live with the harness tests
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "harness"))
from harness_cases import EchoConfig, EchoTracker, box_sequence, write_box_dataset  # noqa: E402

__all__ = [
    "read_with_mcap_ros2",
    "read_with_rosbags",
    "box_sequence",
    "write_box_dataset",
    "EchoConfig",
    "EchoTracker",
]


def _stamp_ns(message: Any) -> int | None:
    header = getattr(message, "header", None)
    if header is None:  # TFMessage: the stamp of its (only) transform
        header = message.transforms[0].header
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def read_with_mcap_ros2(path: Path) -> list[tuple[str, str, int, int | None, Any]]:
    """Every message of ``path`` decoded by mcap_ros2."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # its reader module says "deprecated"
        from mcap_ros2.reader import read_ros2_messages

        return [
            (m.channel.topic, m.schema.name, m.log_time_ns, _stamp_ns(m.ros_msg), m.ros_msg)
            for m in read_ros2_messages(str(path))
        ]


def read_with_rosbags(path: Path) -> list[tuple[str, str, int, int | None, Any]]:
    """Every message of ``path`` decoded by rosbags (from the bag's own definitions)."""
    from rosbags.highlevel import AnyReader

    out = []
    with AnyReader([path]) as reader:
        for connection, log_time, raw in reader.messages():
            msg = reader.deserialize(raw, connection.msgtype)
            out.append((connection.topic, connection.msgtype, log_time, _stamp_ns(msg), msg))
    return out
