"""A packet capture that counts the RTPS packets of one DDS domain by network interface and vendor.

Used to check, from outside the DDS processes, that a test's DDS traffic stays on loopback.  It
reads every frame of every interface of the current network namespace (AF_PACKET, so it needs
CAP_NET_RAW) and counts UDP datagrams that start with the RTPS magic and go to or come from the
port range of the domain (RTPS port mapping: 7400 + 250 * domain, 250 ports).
"""
from __future__ import annotations

import select
import socket
import struct
import threading

VENDORS = {b"\x01\x0f": "Fast DDS", b"\x01\x10": "Cyclone DDS"}


class RtpsCapture:
    """``with RtpsCapture(domain) as cap: ...``; then ``cap.seen[(interface, vendor)]`` = packets.
    Raises PermissionError without CAP_NET_RAW."""

    def __init__(self, domain: int) -> None:
        self.ports = range(7400 + 250 * domain, 7400 + 250 * (domain + 1))
        self.seen: dict[tuple[str, str], int] = {}
        self.sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.ntohs(0x0003))
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> "RtpsCapture":
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5)
        self.sock.close()

    def _run(self) -> None:
        while not self._stop.is_set():
            if select.select([self.sock], [], [], 0.1)[0]:
                self._read()
        for _ in range(100_000):  # what was queued before the stop; bounded, as loopback may be busy
            if not select.select([self.sock], [], [], 0)[0]:
                break
            self._read()

    def _read(self) -> None:
        frame, address = self.sock.recvfrom(65535)
        self._count(address[0], frame)

    def _count(self, interface: str, frame: bytes) -> None:
        ethertype = frame[12:14]
        if ethertype == b"\x08\x00":
            ihl = (frame[14] & 0x0F) * 4
            if frame[23] != 17 or struct.unpack("!H", frame[20:22])[0] & 0x1FFF:
                return  # not UDP, or a fragment after the first
            udp = 14 + ihl
        elif ethertype == b"\x86\xdd":
            if frame[20] != 17:
                return
            udp = 14 + 40
        else:
            return
        if len(frame) < udp + 16:
            return
        sport, dport = struct.unpack("!HH", frame[udp:udp + 4])
        payload = frame[udp + 8:]
        if payload[:4] == b"RTPS" and (sport in self.ports or dport in self.ports):
            key = (interface, VENDORS.get(payload[6:8], payload[6:8].hex()))
            self.seen[key] = self.seen.get(key, 0) + 1
