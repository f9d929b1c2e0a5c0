"""Write a ROS 2 bag directory (``metadata.yaml`` + one MCAP file) that is a valid bag at every checkpoint.

The MCAP file is chunked by the ``mcap`` library's public writer: zstd-compressed chunks, each with the CRC-32
of its records, so a reader detects a damaged chunk, skips it and goes on with the next
(:mod:`moose_ros.bag.reader`).  A chunk is closed, at the latest, once it spans :data:`CHUNK_SPAN_S` of message
time or has been open that long on the wall clock (:meth:`BagWriter.poll`, which the live recorder calls from a
timer, so a chunk is closed also when messages stop coming), or holds :data:`CHUNK_BYTES`.

**Checkpoints.**  Closing a chunk is a checkpoint: everything since the previous one (the chunk, its message
indexes, new schema and channel records) and then a data end record, a footer without summary and the closing
magic go to the file in one write, over the previous checkpoint's footer.  After every checkpoint the file is a
complete MCAP file (its footer says "no summary": readers scan it), which ``mcap``'s own readers, rosbags and
Foxglove open.  ``metadata.yaml`` (rosbag2 format version 9) is rewritten before a checkpoint that adds a topic,
naming it with the messages the file holds, and else at most every ``fsync_period`` of wall time: rosbags reads
only the topics ``metadata.yaml`` names (every message of the file on those), mcap's reader every record of the
file, so a topic is named before its first records reach the file (and ``metadata.yaml`` is written before the
file's first bytes).  A kill between any two of the writer's writes leaves a bag that mcap's reader, rosbags and
ours read message for message, or all refuse (an empty file).  The space a checkpoint needs is reserved first,
without changing the file's size (:func:`_reserve`), so a full disk fails before anything is written and leaves
the previous checkpoint's file intact.  A recorder killed with SIGKILL therefore leaves a valid bag of every
message up to its last checkpoint: it loses what was in the open chunk (at most :data:`CHUNK_SPAN_S` of
recording) and what its DDS readers still held; killed inside the checkpoint's one write (the kernel can stop a
write between two pages), the file ends without a footer, and only our reader recovers it.  The file is fsync'ed
at a checkpoint at least every ``fsync_period`` seconds, which bounds what a power loss can take.

Schema and channel records are also written outside the chunks (the writer repeats them inside, as the mcap
library does): a damaged chunk then never takes the definition of a topic with it.  :meth:`BagWriter.close`
writes the summary (schemas, channels, statistics, chunk indexes) and the final ``metadata.yaml``.

Message definitions (``ros2msg``) and type hashes (RIHS01) come from rosbags' type store, so ``ros2 bag``,
rosbags and Foxglove read the bag.  Each topic of the graph contract carries its publishers' QoS as
``offered_qos_profiles`` (rosbag2's version-9 form), so ``ros2 bag play`` offers it again: ``/tf_static`` stays
transient local for RViz.  ``custom_data`` (strings) goes into ``metadata.yaml`` and, at once, into an MCAP
metadata record (:mod:`.params`).  Messages must be written in time order; an earlier timestamp is a
:class:`BagError`.  A write that fails (a full disk) is a :class:`BagError` saying what the bag holds; the
writer then takes no more messages.
"""
from __future__ import annotations

import ctypes
import errno
import os
import sys
import time
from collections import defaultdict
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import Any, Callable, Optional

from mcap.data_stream import RecordBuilder
from mcap.records import Channel, DataEnd, Footer, Schema
from mcap.writer import CompressionType, Writer

from moose.files import dump_yaml

from ..graph import TOPICS
from ..interfaces import typestore
from ..runtime.qos import Qos
from .errors import BagError
from .params import METADATA_NAME

ROSBAG2_VERSION = 9
"""rosbag2 metadata version (ROS 2 Jazzy)."""
CHUNK_SPAN_S = 0.25
"""Longest a chunk stays open (s of message time, and of wall time through :meth:`BagWriter.poll`): what a
SIGKILL can take from a recording, and the most one damaged chunk takes from a bag."""
CHUNK_BYTES = 1024 * 1024
"""Most uncompressed bytes of messages in a chunk (a burst closes it earlier than :data:`CHUNK_SPAN_S`)."""
MAGIC = b"\x89MCAP0\r\n"
"""The MCAP file's opening and closing magic (MCAP specification, version 0)."""


FALLOC_FL_KEEP_SIZE = 1
"""Linux ``fallocate(2)``'s mode that reserves blocks without changing the file's size."""


def _fallocate() -> Optional[Callable[..., int]]:
    """Linux's ``fallocate`` from the C library (None elsewhere: Python's ``os`` has only ``posix_fallocate``)."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None
    function = getattr(libc, "fallocate64", None) or getattr(libc, "fallocate", None)
    if function is not None:
        function.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64]
        function.restype = ctypes.c_int
    return function


_FALLOCATE = _fallocate()


def _reserve(fd: int, offset: int, length: int) -> None:
    """Reserve the blocks ``length`` bytes at ``offset`` need, so that writing them cannot fail for want of space
    (:class:`OSError` here, on a full disk, with nothing written).  The file keeps its size (Linux,
    :data:`FALLOC_FL_KEEP_SIZE`): ``posix_fallocate`` extends it with zeros, and a kill between that and the write
    left a file whose end is no footer, which mcap's and rosbags' readers refuse.  ``posix_fallocate`` only where
    that mode is missing; nothing on a file system that cannot reserve space."""
    if _FALLOCATE is not None:
        if _FALLOCATE(fd, FALLOC_FL_KEEP_SIZE, offset, length) == 0:
            return
        code = ctypes.get_errno()
        if code not in (errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
            raise OSError(code, os.strerror(code))
    if hasattr(os, "posix_fallocate"):
        try:
            os.posix_fallocate(fd, offset, length)
        except OSError as exc:
            if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):  # a file system without it: write
                raise


def _library() -> str:
    try:
        return f"moose_ros-{version('moose_ros')}"
    except PackageNotFoundError:
        return "moose_ros"


def _records(*records: Any) -> bytes:
    builder = RecordBuilder()
    for record in records:
        record.write(builder)
    return bytes(builder.end())


TAIL = _records(DataEnd(0), Footer(summary_start=0, summary_offset_start=0, summary_crc=0)) + MAGIC
"""What ends the file at a checkpoint: the data section's end, a footer without summary, the magic."""


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


class _Staged:
    """The stream the mcap writer writes into: held here until the next checkpoint puts it on the file at
    :attr:`base`, the offset where the previous checkpoint's :data:`TAIL` begins."""

    def __init__(self) -> None:
        self.base = 0
        self.buffer = bytearray()

    def write(self, data: bytes) -> int:
        self.buffer += data
        return len(data)

    def tell(self) -> int:
        return self.base + len(self.buffer)

    def flush(self) -> None:
        """The file is written at checkpoints (:meth:`BagWriter._checkpoint`), not here."""


class BagWriter:
    """A new ROS 2 bag directory with MCAP storage, a valid bag after every checkpoint (module doc).

    ``custom_data``: strings kept with the bag (the run's parameters, :mod:`.params`)."""

    def __init__(self, path: str | Path, fsync_period: float = 1.0, custom_data: dict[str, str] | None = None,
                 chunk_span: float = CHUNK_SPAN_S) -> None:
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
            self._fd: Optional[int] = os.open(self.file, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            raise BagError(f"bag {str(self.path)!r} cannot be written: {exc.strerror or exc}") from None
        self._staged = _Staged()
        self._mcap = Writer(self._staged, chunk_size=4 * CHUNK_BYTES, compression=CompressionType.ZSTD)  # type: ignore[arg-type]
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
        self.chunk_span = chunk_span
        self._saved: dict[str, int] = {}  # messages per topic on the file (up to the last checkpoint)
        self._saved_until: Optional[int] = None
        self.failed = ""
        """Why writing stopped (a :class:`BagError` said so); "" while it works."""
        self._open_since: Optional[tuple[int, float]] = None  # (log time, monotonic time) of the open chunk's first
        self._open_bytes = 0
        self._listed: set[str] = set()  # the topics metadata.yaml names
        self._listed_at = self._last_sync = time.monotonic()
        try:  # the run's parameters from the start: metadata.yaml, then a valid, empty file
            self._write_metadata()
            self._checkpoint()
        except BagError:
            self.close()
            raise

    @property
    def saved(self) -> int:
        """Messages on the file (up to the last checkpoint)."""
        return sum(self._saved.values())

    def _channel(self, topic: str, type_name: str) -> int:
        known = self._channels.get(topic)
        if known is not None:
            if known[1] != type_name:
                raise BagError(f"bag {str(self.path)!r}: topic {topic!r} carries {known[1]!r}, not {type_name!r}")
            return known[0]
        outside: list[Any] = []  # also written outside the chunks: a damaged chunk cannot take the definitions with it
        if type_name not in self._schemas:
            msgdef, _ = self._store.generate_msgdef(type_name, ros_version=2)
            schema = self._schemas[type_name] = self._mcap.register_schema(type_name, "ros2msg", msgdef.encode())
            outside.append(Schema(id=schema, data=msgdef.encode(), encoding="ros2msg", name=type_name))
        offered = dump_yaml(_offered(topic)) if topic in TOPICS else ""
        metadata = {"offered_qos_profiles": offered}
        channel = self._mcap.register_channel(topic, "cdr", self._schemas[type_name], metadata)
        outside.append(Channel(id=channel, topic=topic, message_encoding="cdr", metadata=metadata,
                               schema_id=self._schemas[type_name]))
        self._staged.write(_records(*outside))
        self._channels[topic] = (channel, type_name)
        return channel

    def write(self, topic: str, type_name: str, timestamp_ns: int, cdr: bytes) -> None:
        """Append one CDR-serialised message stamped ``timestamp_ns`` (not earlier than the previous one)."""
        if self.failed:
            raise BagError(self.failed)
        timestamp_ns = int(timestamp_ns)
        if self.last_ns is not None and timestamp_ns < self.last_ns:
            raise BagError(f"bag {str(self.path)!r}: {topic} at {timestamp_ns} ns is earlier than the previous "
                           f"message ({self.last_ns} ns); messages are written in time order")
        if self._open_since is not None and timestamp_ns - self._open_since[0] >= self.chunk_span * 1e9:
            self._checkpoint()
        channel = self._channel(topic, type_name)
        self._mcap.add_message(channel, log_time=timestamp_ns, data=cdr, publish_time=timestamp_ns,
                               sequence=self.counts[topic] % 2**32)
        self.counts[topic] += 1
        self.first_ns = timestamp_ns if self.first_ns is None else self.first_ns
        self.last_ns = timestamp_ns
        if self._open_since is None:
            self._open_since = (timestamp_ns, time.monotonic())
        self._open_bytes += len(cdr)
        if self._open_bytes >= CHUNK_BYTES:
            self._checkpoint()

    def poll(self) -> None:
        """Checkpoint if the open chunk has been open :attr:`chunk_span` on the wall clock (a live recorder calls
        this from a timer: a chunk is closed in time also when messages stop coming)."""
        if not self.failed and self._open_since is not None and \
                time.monotonic() - self._open_since[1] >= self.chunk_span:
            self._checkpoint()

    def _checkpoint(self) -> None:
        """Close the open chunk and put everything since the last checkpoint on the file, then :data:`TAIL`."""
        self._mcap.flush()  # the open chunk and its message indexes, into the staged bytes
        self._commit(TAIL)
        self._open_since, self._open_bytes = None, 0
        now = time.monotonic()
        if now - self._listed_at >= self.fsync_period:
            self._write_metadata()
        if now - self._last_sync >= self.fsync_period:
            self._sync()

    def _commit(self, end: bytes, truncate: bool = False) -> None:
        """Put the staged records, then ``end``, on the file (:meth:`_put`).  ``metadata.yaml`` names a new topic
        before its records reach the file: rosbags reads only the topics it names, mcap's reader every record of
        the file, so a kill between the two left messages that only mcap's reader delivered."""
        if set(self._channels) - self._listed:
            self._write_metadata()  # the new topics, with none of their messages on the file yet
        self._put(bytes(self._staged.buffer) + end, truncate)
        self._staged.base += len(self._staged.buffer)
        self._staged.buffer.clear()
        self._saved, self._saved_until = dict(self.counts), self.last_ns

    def _put(self, data: bytes, truncate: bool = False) -> None:
        """Write ``data`` at the staged base offset in one write, after reserving its space (a full disk fails
        here, with nothing written)."""
        assert self._fd is not None
        offset = self._staged.base
        try:
            _reserve(self._fd, offset, len(data))
            view = memoryview(data)
            while view:
                written = os.pwrite(self._fd, view, offset)
                view, offset = view[written:], offset + written
            if truncate:
                os.ftruncate(self._fd, offset)
        except OSError as exc:
            self._fail(exc)

    def _fail(self, exc: OSError) -> None:
        held = "no message" if not self.saved else \
            f"{self.saved} messages ({((self._saved_until or 0) - (self.first_ns or 0)) * 1e-9:.2f} s of recording)"
        self.failed = (f"bag {str(self.path)!r}: writing failed ({exc.strerror or exc}); the bag holds {held} "
                       "and is readable, later messages are not recorded")
        raise BagError(self.failed) from None

    def _sync(self) -> None:
        assert self._fd is not None
        try:
            os.fsync(self._fd)
        except OSError as exc:
            self._fail(exc)
        self._last_sync = time.monotonic()

    def _write_metadata(self) -> None:
        """``metadata.yaml`` of what the file holds, replaced atomically."""
        info = self.metadata(on_file=True)
        try:
            tmp = self.path / "metadata.yaml.tmp"
            tmp.write_text(dump_yaml({"rosbag2_bagfile_information": info}, sort_keys=True), encoding="utf-8")
            tmp.replace(self.path / "metadata.yaml")
        except OSError as exc:
            self._fail(exc)
        self._listed, self._listed_at = set(self._channels), time.monotonic()

    def metadata(self, on_file: bool = False) -> dict[str, Any]:
        """The ``rosbag2_bagfile_information`` of what was written; ``on_file``: of the messages on the file (up to
        the last checkpoint), naming every topic written, also one none of whose messages are on the file yet."""
        counts, last = (self._saved, self._saved_until) if on_file else (self.counts, self.last_ns)
        start = (self.first_ns or 0) if last is not None else 0
        duration = (last or 0) - start
        count = sum(counts.values())
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
                 "message_count": counts.get(topic, 0)}
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
        """Write the last chunk, the summary and the footer, then the final ``metadata.yaml``.  After a failed
        write only the file is closed: it stays as its last checkpoint left it."""
        if self._fd is None:
            return
        try:
            if not self.failed:
                info = self.metadata()
                self._mcap.add_metadata("rosbag2", {"serialized_metadata": dump_yaml(info, sort_keys=True)})
                self._mcap.finish()
                self._commit(b"", truncate=True)
                self._sync()
                self._write_metadata()
        finally:
            os.close(self._fd)
            self._fd = None
