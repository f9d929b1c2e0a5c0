"""Write a ROS 2 bag directory (``metadata.yaml`` + one MCAP file) that survives a killed writer.

The MCAP file is written with the ``mcap`` library's public writer, without chunks: every record
goes to the file as it comes, and the file is flushed to the operating system after each message,
so a writer killed with SIGKILL loses no message it had written (the file then lacks its summary
and footer, and ``metadata.yaml`` is missing: :func:`moose_ros.bag.reader.read_bag` streams such a
file record by record).  The file is also fsync'ed at least every ``fsync_period`` seconds of
writing, which bounds what a power loss can take.  :meth:`BagWriter.close` writes the summary, the
footer and ``metadata.yaml`` (rosbag2 format version 9).  Message definitions (``ros2msg``) and
type hashes (RIHS01) come from rosbags' type store, so ``ros2 bag``, rosbags and Foxglove read
the bag.  Each topic of the graph contract carries its publishers' QoS as ``offered_qos_profiles``
(rosbag2's version-9 form), so ``ros2 bag play`` offers it again: ``/tf_static`` stays transient
local for RViz.  ``custom_data`` (strings) goes into ``metadata.yaml`` and, at once, into an MCAP
metadata record (:mod:`.params`).

Messages must be written in time order (rosbags reads an MCAP file without chunk indexes in file
order); an earlier timestamp is a :class:`BagError`.
"""
from __future__ import annotations

import os
import time
from collections import defaultdict
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any

import yaml
from mcap.writer import CompressionType, Writer

from ..graph import TOPICS
from ..interfaces import typestore
from ..runtime.qos import Qos
from .errors import BagError
from .params import METADATA_NAME

ROSBAG2_VERSION = 9
"""rosbag2 metadata version (ROS 2 Jazzy)."""


def _library() -> str:
    try:
        return f"moose_ros-{version('moose_ros')}"
    except PackageNotFoundError:
        return "moose_ros"


def offered_qos(qos: Qos) -> dict[str, Any]:
    """A QoS profile as rosbag2 (metadata version 9) writes an offered profile; durations unspecified."""
    unspecified = {"sec": 0, "nsec": 0}
    return {"history": "keep_last", "depth": qos.depth, "reliability": "reliable" if qos.reliable else "best_effort",
            "durability": "transient_local" if qos.transient_local else "volatile", "deadline": unspecified,
            "lifespan": unspecified, "liveliness": "system_default", "liveliness_lease_duration": unspecified,
            "avoid_ros_namespace_conventions": False}


def _offered(topic: str) -> list[dict[str, Any]]:
    contract = TOPICS.get(topic)
    return [offered_qos(contract.qos)] if contract is not None else []


class BagWriter:
    """A new ROS 2 bag directory with MCAP storage; every message reaches the OS as it is written.

    ``custom_data``: strings kept with the bag (the run's parameters, :mod:`.params`)."""

    def __init__(self, path: str | Path, fsync_period: float = 1.0, custom_data: dict[str, str] | None = None) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f"bag {str(self.path)!r} exists already: choose another output directory")
        parent = self.path.parent
        try:
            parent.mkdir(parents=True, exist_ok=True)
            if not os.access(parent, os.W_OK):
                raise BagError(f"bag {str(self.path)!r} cannot be written: {str(parent)!r} is not writable")
            self.path.mkdir()
            self.file = self.path / f"{self.path.name}_0.mcap"
            self._stream = open(self.file, "xb")  # noqa: SIM115 - closed by close()
        except OSError as exc:
            raise BagError(f"bag {str(self.path)!r} cannot be written: {exc.strerror or exc}") from None
        self._mcap = Writer(self._stream, use_chunking=False, compression=CompressionType.NONE)
        self._mcap.start(profile="ros2", library=_library())
        self.custom_data = dict(custom_data or {})
        if self.custom_data:
            self._mcap.add_metadata(METADATA_NAME, self.custom_data)
        self._store = typestore()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, tuple[int, str]] = {}
        self.counts: dict[str, int] = defaultdict(int)
        self.first_ns: int | None = None
        self.last_ns: int | None = None
        self.fsync_period = fsync_period
        self._last_sync = time.monotonic()
        self._stream.flush()

    def _channel(self, topic: str, type_name: str) -> int:
        known = self._channels.get(topic)
        if known is not None:
            if known[1] != type_name:
                raise BagError(f"bag {str(self.path)!r}: topic {topic!r} carries {known[1]!r}, not {type_name!r}")
            return known[0]
        if type_name not in self._schemas:
            msgdef, _ = self._store.generate_msgdef(type_name, ros_version=2)
            self._schemas[type_name] = self._mcap.register_schema(type_name, "ros2msg", msgdef.encode())
        offered = yaml.safe_dump(_offered(topic), sort_keys=False) if topic in TOPICS else ""
        channel = self._mcap.register_channel(topic, "cdr", self._schemas[type_name], {"offered_qos_profiles": offered})
        self._channels[topic] = (channel, type_name)
        return channel

    def write(self, topic: str, type_name: str, timestamp_ns: int, cdr: bytes) -> None:
        """Append one CDR-serialised message stamped ``timestamp_ns`` (not earlier than the previous one)."""
        timestamp_ns = int(timestamp_ns)
        if self.last_ns is not None and timestamp_ns < self.last_ns:
            raise BagError(f"bag {str(self.path)!r}: {topic} at {timestamp_ns} ns is earlier than the previous "
                           f"message ({self.last_ns} ns); messages are written in time order")
        channel = self._channel(topic, type_name)
        try:
            self._mcap.add_message(channel, log_time=timestamp_ns, data=cdr, publish_time=timestamp_ns,
                                   sequence=self.counts[topic] % 2**32)
            self._stream.flush()
            if time.monotonic() - self._last_sync >= self.fsync_period:
                self.sync()
        except OSError as exc:
            raise BagError(f"bag {str(self.path)!r}: write failed ({exc.strerror}); "
                           "the bag is readable up to here") from None
        self.counts[topic] += 1
        self.first_ns = timestamp_ns if self.first_ns is None else self.first_ns
        self.last_ns = timestamp_ns

    def sync(self) -> None:
        """Push what was written to the disk (fsync)."""
        self._stream.flush()
        os.fsync(self._stream.fileno())
        self._last_sync = time.monotonic()

    def metadata(self) -> dict[str, Any]:
        """The ``rosbag2_bagfile_information`` of what was written."""
        start = self.first_ns or 0
        duration = (self.last_ns or 0) - start
        count = sum(self.counts.values())
        return {
            "version": ROSBAG2_VERSION,
            "storage_identifier": "mcap",
            "relative_file_paths": [self.file.name],
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": count,
            "topics_with_message_count": [
                {"topic_metadata": {"name": topic, "type": type_name, "serialization_format": "cdr",
                                    "offered_qos_profiles": _offered(topic),
                                    "type_description_hash": self._store.hash_rihs01(type_name)},
                 "message_count": self.counts[topic]}
                for topic, (_channel, type_name) in self._channels.items()
            ],
            "compression_format": "",
            "compression_mode": "",
            "files": [{"path": self.file.name, "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration}, "message_count": count}],
            "custom_data": self.custom_data or None,
            "ros_distro": "jazzy",
        }

    def close(self) -> None:
        """Write the MCAP summary and footer, then ``metadata.yaml`` (atomically)."""
        if self._stream.closed:
            return
        info = self.metadata()
        try:
            self._mcap.add_metadata("rosbag2", {"serialized_metadata": yaml.safe_dump(info, sort_keys=True)})
            self._mcap.finish()
            self.sync()
            self._stream.close()
            tmp = self.path / "metadata.yaml.tmp"
            tmp.write_text(yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=True), encoding="utf-8")
            tmp.replace(self.path / "metadata.yaml")
        except OSError as exc:
            raise BagError(f"bag {str(self.path)!r}: closing failed ({exc.strerror}); the bag is readable up to the "
                           "last message") from None
