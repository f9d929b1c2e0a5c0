"""python-can buses by interface name, and the thin I/O shell around the bridge and ECU cores.

Interfaces: ``socketcan`` (the car, 500 kbit/s), ``udp_multicast`` (processes on this
machine), ``virtual`` (in-process tests).

``udp_multicast`` is python-can's UDP multicast bus (same datagrams, msgpack-encoded
frames) confined to the loopback interface: IPv4 multicast with TTL 0, outgoing
interface ``lo`` (IP_MULTICAST_IF 127.0.0.1) and the group joined on ``lo`` only — python-can's own bus joins on the default interface, which sends IGMP
membership reports onto the network even with TTL 0.  A datagram that is not a frame is
skipped and counted (python-can would raise), so a stray sender cannot fail the bus.
IPv6 groups are refused: ``lo`` has no IPv6 multicast route (sending fails with "network
is unreachable").
"""
from __future__ import annotations

import errno
import socket
import struct
from typing import Any, Callable, Optional

import can
from can.interfaces.udp_multicast.bus import (
    SO_TIMESTAMPNS,
    GeneralPurposeUdpMulticastBus,
    UdpMulticastBus,
)
from can.interfaces.udp_multicast.utils import is_msgpack_installed, unpack_message

from .health import BusHealth

INTERFACES = ("socketcan", "udp_multicast", "virtual")
BITRATE = 500_000
DEFAULT_GROUP = "239.74.163.2"
DEFAULT_PORT = 43113
LOOPBACK = "lo"


class _LoopbackMulticast(GeneralPurposeUdpMulticastBus):
    """python-can's multicast socket, configured for the loopback interface only (IPv4)."""

    def _create_socket(self, address_family: socket.AddressFamily) -> socket.socket:
        if address_family != socket.AF_INET:
            raise OSError(errno.EAFNOSUPPORT, "only IPv4 groups: IPv6 multicast has no route on the loopback interface")
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            loopback = socket.inet_aton("127.0.0.1")
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, struct.pack("@I", 0))
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, loopback)
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_LOOP, 1)
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if hasattr(socket, "SO_REUSEPORT"):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
            try:
                sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
                self.timestamp_nanosecond = True
            except OSError as error:
                if error.errno not in (errno.ENOPROTOOPT, errno.EINVAL):
                    raise
                self.timestamp_nanosecond = False
            sock.bind((self.group, self.port))  # only this group's datagrams
            sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, socket.inet_aton(self.group) + loopback)
            return sock
        except OSError as error:
            sock.close()
            raise can.CanInitializationError(f"could not open multicast group {self.group} on {LOOPBACK}: {error}") from error


class LoopbackMulticastBus(UdpMulticastBus):
    """python-can's ``udp_multicast`` bus on the loopback interface (classic CAN frames only)."""

    def __init__(self, channel: str = DEFAULT_GROUP, port: int = DEFAULT_PORT, **kwargs: Any) -> None:
        is_msgpack_installed()
        can.BusABC.__init__(self, channel, **kwargs)  # not UdpMulticastBus.__init__: it would join on the default interface
        self._multicast = _LoopbackMulticast(channel, int(port), 0)
        self._can_protocol = can.CanProtocol.CAN_20
        self.channel_info = f"udp_multicast {channel}:{port} on {LOOPBACK}"
        self.malformed = 0
        """Datagrams on the group that were not frames (skipped)."""

    def _recv_internal(self, timeout: Optional[float]) -> tuple[Optional[can.Message], bool]:
        result = self._multicast.recv(timeout)
        if not result:
            return None, False
        data, _, timestamp = result
        try:
            message = unpack_message(data, replace={"timestamp": timestamp}, check=True)
        except Exception:  # noqa: BLE001 - msgpack and the check raise several types
            self.malformed += 1
            return None, False
        if message.is_fd:
            self.malformed += 1
            return None, False
        return message, False


def is_loopback_group(channel: str) -> bool:
    """An IPv4 multicast group (224.0.0.0/4): what the loopback multicast bus can join."""
    try:
        return 224 <= socket.inet_aton(channel)[0] <= 239 and channel.count(".") == 3
    except OSError:
        return False


def open_bus(interface: str, channel: str, port: Any = None) -> can.BusABC:
    """Open ``channel`` on ``interface``; a clear error names a wrong interface.

    ``udp_multicast``: ``channel`` is the IPv4 multicast group (``239.x.y.z``:
    administratively scoped), ``port`` the UDP port (default 43113); loopback only, see the
    module doc.
    """
    if interface not in INTERFACES:
        raise ValueError(f"interface = {interface!r} is invalid: expected one of {list(INTERFACES)}")
    if interface == "socketcan":
        return can.Bus(interface="socketcan", channel=channel, bitrate=BITRATE)
    if interface == "udp_multicast":
        if not is_loopback_group(channel):
            raise ValueError(f"channel = {channel!r} is invalid: expected an IPv4 multicast group (224.0.0.0/4)")
        return LoopbackMulticastBus(channel, int(port) if port is not None else DEFAULT_PORT)
    return can.Bus(interface="virtual", channel=channel, receive_own_messages=False)


class BusLink:
    """The I/O shell: opens the bus, moves frames, reports failures to ``health`` and re-opens after its back-off.

    Any ``can.CanError`` or ``OSError`` from open, send or receive closes the bus object
    (``health.on_io_failure``); the next call after ``health``'s back-off opens it again.
    Error frames are returned with the data frames (the bridge core hands them to ``health``).
    """

    MAX_FRAMES_PER_POLL = 1000

    def __init__(self, opener: Callable[[], can.BusABC], health: BusHealth,
                 logger: Optional[Callable[[can.Message], Any]] = None) -> None:
        self.opener = opener
        self.health = health
        self.logger = logger
        self.bus: Optional[can.BusABC] = None

    def ensure_open(self, t: float) -> bool:
        if self.bus is not None:
            return True
        if self.health.reopen_at is not None and not self.health.reopen_due(t):
            return False
        try:
            self.bus = self.opener()
        except (can.CanError, OSError) as exc:
            self.health.on_io_failure(f"open failed: {exc}", t)
            return False
        self.health.on_open(t)
        return True

    def receive(self, t: float) -> list[can.Message]:
        """Every frame waiting (at most MAX_FRAMES_PER_POLL); [] while the bus is closed."""
        frames: list[can.Message] = []
        if not self.ensure_open(t):
            return frames
        assert self.bus is not None
        try:
            while len(frames) < self.MAX_FRAMES_PER_POLL:
                frame = self.bus.recv(timeout=0.0)
                if frame is None:
                    break
                frames.append(frame)
                if self.logger is not None:
                    self.logger(frame)
        except (can.CanError, OSError, ValueError) as exc:  # ValueError: a closed socket's fileno
            self._fail(f"receive failed: {exc}", t)
        return frames

    def send(self, frames: list[can.Message], t: float) -> bool:
        """Send ``frames`` in order; False (and the bus closed) on a failure, or while the bus is closed."""
        if not self.ensure_open(t):
            return False
        assert self.bus is not None
        try:
            for frame in frames:
                self.bus.send(frame)
                if self.logger is not None:
                    self.logger(frame)
        except (can.CanError, OSError, ValueError) as exc:
            self._fail(f"send failed: {exc}", t)
            return False
        if frames:
            self.health.on_traffic(t)
        return True

    def _fail(self, reason: str, t: float) -> None:
        self.health.on_io_failure(reason, t)
        self.close()

    def close(self) -> None:
        if self.bus is not None:
            try:
                self.bus.shutdown()
            except Exception:  # noqa: BLE001 - a failing bus may fail to close too; it is dropped either way
                pass
            self.bus = None
