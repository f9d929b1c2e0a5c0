"""Frames of ``config/kanon.dbc`` through cantools, with the command frames' counter and checksum.

Command frames (CMD_STEER, CMD_TORQUE) carry a 4-bit rolling counter and a CRC-8 SAE J1850
(polynomial 0x1D, initial value 0xFF, final XOR 0xFF — the AUTOSAR E2E profile 1 CRC) over
payload bytes 0–6, stored in byte 7.  Encoding and decoding of every signal go through
cantools; only the CRC byte is computed here.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Optional

import cantools
import can

DBC_FILE = Path(__file__).resolve().parents[3] / "config" / "kanon.dbc"
PROTECTED = ("CMD_STEER", "CMD_TORQUE")
"""Frames with counter and checksum."""


def crc8_j1850(data: bytes) -> int:
    """CRC-8 SAE J1850: poly 0x1D, init 0xFF, xorout 0xFF (check value of b'123456789' is 0x4B)."""
    crc = 0xFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def load_database(path: str | Path = DBC_FILE) -> Any:
    return cantools.database.load_file(str(path))


@dataclass
class FrameStats:
    """Counters of dropped frames, by reason."""

    unknown_id: int = 0
    bad_length: int = 0
    bad_checksum: int = 0
    bad_counter: int = 0
    undecodable: int = 0

    @property
    def dropped(self) -> int:
        return self.unknown_id + self.bad_length + self.bad_checksum + self.bad_counter + self.undecodable


@dataclass
class Codec:
    """Encode frames with rolling counters; decode and validate received frames."""

    db: Any = field(default_factory=load_database)
    stats: FrameStats = field(default_factory=FrameStats)
    _tx_counter: dict[str, int] = field(default_factory=dict)
    _rx_counter: dict[int, int] = field(default_factory=dict)

    def encode(self, name: str, values: dict[str, float], timestamp: float = 0.0) -> can.Message:
        message = self.db.get_message_by_name(name)
        values = dict(values)
        if any(s.name == "Counter" for s in message.signals):
            counter = self._tx_counter.get(name, -1) + 1 & 0x0F
            self._tx_counter[name] = counter
            values["Counter"] = counter
        if name in PROTECTED:
            values["Checksum"] = 0
        data = bytearray(message.encode(values, strict=True))
        if name in PROTECTED:
            data[7] = crc8_j1850(bytes(data[:7]))
        return can.Message(arbitration_id=message.frame_id, data=bytes(data), is_extended_id=False, timestamp=timestamp)

    def decode(self, frame: can.Message) -> Optional[tuple[str, dict[str, float]]]:
        """``(name, signals)`` of a valid frame; ``None`` (and a counted reason) otherwise. Never raises."""
        try:
            message = self.db.get_message_by_frame_id(frame.arbitration_id)
        except KeyError:
            self.stats.unknown_id += 1
            return None
        if frame.is_extended_id or frame.is_error_frame or frame.is_remote_frame:
            self.stats.unknown_id += 1
            return None
        data = bytes(frame.data)
        if len(data) != message.length:
            self.stats.bad_length += 1
            return None
        if message.name in PROTECTED and crc8_j1850(data[:7]) != data[7]:
            self.stats.bad_checksum += 1
            return None
        try:
            values = message.decode(data, decode_choices=False)
        except Exception:  # noqa: BLE001 - cantools raises several types on bad payloads
            self.stats.undecodable += 1
            return None
        if "Counter" in values:
            counter = int(values["Counter"])
            previous = self._rx_counter.get(frame.arbitration_id)
            self._rx_counter[frame.arbitration_id] = counter
            if message.name in PROTECTED and previous is not None and counter != (previous + 1) & 0x0F:
                self.stats.bad_counter += 1
                return None
        return message.name, {k: float(v) for k, v in values.items()}
