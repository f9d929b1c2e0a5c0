"""python-can buses by interface name: ``socketcan`` (the car), ``udp_multicast`` (processes here), ``virtual`` (tests)."""
from __future__ import annotations

from typing import Any

import can

INTERFACES = ("socketcan", "udp_multicast", "virtual")
BITRATE = 500_000


def open_bus(interface: str, channel: str, port: Any = None) -> can.BusABC:
    """Open ``channel`` on ``interface``; a clear error names a wrong interface.

    ``udp_multicast``: ``channel`` is the multicast group, ``port`` the UDP port; the hop
    limit is 0, so frames never leave this machine.
    """
    if interface not in INTERFACES:
        raise ValueError(f"interface = {interface!r} is invalid: expected one of {list(INTERFACES)}")
    if interface == "socketcan":
        return can.Bus(interface="socketcan", channel=channel, bitrate=BITRATE)
    if interface == "udp_multicast":
        extra = {"port": int(port)} if port is not None else {}
        return can.Bus(interface="udp_multicast", channel=channel, hop_limit=0, **extra)
    return can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
