"""CAN layer: DBC round trip, bus load, CRC, malformed frames, command guard limits and timeout, bridge ↔ ECU."""
from __future__ import annotations

from typing import Callable

import can
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from moose.canbus.bridge import BridgeCore
from moose.canbus.bus import open_bus
from moose.canbus.busload import worst_case_bus_load, worst_case_frame_bits
from moose.canbus.codec import Codec, crc8_j1850, load_database
from moose.canbus.ecu import VehicleEcu
from moose.canbus.safety import Command, GuardParams
from moose.params import ParamError
from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

DB = load_database()
GUARD = GuardParams()


def test_dbc_round_trips_every_signal_at_its_limits() -> None:
    codec = Codec(DB)
    for message in DB.messages:
        for bound in ("minimum", "maximum"):
            values = {s.name: getattr(s, bound) for s in message.signals if s.name not in ("Counter", "Checksum")}
            frame = codec.encode(message.name, values)
            name, decoded = Codec(DB).decode(frame)
            assert name == message.name
            for key, value in values.items():
                scale = next(s.scale for s in message.signals if s.name == key)
                assert decoded[key] == pytest.approx(value, abs=scale)


def test_bus_load_below_half_at_500_kbps() -> None:
    assert DB.dbc.attributes["Baudrate"].value == 500_000
    assert worst_case_frame_bits(8) == 135 and worst_case_frame_bits(0) == 55
    load = worst_case_bus_load(DB, 500_000)
    assert 0.05 < load < 0.5


def test_crc_is_sae_j1850() -> None:
    assert crc8_j1850(b"123456789") == 0x4B
    assert crc8_j1850(b"\x00\x00\x00\x00") == 0x59


def test_bad_counter_checksum_length_and_id_are_dropped_and_counted() -> None:
    tx, rx = Codec(DB), Codec(DB)
    first = tx.encode("CMD_TORQUE", {"TorqueRL": 10.0, "TorqueRR": 10.0})
    assert rx.decode(first) is not None
    corrupted = bytearray(tx.encode("CMD_TORQUE", {"TorqueRL": 10.0, "TorqueRR": 10.0}).data)
    corrupted[0] ^= 0x01
    assert rx.decode(can.Message(arbitration_id=0x101, data=bytes(corrupted), is_extended_id=False)) is None
    tx.encode("CMD_TORQUE", {"TorqueRL": 0.0, "TorqueRR": 0.0})  # a lost frame: the counter jumps
    assert rx.decode(tx.encode("CMD_TORQUE", {"TorqueRL": 0.0, "TorqueRR": 0.0})) is None
    assert rx.decode(can.Message(arbitration_id=0x101, data=b"\x00" * 5, is_extended_id=False)) is None
    assert rx.decode(can.Message(arbitration_id=0x7FF, data=b"\x00" * 8, is_extended_id=False)) is None
    s = rx.stats
    assert (s.bad_checksum, s.bad_counter, s.bad_length, s.unknown_id) == (1, 1, 1, 1)


frames = st.builds(
    lambda i, data, ext: can.Message(arbitration_id=i, data=data, is_extended_id=ext),
    st.one_of(st.sampled_from([m.frame_id for m in DB.messages]), st.integers(0, 0x7FF)),
    st.binary(min_size=0, max_size=8),
    st.booleans(),
)


@settings(max_examples=300, deadline=None)
@given(st.lists(frames, max_size=40))
def test_random_and_malformed_frames_never_crash_the_bridge(stream: list) -> None:
    bridge = BridgeCore(GUARD)
    for k, frame in enumerate(stream):
        sample = bridge.on_frame(frame, 0.01 * k)
        assert sample is None or isinstance(sample, (ImuSample, WheelSpeedSample, EpsSample, GpsSample))
        for out in bridge.tick(0.01 * k):
            decoded = Codec(DB).decode(out)
            assert decoded is not None
            name, v = decoded
            if name == "CMD_STEER":
                assert abs(v["SteerAngleCmd"]) <= GUARD.delta_max + 1e-4
            if name == "CMD_TORQUE":
                assert abs(v["TorqueRL"]) <= GUARD.torque_max + 0.01 and abs(v["TorqueRR"]) <= GUARD.torque_max + 0.01


def test_timeout_starts_the_minimum_risk_maneuver_within_one_command_cycle() -> None:
    bridge = BridgeCore(GUARD)
    rx = Codec(DB)
    deadline = 0.2 + GUARD.timeout
    torques, rates, angles = {}, {}, {}
    for k in range(60):  # fresh commands up to 0.2 s, then silence
        t = round(0.01 * k, 9)
        if t <= 0.2:
            bridge.on_command(Command(0.1, 0.5, 150.0, 150.0), t)
        for frame in bridge.tick(t):
            decoded = rx.decode(frame)
            assert decoded is not None
            if decoded[0] == "CMD_TORQUE":
                torques[t] = decoded[1]["TorqueRL"]
            if decoded[0] == "CMD_STEER":
                rates[t], angles[t] = decoded[1]["SteerRateCmd"], decoded[1]["SteerAngleCmd"]
    first_safe = min(t for t in rates if t > deadline)
    assert first_safe <= deadline + 0.01 + 1e-9  # within one 10 ms command cycle of the deadline
    assert torques[first_safe] < torques[0.2] and rates[first_safe] < 0.0  # ramping down, steering back
    assert all(angles[t] == pytest.approx(0.0, abs=1e-4) for t in angles if t > deadline + 0.1 + 0.01)  # straight
    assert all(torques[t] <= 0.0 for t in torques if t > deadline + 150.0 / GUARD.torque_rate_limit + 0.01)
    assert bridge.guard.timed_out


@pytest.mark.can
def test_bridge_and_ecu_over_a_virtual_bus() -> None:
    car_side, bridge_side = open_bus("virtual", "moose-test-vbus"), open_bus("virtual", "moose-test-vbus")
    try:
        bridge, ecu = BridgeCore(GUARD), VehicleEcu()
        samples = []
        for k in range(40):
            t = 0.01 * k
            bridge.on_command(Command(0.05, 0.2, 80.0, 80.0), t)
            for frame in bridge.tick(t):
                bridge_side.send(frame)
            while (frame := car_side.recv(timeout=0.0)) is not None:
                ecu.on_frame(frame, t)
            sensor = [ImuSample(t, 0.5, 0.2, 0.01), WheelSpeedSample(t, 20.0, 20.5), EpsSample(t, 0.04)]
            if k == 20:
                sensor.append(GpsSample(t, t - 0.2, 12.345, -3.21, 6.9, 0.1))
            for sample in sensor:
                for frame in ecu.encode(sample, t):
                    car_side.send(frame)
            while (frame := bridge_side.recv(timeout=0.0)) is not None:
                decoded = bridge.on_frame(frame, t)
                if decoded is not None:
                    samples.append(decoded)
        u = ecu.plant_input(0.39)
        assert u[0] == pytest.approx(0.2, abs=1e-3) and u[1] == pytest.approx(80.0, abs=0.01)  # torque ramped up
        gps = [s for s in samples if isinstance(s, GpsSample)]
        assert len(gps) == 1 and gps[0].x == pytest.approx(12.345)
        assert gps[0].t - gps[0].t_measured == pytest.approx(0.2)
        assert sum(isinstance(s, ImuSample) for s in samples) == 40
        assert bridge.codec.stats.dropped == 0 and ecu.codec.stats.dropped == 0
        assert np.allclose(ecu.plant_input(1.0), 0.0)  # the ECU's own timeout
    finally:
        car_side.shutdown()
        bridge_side.shutdown()


def test_unknown_interface_is_refused() -> None:
    with pytest.raises(ParamError, match="interface = 'serial'"):
        open_bus("serial", "x")


@pytest.mark.can
def test_dump_decodes_and_replay_sends_a_recorded_log(tmp_path) -> None:
    import io

    from moose.canbus.tools import dump, replay

    codec = Codec(DB)
    path = tmp_path / "traffic.asc"
    with can.Logger(str(path)) as logger:
        for k in range(20):
            frame = codec.encode("IMU", {"YawRate": 0.01 * k, "AccelX": 0.1, "AccelY": -0.2}, 1.0 + 0.01 * k)
            logger(frame)
        logger(can.Message(arbitration_id=0x123, data=b"\x01\x02", is_extended_id=False, timestamp=1.3))
    sender, receiver = open_bus("virtual", "moose-test-replay"), open_bus("virtual", "moose-test-replay")
    try:
        assert replay(path, sender, rate=10.0) == 21
        out = io.StringIO()
        assert dump(receiver, out, count=21, duration=5.0) == 21
    finally:
        sender.shutdown()
        receiver.shutdown()
    lines = out.getvalue().splitlines()
    assert lines[5].split()[3] == "IMU" or " IMU " in lines[5]
    assert "YawRate=0.05" in lines[5]
    assert "DROPPED (unknown_id)" in lines[-1]
    with pytest.raises(ParamError, match="missing.asc' does not exist"):
        replay(tmp_path / "missing.asc", sender)


@pytest.mark.can
def test_bridge_node_reports_a_bus_error_and_recovers() -> None:
    """The node shell over BridgeRunner: commands flow, the interface goes away, /diagnostics says so, and the
    bus is re-opened after the back-off and commanding resumes (the sender thread keeps its schedule)."""
    import time as _time

    from moose_ros.nodes.can_bridge import CanBridge
    from moose_ros.runtime import DdsNode

    def wait(condition: Callable[[], bool], seconds: float = 3.0) -> bool:
        deadline = _time.monotonic() + seconds
        while _time.monotonic() < deadline:
            bridge.tick()
            if condition():
                return True
            _time.sleep(0.01)
        return False

    node = DdsNode("can_bridge", overrides={"can_interface": "virtual", "can_channel": "moose-test-buserror"})
    bridge = CanBridge(node)
    peer = open_bus("virtual", "moose-test-buserror")
    try:
        assert peer.recv(timeout=1.0) is not None  # command frames flow (the sender thread)
        bridge.runner.link.bus.shutdown()  # the interface goes away under the bridge (bus-off / unplugged adapter)
        assert wait(lambda: bridge.level == 2 and "bus error" in bridge.message)
        assert wait(lambda: bridge.level != 2)  # re-opened after the back-off
        while peer.recv(timeout=0.0) is not None:
            pass
        assert peer.recv(timeout=1.0) is not None  # commanding again
    finally:
        peer.shutdown()
        bridge.close()
        node.shutdown()
