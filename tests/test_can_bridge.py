"""Bridge and ECU cores under random and malformed traffic; bus health, status frames and the I/O shell."""
from __future__ import annotations

import math

import can
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from can_hostile import clock_step, hostile_guard_params
from can_hostile import wild as wild_value
from moose.canbus.bridge import BridgeCore
from moose.canbus.bus import BusLink, open_bus
from moose.canbus.codec import PROTECTED, Codec, command_checksum, load_database
from moose.canbus.ecu import VehicleEcu
from moose.canbus.health import BusHealth, BusState, HealthParams, error_frame_state
from moose.canbus.safety import Command, GuardParams, GuardState
from moose.params import ParamError
from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

DB = load_database()
GUARD = GuardParams()
COMMAND_IDS = {DB.get_message_by_name(n).frame_id for n in PROTECTED}


def is_valid_command_by_chance(frame: can.Message) -> bool:
    data = bytes(frame.data)
    return (frame.arbitration_id in COMMAND_IDS and len(data) == 8
            and command_checksum(frame.arbitration_id, data) == data[7])


garbage = st.builds(
    lambda i, data, ext, err, rtr: can.Message(arbitration_id=i, data=data, is_extended_id=ext, is_error_frame=err,
                                              is_remote_frame=rtr and not err),
    st.one_of(st.sampled_from([m.frame_id for m in DB.messages]), st.integers(0, 0x7FF), st.integers(0, 0x1FFFFFFF)),
    st.binary(min_size=0, max_size=8), st.booleans(), st.booleans(), st.booleans(),
)


def tampered_frame(name: str, bit: int, flip: bool) -> can.Message:
    """A frame of the DBC, encoded afresh (counter 0: a replay); command frames always with one bit flipped."""
    message = DB.get_message_by_name(name)
    frame = Codec(DB).encode(name, {s.name: 0.0 for s in message.signals if s.name not in ("Counter", "Checksum")})
    if flip or name in PROTECTED:
        data = bytearray(frame.data)
        data[(bit // 8) % len(data)] ^= 1 << (bit % 8)
        frame = can.Message(arbitration_id=frame.arbitration_id, data=bytes(data), is_extended_id=False)
    return frame


tampered = st.builds(tampered_frame, st.sampled_from([m.name for m in DB.messages]), st.integers(0, 63), st.booleans())
garbage = st.one_of(garbage, tampered)
wild = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.floats(-1e4, 1e4))


def decoded_commands(frames: list[can.Message]) -> dict[str, dict[str, float]]:
    out = {}
    for frame in frames:
        decoded = Codec(DB).decode(frame)
        assert decoded is not None
        out[decoded[0]] = decoded[1]
    return out


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.lists(garbage, max_size=4), st.one_of(st.none(), st.tuples(wild, wild, wild, wild))),
                min_size=1, max_size=40))
def test_random_and_malformed_frames_never_crash_the_bridge_nor_reach_the_ecu(steps: list) -> None:
    bridge, ecu = BridgeCore(GUARD), VehicleEcu()
    sent: dict[str, dict[str, float]] = {}
    for k, (junk, command) in enumerate(steps):
        t = 0.01 * k
        if command is not None:
            bridge.on_command(Command(*command), t)
        for frame in junk:
            sample = bridge.on_frame(frame, t)
            assert sample is None or isinstance(sample, (ImuSample, WheelSpeedSample, EpsSample, GpsSample))
        frames = bridge.tick(t)
        values = decoded_commands(frames)
        steer, torque = values["CMD_STEER"], values["CMD_TORQUE"]
        assert abs(steer["SteerAngleCmd"]) <= GUARD.delta_max + 1e-4
        assert abs(steer["SteerRateCmd"]) <= GUARD.steer_rate_limit + 1e-3
        assert abs(torque["TorqueRL"]) <= GUARD.torque_max + 0.01 and abs(torque["TorqueRR"]) <= GUARD.torque_max + 0.01
        if sent:  # rate limits between consecutive frames (one LSB of quantisation each side)
            assert (abs(steer["SteerAngleCmd"] - sent["CMD_STEER"]["SteerAngleCmd"])
                    <= GUARD.steer_rate_limit * 0.01 + 2e-4)
            for wheel in ("TorqueRL", "TorqueRR"):
                assert abs(torque[wheel] - sent["CMD_TORQUE"][wheel]) <= GUARD.torque_rate_limit * 0.01 + 0.02
        sent.update(values)
        # the ECU receives the bridge's frames with the junk in between: only the bridge's are applied
        for frame in junk:
            assume(not is_valid_command_by_chance(frame))
            ecu.on_frame(frame, t)
        for frame in frames:
            ecu.on_frame(frame, t)
        u = ecu.plant_input(t)
        assert u[0] == sent["CMD_STEER"]["SteerRateCmd"]
        assert (u[1], u[2]) == (sent["CMD_TORQUE"]["TorqueRL"], sent["CMD_TORQUE"]["TorqueRR"])
    assert ecu.codec.stats.bad_counter == 0  # the bridge's own sequence was never disturbed


def test_valid_frames_with_a_wrong_counter_or_checksum_are_counted_and_reported() -> None:
    car, bridge = Codec(DB), BridgeCore(GUARD)
    eps = [car.encode("EPS_STATUS", {"SteerAngle": 0.01 * k}) for k in range(4)]
    assert isinstance(bridge.on_frame(eps[0], 0.0), EpsSample)
    assert bridge.on_frame(eps[0], 0.01) is None  # repeated counter: stale
    gps = car.encode("GPS_POSITION", {"PosX": 1.0, "PosY": 2.0})
    assert bridge.on_frame(can.Message(arbitration_id=gps.arbitration_id, data=bytes(gps.data)[:7],
                                       is_extended_id=False), 0.02) is None  # DLC 7
    ecu = VehicleEcu()
    bridge_tx = Codec(DB)
    cmd = bytearray(bridge_tx.encode("CMD_TORQUE", {"TorqueRL": 5.0, "TorqueRR": 5.0}).data)
    cmd[7] ^= 0xFF
    ecu.on_frame(can.Message(arbitration_id=0x101, data=bytes(cmd), is_extended_id=False), 0.0)
    assert ecu.codec.stats.bad_checksum == 1 and list(ecu.plant_input(0.0)) == [0.0, 0.0, 0.0]
    status = {}
    for frame in bridge.tick(0.1):
        decoded = Codec(DB).decode(frame)
        assert decoded is not None
        status[decoded[0]] = decoded[1]
    s = status["BRIDGE_STATUS"]
    assert (s["BadCounter"], s["BadFrame"], s["BadChecksum"], s["CommandTimeout"]) == (1, 1, 0, 1)
    assert status["BRIDGE_HEARTBEAT"]["State"] == 1  # safe state: no command yet


def test_gps_position_and_velocity_are_paired_by_their_counter() -> None:
    car, bridge = VehicleEcu(), BridgeCore(GUARD)
    fixes = [GpsSample(1.2 + k, 1.0 + k, 10.0 * k, -1.0, 5.0, 0.25) for k in range(3)]
    frames = [car.encode(f, f.t) for f in fixes]
    got = [bridge.on_frame(frames[0][0], 1.2), bridge.on_frame(frames[0][1], 1.2)]
    assert got[0] is None and isinstance(got[1], GpsSample)
    assert (got[1].x, got[1].y, got[1].vX, got[1].vY) == pytest.approx((0.0, -1.0, 5.0, 0.25), abs=1e-3)
    assert got[1].t_measured == pytest.approx(1.0, abs=1e-3)
    # fix 1 loses its velocity frame: its position must not be paired with fix 2's velocity
    assert bridge.on_frame(frames[1][0], 2.2) is None
    assert bridge.on_frame(frames[2][1], 3.2) is None
    assert bridge.on_frame(frames[2][0], 3.2) is None  # position after velocity: the pair is incomplete
    assert bridge.codec.stats.lost >= 1


def error_frame(err_class: int, data: bytes = b"\x00" * 8) -> can.Message:
    return can.Message(arbitration_id=err_class, data=data, is_error_frame=True, is_extended_id=False)


def test_error_frames_set_the_bus_state_like_linux_reports_it() -> None:
    assert error_frame_state(error_frame(0x040)) == BusState.BUS_OFF
    assert error_frame_state(error_frame(0x004, bytes([0, 0x20, 0, 0, 0, 0, 0, 0]))) == BusState.ERROR_PASSIVE
    assert error_frame_state(error_frame(0x004, bytes([0, 0x04, 0, 0, 0, 0, 0, 0]))) == BusState.ERROR_WARNING
    assert error_frame_state(error_frame(0x004, bytes([0, 0x40, 0, 0, 0, 0, 0, 0]))) == BusState.ERROR_ACTIVE
    assert error_frame_state(error_frame(0x100)) == BusState.ERROR_ACTIVE
    assert error_frame_state(error_frame(0x008)) is None  # a protocol error alone changes no state
    bridge = BridgeCore(GUARD)
    bridge.on_command(Command(0.0, 0.0, 10.0, 10.0), 0.0)
    bridge.on_frame(error_frame(0x040), 0.05)
    assert bridge.bus_error and bridge.heartbeat_state() == "fault"
    status = {Codec(DB).decode(f)[0]: Codec(DB).decode(f)[1] for f in bridge.tick(0.05)}  # type: ignore[index]
    assert status["BRIDGE_STATUS"]["BusState"] == 3 and status["BRIDGE_STATUS"]["BusError"] == 1
    assert status["BRIDGE_STATUS"]["ErrorFrames"] == 1 and status["BRIDGE_HEARTBEAT"]["State"] == 2
    bridge.on_frame(error_frame(0x100), 0.1)  # controller restarted
    assert not bridge.bus_error and bridge.heartbeat_state() == "commanding"
    assert bridge.health.bus_error is False  # the latch was reported once


def test_backoff_doubles_up_to_its_cap_and_resets_after_healthy_traffic() -> None:
    health = BusHealth(HealthParams(backoff_initial=0.1, backoff_max=0.5, backoff_reset=1.0))
    waits, t = [], 0.0
    for _ in range(5):
        health.on_io_failure("unplugged", t)
        assert not health.reopen_due(t) and health.fault
        waits.append(round(health.reopen_at - t, 9))  # type: ignore[operator]
        t = health.reopen_at  # type: ignore[assignment]
        assert health.reopen_due(t)
        health.on_open(t)
    assert waits == [0.1, 0.2, 0.4, 0.5, 0.5] and health.reopens == 5
    for k in range(12):
        health.on_traffic(t + 0.1 * k)
    health.on_io_failure("again", t + 2.0)
    assert health.reopen_at == pytest.approx(t + 2.1)
    with pytest.raises(ParamError, match="backoff_max = 0.05"):
        HealthParams(backoff_initial=0.1, backoff_max=0.05)


@pytest.mark.can
def test_bus_link_reopens_a_failed_bus_after_the_backoff() -> None:
    interface = ["socketcan"]  # no SocketCAN in this kernel: opening really fails
    health = BusHealth(HealthParams(backoff_initial=0.1, backoff_max=1.0))
    link = BusLink(lambda: open_bus(interface[0], "moose-test-link"), health)
    peer = open_bus("virtual", "moose-test-link")
    frame = Codec(DB).encode("BRIDGE_HEARTBEAT", {"Alive": 1, "State": 0})
    try:
        assert not link.send([frame], 0.0)
        assert health.state == BusState.IO_FAILURE and "open failed" in health.last_error
        interface[0] = "virtual"
        assert not link.send([frame], 0.05) and link.bus is None  # still backing off
        assert link.send([frame], 0.1) and health.state == BusState.ERROR_ACTIVE
        assert peer.recv(timeout=1.0) is not None
        link.bus.shutdown()  # type: ignore[union-attr]  # the interface goes away under the link
        assert not link.send([frame], 0.2) and link.bus is None and "send failed" in health.last_error
        assert link.receive(0.25, 10) == ([], False) and link.bus is None  # back-off 0.2 s after the second failure
        peer.send(Codec(DB).encode("EPS_STATUS", {"SteerAngle": 0.1}))
        assert link.receive(0.4, 10) == ([], False) and link.bus is not None  # re-opened (frames sent before are gone)
        peer.send(Codec(DB).encode("EPS_STATUS", {"SteerAngle": 0.1}))
        frames, full = link.receive(0.41, 10)
        assert len(frames) == 1 and not full and health.reopens == 2
    finally:
        link.close()
        peer.shutdown()


def test_ecu_saturates_sensors_and_skips_non_finite_samples() -> None:
    ecu = VehicleEcu()
    frames = ecu.frames([ImuSample(0.0, 45.0, -45.0, 3.5), EpsSample(0.0, math.nan)], 0.0)
    assert len(frames) == 1 and ecu.unsendable == 1
    decoded = Codec(DB).decode(frames[0])
    assert decoded is not None
    assert decoded[1]["AccelX"] == pytest.approx(30.0) and decoded[1]["YawRate"] == pytest.approx(3.0)
    with pytest.raises(TypeError, match="has no frame"):
        ecu.encode(object(), 0.0)
    with pytest.raises(ValueError, match="timeout"):
        VehicleEcu(timeout=0.0)


@pytest.mark.can
def test_bus_link_logs_every_frame_in_candump_format(tmp_path) -> None:
    path = tmp_path / "traffic.log"
    peer = open_bus("virtual", "moose-test-log")
    codec = Codec(DB)
    sent = [codec.encode("CMD_TORQUE", {"TorqueRL": float(k), "TorqueRR": -float(k)}, 0.01 * k) for k in range(5)]
    with can.Logger(str(path)) as logger:
        link = BusLink(lambda: open_bus("virtual", "moose-test-log"), BusHealth(), logger=logger)
        try:
            assert link.send(sent, 0.0)
            peer.send(codec.encode("EPS_STATUS", {"SteerAngle": -0.05}, 0.2))
            assert len(link.receive(0.2, 10)[0]) == 1
        finally:
            link.close()
            peer.shutdown()
    lines = path.read_text().splitlines()
    assert len(lines) == 6 and lines[0].split()[2].startswith("101#")  # candump: (time) channel id#data
    replayed = list(can.LogReader(str(path)))
    rx = Codec(DB)
    decoded = [rx.decode(frame) for frame in replayed]
    assert [d[1]["TorqueRL"] for d in decoded[:5]] == pytest.approx([0.0, 1.0, 2.0, 3.0, 4.0])  # type: ignore[index]
    assert decoded[5] is not None and decoded[5][0] == "EPS_STATUS"


def test_a_node_does_not_decode_frames_it_transmits_itself() -> None:
    ecu, bridge = VehicleEcu(), BridgeCore(GUARD)
    status = Codec(DB).encode("EPS_STATUS", {"SteerAngle": 0.1})
    for _ in range(2):  # the same counter twice would be a sequence error if the ECU decoded its own identifier
        ecu.on_frame(status, 0.0)
    assert ecu.codec.stats.own_id == 2 and ecu.codec.stats.bad_counter == 0
    assert bridge.on_frame(status, 0.0) is not None  # the bridge receives it
    heartbeat = Codec(DB).encode("BRIDGE_HEARTBEAT", {s.name: 0.0
                                                      for s in DB.get_message_by_name("BRIDGE_HEARTBEAT").signals
                                                      if s.name != "Counter"})
    assert bridge.on_frame(heartbeat, 0.0) is None and bridge.codec.stats.own_id == 1


# -- clock steps, floods and hostile configurations through the bridge core ---------------------------

LSB = {"SteerAngleCmd": 1e-4, "SteerRateCmd": 1e-3, "TorqueRL": 0.01, "TorqueRR": 0.01}


def decode_all(frames: list[can.Message], rx: Codec) -> dict[str, dict[str, float]]:
    """The bridge's frames through an independent codec: each must be valid (CRC, counter, ranges)."""
    out = {}
    for frame in frames:
        decoded = rx.decode(frame)
        assert decoded is not None, (frame, rx.stats)
        out[decoded[0]] = decoded[1]
    return out


@settings(max_examples=150, deadline=None)
@given(hostile_guard_params(),
       st.lists(st.tuples(clock_step, st.lists(garbage, max_size=30),
                          st.one_of(st.none(), st.tuples(wild_value, wild_value, wild_value, wild_value)),
                        st.booleans()),
                min_size=1, max_size=60))
def test_nothing_received_commanded_or_configured_raises_out_of_the_tick(params: GuardParams, steps: list) -> None:
    bridge, rx = BridgeCore(params), Codec(DB)
    period = bridge.command_period
    t, previous, ticks_since_command = 0.0, None, None
    for step, junk, command, overflow in steps:
        t_call = t + step
        if math.isfinite(t_call):
            t = t_call
        if command is not None:
            bridge.on_command(Command(*command), t_call)
            ticks_since_command = 0 if Command(*command).valid else None
        for frame in junk:  # a flood of random, malformed and tampered frames between two ticks
            bridge.on_frame(frame, t_call)
        if overflow:
            bridge.note_rx_overflow()
        frames = bridge.tick(t_call)
        values = decode_all(frames, rx)
        if "CMD_STEER" not in values:
            continue
        if ticks_since_command is not None:
            ticks_since_command += 1
        steer, torque = values["CMD_STEER"], values["CMD_TORQUE"]
        limits = {"SteerAngleCmd": params.delta_max, "SteerRateCmd": params.steer_rate_limit,
                  "TorqueRL": params.torque_max, "TorqueRR": params.torque_max}
        now = {**steer, **torque}
        for name, limit in limits.items():
            assert abs(now[name]) <= limit + LSB[name], name
        if previous is not None:  # one command period's step at the limit rate, one LSB of rounding each side
            steps_ok = {"SteerAngleCmd": params.steer_rate_limit * period,
                        "TorqueRL": params.torque_rate_limit * period,
                        "TorqueRR": params.torque_rate_limit * period}
            for name, bound in steps_ok.items():
                assert abs(now[name] - previous[name]) <= bound + 2 * LSB[name], name
        previous = now
        if bridge.guard.state == GuardState.COMMANDING:  # the timeout, counted in command frames
            assert ticks_since_command is not None and (ticks_since_command - 1) * period <= params.timeout + 1e-9
        if "BRIDGE_HEARTBEAT" in values and values["BRIDGE_HEARTBEAT"]["State"] == 0:
            assert bridge.guard.state == GuardState.COMMANDING


def test_command_frames_keep_coming_after_the_clock_steps_back() -> None:
    bridge = BridgeCore(GUARD)
    for k in range(50):
        bridge.on_command(Command(0.1, 0.0, 50.0, 50.0))
        bridge.tick(round(100.0 + 0.01 * k, 9))
    sent = []
    for k in range(20):  # the caller's clock stepped back 5 s
        bridge.on_command(Command(0.1, 0.0, 50.0, 50.0))
        sent.append(sum(f.arbitration_id == 0x100 for f in bridge.tick(round(95.5 + 0.01 * k, 9))))
    assert sent == [1] * 20 and bridge.guard.state == GuardState.COMMANDING


def test_a_late_command_tick_makes_the_heartbeat_say_fault_and_sets_tx_late() -> None:
    bridge, rx = BridgeCore(GUARD), Codec(DB)
    status = []
    times = [round(0.01 * k, 9) for k in range(30)] + [0.49] + [round(0.5 + 0.01 * k, 9) for k in range(1, 30)]
    for t in times:  # commands all the time; the ticks stall from 0.29 s to 0.49 s
        bridge.on_command(Command(0.0, 0.0, 10.0, 10.0))
        values = decode_all(bridge.tick(t), rx)
        if "BRIDGE_HEARTBEAT" in values:
            status.append((t, values["BRIDGE_HEARTBEAT"]["State"], values["BRIDGE_STATUS"]["TxLate"]))
    assert status[1:3] == [(0.1, 0, 0), (0.2, 0, 0)]  # commanding
    assert (0.49, 2, 1) in status  # the first heartbeat after the stall: fault, TxLate
    assert status[-1][1:] == (0, 0) and bridge.late_commands == 1
    assert bridge.max_command_gap == pytest.approx(0.2)
    # late means: more than the timeout less one command period, so frames still land before the ECUs time out
    assert bridge.late_after == pytest.approx(GUARD.timeout - 0.01)
    bridge.on_command(Command(0.0, 0.0, 10.0, 10.0))
    bridge.tick(0.79 + 0.045)  # a 45 ms gap
    assert bridge.heartbeat_state() == "fault" and bridge.late_commands == 2


def test_command_frames_handed_to_the_bus_late_make_the_same_cycles_heartbeat_say_fault() -> None:
    bridge, rx = BridgeCore(GUARD), Codec(DB)
    for k in range(10):  # ticks and sends on time
        t = round(0.01 * k, 9)
        bridge.on_command(Command(0.0, 0.0, 10.0, 10.0))
        decode_all(bridge.command_frames(t), rx)
        bridge.note_sent(t + 0.001)
        decode_all(bridge.status_frames(t), rx)
    bridge.on_command(Command(0.0, 0.0, 10.0, 10.0))
    decode_all(bridge.command_frames(0.1), rx)  # the tick is on time ...
    bridge.note_sent(0.1 + 0.06)  # ... but the frames reach the bus 60 ms later
    values = decode_all(bridge.status_frames(0.1), rx)
    assert values["BRIDGE_HEARTBEAT"]["State"] == 2 and values["BRIDGE_STATUS"]["TxLate"] == 1


def test_a_receive_overflow_is_flagged_in_the_next_status_frame_only() -> None:
    bridge, rx = BridgeCore(GUARD), Codec(DB)
    flags = []
    for k in range(31):
        if k == 12:
            bridge.note_rx_overflow()
        values = decode_all(bridge.tick(round(0.01 * k, 9)), rx)
        if "BRIDGE_STATUS" in values:
            flags.append(values["BRIDGE_STATUS"]["RxOverflow"])
    assert flags == [0, 0, 1, 0] and bridge.rx_overflows == 1


def test_lost_commands_lead_the_frames_into_the_minimum_risk_maneuver() -> None:
    bridge, rx = BridgeCore(GUARD), Codec(DB)
    car = Codec(DB)
    frames_by_t = {}
    for k in range(120):
        t = round(0.01 * k, 9)
        if t <= 0.2:
            bridge.on_command(Command(0.1, 0.5, 150.0, 150.0), t)
        bridge.on_frame(car.encode("WHEEL_SPEEDS", {"OmegaRL": 20.0, "OmegaRR": 20.0}), t)
        frames_by_t[t] = decode_all(bridge.tick(t), rx)
    deadline = 0.2 + GUARD.timeout
    first = min(t for t in frames_by_t if t > deadline + 1e-9)
    assert first <= deadline + 0.01 + 1e-9 and bridge.guard.state == GuardState.MINIMUM_RISK
    steer = {t: v["CMD_STEER"] for t, v in frames_by_t.items()}
    torque = {t: v["CMD_TORQUE"]["TorqueRL"] for t, v in frames_by_t.items()}
    assert steer[first]["SteerRateCmd"] < 0.0 and steer[first]["SteerAngleCmd"] < steer[0.2]["SteerAngleCmd"]
    assert all(steer[t]["SteerAngleCmd"] == pytest.approx(0.0, abs=1e-4) for t in steer if t >= first + 0.1)
    assert torque[first] == pytest.approx(130.0) and min(torque.values()) == pytest.approx(-GUARD.brake_torque)
    assert frames_by_t[0.3]["BRIDGE_HEARTBEAT"]["State"] == 1
    assert frames_by_t[0.3]["BRIDGE_STATUS"]["CommandTimeout"] == 1



def test_each_command_field_travels_in_its_own_signal_to_its_own_actuator() -> None:
    """Four different values, so a swap of any two (rear left/right, angle/rate) shows: the frames read back by
    cantools with the DBC (not by the bridge's codec), and the ECU's plant input U = [δ̇_cmd, T_rl, T_rr]."""
    bridge, ecu = BridgeCore(GUARD), VehicleEcu()
    command = Command(steering_angle=0.012, steering_rate=0.25, torque_rl=13.0, torque_rr=-7.0)
    for k in range(5):  # inside the rate limits from rest: reached in the first command period
        t = round(0.01 * k, 9)
        bridge.on_command(command, t)
        frames = bridge.command_frames(t)
        for frame in frames:
            ecu.on_frame(frame, t)
    wire = {DB.get_message_by_frame_id(f.arbitration_id).name: DB.decode_message(f.arbitration_id, f.data)
            for f in frames}
    assert wire["CMD_STEER"]["SteerAngleCmd"] == pytest.approx(0.012, abs=1e-4)
    assert wire["CMD_STEER"]["SteerRateCmd"] == pytest.approx(0.25, abs=1e-3)
    assert wire["CMD_TORQUE"]["TorqueRL"] == pytest.approx(13.0, abs=0.01)
    assert wire["CMD_TORQUE"]["TorqueRR"] == pytest.approx(-7.0, abs=0.01)
    assert list(ecu.plant_input(0.04)) == pytest.approx([0.25, 13.0, -7.0], abs=0.01)
