"""Reading ROS 2 bags in MCAP with ``mcap`` and ``mcap-ros2-support``: a ``.mcap`` file or a
rosbag2 folder of them (what ``ros2 bag record -s mcap`` writes), its topics, its
:data:`~roft_sim.bags.writer.METADATA_NAME` metadata and its decoded messages."""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from roft_sim.bags.writer import METADATA_NAME, TopicCount, require_bags_extra
from roft_sim.errors import ConfigError, DatasetFormatError

__all__ = ["BagMessage", "bag_files", "bag_topics", "bag_metadata", "read_messages"]


@dataclass(frozen=True, slots=True)
class BagMessage:
    """One decoded message."""

    topic: str
    """Its topic."""
    log_time_ns: int
    """When it was logged (recorded) [ns]."""
    message: Any
    """The decoded message (attributes named as in its ``.msg``)."""


def bag_files(path: str | os.PathLike[str]) -> list[Path]:
    """The MCAP files of a bag: ``path`` itself (a ``.mcap`` file) or the ``.mcap`` files of a
    rosbag2 folder, in name order.

    Raises:
        ConfigError: no such file or folder, or a folder without ``.mcap`` files (a sqlite3 bag:
            record with ``-s mcap``, or convert it).
    """
    require_bags_extra()
    path = Path(path)
    if path.is_file() and path.suffix == ".mcap":
        return [path]
    if path.is_dir():
        files = sorted(path.glob("*.mcap"))
        if files:
            return files
        hint = " (it holds sqlite3 .db3 files: record with ros2 bag record -s mcap)" * any(
            path.glob("*.db3")
        )
        raise ConfigError(f"bag folder {str(path)!r} has no .mcap file{hint}")
    if not path.exists():
        raise ConfigError(f"bag {str(path)!r} does not exist")
    raise ConfigError(f"bag {str(path)!r} is not a .mcap file or a rosbag2 folder")


def _reader(stream: Any) -> Any:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    return make_reader(stream, decoder_factories=[DecoderFactory()])


def bag_topics(files: Sequence[Path]) -> dict[str, TopicCount]:
    """Every topic of the bag with its type and message count (from the MCAP summaries).

    Raises:
        DatasetFormatError: a file without a summary section (not closed properly).
    """
    out: dict[str, TopicCount] = {}
    for file in files:
        with open(file, "rb") as stream:
            summary = _reader(stream).get_summary()
        if summary is None or summary.statistics is None:
            raise DatasetFormatError(
                f"{file} has no MCAP summary (the recording was not closed properly); repair it "
                "with `mcap recover`"
            )
        counts = summary.statistics.channel_message_counts
        for channel_id, channel in summary.channels.items():
            schema = summary.schemas.get(channel.schema_id)
            datatype = schema.name if schema is not None else "?"
            seen = out.get(channel.topic)
            before = 0 if seen is None else seen.messages
            out[channel.topic] = TopicCount(datatype, before + counts.get(channel_id, 0))
    return out


def bag_metadata(files: Sequence[Path]) -> dict[str, str]:
    """The :data:`~roft_sim.bags.writer.METADATA_NAME` metadata of the bag ({} when absent)."""
    out: dict[str, str] = {}
    for file in files:
        with open(file, "rb") as stream:
            for record in _reader(stream).iter_metadata():
                if record.name == METADATA_NAME:
                    out |= dict(record.metadata)
    return out


def read_messages(files: Sequence[Path], topics: Sequence[str]) -> Iterator[BagMessage]:
    """The decoded messages of ``topics``, in log-time order within each file."""
    for file in files:
        with open(file, "rb") as stream:
            for _, channel, message, decoded in _reader(stream).iter_decoded_messages(
                topics=list(topics), log_time_order=True
            ):
                yield BagMessage(channel.topic, int(message.log_time), decoded)
