"""Writing a ROS 2 bag as one MCAP file (profile ``ros2``, schemas ``ros2msg``, messages ``cdr``),
atomically: the messages go to a hidden temporary file beside the target, renamed into place when
the bag is complete, removed when writing fails.

The MCAP is written by ``mcap`` (zstd-compressed chunks, CRCs) with the messages encoded by
``mcap-ros2-support``; each message type is registered once with its definitions
(:func:`~roft_sim.bags.msgdefs.schema_text`).
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from roft_sim.bags.msgdefs import schema_text
from roft_sim.datasets.atomic_files import atomic_path
from roft_sim.errors import ConfigError

__all__ = [
    "BagWriter",
    "TopicCount",
    "open_bag",
    "check_bag_path",
    "require_bags_extra",
    "METADATA_NAME",
    "QOS_METADATA",
]

METADATA_NAME = "roft_sim"
"""Name of the MCAP metadata record in which a bag says what it holds (all values strings)."""


def check_bag_path(path: str | os.PathLike[str], *, overwrite: bool) -> Path:
    """Checks that a bag may be written at ``path``; returns it as a Path.

    Raises:
        ConfigError: not a ``.mcap`` name, an existing file without ``overwrite``, or a folder.
    """
    path = Path(path)
    if path.suffix != ".mcap":
        raise ConfigError(
            f"bag path {str(path)!r} must end in .mcap (ros2 bag play picks the storage plugin "
            "by the extension)"
        )
    if path.is_dir():
        raise ConfigError(f"bag path {str(path)!r} is a folder; give a file name ending in .mcap")
    if path.exists() and not overwrite:
        raise ConfigError(
            f"bag {str(path)!r} exists; pass --overwrite to replace it or choose another --out"
        )
    return path


@dataclass(frozen=True, slots=True)
class TopicCount:
    """One topic of a written bag."""

    datatype: str
    """Its message type, e.g. ``sensor_msgs/msg/Image``."""
    messages: int
    """How many messages it has."""


QOS_METADATA = {"offered_qos_profiles": ""}
"""Channel metadata of every topic: the ``ros2`` profile requires the key; rosbag2 reads an
empty value as "no recorded QoS" and ``ros2 bag play`` then publishes with its default QoS."""


class BagWriter:
    """Writes messages (dicts in their ``.msg`` layout) to an open MCAP stream.

    Use :func:`open_bag`; :meth:`write` registers each type's schema and each topic's channel on
    first use. Messages are encoded to CDR by the encoder of ``mcap-ros2-support``; the file is
    written with ``mcap``'s writer directly, because the ROS 2 writer of ``mcap-ros2-support``
    registers channels without the ``offered_qos_profiles`` metadata the profile requires.
    """

    def __init__(self, stream: Any) -> None:
        from mcap.writer import CompressionType, Writer

        from roft_sim import __version__

        self._writer = Writer(stream, compression=CompressionType.ZSTD)
        self._writer.start(profile="ros2", library=f"roft_sim {__version__}")
        self._schemas: dict[str, tuple[int, Any]] = {}
        self._channels: dict[str, int] = {}
        self._topics: dict[str, TopicCount] = {}

    def _schema(self, datatype: str) -> tuple[int, Any]:
        """``(schema id, CDR encoder)`` of ``datatype``, registered on first use."""
        if datatype not in self._schemas:
            from mcap.well_known import SchemaEncoding
            from mcap_ros2._dynamic import serialize_dynamic

            text = schema_text(datatype)
            data = text.encode()
            schema_id = self._writer.register_schema(datatype, SchemaEncoding.ROS2, data)
            self._schemas[datatype] = (schema_id, serialize_dynamic(datatype, text)[datatype])
        return self._schemas[datatype]

    def write(
        self, topic: str, datatype: str, message: Mapping[str, Any], log_time_ns: int
    ) -> None:
        """Writes ``message`` of ``datatype`` on ``topic``, logged and published at
        ``log_time_ns`` [ns].

        Raises:
            ConfigError: the topic was written before with another type.
        """
        seen = self._topics.get(topic)
        if seen is not None and seen.datatype != datatype:
            raise ConfigError(f"topic {topic!r} carries {seen.datatype}, not {datatype}")
        schema_id, encode = self._schema(datatype)
        if topic not in self._channels:
            from mcap.well_known import MessageEncoding

            self._channels[topic] = self._writer.register_channel(
                topic, MessageEncoding.CDR, schema_id, metadata=dict(QOS_METADATA)
            )
        count = 0 if seen is None else seen.messages
        self._writer.add_message(
            self._channels[topic],
            log_time=int(log_time_ns),
            data=encode(message),
            publish_time=int(log_time_ns),
            sequence=count,
        )
        self._topics[topic] = TopicCount(datatype, count + 1)

    def add_metadata(self, values: Mapping[str, str]) -> None:
        """Adds the :data:`METADATA_NAME` metadata record."""
        self._writer.add_metadata(METADATA_NAME, dict(values))

    @property
    def topics(self) -> dict[str, TopicCount]:
        """Every topic written so far, in the order of their first message."""
        return dict(self._topics)

    def finish(self) -> None:
        """Writes the summary section and the footer."""
        self._writer.finish()  # type: ignore[no-untyped-call]  # mcap leaves it untyped


@contextlib.contextmanager
def open_bag(path: str | os.PathLike[str]) -> Iterator[BagWriter]:
    """A :class:`BagWriter` on a temporary file beside ``path``, renamed to ``path`` when the
    ``with`` block ends normally and removed when it raises (``path`` is then left as it was).

    Raises:
        ConfigError: the ``bags`` extra (``mcap``, ``mcap-ros2-support``) is not installed.
    """
    require_bags_extra()
    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        writer = BagWriter(stream)
        yield writer
        writer.finish()


def require_bags_extra() -> None:
    """Raises ConfigError, saying how to install it, when the ``bags`` extra is missing."""
    try:
        import mcap  # noqa: F401
        import mcap_ros2  # noqa: F401
    except ImportError:
        raise ConfigError(
            "ROS 2 bags need the optional extra 'bags' (mcap, mcap-ros2-support): "
            "pip install -e '.[bags]' (or bash scripts/setup.sh dev,bags)"
        ) from None
