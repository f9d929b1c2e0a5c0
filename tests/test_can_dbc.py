"""config/kanon.dbc against the brief and the vehicle limits; the codec's CRC and counters; the bus-load bound."""
from __future__ import annotations

import can
import cantools
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from moose.canbus.bridge import LIMIT_SIGNALS, BridgeCore, check_limits_encodable
from moose.canbus.busload import frame_loads, worst_case_bus_load, worst_case_frame_bits
from moose.canbus.codec import (
    PROTECTED,
    Codec,
    command_checksum,
    crc8_j1850,
    load_database,
)
from moose.canbus.safety import HARD_LIMIT, GuardParams
from moose.params import VEHICLE_LIMITS, ParamError, VehicleParams
from moose.resources import DBC_FILE

DB = load_database()
VEHICLE = VehicleParams()

CYCLE_MS = {"CMD_STEER": 10, "CMD_TORQUE": 10, "EPS_STATUS": 10, "WHEEL_SPEEDS": 10, "IMU": 10,
            "GPS_POSITION": 1000, "GPS_VELOCITY": 1000, "BRIDGE_HEARTBEAT": 100, "BRIDGE_STATUS": 100}
"""The brief's cycle times."""

MUST_COVER = {  # signal: the magnitude it must represent (the vehicle's hard limits, sensor ranges of the brief)
    ("CMD_STEER", "SteerAngleCmd"): VEHICLE_LIMITS.delta_max,
    ("CMD_STEER", "SteerRateCmd"): VEHICLE_LIMITS.delta_rate_max,
    ("CMD_TORQUE", "TorqueRL"): VEHICLE_LIMITS.T_max, ("CMD_TORQUE", "TorqueRR"): VEHICLE_LIMITS.T_max,
    ("EPS_STATUS", "SteerAngle"): VEHICLE_LIMITS.delta_max,
    ("WHEEL_SPEEDS", "OmegaRL"): 20.0 / VEHICLE.r, ("WHEEL_SPEEDS", "OmegaRR"): 20.0 / VEHICLE.r,
    ("IMU", "YawRate"): 2.0, ("IMU", "AccelX"): 20.0, ("IMU", "AccelY"): 20.0,
    ("GPS_VELOCITY", "VelX"): 20.0, ("GPS_VELOCITY", "VelY"): 20.0,
    ("GPS_POSITION", "PosX"): 1000.0, ("GPS_POSITION", "PosY"): 1000.0,
}


def test_frame_table_matches_the_brief() -> None:
    assert DB.dbc.attributes["Baudrate"].value == 500_000
    assert {m.name: m.cycle_time for m in DB.messages} == CYCLE_MS
    ids = [m.frame_id for m in DB.messages]
    assert len(set(ids)) == len(ids) and all(i <= 0x7FF and not m.is_extended_frame for i, m in zip(ids, DB.messages))
    # commands outrank sensors, sensors outrank the bridge's own status (lower id wins arbitration)
    assert max(DB.get_message_by_name(n).frame_id for n in PROTECTED) < DB.get_message_by_name("EPS_STATUS").frame_id
    for message in DB.messages:
        if message.name in PROTECTED:
            names = {s.name: s for s in message.signals}
            assert names["Counter"].length == 4 and names["Checksum"].length == 8 and names["Checksum"].start == 56
    for (frame, signal), magnitude in MUST_COVER.items():
        s = DB.get_message_by_name(frame).get_signal_by_name(signal)
        assert s.minimum <= -magnitude and s.maximum >= magnitude, (frame, signal)
        raw_span = 2 ** (s.length - 1) if s.is_signed else 2 ** s.length
        assert s.maximum / s.scale <= raw_span, (frame, signal)  # the range fits the bits
    for signal in ("PosX", "PosY"):
        assert DB.get_message_by_name("GPS_POSITION").get_signal_by_name(signal).scale <= 0.01
    fix_age = DB.get_message_by_name("GPS_VELOCITY").get_signal_by_name("FixAge")
    assert fix_age.unit == "s" and fix_age.maximum >= 1.0
    status = {s.name for s in DB.get_message_by_name("BRIDGE_STATUS").signals}
    assert {"CommandTimeout", "LimitClamp", "BusError", "BadCounter", "BadChecksum", "BadFrame", "TxLate",
            "RxOverflow"} <= status


def test_every_hard_limit_of_the_vehicle_is_encodable_in_the_command_frames() -> None:
    hard = GuardParams()  # the defaults are the hard limits: the loosest configuration that validates
    assert {getattr(hard, name) for name in HARD_LIMIT} == {getattr(VEHICLE_LIMITS, f) for f in HARD_LIMIT.values()}
    check_limits_encodable(DB, hard)
    rx = Codec(DB)
    tx = Codec(DB)
    for sign in (-1.0, 1.0):
        for (frame, signal), limit_name in LIMIT_SIGNALS.items():
            values = {s.name: 0.0 for s in DB.get_message_by_name(frame).signals
                      if s.name not in ("Counter", "Checksum")}
            values[signal] = sign * getattr(hard, limit_name)
            decoded = rx.decode(tx.encode(frame, values))
            assert decoded is not None and decoded[1][signal] == pytest.approx(values[signal], abs=1e-9)


@pytest.mark.parametrize("signal, text, limit", [
    ("SteerAngleCmd", "(0.0001,0) [-0.2|0.2]", "delta_max = 0.3"),
    ("SteerRateCmd", "(0.001,0) [-0.5|0.5]", "steer_rate_limit = 1.0"),
    ("TorqueRL", "(0.01,0) [-150|150]", "torque_max = 200.0"),
])
def test_a_dbc_that_cannot_carry_a_limit_is_refused_at_start_up(signal: str, text: str, limit: str) -> None:
    original = DBC_FILE.read_text()
    line = next(row for row in original.splitlines() if f"SG_ {signal} :" in row)
    narrowed = line[:line.index("(")] + text + " " + line[line.index('"'):]
    db = cantools.database.load_string(original.replace(line, narrowed), "dbc")
    with pytest.raises(ParamError, match=rf"{limit} is invalid: CMD_\w+\.{signal} \(range .*\) cannot carry"):
        BridgeCore(GuardParams(), Codec(db, node="BRIDGE"))


def test_every_signal_round_trips_at_its_limits_and_zero() -> None:
    for message in DB.messages:
        for pick in (lambda s: s.minimum, lambda s: s.maximum, lambda s: 0.0):
            values = {s.name: pick(s) for s in message.signals if s.name not in ("Counter", "Checksum")}
            frame = Codec(DB).encode(message.name, values)
            assert len(frame.data) == message.length and not frame.is_extended_id
            decoded = Codec(DB).decode(frame)
            assert decoded is not None and decoded[0] == message.name
            for name, value in values.items():
                scale = message.get_signal_by_name(name).scale
                assert decoded[1][name] == pytest.approx(value, abs=scale / 2 + 1e-12), (message.name, name)


@settings(max_examples=150, deadline=None)
@given(st.sampled_from([m.name for m in DB.messages]), st.data())
def test_random_values_round_trip_within_half_a_step(name: str, data: st.DataObject) -> None:
    message = DB.get_message_by_name(name)
    values = {s.name: data.draw(st.floats(float(s.minimum), float(s.maximum)), label=s.name)
              for s in message.signals if s.name not in ("Counter", "Checksum")}
    decoded = Codec(DB).decode(Codec(DB).encode(name, values))
    assert decoded is not None
    for key, value in values.items():
        assert decoded[1][key] == pytest.approx(value, abs=message.get_signal_by_name(key).scale / 2 + 1e-9)


def test_out_of_range_values_are_refused_or_saturated() -> None:
    codec = Codec(DB)
    with pytest.raises(cantools.database.EncodeError):
        codec.encode("CMD_TORQUE", {"TorqueRL": 1e4, "TorqueRR": 0.0})
    with pytest.raises(ValueError, match="IMU.AccelX = nan"):
        codec.encode("IMU", {"YawRate": 0.0, "AccelX": float("nan"), "AccelY": 0.0}, saturate=True)
    decoded = Codec(DB).decode(codec.encode("IMU", {"YawRate": -99.0, "AccelX": 99.0, "AccelY": 0.0}, saturate=True))
    assert decoded is not None
    assert decoded[1]["YawRate"] == pytest.approx(-3.0) and decoded[1]["AccelX"] == pytest.approx(30.0)


def test_crc8_sae_j1850_check_values() -> None:
    # AUTOSAR SWS CRC Library, 8-bit SAE J1850 check values
    vectors = {"00000000": 0x59, "F20183": 0x37, "0FAA0055": 0x79, "00FF5511": 0xB8,
               "332255AABBCCDDEEFF": 0xCB, "926B55": 0x8C, "FFFFFFFF": 0x74}
    for data, crc in vectors.items():
        assert crc8_j1850(bytes.fromhex(data)) == crc, data
    assert crc8_j1850(b"123456789") == 0x4B


def test_checksum_detects_every_single_and_double_bit_error_and_a_wrong_identifier() -> None:
    frame = Codec(DB).encode("CMD_STEER", {"SteerAngleCmd": 0.1234, "SteerRateCmd": -0.5})
    data = bytes(frame.data)
    assert data[7] == command_checksum(0x100, data)
    flips = [1 << i for i in range(64)] + [(1 << i) | (1 << j) for i in range(64) for j in range(i + 1, 64)]
    for mask in flips:
        corrupted = (int.from_bytes(data, "little") ^ mask).to_bytes(8, "little")
        assert Codec(DB).decode(can.Message(arbitration_id=0x100, data=corrupted, is_extended_id=False)) is None
    # the same payload under the other command's identifier (same layout) is refused
    relabelled = can.Message(arbitration_id=0x101, data=data, is_extended_id=False)
    rx = Codec(DB)
    assert rx.decode(relabelled) is None and rx.stats.bad_checksum == 1


def test_counters_commands_strict_sensors_tolerate_loss_but_not_repetition() -> None:
    tx, rx = Codec(DB), Codec(DB)
    commands = [tx.encode("CMD_TORQUE", {"TorqueRL": 1.0, "TorqueRR": 2.0}) for _ in range(40)]
    assert all(rx.decode(f) is not None for f in commands[:20])  # wraps 15 → 0
    assert rx.decode(commands[19]) is None  # a repeated frame
    assert rx.decode(commands[21]) is None  # a jump: dropped, counter re-synchronised
    assert rx.decode(commands[22]) is not None
    assert rx.stats.bad_counter == 2
    sensors = [tx.encode("IMU", {"YawRate": 0.0, "AccelX": 0.0, "AccelY": 0.0}) for _ in range(10)]
    assert rx.decode(sensors[0]) is not None
    assert rx.decode(sensors[3]) is not None and rx.stats.lost == 2  # two frames lost, this one is valid
    assert rx.decode(sensors[3]) is None  # stale repetition
    assert rx.stats.bad_counter == 3


def test_a_signal_outside_its_range_is_dropped() -> None:
    message = DB.get_message_by_name("EPS_STATUS")
    raw = message.encode({"SteerAngle": 0.0, "Counter": 0}, scaling=False)
    data = bytearray(raw)
    data[0:2] = (20000).to_bytes(2, "little", signed=True)  # 2 rad: representable, outside [-0.5, 0.5]
    rx = Codec(DB)
    assert rx.decode(can.Message(arbitration_id=0x200, data=bytes(data), is_extended_id=False)) is None
    assert rx.stats.out_of_range == 1


def test_worst_case_frame_bits_follow_davis_et_al() -> None:
    # 11-bit identifier: 47 + 8·DLC bits, 34 + 8·DLC of them stuffable, one stuff bit per 4 after the first
    assert [worst_case_frame_bits(n) for n in range(9)] == [55, 65, 75, 85, 95, 105, 115, 125, 135]


def test_bus_load_below_half_at_500_kbps() -> None:
    loads = frame_loads(DB, 500_000)
    expected = sum(worst_case_frame_bits(m.length) * 1000 / CYCLE_MS[m.name] for m in DB.messages) / 500_000
    assert worst_case_bus_load(DB, 500_000) == pytest.approx(expected)
    assert loads["CMD_STEER"] == pytest.approx(135 * 100 / 500_000)  # 2.7 %
    assert 0.10 < worst_case_bus_load(DB, 500_000) < 0.5


def test_bus_load_refuses_frames_without_a_cycle_time() -> None:
    db = cantools.database.load_string('VERSION ""\nBS_:\nBU_: A\nBO_ 1 F: 8 A\n SG_ S : 0|8@1+ (1,0) [0|255] "" A\n',
                                       database_format="dbc")
    with pytest.raises(ValueError, match="F has no GenMsgCycleTime"):
        worst_case_bus_load(db, 500_000)
