"""python-can buses by interface name, and the thin I/O shell around the bridge and ECU cores.

Interfaces: ``socketcan`` (the car, 500 kbit/s), ``udp_multicast`` (processes on this
machine), ``virtual`` (in-process tests).

``udp_multicast`` is python-can's UDP multicast bus (same datagrams, msgpack-encoded
frames) confined to the loopback interface: IPv4 multicast with TTL 0, outgoing
interface ``lo`` (IP_MULTICAST_IF 127.0.0.1) and the group joined on ``lo`` only —
python-can's own bus joins on the default interface, which sends IGMP membership reports
onto the network even with TTL 0.  A datagram that is not a frame is skipped and counted
(python-can would raise), so a stray sender cannot fail the bus.  IPv6 groups are
refused: ``lo`` has no IPv6 multicast route (sending fails with "network is
unreachable").
"""
from __future__ import annotations

import dataclasses
import errno
import socket
import struct
import threading
from typing import Any, Callable, Optional

import can
from can.interfaces.udp_multicast.bus import (
    SO_TIMESTAMPNS,
    GeneralPurposeUdpMulticastBus,
    UdpMulticastBus,
)
from can.interfaces.udp_multicast.utils import is_msgpack_installed, unpack_message

from moose.params import check

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
            raise can.CanInitializationError(
                f"could not open multicast group {self.group} on {LOOPBACK}: {error}") from error


class LoopbackMulticastBus(UdpMulticastBus):
    """python-can's ``udp_multicast`` bus on the loopback interface (classic CAN frames only)."""

    def __init__(self, channel: str = DEFAULT_GROUP, port: int = DEFAULT_PORT, **kwargs: Any) -> None:
        is_msgpack_installed()
        # not UdpMulticastBus.__init__: it would join on the default interface
        can.BusABC.__init__(self, channel, **kwargs)
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


def is_loopback_group(channel: object) -> bool:
    """An IPv4 multicast group (224.0.0.0/4): what the loopback multicast bus can join."""
    if not isinstance(channel, str) or channel.count(".") != 3:
        return False
    try:
        return 224 <= socket.inet_aton(channel)[0] <= 239
    except OSError:
        return False


@dataclasses.dataclass(frozen=True)
class BusParams:
    """Which bus to open; every field is checked here, so a bad value is a :class:`ParamError` naming it."""

    interface: str = "udp_multicast"
    """``socketcan`` (the car), ``udp_multicast`` (processes on this machine) or ``virtual`` (one process)."""
    channel: str = DEFAULT_GROUP
    """SocketCAN device, multicast group (IPv4, 224.0.0.0/4; ``239.x.y.z`` is administratively scoped) or
    virtual channel name."""
    port: int = DEFAULT_PORT
    """UDP port of the ``udp_multicast`` bus (1–65535)."""

    def __post_init__(self) -> None:
        check("interface", self.interface, lambda v: v in INTERFACES, f"one of {list(INTERFACES)}")
        check("channel", self.channel, lambda v: isinstance(v, str) and v.strip() != "", "a non-empty name")
        if self.interface == "udp_multicast":
            check("channel", self.channel, is_loopback_group, "an IPv4 multicast group (224.0.0.0/4)")
        check("port", self.port, lambda v: isinstance(v, int) and not isinstance(v, bool) and 1 <= v <= 65535,
              "a UDP port number in 1..65535")

    def open(self) -> can.BusABC:
        """The python-can bus (``can.CanError`` or ``OSError`` when the interface cannot be opened)."""
        if self.interface == "socketcan":
            return can.Bus(interface="socketcan", channel=self.channel, bitrate=BITRATE)
        if self.interface == "udp_multicast":
            return LoopbackMulticastBus(self.channel, self.port)
        return can.Bus(interface="virtual", channel=self.channel, receive_own_messages=False)


def open_bus(interface: str, channel: str, port: Any = None) -> can.BusABC:
    """Open ``channel`` on ``interface`` (``port``: the udp_multicast port, default 43113).

    A bad interface, channel or port raises :class:`ParamError` naming it; an interface that
    cannot be opened raises ``can.CanError`` or ``OSError``.
    """
    return BusParams(interface, channel, DEFAULT_PORT if port is None else port).open()


SEND_TIMEOUT = 0.005
"""Longest a send may block (s): half a command period (a full SocketCAN transmit queue raises instead)."""


def descriptor(bus: Optional[can.BusABC]) -> Optional[int]:
    """The file descriptor to wait on for ``bus``'s frames (``select``), or ``None``: no bus, or one without a
    descriptor (python-can's ``virtual`` bus), or a closed one."""
    if bus is None:
        return None
    try:
        fd = bus.fileno()
    except (NotImplementedError, OSError, ValueError, AttributeError):
        return None
    return fd if isinstance(fd, int) and fd >= 0 else None


class BusLink:
    """The I/O shell: opens the bus, moves frames, reports failures to ``health`` and re-opens after its back-off.

    Any ``can.CanError`` or ``OSError`` from open, send or receive closes the bus object
    (``health.on_io_failure``); the next call after ``health``'s back-off opens it again.
    Error frames are returned with the data frames (the bridge core hands them to ``health``).

    Safe for one sending and one receiving thread: ``lock`` guards the bus object, ``health``
    and the logger; the socket calls themselves run outside it, so neither thread waits for the
    other's I/O.
    """

    def __init__(self, opener: Callable[[], can.BusABC], health: BusHealth,
                 logger: Optional[Callable[[can.Message], Any]] = None,
                 lock: Optional[threading.Lock] = None, send_timeout: float = SEND_TIMEOUT) -> None:
        self.opener = opener
        self.health = health
        self.logger = logger
        self.lock = lock or threading.Lock()
        self.send_timeout = send_timeout
        self.bus: Optional[can.BusABC] = None

    def fileno(self) -> Optional[int]:
        """The open bus's file descriptor (:func:`descriptor`), ``None`` while it is closed."""
        return descriptor(self.bus)

    def ensure_open(self, t: float) -> Optional[can.BusABC]:
        """The open bus, opening it if the back-off allows; ``None`` while it is closed."""
        with self.lock:
            if self.bus is not None:
                return self.bus
            if self.health.reopen_at is not None and not self.health.reopen_due(t):
                return None
            try:
                self.bus = self.opener()
            except (can.CanError, OSError) as exc:
                self.health.on_io_failure(f"open failed: {exc}", t)
                return None
            self.health.on_open(t)
            return self.bus

    def receive(self, t: float, limit: int) -> tuple[list[can.Message], bool]:
        """The frames among up to ``limit`` reads, and whether the limit was reached ([] while the bus is closed).

        A read the bus skipped as malformed (it counts them in ``malformed``, as
        :class:`LoopbackMulticastBus` does) counts against the limit and does not end the reading.
        """
        frames: list[can.Message] = []
        bus = self.ensure_open(t)
        if bus is None:
            return frames, False
        reads = 0
        try:
            while reads < limit:
                skipped = getattr(bus, "malformed", 0)
                frame = bus.recv(timeout=0.0)
                reads += 1
                if frame is not None:
                    frames.append(frame)
                elif getattr(bus, "malformed", 0) == skipped:
                    break  # nothing waiting
        except (can.CanError, OSError, ValueError) as exc:  # ValueError: a closed socket's fileno
            self._fail(bus, f"receive failed: {exc}", t)
        self._log(frames)
        return frames, reads >= limit

    def send(self, frames: list[can.Message], t: float) -> bool:
        """Send ``frames`` in order; False (and the bus closed) on a failure, or while the bus is closed."""
        bus = self.ensure_open(t)
        if bus is None:
            return False
        sent = 0
        try:
            for frame in frames:
                bus.send(frame, timeout=self.send_timeout)
                sent += 1
        except (can.CanError, OSError, ValueError) as exc:
            self._fail(bus, f"send failed: {exc}", t)
        self._log(frames[:sent])
        if sent and sent == len(frames):
            with self.lock:
                self.health.on_traffic(t)
        return sent == len(frames)

    def _log(self, frames: list[can.Message]) -> None:
        if self.logger is not None and frames:
            with self.lock:
                for frame in frames:
                    self.logger(frame)

    def _fail(self, bus: can.BusABC, reason: str, t: float) -> None:
        with self.lock:
            if self.bus is not bus:  # the other thread saw the failure first
                return
            self.health.on_io_failure(reason, t)
            self._close()

    def close(self) -> None:
        with self.lock:
            self._close()

    def _close(self) -> None:
        if self.bus is not None:
            try:
                self.bus.shutdown()
            except Exception:  # noqa: BLE001 - a failing bus may fail to close too; it is dropped either way
                pass
            self.bus = None
