"""A flood on the bus cannot hold the command frames back: measured from outside the bridge's process.

Three parties on a loopback ``udp_multicast`` bus of their own (a port claimed through
``tests/isolation.py``, a random organisation-local group, TTL 0, ``lo`` only):

* the bridge process: a :class:`~moose.canbus.runner.BridgeRunner` used as the node uses
  it (sender thread; every 10 ms one command forwarded and one bounded receive);
* a flooder process (real-time below the bridge when permitted, so other load cannot thin
  the flood out): ~100 000 junk frames/s for 3 s: half well-formed sensor frames (IMU,
  WHEEL_SPEEDS, EPS_STATUS with in-range values: the bridge must decode them in full), half
  random identifiers and lengths, an extended identifier, 2 in 515 datagrams not frames;
* this process, the independent reader: a socket with a kernel filter (classic BPF) that
  passes only the bridge's own identifiers, stamped by the kernel on arrival
  (SO_TIMESTAMPNS), so neither the flood nor this process's scheduling distorts the gaps it
  measures; the rolling counters prove it missed no command frame.
"""
from __future__ import annotations

import ctypes
import json
import os
import secrets
import select
import socket
import struct
import subprocess
import sys
import threading
import time
from typing import Any, Optional

import pytest
from can.interfaces.udp_multicast.bus import SO_TIMESTAMPNS
from can.interfaces.udp_multicast.utils import unpack_message

from isolation import claim_udp_port, realtime_slot
from moose.canbus.codec import Codec

# the command frames' schedule is judged against the wall clock: in the serial real-time phase of make test
pytestmark = [pytest.mark.can, pytest.mark.realtime]

FLOOD_RATE = 100_000
"""Junk frames per second the flooder aims at."""
FLOOD_S = 3.0
QUIET_S = 0.5
"""The bridge commands this long before and after the flood."""
ECU_TIMEOUT = 0.05

BRIDGE = r"""
import json, select, sys, time
from moose.canbus.bus import BusParams
from moose.canbus.runner import BridgeParams, BridgeRunner
from moose.canbus.safety import Command

group, port = sys.argv[1], int(sys.argv[2])
runner = BridgeRunner(BridgeParams(bus=BusParams("udp_multicast", group, port)))
runner.start()
print("ready", flush=True)
messages, start, k = set(), time.monotonic(), 0
try:
    while not select.select([sys.stdin], [], [], 0.0)[0]:  # until told to stop
        runner.command(Command(0.05, 0.0, 20.0, 20.0))
        runner.receive()
        if k % 10 == 0:
            messages.add(runner.diagnostics().message)
        k += 1
        time.sleep(max(0.0, start + 0.01 * k - time.monotonic()))
    values = runner.diagnostics().values
finally:
    runner.close()
print(json.dumps({"values": values, "messages": sorted(messages), "send_failures": runner.send_failures}), flush=True)
"""

FLOODER = r"""
import os, random, socket, sys, time
import can
from can.interfaces.udp_multicast.utils import pack_message
from moose.canbus.codec import Codec

group, port = sys.argv[1], int(sys.argv[2])
rate, duration, malformed = float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
bridge_ids = {0x100, 0x101, 0x300, 0x301}
rng = random.Random(1)
junk = []
for _ in range(256):
    ident = rng.choice([rng.randrange(0x800), 0x200, 0x201, 0x202, 0x203, 0x204])
    while ident in bridge_ids:
        ident = rng.randrange(0x800)
    data = bytes(rng.randrange(256) for _ in range(rng.randrange(9)))
    junk.append(pack_message(can.Message(arbitration_id=ident, data=data, is_extended_id=False, timestamp=1.0)))
car = Codec(node="VEHICLE")  # well-formed sensor frames: the bridge must decode them in full to judge them
for k in range(256):
    name = ("IMU", "WHEEL_SPEEDS", "EPS_STATUS")[k % 3]
    message = car.db.get_message_by_name(name)
    values = {s.name: rng.uniform(s.minimum, s.maximum) for s in message.signals if s.name != "Counter"}
    junk.append(pack_message(car.encode(name, values, 1.0)))
junk.append(pack_message(can.Message(arbitration_id=0x1ABCDEF, data=b"\0" * 8, timestamp=1.0)))
junk += [b"not a frame", os.urandom(64)][:malformed]
sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
address, batch, sent = (group, port), 500, 0
try:  # real-time below the bridge (10), so other test runs on this machine cannot thin the flood out
    os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK, os.sched_param(5))
except OSError:
    pass
print("ready", flush=True)
sys.stdin.readline()
start = time.monotonic()
while time.monotonic() - start < duration:
    for i in range(batch):
        try:
            sock.sendto(junk[(sent + i) % len(junk)], address)
        except OSError:  # ENOBUFS under load: the datagram is lost, the flood goes on
            pass
    sent += batch
    time.sleep(max(0.0, start + sent / rate - time.monotonic()))
print(sent, time.monotonic() - start, flush=True)
"""

BRIDGE_IDS = (0x100, 0x101, 0x300, 0x301)
SO_ATTACH_FILTER = 26
MSGPACK_ID_OFFSET = 8 + 35
"""python-can's msgpack frame: fixmap, "timestamp", float64, "arbitration_id" — the id (uint16, 0xcd) starts at byte 35
of the UDP payload, after the 8-byte UDP header the filter sees."""


def bridge_id_filter() -> tuple[bytes, Any]:
    """A classic BPF program that accepts only datagrams carrying one of the bridge's identifiers."""
    ld_b, ld_h, jeq, ret = 0x30, 0x28, 0x15, 0x06
    program = [(ld_b, 0, 0, MSGPACK_ID_OFFSET), (jeq, 0, 6, 0xCD), (ld_h, 0, 0, MSGPACK_ID_OFFSET + 1)]
    program += [(jeq, 3 - i, 0 if i < 3 else 1, ident) for i, ident in enumerate(BRIDGE_IDS)]
    program += [(ret, 0, 0, 0x40000), (ret, 0, 0, 0)]
    code = ctypes.create_string_buffer(b"".join(struct.pack("HBBI", *ins) for ins in program))
    return struct.pack("HL", len(program), ctypes.addressof(code)), code


class Reader:
    """The third party: every frame of the bridge on the bus, with the kernel's arrival time."""

    def __init__(self, group: str, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
        program, self._code = bridge_id_filter()
        self.sock.setsockopt(socket.SOL_SOCKET, SO_ATTACH_FILTER, program)
        self.sock.bind((group, port))
        self.sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP,
                             socket.inet_aton(group) + socket.inet_aton("127.0.0.1"))
        self.frames: list[tuple[float, str, dict[str, float]]] = []
        self.codec = Codec()
        self.other = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            if not select.select([self.sock], [], [], 0.05)[0]:
                continue
            data, ancillary, _, _ = self.sock.recvmsg(4096, socket.CMSG_SPACE(16))
            stamp = next(sec + ns * 1e-9 for level, kind, raw in ancillary
                         if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS
                         for sec, ns in [struct.unpack("@ll", raw[:16])])
            decoded = self.codec.decode(unpack_message(data))
            if decoded is None:
                self.other += 1
            else:
                self.frames.append((stamp, decoded[0], decoded[1]))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.sock.close()


def unique_group() -> str:
    r = secrets.token_bytes(3)
    return f"239.{192 + (r[0] & 3)}.{r[1]}.{max(r[2], 1)}"


def start(script: str, *args: object, env: Optional[dict[str, str]] = None) -> subprocess.Popen:
    child = subprocess.Popen([sys.executable, "-c", script, *map(str, args)], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=dict(os.environ, PYTHONUNBUFFERED="1", **(env or {})))
    ready, _, _ = select.select([child.stdout], [], [], 60.0)
    line = child.stdout.readline().strip() if ready and child.stdout else ""
    if line != "ready":
        child.kill()
        raise AssertionError(f"child did not start: {line!r} {child.communicate()[1]}")
    return child


def flood_run(bridge_script: str = BRIDGE, bridge_env: Optional[dict[str, str]] = None,
              malformed: int = 2) -> dict[str, Any]:
    """Bridge and flooder processes on a fresh bus, the reader here; what each saw."""
    group, port = unique_group(), claim_udp_port()
    reader = Reader(group, port)
    children: list[subprocess.Popen] = []
    try:
        bridge = start(bridge_script, group, port, env=bridge_env)
        children.append(bridge)
        flooder = start(FLOODER, group, port, FLOOD_RATE, FLOOD_S, malformed)
        children.append(flooder)
        time.sleep(QUIET_S)
        flood_start = time.time()
        assert flooder.stdin is not None and bridge.stdin is not None
        flooder.stdin.write("go\n")
        flooder.stdin.flush()
        flood_out, flood_err = flooder.communicate(timeout=FLOOD_S + 30.0)
        assert flooder.returncode == 0, flood_err
        sent, seconds = flood_out.split()
        time.sleep(QUIET_S)
        bridge_out, bridge_err = bridge.communicate("stop\n", timeout=30.0)
        assert bridge.returncode == 0, bridge_err
        time.sleep(0.1)
    finally:
        for child in children:
            if child.poll() is None:
                child.kill()
                child.wait()
        reader.close()
    return {"reader": reader, "bridge": json.loads(bridge_out.strip().splitlines()[-1]) if bridge_out.strip() else {},
            "flood_sent": int(sent), "flood_rate": int(sent) / float(seconds), "flood_start": flood_start,
            "flood_s": float(seconds)}


def gaps(times: list[float]) -> list[float]:
    return [b - a for a, b in zip(times[:-1], times[1:])]


@pytest.fixture(scope="module")
def flood() -> dict[str, Any]:
    with realtime_slot():
        return flood_run()


def test_the_flood_reached_the_bridge_and_was_reported(flood: dict[str, Any]) -> None:
    assert flood["flood_rate"] > 0.5 * FLOOD_RATE, flood["flood_rate"]  # the machine really produced a flood
    values = flood["bridge"]["values"]
    assert int(values["rx_overflow_cycles"]) >= 100  # most of the 300 flooded cycles hit the bound
    assert any(m.startswith("receive flood") for m in flood["bridge"]["messages"])
    status = [v for _, name, v in flood["reader"].frames if name == "BRIDGE_STATUS"]
    assert sum(s["RxOverflow"] for s in status) >= 10  # flagged on the bus too (BRIDGE_STATUS every 100 ms)


def test_command_frames_keep_their_schedule_under_the_flood(flood: dict[str, Any]) -> None:
    reader = flood["reader"]
    assert reader.codec.stats.bad_counter == 0 and reader.codec.stats.lost == 0  # the reader missed no frame
    start, end = flood["flood_start"], flood["flood_start"] + flood["flood_s"]
    for name in ("CMD_STEER", "CMD_TORQUE"):
        times = [t for t, n, _ in reader.frames if n == name]
        assert times[0] < start - 0.3 and times[-1] > end + 0.3  # the frames span the flood and some quiet
        assert max(gaps(times)) < ECU_TIMEOUT, (name, max(gaps(times)))
    values = flood["bridge"]["values"]
    assert values["late_commands"] == "0" and flood["bridge"]["send_failures"] == 0


def test_the_heartbeat_says_commanding_only_while_commands_go_out(flood: dict[str, Any]) -> None:
    frames = flood["reader"].frames
    steer = [t for t, n, _ in frames if n == "CMD_STEER"]
    beats = [(t, v["State"]) for t, n, v in frames if n == "BRIDGE_HEARTBEAT"]
    assert len(beats) >= 0.9 * (FLOOD_S + 2 * QUIET_S) / 0.1
    assert sum(state == 0 for _, state in beats) >= len(beats) // 2
    for t, state in beats:
        if state == 0:  # commanding: no command gap over the ECU timeout in the status period before it
            window = [s for s in steer if t - 0.1 <= s <= t]
            assert window and max(gaps(window) or [0.0]) < ECU_TIMEOUT and t - window[-1] < ECU_TIMEOUT
