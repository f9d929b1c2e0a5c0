"""Frames of ``config/kanon.dbc`` through cantools, with rolling counters and the command frames' checksum.

Every signal is encoded and decoded by cantools; only the CRC byte is computed here.

* **Checksum** (command frames CMD_STEER, CMD_TORQUE): CRC-8 SAE J1850 — polynomial 0x1D,
  initial value 0xFF, final XOR 0xFF, the CRC of AUTOSAR E2E profile 1 — over the frame
  identifier's two bytes (low byte first) followed by payload bytes 0–6, stored in byte 7
  (E2E profile 1, data-ID mode "both").  Keying the CRC with the identifier rejects a
  payload that arrives under the wrong identifier (CMD_STEER and CMD_TORQUE have the same
  layout).
* **Counters**: every frame with a ``Counter`` signal counts 0…15 per frame name.  A
  command frame is accepted only if its counter is the previous one + 1 (mod 16); after a
  jump the frame is dropped and the counter re-synchronised, so the next frame is accepted
  (E2E profile 1 with MaxDeltaCounter = 1).  A sensor frame that repeats the previous
  counter is stale and dropped; a sensor frame after a jump is valid and the missing frames
  are counted as lost.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import can
import cantools

from ..errors import ParamError
from ..resources import DBC_FILE

PROTECTED = ("CMD_STEER", "CMD_TORQUE")
"""Frames with counter and checksum."""
CHECKSUM_BYTE = 7


def crc8_j1850(data: bytes, crc: int = 0xFF) -> int:
    """CRC-8 SAE J1850: poly 0x1D, init 0xFF, xorout 0xFF (check value of b'123456789' is 0x4B)."""
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def command_checksum(frame_id: int, payload: bytes) -> int:
    """The checksum byte of a command frame: CRC-8 SAE J1850 over (id low, id high, bytes 0–6)."""
    return crc8_j1850(bytes((frame_id & 0xFF, (frame_id >> 8) & 0xFF)) + bytes(payload[:CHECKSUM_BYTE]))


def load_database(path: str | Path = DBC_FILE) -> Any:
    """The cantools database of a DBC file (parsed anew: the caller may own it)."""
    return cantools.database.load_file(str(path))


@functools.lru_cache(maxsize=1)
def default_database() -> Any:
    """config/kanon.dbc, parsed once per process and shared (encoding and decoding do not change it)."""
    return load_database(DBC_FILE)


@dataclass
class FrameStats:
    """Received frames that were dropped, by reason; plus error frames and lost sensor frames."""

    unknown_id: int = 0
    """Identifier not in the DBC, extended identifier or remote frame."""
    bad_length: int = 0
    bad_checksum: int = 0
    bad_counter: int = 0
    """Command frame out of sequence, or sensor frame repeating its counter."""
    undecodable: int = 0
    out_of_range: int = 0
    """A signal outside its DBC range [minimum, maximum] (a broken sender)."""
    error_frames: int = 0
    """Error frames (not data: handed to :class:`~moose.canbus.health.BusHealth`)."""
    lost: int = 0
    """Sensor frames missing according to the counters (the frames received were accepted)."""
    own_id: int = 0
    """Frames with an identifier this node transmits itself (an echo, or another sender on our identifier)."""

    @property
    def dropped(self) -> int:
        return (self.unknown_id + self.own_id + self.bad_length + self.bad_checksum + self.bad_counter
                + self.undecodable + self.out_of_range)

    def snapshot(self) -> dict[str, int]:
        return dataclasses.asdict(self)


@dataclass
class Codec:
    """Encode frames with rolling counters; decode and validate received frames."""

    db: Any = field(default_factory=default_database)
    node: Optional[str] = None
    """The DBC node this codec receives for; frames that node transmits itself are not decoded."""
    stats: FrameStats = field(default_factory=FrameStats)
    _tx_counter: dict[str, int] = field(default_factory=dict)
    _rx_counter: dict[int, int] = field(default_factory=dict)

    def encode(self, name: str, values: dict[str, float], timestamp: float = 0.0,
               saturate: bool = False) -> can.Message:
        """The frame ``name`` with ``values`` (counter and checksum added).

        Values outside a signal's DBC range raise, unless ``saturate`` (a sensor at full
        scale): then they are clipped to the range.  Non-finite values always raise.
        """
        message = self.db.get_message_by_name(name)
        values = dict(values)
        for signal in message.signals:
            if signal.name in values:
                value = float(values[signal.name])
                if not math.isfinite(value):
                    raise ValueError(f"{name}.{signal.name} = {value!r} is invalid: expected a finite number")
                if saturate:
                    value = min(max(value, signal.minimum), signal.maximum)
                values[signal.name] = value
        if any(s.name == "Counter" for s in message.signals):
            counter = (self._tx_counter.get(name, -1) + 1) & 0x0F
            self._tx_counter[name] = counter
            values["Counter"] = counter
        if name in PROTECTED:
            values["Checksum"] = 0
        data = bytearray(message.encode(values, strict=True))
        if name in PROTECTED:
            data[CHECKSUM_BYTE] = command_checksum(message.frame_id, bytes(data))
        return can.Message(arbitration_id=message.frame_id, data=bytes(data), is_extended_id=False,
                           timestamp=timestamp, dlc=len(data))

    def own(self, frame: can.Message) -> bool:
        """Whether ``frame`` has an identifier :attr:`node` transmits (an echo of our own frame on the bus)."""
        try:
            message = self.db.get_message_by_frame_id(frame.arbitration_id)
        except KeyError:
            return False
        return self.node is not None and self.node in message.senders

    def decode(self, frame: can.Message) -> Optional[tuple[str, dict[str, float]]]:
        """``(name, signals)`` of a valid frame; ``None`` (and a counted reason) otherwise. Never raises."""
        if frame.is_error_frame:
            self.stats.error_frames += 1
            return None
        if frame.is_extended_id or frame.is_remote_frame or frame.is_fd:
            self.stats.unknown_id += 1
            return None
        try:
            message = self.db.get_message_by_frame_id(frame.arbitration_id)
        except KeyError:
            self.stats.unknown_id += 1
            return None
        if self.node is not None and self.node in message.senders:
            self.stats.own_id += 1
            return None
        data = bytes(frame.data)
        if len(data) != message.length:
            self.stats.bad_length += 1
            return None
        protected = message.name in PROTECTED
        if protected and command_checksum(message.frame_id, data) != data[CHECKSUM_BYTE]:
            self.stats.bad_checksum += 1
            return None
        try:
            values = message.decode(data, decode_choices=False, scaling=True)
        except Exception:  # noqa: BLE001 - cantools raises several types on bad payloads
            self.stats.undecodable += 1
            return None
        for signal in message.signals:
            tolerance = 0.5 * abs(signal.scale)
            if not signal.minimum - tolerance <= values[signal.name] <= signal.maximum + tolerance:
                self.stats.out_of_range += 1
                return None
        if "Counter" in values:
            counter = int(values["Counter"])
            previous = self._rx_counter.get(frame.arbitration_id)
            self._rx_counter[frame.arbitration_id] = counter
            if previous is not None:
                gap = (counter - previous - 1) & 0x0F
                if counter == previous or (protected and gap != 0):
                    self.stats.bad_counter += 1
                    return None
                self.stats.lost += gap
        return message.name, {k: float(v) for k, v in values.items()}


def cycle_time(db: Any, *names: str) -> float:
    """The common ``GenMsgCycleTime`` of the frames ``names`` (s); ParamError if they differ or have none."""
    times = {name: db.get_message_by_name(name).cycle_time for name in names}
    values = set(times.values())
    if len(values) != 1 or not all(isinstance(v, int) and v > 0 for v in values):
        raise ParamError(f"GenMsgCycleTime of {times!r} is invalid: expected one positive cycle time (ms) for all")
    return values.pop() / 1000.0
