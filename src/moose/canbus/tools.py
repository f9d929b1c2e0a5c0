"""Bus tools: decode live frames with the DBC (``moose can dump``) and replay python-can logs (``moose can replay``)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import IO, Optional

import can

from .codec import Codec


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
    codec = codec or Codec()
    seen, start = 0, time.monotonic()
    while (count is None or seen < count) and (duration is None or time.monotonic() - start < duration):
        frame = bus.recv(timeout=0.1)
        if frame is None:
            continue
        out.write(describe(frame, codec) + "\n")
        seen += 1
    return seen


def replay(path: str | Path, bus: can.BusABC, rate: float = 1.0) -> int:
    """Send the frames of a python-can log (.asc, .blf, .log, .csv, .trc, ...) with their timing; returns the count."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"log {str(path)!r} does not exist")
    sent = 0
    first: Optional[float] = None
    start = time.monotonic()
    for frame in can.LogReader(str(path)):
        if frame.is_error_frame:
            continue
        first = frame.timestamp if first is None else first
        delay = (frame.timestamp - first) / rate - (time.monotonic() - start)
        if delay > 0:
            time.sleep(delay)
        bus.send(frame)
        sent += 1
    return sent
