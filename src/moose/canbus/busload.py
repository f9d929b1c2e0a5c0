"""Worst-case bus load of the DBC's periodic frames at the bus bit rate.

A classic CAN data frame with an 11-bit identifier has 47 + 8·DLC bits, of which
34 + 8·DLC are subject to bit stuffing; in the worst case one stuff bit follows every four
bits after the first, giving floor((34 + 8·DLC − 1) / 4) stuff bits (Davis et al.,
"Controller Area Network (CAN) schedulability analysis: refuted, revisited and revised",
Real-Time Systems 35, 2007).
"""
from __future__ import annotations

from typing import Any


def worst_case_frame_bits(dlc: int) -> int:
    """Bits on the wire of an 11-bit-identifier data frame, worst-case stuffing included."""
    return 47 + 8 * dlc + (34 + 8 * dlc - 1) // 4


def frame_loads(db: Any, bitrate: int) -> dict[str, float]:
    """Worst-case share of the bus (0..1) of each periodic frame of ``db``, by name."""
    if not (isinstance(bitrate, int) and bitrate > 0):
        raise ValueError(f"bitrate = {bitrate!r} is invalid: expected a positive number of bit/s")
    loads: dict[str, float] = {}
    for message in db.messages:
        if message.is_extended_frame or message.is_fd:
            raise ValueError(f"message {message.name} is not a classic 11-bit frame: the bound does not apply")
        if not message.cycle_time:
            raise ValueError(f"message {message.name} has no GenMsgCycleTime: its load cannot be bounded")
        loads[message.name] = worst_case_frame_bits(message.length) * 1000.0 / message.cycle_time / bitrate
    return loads


def worst_case_bus_load(db: Any, bitrate: int) -> float:
    """Share of the bus the periodic frames occupy in the worst case (0..1)."""
    return sum(frame_loads(db, bitrate).values())
