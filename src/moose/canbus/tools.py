"""Bus tools: decode live frames with the DBC (``moose can dump``) and replay python-can logs (``moose can replay``).

Every bad input is a :class:`~moose.params.ParamError` naming the field or file and the value:
an interface, channel or port (:func:`open_tool_bus`), a log's path, suffix or content
(:func:`read_log`: a corrupt file is found before the first frame is sent), a log without frames
(:func:`replay`), a rate, count or duration.
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import IO, Any, Iterator, Optional

import can

from moose.params import ParamError, check

from .bus import BusParams
from .codec import Codec

LOG_SUFFIXES = (".asc", ".blf", ".csv", ".db", ".log", ".mf4", ".trc")
"""The formats python-can's LogReader reads since 4.0 (each may also be gzip-compressed: ``.asc.gz``)."""


def open_tool_bus(interface: str, channel: str, port: Any = None) -> can.BusABC:
    """The bus a tool works on; ParamError for a bad interface, channel or port, or one that cannot be opened."""
    params = BusParams(interface, channel, port) if port is not None else BusParams(interface, channel)
    try:
        return params.open()
    except (can.CanError, OSError) as exc:
        raise ParamError(f"channel = {channel!r} on interface = {interface!r} cannot be opened: {exc}") from None


def describe(frame: can.Message, codec: Codec) -> str:
    """One line: time, id, frame name and signals — or why the frame would be dropped."""
    before = codec.stats.snapshot()
    decoded = codec.decode(frame)
    head = f"{frame.timestamp:14.6f}  {frame.arbitration_id:03X}  [{len(frame.data)}]  {bytes(frame.data).hex(' ')}"
    if frame.is_error_frame:
        return f"{head}  ERROR FRAME"
    if decoded is None:
        after = codec.stats.snapshot()
        reason = next((k for k in after if after[k] > before[k]), "invalid")
        return f"{head}  DROPPED ({reason})"
    name, values = decoded
    signals = " ".join(f"{k}={v:g}" for k, v in values.items() if k not in ("Checksum",))
    return f"{head}  {name} {signals}"


def dump(bus: can.BusABC, out: IO[str], count: Optional[int] = None, duration: Optional[float] = None,
         codec: Optional[Codec] = None) -> int:
    """Print decoded frames until ``count`` frames or ``duration`` seconds; returns the frames seen."""
    if count is not None:
        check("count", count, lambda v: isinstance(v, int) and not isinstance(v, bool) and v > 0, "a positive integer")
    if duration is not None:
        check("duration", duration, _positive_finite, "a positive number of seconds")
    codec = codec or Codec()
    seen, start = 0, time.monotonic()
    while (count is None or seen < count) and (duration is None or time.monotonic() - start < duration):
        frame = bus.recv(timeout=0.1)
        if frame is None:
            continue
        out.write(describe(frame, codec) + "\n")
        seen += 1
    return seen


def read_log(path: str | Path) -> Iterator[can.Message]:
    """The frames of a python-can log; ParamError naming the file for a missing file, an unknown suffix or bad content.

    The error frames of the log are skipped.  A frame the log describes but CAN cannot carry
    (an identifier or a length out of range) is bad content too, and so is a BLF file shorter than
    its header says (python-can would read the frames before the cut without a word).
    """
    path = Path(path)
    if not path.is_file():
        raise ParamError(f"log {str(path)!r} does not exist or is not a file")
    suffixes = [s.lower() for s in path.suffixes]
    fmt = suffixes[-2] if suffixes[-1:] == [".gz"] and len(suffixes) >= 2 else (suffixes[-1] if suffixes else "")
    if fmt not in LOG_SUFFIXES:
        raise ParamError(f"log {str(path)!r} has an unknown format {''.join(path.suffixes) or '(no suffix)'!r}: "
                         f"expected one of {list(LOG_SUFFIXES)} (optionally .gz)")
    index = 0
    try:
        reader = can.LogReader(str(path))
        if isinstance(reader, can.BLFReader) and reader.file_size > path.stat().st_size:
            raise ParamError(f"log {str(path)!r} is truncated: its header says {reader.file_size} bytes, the file has "
                             f"{path.stat().st_size}")
        for index, frame in enumerate(reader, start=1):
            if frame.is_error_frame:
                continue
            problem = _frame_problem(frame)
            if problem:
                raise ParamError(f"log {str(path)!r} is corrupt: frame {index}: {problem}")
            yield frame
    except ParamError:
        raise
    except Exception as exc:  # noqa: BLE001 - python-can's readers raise many types on a corrupt file
        raise ParamError(f"log {str(path)!r} is not a valid {fmt} file (after {index} frames): "
                         f"{type(exc).__name__}: {exc}") from None


def replay(path: str | Path, bus: can.BusABC, rate: float = 1.0) -> int:
    """Send the frames of a python-can log with their timing (``rate``: speed-up); returns the count.

    The whole log is read once before the first frame is sent, so a corrupt file sends nothing; a log
    without a frame to send (empty, or error frames only) is a ParamError naming it, not "sent 0 frames".
    """
    check("rate", rate, _positive_finite, "a positive, finite speed-up")
    if sum(1 for _ in read_log(path)) == 0:  # reads (validates) the whole log before the first frame is sent
        raise ParamError(f"log {str(path)!r} holds no CAN frames to replay (error frames aside)")
    sent = 0
    first: Optional[float] = None
    start = time.monotonic()
    for frame in read_log(path):
        first = frame.timestamp if first is None else first
        delay = (frame.timestamp - first) / rate - (time.monotonic() - start)
        if delay > 0:
            time.sleep(delay)
        bus.send(frame)
        sent += 1
    return sent


def _frame_problem(frame: can.Message) -> str:
    id_max = 0x1FFFFFFF if frame.is_extended_id else 0x7FF
    if not 0 <= frame.arbitration_id <= id_max:
        return f"identifier 0x{frame.arbitration_id:X} out of range"
    length_max = 64 if frame.is_fd else 8
    if len(frame.data) > length_max or frame.dlc > length_max:
        return f"{len(frame.data)} data bytes (DLC {frame.dlc}), at most {length_max}"
    if not math.isfinite(frame.timestamp):
        return f"timestamp {frame.timestamp!r}"
    return ""


def _positive_finite(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and 0.0 < value < math.inf
