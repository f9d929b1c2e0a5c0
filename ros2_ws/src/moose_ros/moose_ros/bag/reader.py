"""Read a bag: messages in time order, also from the unfinished file of a killed recorder; summary statistics.

Nothing is lost silently.  :class:`BagReader` says, in its :class:`ReadReport`, every message it could not
deliver and why:

- **Types this installation does not know** are decoded with the definition the bag embeds (``ros2msg``
  or ``ros2idl``, as rosbags' AnyReader does), and so is a known type that the bag recorded with another
  definition (its RIHS01 hash differs).  A message that still cannot be decoded (no definition, corrupt
  CDR) is skipped, counted per topic and reported; reading goes on.
- **Damaged, truncated or unfinished files**: a bag with ``metadata.yaml`` is read with rosbags' public
  :class:`rosbags.rosbag2.Reader` while that works; the messages it could not deliver are those
  ``metadata.yaml`` counts and the files no longer hold (reported per topic, with the unreadable bytes).  A
  bag without it, whose metadata or index is unreadable, or where rosbags' reading fails (a chunk whose
  checksum fails, no footer) is scanned record by record from where rosbags stopped (:class:`_Scan`): records
  are parsed strictly (each read to its exact length); a chunk whose CRC-32 fails is skipped whole (its data
  are corrupt) and reported with the messages its indexes count; after a record that does not parse, reading
  resumes at the next offset where records verify again (a chunk whose checksum holds, or three well-formed
  records in a row); the complete records at the start of a cut chunk are kept.  Unreadable bytes, skipped
  chunks and files that were not closed (a footer without summary: the recorder was killed, or its disk
  filled) or have no footer (cut short) are reported.
- **A topic filter naming a topic the bag does not have** is a :class:`BagError` listing the bag's topics
  (rosbags reads *every* topic when given an empty selection).
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
import struct
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Optional, Sequence, Union

from ..interfaces import typestore
from .errors import BagError
from .writer import CHUNK_SPAN_S, MAGIC


@dataclass(frozen=True)
class BagMessage:
    """One message of a bag."""

    topic: str
    type_name: str
    timestamp_ns: int
    msg: Any
    """The rosbags message (fields by their .msg names)."""


@dataclass
class ReadReport:
    """What reading a bag delivered, and everything it could not deliver."""

    path: str
    delivered: int = 0
    skipped: dict[str, dict[str, Any]] = dataclasses.field(default_factory=dict)
    """Messages not delivered because they could not be decoded: topic → {type, count, reason}."""
    missing: dict[str, int] = dataclasses.field(default_factory=dict)
    """Messages ``metadata.yaml`` counts that the files no longer hold, by topic."""
    lost_bytes: int = 0
    """Bytes of records that could not be read: after the last complete record of a truncated file, a corrupt
    record skipped, the unparsable rest of a chunk (counted in its uncompressed bytes)."""
    registered: list[str] = dataclasses.field(default_factory=list)
    """Types decoded with the definitions embedded in the bag."""
    recovered: str = ""
    """Why the bag was read record by record instead of through its index (``""``: it was not)."""
    damaged: list[str] = dataclasses.field(default_factory=list)
    """Chunks skipped because their checksum fails (their data are corrupt), each with the messages it held."""
    unfinished: list[str] = dataclasses.field(default_factory=list)
    """Files whose recording was not closed, each with how it ends."""
    stopped: str = ""
    """Why reading ended before the end of the bag (``""``: it did not)."""
    metadata: str = ""
    """Why the bag's ``metadata.yaml`` could not be read (``""``: it could, or the bag has none)."""

    def skip(self, topic: str, type_name: str, reason: str) -> None:
        entry = self.skipped.setdefault(topic, {"type": type_name, "count": 0, "reason": reason})
        entry["count"] += 1

    @property
    def complete(self) -> bool:
        """Whether every message of the bag was delivered, from a recording that was closed."""
        return not (self.skipped or self.missing or self.lost_bytes or self.damaged or self.unfinished or self.stopped
                    or self.metadata)

    def losses(self) -> list[str]:
        """One line per loss (empty when :attr:`complete`)."""
        lines = [f"bag {self.path!r}: {e['count']} message(s) on {topic} ({e['type']}) skipped: {e['reason']}"
                 for topic, e in sorted(self.skipped.items())]
        if self.missing:
            per_topic = ", ".join(f"{t} {n}" for t, n in sorted(self.missing.items()))
            lines.append(f"bag {self.path!r}: {sum(self.missing.values())} message(s) that metadata.yaml lists are "
                         f"missing from its files (truncated or corrupt): {per_topic}")
        if self.lost_bytes:
            lines.append(f"bag {self.path!r}: {self.lost_bytes} byte(s) of records are unreadable (a truncated or "
                         "corrupt file); their messages are lost")
        notes = [self.metadata, *self.damaged, *self.unfinished, self.stopped]
        lines += [f"bag {self.path!r}: {line}" for line in notes if line]
        return lines


Decoder = Union[Callable[[bytes], Any], str]
"""A function that deserialises one message's CDR, or the reason there is none."""


class _Decoders:
    """A decoder per connection: this installation's types, else the definition embedded in the bag."""

    def __init__(self, report: ReadReport) -> None:
        self.store = typestore()
        self.report = report
        self._cache: dict[tuple[str, str, str], Decoder] = {}

    def get(self, type_name: str, encoding: str, definition: str, digest: Optional[str] = None) -> Decoder:
        key = (type_name, encoding, definition if digest is None or type_name not in self.store.fielddefs else digest)
        if key not in self._cache:
            self._cache[key] = self._make(type_name, encoding, definition, digest)
        return self._cache[key]

    def _make(self, type_name: str, encoding: str, definition: str, digest: Optional[str]) -> Decoder:
        known = type_name in self.store.fielddefs
        if known and (not digest or digest == self.store.hash_rihs01(type_name)):
            store = self.store
            return lambda raw: store.deserialize_cdr(raw, type_name)
        if not definition.strip():
            return f"type {type_name} is unknown here and the bag holds no definition of it"
        try:
            from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

            if encoding in ("ros2idl", "idl"):
                sep = "=" * 80 + "\n"
                parts = [p.split("\n", 1)[1] for p in definition.split(sep)[1:]] if definition.startswith(sep) \
                    else [definition]
                types: dict[str, Any] = {}
                for part in parts:
                    types.update(get_types_from_idl(part))
            elif encoding in ("ros2msg", "msg"):
                types = get_types_from_msg(definition, type_name)
            else:
                return f"type {type_name} is unknown here and its definition is in {encoding!r}, not ros2msg/ros2idl"
            own = get_typestore(Stores.EMPTY)
            own.register(types)
            if type_name not in own.fielddefs:
                return f"the bag's definition of {type_name} does not define it"
        except Exception as exc:  # noqa: BLE001 - the parsers raise several kinds
            return f"the bag's definition of {type_name} cannot be parsed: {exc}"
        self.report.registered.append(type_name + (" (recorded with another definition)" if known else ""))
        return lambda raw: own.deserialize_cdr(raw, type_name)


def decode(decoder: Decoder, raw: bytes) -> tuple[Any, str]:
    """(message, "") or (None, why not)."""
    if isinstance(decoder, str):
        return None, decoder
    try:
        return decoder(raw), ""
    except Exception as exc:  # noqa: BLE001 - corrupt CDR raises many kinds
        return None, f"undecodable CDR ({type(exc).__name__}: {exc})"


def _records(data: bytes) -> tuple[list[Any], int]:
    """The schema, channel and message records at the start of a chunk's (uncompressed) records, parsed strictly:
    a record must fit in ``data`` and be read to its exact length.  A complete record that does not parse is
    skipped.  Returns the records and how many bytes of ``data`` they and the skipped ones span (up to the first
    record that does not fit)."""
    from io import BytesIO

    from mcap.data_stream import ReadDataStream
    from mcap.opcode import Opcode
    from mcap.records import Channel, Message, Schema

    records: list[Any] = []
    position = 0
    while position + 9 <= len(data):
        opcode, length = data[position], int.from_bytes(data[position + 1:position + 9], "little")
        if position + 9 + length > len(data):
            break
        body = data[position + 9:position + 9 + length]
        stream = ReadDataStream(BytesIO(body))
        try:
            if opcode == Opcode.MESSAGE and length >= 22:
                records.append(Message.read(stream, length))
            elif opcode == Opcode.SCHEMA:
                records.append(Schema.read(stream))
            elif opcode == Opcode.CHANNEL:
                records.append(Channel.read(stream))
        except Exception:  # noqa: BLE001 - a corrupt record: skipped, the next one is read
            pass
        position += 9 + length
    return records, position


def _decompress(compression: str, data: bytes, size: Optional[int] = None) -> Optional[bytes]:
    """A chunk's records, decompressed as far as ``data`` goes (None: an unknown compression or corrupt data)."""
    try:
        if compression == "zstd":
            import zstandard

            return zstandard.ZstdDecompressor().decompressobj().decompress(data)
        if compression == "lz4":
            import lz4.frame

            return lz4.frame.LZ4FrameDecompressor().decompress(data)
    except Exception:  # noqa: BLE001 - corrupt data: nothing to recover
        return None
    return data if not compression else None


def _partial_chunk(tail: bytes) -> tuple[list[Any], int]:
    """The complete records at the start of a truncated chunk (``tail``: the file from the chunk's first byte;
    uncompressed, zstd or lz4), and how many bytes of ``tail`` they span (0 for a compressed chunk: the
    compressed bytes they came from are not known, so the whole chunk counts as lost)."""
    import struct

    from mcap.opcode import Opcode

    head = 1 + 8 + 8 + 8 + 8 + 4  # opcode, length, start and end time, uncompressed size, crc
    if len(tail) < head + 4 or tail[0] != Opcode.CHUNK:
        return [], 0
    (name_length,) = struct.unpack_from("<I", tail, head)
    start = head + 4 + name_length + 8  # the compression's name, then the records' length
    compression = tail[head + 4:head + 4 + name_length].decode("utf-8", "replace")
    data = _decompress(compression, tail[start:])
    if data is None:
        return [], 0
    records, good = _records(data)
    return records, (start + good if good and not compression else 0)


@dataclass
class _Stream:
    """The complete records of one MCAP file, read in order."""

    schemas: dict[int, tuple[str, str, str]]
    """id → (name, encoding, definition)."""
    channels: dict[int, tuple[str, int]]
    """id → (topic, schema id)."""
    messages: list[tuple[int, int, bytes]]
    """(channel id, log time, CDR)."""
    lost_bytes: int = 0
    damaged: list[tuple[int, dict[int, int]]] = dataclasses.field(default_factory=list)
    """Chunks skipped because their checksum fails: (file offset, messages per channel id its indexes count)."""
    ending: str = ""
    """How the file ends: "closed" (a footer and a summary), "checkpoint" (a footer without summary: the writer
    stopped before closing it), "cut" (no footer: truncated, or killed in the middle of a write)."""


_CHUNK_HEAD = struct.Struct("<QQQI")
"""A chunk record's start and end time, uncompressed size and CRC-32 (then its compression and records)."""
_HEADER_AT = re.compile(rb"[\x01-\x0f].{4}\x00\x00\x00\x00", re.S)
"""Where a record may start: a known opcode and a length below 4 GiB (resynchronisation after damage)."""


class _Scan:
    """One MCAP file read record by record, with no summary, index or footer needed (module doc)."""

    def __init__(self, data: Any, file: Path) -> None:
        self.data, self.size, self.file = data, len(data), file
        self.found = _Stream({}, {}, [])
        self._skipped: Optional[dict[int, int]] = None  # message counts of the chunk skipped last

    def run(self) -> _Stream:
        from mcap.opcode import Opcode

        if self.data[:8] != MAGIC:
            raise BagError(f"bag file {str(self.file)!r} is not a readable MCAP file ({self.size} bytes, "
                           "no MCAP magic)")
        position = 8
        while position < self.size:
            end = self._parse(position, keep=True)
            if end is None:  # damaged here: on at the next record that verifies
                following = self._resync(position + 1)
                if following is None:
                    self._cut(position)
                    break
                self.found.lost_bytes += following - position
                end = following
            elif self.data[position] == Opcode.FOOTER:
                (summary,) = struct.unpack_from("<Q", self.data, position + 9)
                self.found.ending = "closed" if summary else "checkpoint"
                break
            position = end
        else:
            self.found.ending = "cut"
        if not self.found.channels and not self.found.messages:
            raise BagError(f"bag file {str(self.file)!r} is truncated before its first complete chunk or channel: "
                           f"{self.found.lost_bytes} of {self.size} bytes unreadable, no message can be recovered")
        return self.found

    def _head(self, position: int) -> Optional[tuple[int, int]]:
        """(opcode, end) of the record at ``position``, if its header and body fit in the file."""
        if position + 9 > self.size:
            return None
        end = position + 9 + struct.unpack_from("<Q", self.data, position + 1)[0]
        return (self.data[position], end) if end <= self.size else None

    def _parse(self, position: int, keep: bool) -> Optional[int]:
        """The end of the record at ``position`` if it is one (a chunk: its checksum holds, or it is skipped as
        damaged); ``keep``: take what it holds."""
        from mcap.opcode import Opcode

        head = self._head(position)
        if head is None or not 0x01 <= head[0] <= 0x0F:
            return None
        opcode, end = head
        body = self.data[position + 9:end]
        if opcode == Opcode.CHUNK:
            return end if self._chunk(position, body, keep) else None
        if opcode in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE):
            records, span = _records(self.data[position:end])
            if span != end - position or not records:
                return None
            if keep:
                self._keep(records[0])
                self._skipped = None
        elif opcode == Opcode.MESSAGE_INDEX and keep and self._skipped is not None and len(body) >= 6:
            channel, size = struct.unpack_from("<HI", body)
            self._skipped[channel] = self._skipped.get(channel, 0) + size // 16
        elif opcode == Opcode.FOOTER and (len(body) != 20 or self.data[end:end + 8] != MAGIC):
            return None
        return end

    def _chunk(self, position: int, body: bytes, keep: bool) -> bool:
        """Whether the chunk record ``body`` is well formed; a damaged one (its checksum fails, its data do not
        decompress) is counted and skipped, an intact one's records are kept."""
        import zlib

        try:
            _start, _end, size, crc = _CHUNK_HEAD.unpack_from(body)
            (name_length,) = struct.unpack_from("<I", body, _CHUNK_HEAD.size)
            offset = _CHUNK_HEAD.size + 4 + name_length
            compression = body[_CHUNK_HEAD.size + 4:offset].decode("utf-8")
            (length,) = struct.unpack_from("<Q", body, offset)
        except (struct.error, UnicodeDecodeError):
            return False
        if offset + 8 + length != len(body):
            return False
        data = _decompress(compression, body[offset + 8:], size)
        intact = data is not None and len(data) == size and (crc == 0 or zlib.crc32(data) == crc)
        if not keep:
            return intact
        if not intact:
            self.found.lost_bytes += 9 + len(body)
            self._skipped = {}
            self.found.damaged.append((position, self._skipped))
            return True
        assert data is not None
        records, span = _records(data)
        for record in records:
            self._keep(record)
        self.found.lost_bytes += len(data) - span
        self._skipped = None
        return True

    def _keep(self, record: Any) -> None:
        from mcap.records import Channel, Message, Schema

        found = self.found
        if isinstance(record, Schema):
            found.schemas[record.id] = (record.name, record.encoding, bytes(record.data).decode("utf-8", "replace"))
        elif isinstance(record, Channel):
            found.channels[record.id] = (record.topic, record.schema_id)
        elif isinstance(record, Message):
            found.messages.append((record.channel_id, record.log_time, bytes(record.data)))

    def _resync(self, start: int) -> Optional[int]:
        """The first offset from ``start`` where records verify again: a chunk whose checksum holds, or three
        well-formed records in a row (a file without chunks has no checksum), or one that ends the file."""
        for match in _HEADER_AT.finditer(self.data, start):
            if self._verifies(match.start(), 3):
                return match.start()
        return None

    def _verifies(self, position: int, depth: int) -> bool:
        from mcap.opcode import Opcode

        if self.data[position] == Opcode.CHUNK:
            head = self._head(position)
            return head is not None and self._chunk(position, self.data[position + 9:head[1]], keep=False)
        end = self._parse(position, keep=False)
        last = end is not None and (end == self.size or self.data[position] == Opcode.FOOTER)
        return end is not None and (depth == 1 or last or self._verifies(end, depth - 1))

    def _cut(self, position: int) -> None:
        """The file ends inside the record at ``position``: keep the complete records at the start of a cut chunk."""
        records, span = _partial_chunk(bytes(self.data[position:]))
        for record in records:
            self._keep(record)
        self.found.lost_bytes += self.size - position - span
        self.found.ending = "cut"


def _stream(file: Path) -> _Stream:
    """Every record of ``file`` that can be read (:class:`_Scan`)."""
    import mmap

    with open(file, "rb") as handle:
        if os.fstat(handle.fileno()).st_size == 0:
            raise BagError(f"bag file {str(file)!r} is not a readable MCAP file (0 bytes, no complete record)")
        with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return _Scan(data, file).run()


def _ending(file: Path) -> str:
    """How ``file`` ends (:attr:`_Stream.ending`), from its last 37 bytes."""
    try:
        with open(file, "rb") as handle:
            handle.seek(max(os.fstat(handle.fileno()).st_size - 37, 0))
            tail = handle.read(37)
    except OSError:
        return "cut"
    if len(tail) != 37 or tail[-8:] != MAGIC or tail[:9] != b"\x02\x14" + bytes(7):
        return "cut"
    return "closed" if struct.unpack_from("<Q", tail, 9)[0] else "checkpoint"


def _listed_counts(path: Path) -> tuple[dict[str, int], str]:
    """Messages per topic that ``metadata.yaml`` lists (empty without one), and why it could not be read (``""``:
    it could, or there is none — a bag of one ``.mcap`` file, a recording not closed)."""
    import yaml

    meta = path / "metadata.yaml"
    if not meta.is_file():
        return {}, ""
    try:
        info = yaml.safe_load(meta.read_text(encoding="utf-8"))["rosbag2_bagfile_information"]
        return {e["topic_metadata"]["name"]: int(e["message_count"]) for e in info["topics_with_message_count"]}, ""
    except Exception as exc:  # noqa: BLE001 - not UTF-8, not YAML, another layout: nothing listed, and said so
        return {}, (f"metadata.yaml is unreadable ({type(exc).__name__}): the messages were read from the MCAP files "
                    "alone, and rosbag2 or rosbags will refuse this bag until it is rewritten")


class _IndexFailed(Exception):
    """rosbags' indexed reading failed (a damaged chunk, a broken index): the files are streamed instead."""


class BagReader:
    """A bag directory (or one ``.mcap`` file) opened for reading; :attr:`topics` and :attr:`report`."""

    def __init__(self, path: str | Path, report: Optional[ReadReport] = None) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f"bag {str(self.path)!r} does not exist")
        self.report = report if report is not None else ReadReport(str(self.path))
        self._decoders = _Decoders(self.report)
        self._indexed: Any = None
        self._streams: list[_Stream] = []
        self.topics: dict[str, str] = {}
        """Topic → message type, every topic of the bag."""
        self.counts: dict[str, Optional[int]] = {}
        """Messages per topic that ``metadata.yaml`` lists (None: not listed)."""
        if (self.path / "metadata.yaml").is_file():
            from rosbags.rosbag2 import Reader

            try:
                reader = Reader(self.path)
                reader.open()
                self._indexed = reader
            except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds; recover or explain below
                if not self._files():
                    raise BagError(f"bag {str(self.path)!r} is unreadable: {exc or type(exc).__name__}") from None
                self.report.recovered = f"metadata.yaml or the index is unreadable ({exc or type(exc).__name__})"
        if self._indexed is not None:
            for c in self._indexed.connections:
                self.topics[c.topic] = c.msgtype
                self.counts[c.topic] = (self.counts.get(c.topic) or 0) + c.msgcount
            self._unfinished({f: _ending(f) for f in self._files()})
            return
        if not self._files():
            raise BagError(f"bag {str(self.path)!r} has neither metadata.yaml nor an .mcap file")
        self.report.recovered = self.report.recovered or "no metadata.yaml (an unfinished bag)"
        self._load_streams()

    def _files(self) -> list[Path]:
        return sorted(self.path.glob("*.mcap")) if self.path.is_dir() else [self.path]

    def _load_streams(self) -> None:
        files = self._files()
        self._streams = [_stream(f) for f in files]
        for s in self._streams:
            for topic, schema in s.channels.values():
                self.topics.setdefault(topic, s.schemas.get(schema, ("", "", ""))[0])
        listed, self.report.metadata = _listed_counts(self.path)
        self.counts = {t: listed.get(t) for t in set(self.topics) | set(listed)}
        self._unfinished({f: s.ending for f, s in zip(files, self._streams)})
        self._damage(files, self._streams)

    def _unfinished(self, endings: Mapping[Path, str]) -> None:
        """Say which files were not closed (:attr:`ReadReport.unfinished`)."""
        self.report.unfinished = [
            f"file {f.name} was not closed (its recorder stopped without closing it: killed, or its disk full): it "
            f"ends at its last checkpoint, what was recorded after that is not in it (a kill takes at most the last "
            f"{CHUNK_SPAN_S:g} s)"
            if ending == "checkpoint" else
            f"file {f.name} ends without a footer: it was cut short (truncated, or its writer killed in a write)"
            for f, ending in endings.items() if ending != "closed"]

    def _damage(self, files: Sequence[Path], streams: Sequence[_Stream]) -> None:
        """Bytes that could not be read and chunks skipped for their checksum (:attr:`ReadReport.damaged`)."""
        self.report.lost_bytes = sum(s.lost_bytes for s in streams)
        self.report.damaged = []
        for f, s in zip(files, streams):
            for offset, counts in s.damaged:
                held = ", ".join(f"{s.channels.get(c, (f'channel {c}', 0))[0]} {n}" for c, n in sorted(counts.items()))
                self.report.damaged.append(
                    f"the chunk at byte {offset} of {f.name} fails its checksum (its data are corrupt): skipped"
                    + (f"; its message indexes that could be read count {sum(counts.values())} message(s): {held}"
                       if counts else "; its message indexes are lost too"))

    def close(self) -> None:
        if self._indexed is not None:
            self._indexed.close()
            self._indexed = None

    def check(self, topics: Optional[Sequence[str]] = None, types: Optional[Mapping[str, str]] = None) -> None:
        """:class:`BagError` unless the bag has every topic of ``topics`` and each topic of ``types`` that it
        has carries that type."""
        for topic in topics or ():
            if topic not in self.topics:
                raise BagError(f"topic {topic!r} is not in bag {str(self.path)!r}; its topics: "
                               f"{', '.join(sorted(self.topics)) or 'none'}")
        for topic, expected in (types or {}).items():
            found = self.topics.get(topic)
            if found is not None and found != expected:
                raise BagError(f"topic {topic!r} of bag {str(self.path)!r} carries {found!r}, not {expected!r}")

    def messages(self, topics: Optional[Sequence[str]] = None) -> Iterator[BagMessage]:
        """The messages (of ``topics``, each of which the bag must have) in time order; what cannot be decoded is
        skipped and counted in :attr:`report`, and so is what ``metadata.yaml`` lists but the files lack.

        Through the index while it works.  If it fails (a chunk whose checksum does not match, a broken index),
        the files are streamed instead, from where the index stopped: per topic, the messages it had handed out
        are not delivered again."""
        self.check(topics)
        wanted = set(topics) if topics else set(self.topics)
        delivered: dict[str, int] = defaultdict(int)
        if self._indexed is not None:
            try:
                yield from self._indexed_messages(wanted, delivered)
                return
            except _IndexFailed as exc:
                self.report.recovered = f"the index failed after {sum(delivered.values())} messages ({exc})"
                self.close()
                try:
                    self._load_streams()
                except BagError as error:  # no file can be streamed either: what was delivered is all there is
                    self.report.stopped = f"reading stopped after {sum(delivered.values())} messages: {error}"
                    return
        yield from self._streamed_messages(wanted, listed_too=not topics, given=delivered)

    def _indexed_messages(self, wanted: set[str], delivered: dict[str, int]) -> Iterator[BagMessage]:
        report = self.report
        connections = [c for c in self._indexed.connections if c.topic in wanted]
        try:
            for connection, timestamp, raw in self._indexed.messages(connections=connections):
                fmt = connection.msgdef.format.name.lower()
                decoder = self._decoders.get(connection.msgtype, {"msg": "ros2msg", "idl": "ros2idl"}.get(fmt, fmt),
                                             connection.msgdef.data, connection.digest or None)
                msg, why = decode(decoder, raw)
                delivered[connection.topic] += 1
                if msg is None:
                    report.skip(connection.topic, connection.msgtype, why)
                    continue
                report.delivered += 1
                yield BagMessage(connection.topic, connection.msgtype, timestamp, msg)
        except Exception as exc:  # noqa: BLE001 - a corrupt chunk or index: stream the files from here
            raise _IndexFailed(str(exc) or type(exc).__name__) from None
        self._count_missing(wanted, delivered)
        if report.missing:
            files = self._files()
            self._damage(files, [_stream(f) for f in files])

    def _streamed_messages(self, wanted: set[str], listed_too: bool,
                           given: Mapping[str, int]) -> Iterator[BagMessage]:
        """The messages of the streamed files, but per topic not the first ``given`` (handed out already)."""
        report = self.report
        found: list[tuple[int, int, str, str, Decoder, bytes]] = []
        for index, s in enumerate(self._streams):
            for channel_id, log_time, raw in s.messages:
                if channel_id not in s.channels:
                    report.skip(f"channel {channel_id}", "unknown", "its channel record is not in the file")
                    continue
                topic, schema_id = s.channels[channel_id]
                if topic not in wanted:
                    continue
                name, encoding, definition = s.schemas.get(schema_id, ("", "", ""))
                found.append((log_time, index, topic, name, self._decoders.get(name, encoding, definition), raw))
        found.sort(key=lambda m: (m[0], m[1]))
        read: dict[str, int] = defaultdict(int)
        for log_time, _index, topic, name, decoder, raw in found:
            read[topic] += 1
            if read[topic] <= given.get(topic, 0):
                continue
            msg, why = decode(decoder, raw)
            if msg is None:
                report.skip(topic, name, why)
                continue
            report.delivered += 1
            yield BagMessage(topic, name, log_time, msg)
        self._count_missing(wanted | ({t for t, n in self.counts.items() if n} if listed_too else set()), read)

    def _count_missing(self, topics: set[str], read: Mapping[str, int]) -> None:
        """What ``metadata.yaml`` lists on ``topics`` beyond what the files held (``read``: messages found)."""
        for topic in topics:
            lacking = (self.counts.get(topic) or 0) - read.get(topic, 0)
            if lacking > 0:
                self.report.missing[topic] = lacking


def read_bag(path: str | Path, topics: Optional[Sequence[str]] = None,
             report: Optional[ReadReport] = None) -> Iterator[BagMessage]:
    """Messages of a bag in time order (of ``topics``, which the bag must have); a bag without metadata (a crashed
    recorder) is recovered.  Pass a :class:`ReadReport` to learn what could not be read."""
    reader = BagReader(path, report)
    try:
        yield from reader.messages(topics)
    finally:
        reader.close()


def bag_info(path: str | Path, report: Optional[ReadReport] = None) -> dict[str, Any]:
    """Topics, types, counts, rates (Hz) and duration (s); ``losses``: what could not be read, one line each;
    ``registered_types``: types decoded with the definitions embedded in the bag."""
    stats: dict[str, dict[str, Any]] = {}
    first = last = None
    report = report if report is not None else ReadReport(str(path))
    for m in read_bag(path, report=report):
        entry = stats.setdefault(m.topic, {"type": m.type_name, "count": 0, "first": m.timestamp_ns,
                                           "last": m.timestamp_ns})
        entry["count"] += 1
        entry["last"] = m.timestamp_ns
        first = m.timestamp_ns if first is None else min(first, m.timestamp_ns)
        last = m.timestamp_ns if last is None else max(last, m.timestamp_ns)
    duration = (last - first) * 1e-9 if first is not None and last is not None else 0.0
    topics = {}
    for topic, e in sorted(stats.items()):
        span = (e["last"] - e["first"]) * 1e-9
        topics[topic] = {"type": e["type"], "count": e["count"],
                         "rate_hz": (e["count"] - 1) / span if span > 0 else math.nan}
    return {"path": str(path), "duration_s": duration, "messages": sum(e["count"] for e in stats.values()),
            "topics": topics, "losses": report.losses(), "registered_types": list(report.registered)}
