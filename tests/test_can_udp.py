"""The cross-process bus: python-can udp_multicast confined to loopback, bridge and ECU emulator in two processes.

A unique IPv4 group (239.192.0.0/14, organisation-local scope) and UDP port per test run.
The ECU process runs the real plant and sensors behind ``VehicleEcu``; this process runs
the bridge as the node does — a ``BridgeRunner`` with its sender thread, commands forwarded
and samples taken every 10 ms — with a feedback EPS law closing the steering loop over the
bus.  When raw packet sockets are allowed, every interface is watched during the run: the
frames must appear on ``lo`` and nothing of the group (data or IGMP) anywhere else.
"""
from __future__ import annotations

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
from typing import Any

import pytest

from isolation import claim_udp_port
from moose.canbus.bus import BusParams, LoopbackMulticastBus
from moose.canbus.runner import BridgeParams, BridgeRunner
from moose.canbus.safety import Command
from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

pytestmark = [pytest.mark.can]

RUN_S = 1.5
"""How long the bridge commands (wall clock)."""

ECU_PROCESS = r"""
import json, sys, time
import numpy as np
from moose.canbus.bus import open_bus
from moose.canbus.ecu import VehicleEcu
from moose.params import VehicleParams
from moose.sensors import Sensors
from moose.vehicle import DELTA, VX, VehiclePlant, initial_state
from moose.schema import SensorParams

group, port, cap = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
vehicle = VehicleParams()
plant = VehiclePlant(vehicle)
plant.reset(initial_state(vehicle, vx=5.0))
sensors = Sensors(SensorParams(), vehicle, np.random.default_rng(0))
ecu = VehicleEcu()
bus = open_bus("udp_multicast", group, port)
print("ready", flush=True)
start, k, accepted, last_command, u = time.monotonic(), 0, 0, None, np.zeros(3)
try:
    while k * 0.01 <= cap:
        t = k * 0.01
        lag = t - (time.monotonic() - start)
        if lag > 0:
            time.sleep(lag)
        while (frame := bus.recv(timeout=0.0)) is not None:
            before = ecu.codec.stats.dropped
            ecu.on_frame(frame, t)
            if frame.arbitration_id in (0x100, 0x101) and ecu.codec.stats.dropped == before:
                accepted, last_command = accepted + 1, t
        if last_command is not None and t - last_command > 0.3:
            break
        u = ecu.plant_input(t)
        state = plant.state
        for frame in ecu.frames(sensors.sample(t, state, plant.imu_specific_force(state, u)), t):
            bus.send(frame)
        plant.step(u, 10)
        k += 1
finally:
    bus.shutdown()
s = ecu.codec.stats
print(json.dumps({"accepted": accepted, "bad_checksum": s.bad_checksum, "bad_counter": s.bad_counter,
                  "unknown_id": s.unknown_id, "bad_length": s.bad_length, "t_end": k * 0.01,
                  "delta": float(plant.state[DELTA]), "vx": float(plant.state[VX]), "u_end": [float(v) for v in u]}),
      flush=True)
"""


def unique_group_and_port() -> tuple[str, int]:
    """A random group, and a port free now and locked for this run (tests/isolation.py: no concurrent run takes it)."""
    r = secrets.token_bytes(3)
    return f"239.{192 + (r[0] & 3)}.{r[1]}.{max(r[2], 1)}", claim_udp_port()


class Sniffer:
    """Counts, per interface, IPv4 packets of the group (UDP to the port, or IGMP naming the group)."""

    ETH_P_ALL = 0x0003

    def __init__(self, group: str, port: int) -> None:
        self.group, self.port = socket.inet_aton(group), port
        self.counts: dict[str, int] = {}
        self.down: list[str] = []
        self._stop = threading.Event()
        self._sockets = []
        for _, name in socket.if_nameindex():
            s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(self.ETH_P_ALL))
            s.bind((name, 0))
            s.setblocking(False)
            self._sockets.append((name, s))
            self.counts[name] = 0
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _matches(self, packet: bytes) -> bool:
        if len(packet) < 34 or packet[12:14] != b"\x08\x00":
            return False
        ip = packet[14:]
        header, protocol, destination = (ip[0] & 0x0F) * 4, ip[9], ip[16:20]
        if protocol == 17 and len(ip) >= header + 4:
            return struct.unpack("!H", ip[header + 2:header + 4])[0] == self.port or destination == self.group
        if protocol == 2:  # IGMP: a report or leave for the group (v2: destination or payload; v3: group records)
            return destination == self.group or self.group in ip[header:]
        return destination == self.group

    def _run(self) -> None:
        while not self._stop.is_set() and self._sockets:
            ready, _, _ = select.select([s for _, s in self._sockets], [], [], 0.05)
            for name, s in list(self._sockets):
                if s not in ready:
                    continue
                while True:
                    try:
                        packet = s.recv(65535)
                    except BlockingIOError:
                        break
                    except OSError:  # an interface that is down (ENETDOWN) carries nothing: stop watching it
                        self._sockets.remove((name, s))
                        self.down.append(name)
                        s.close()
                        break
                    if self._matches(packet):
                        self.counts[name] += 1

    def __enter__(self) -> "Sniffer":
        self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        time.sleep(0.2)  # late IGMP leave reports
        self._stop.set()
        self._thread.join(timeout=5.0)
        for _, s in self._sockets:
            s.close()
        assert "lo" not in self.down


def raw_sockets_allowed() -> bool:
    try:
        socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(Sniffer.ETH_P_ALL)).close()
        return True
    except (PermissionError, OSError, AttributeError):
        return False


def run_bridge(group: str, port: int) -> dict[str, Any]:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    child = subprocess.Popen([sys.executable, "-c", ECU_PROCESS, group, str(port), "10.0"], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=env)
    igmp_lines: list[str] = []
    try:
        ready, _, _ = select.select([child.stdout], [], [], 60.0)
        assert ready and child.stdout is not None and child.stdout.readline().strip() == "ready", child.stderr.read()
        runner = BridgeRunner(BridgeParams(bus=BusParams("udp_multicast", group, port)))
        bridge = runner.core
        records: list[Any] = []
        delta_meas, start, k = 0.0, time.monotonic(), 0
        runner.start()
        try:
            while k * 0.01 <= RUN_S:
                t = k * 0.01
                lag = t - (time.monotonic() - start)
                if lag > 0:
                    time.sleep(lag)
                for record in runner.receive(stamp=t):
                    records.append(record)
                    if isinstance(record, EpsSample):
                        delta_meas = record.delta
                runner.command(Command(0.1, 20.0 * (0.1 - delta_meas), 100.0, 100.0))
                if k == 50:
                    with open("/proc/net/igmp") as f:
                        igmp_lines = f.read().splitlines()
                k += 1
            diagnostics = runner.diagnostics()
            malformed = runner.link.bus.malformed if isinstance(runner.link.bus, LoopbackMulticastBus) else -1
        finally:
            runner.close()
        assert runner.send_failures == 0 and diagnostics.level != 2, diagnostics  # no bus error
        out, err = child.communicate(timeout=30.0)
        assert child.returncode == 0, err
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    return {"ecu": json.loads(out.strip().splitlines()[-1]), "records": records, "bridge": bridge,
            "igmp": igmp_lines, "malformed": malformed}


@pytest.fixture(scope="module")
def exchange() -> dict[str, Any]:
    group, port = unique_group_and_port()
    if raw_sockets_allowed():
        with Sniffer(group, port) as sniffer:
            result = run_bridge(group, port)
        result["sniffed"] = sniffer.counts
    else:
        result = run_bridge(group, port)
    result["group"] = group
    return result


def test_bridge_and_ecu_emulator_in_two_processes_over_loopback_multicast(exchange: dict[str, Any]) -> None:
    ecu, records, bridge = exchange["ecu"], exchange["records"], exchange["bridge"]
    # commands: 2 frames per 10 ms for 1.5 s; scheduling on a shared machine may delay, never corrupt
    assert ecu["accepted"] >= 200 and ecu["bad_checksum"] == 0 and ecu["unknown_id"] == 0 and ecu["bad_length"] == 0
    assert ecu["bad_counter"] <= 2
    assert ecu["delta"] == pytest.approx(0.1, abs=0.01)  # steered through the bus
    assert ecu["vx"] > 5.0  # driven by the torque commands
    assert ecu["u_end"] == [0.0, 0.0, 0.0]  # the ECU's own timeout once the bridge fell silent
    assert ecu["t_end"] < 5.0
    count = {kind: sum(isinstance(r, kind) for r in records)
             for kind in (ImuSample, WheelSpeedSample, EpsSample, GpsSample)}
    assert count[ImuSample] >= 100 and count[WheelSpeedSample] >= 100 and count[EpsSample] >= 100
    assert count[GpsSample] >= 1
    wheels = [r for r in records if isinstance(r, WheelSpeedSample)]
    assert wheels[-1].omega_rl > wheels[0].omega_rl
    s = bridge.codec.stats
    assert s.bad_checksum == 0 and s.unknown_id == 0 and s.bad_length == 0 and exchange["malformed"] == 0
    assert not bridge.bus_error


def test_the_group_is_joined_on_loopback_only(exchange: dict[str, Any]) -> None:
    group_hex = socket.inet_aton(exchange["group"])[::-1].hex().upper()  # /proc/net/igmp: host byte order
    device = None
    joined_on = []
    for line in exchange["igmp"]:
        if not line.startswith("\t"):
            device = line.split()[1] if line[:1].isdigit() else device
        elif line.split()[0] == group_hex:
            joined_on.append(device)
    assert joined_on and set(joined_on) == {"lo"}


def test_no_packet_of_the_group_leaves_the_machine(exchange: dict[str, Any]) -> None:
    if "sniffed" not in exchange:
        pytest.skip("raw packet sockets need CAP_NET_RAW: the interfaces cannot be watched here")
    counts = exchange["sniffed"]
    assert counts["lo"] > 100  # the watch sees the frames where they are
    assert {name: n for name, n in counts.items() if name != "lo" and n} == {}


def test_the_bus_descriptor_to_wait_on() -> None:
    """What the lockstep nodes wait on for frames (``moose.canbus.bus.descriptor``): the loopback multicast bus's
    socket, readable once a frame is on the group; none for python-can's virtual bus or a closed bus."""
    import can

    from moose.canbus.bus import descriptor

    group = f"239.192.{secrets.randbelow(250)}.{1 + secrets.randbelow(250)}"
    port = claim_udp_port()
    reader, writer = LoopbackMulticastBus(group, port), LoopbackMulticastBus(group, port)
    try:
        fd = descriptor(reader)
        assert isinstance(fd, int) and fd == reader.fileno()
        assert select.select([fd], [], [], 0.0)[0] == []
        writer.send(can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False))
        assert select.select([fd], [], [], 5.0)[0] == [fd]
    finally:
        reader.shutdown()
        writer.shutdown()
    assert descriptor(reader) is None and descriptor(None) is None
    virtual = can.Bus(interface="virtual", channel="descriptor-test")
    try:
        assert descriptor(virtual) is None
    finally:
        virtual.shutdown()
