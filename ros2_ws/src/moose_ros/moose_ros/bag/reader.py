"""Read a bag: messages in time order, also from the unfinished file of a killed recorder; summary statistics.

A bag with ``metadata.yaml`` is read with rosbags' public :class:`rosbags.rosbag2.Reader`.  Without it
(a recorder killed before closing the bag), each ``.mcap`` file of the directory is streamed record by
record with the ``mcap`` library's public :class:`~mcap.stream_reader.StreamReader`: every complete
record is kept (for chunked files, every complete chunk), so no summary, index or footer is needed.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Optional, Sequence

from rosbags.rosbag2 import Reader

from ..interfaces import typestore
from .errors import BagError


@dataclass(frozen=True)
class BagMessage:
    """One message of a bag."""

    topic: str
    type_name: str
    timestamp_ns: int
    msg: Any
    """The rosbags message (fields by their .msg names)."""


def read_bag(path: str | Path, topics: Optional[Sequence[str]] = None) -> Iterator[BagMessage]:
    """Messages of a bag in time order; a bag without metadata (a crashed recorder) is recovered."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"bag {str(path)!r} does not exist")
    store = typestore()
    wanted = set(topics) if topics else None
    if (path / "metadata.yaml").is_file():
        yielded = 0
        try:
            with Reader(path) as reader:
                connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
                for connection, timestamp, raw in reader.messages(connections=connections):
                    yield BagMessage(connection.topic, connection.msgtype, timestamp,
                                     store.deserialize_cdr(raw, connection.msgtype))
                    yielded += 1
            return
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds; recover or explain below
            if yielded:
                raise BagError(f"bag {str(path)!r} is unreadable after {yielded} messages: {exc}") from None
            if not sorted(path.glob("*.mcap")):
                raise BagError(f"bag {str(path)!r} is unreadable: {exc}") from None
    yield from _recover(path, wanted)


def _recover(path: Path, wanted: Optional[set[str]]) -> Iterator[BagMessage]:
    """The messages of the complete records (and chunks) of unfinished MCAP files, in time order per file."""
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    files = sorted(path.glob("*.mcap")) if path.is_dir() else [path]
    if not files:
        raise BagError(f"bag {str(path)!r} has neither metadata.yaml nor an .mcap file")
    store = typestore()
    found = False
    for file in files:
        schemas: dict[int, str] = {}
        channels: dict[int, tuple[str, str]] = {}
        messages: list[BagMessage] = []
        with open(file, "rb") as stream:
            try:
                for record in StreamReader(stream, skip_magic=False).records:
                    if isinstance(record, Schema):
                        schemas[record.id] = record.name
                    elif isinstance(record, Channel):
                        channels[record.id] = (record.topic, schemas.get(record.schema_id, ""))
                    elif isinstance(record, Message) and record.channel_id in channels:
                        topic, type_name = channels[record.channel_id]
                        if wanted is None or topic in wanted:
                            messages.append(BagMessage(topic, type_name, record.log_time,
                                                       store.deserialize_cdr(record.data, type_name)))
            except (McapError, EOFError, ValueError, KeyError, AssertionError, struct.error) as exc:  # a cut record
                if not messages and not channels:
                    raise BagError(f"bag file {str(file)!r} is not a readable MCAP file: {exc}") from None
            found = found or bool(channels)
        messages.sort(key=lambda m: m.timestamp_ns)
        yield from messages
    if not found:
        raise BagError(f"bag {str(path)!r} holds no complete chunk or channel record")


def bag_info(path: str | Path) -> dict[str, Any]:
    """Topics, types, counts, rates (Hz) and duration (s)."""
    stats: dict[str, dict[str, Any]] = {}
    first = last = None
    for m in read_bag(path):
        entry = stats.setdefault(m.topic, {"type": m.type_name, "count": 0, "first": m.timestamp_ns, "last": m.timestamp_ns})
        entry["count"] += 1
        entry["last"] = m.timestamp_ns
        first = m.timestamp_ns if first is None else min(first, m.timestamp_ns)
        last = m.timestamp_ns if last is None else max(last, m.timestamp_ns)
    duration = (last - first) * 1e-9 if first is not None else 0.0
    topics = {}
    for topic, e in sorted(stats.items()):
        span = (e["last"] - e["first"]) * 1e-9
        topics[topic] = {"type": e["type"], "count": e["count"], "rate_hz": (e["count"] - 1) / span if span > 0 else math.nan}
    return {"path": str(path), "duration_s": duration, "messages": sum(e["count"] for e in stats.values()), "topics": topics}
