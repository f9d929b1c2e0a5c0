"""The codec's checksum, counters and drop reasons, each against a reference the codec does not share: the CRC by
polynomial division over GF(2), payloads packed by hand (little-endian, as the DBC says), counts of every reason."""
from __future__ import annotations

import struct

import can
import cantools
import pytest

from moose.canbus.codec import CHECKSUM_BYTE, PROTECTED, Codec, FrameStats, command_checksum, crc8_j1850, load_database

DB = load_database()


def crc8_by_division(data: bytes) -> int:
    """CRC-8 SAE J1850 as polynomial division: the message (its first byte XORed with the initial 0xFF) times x^8,
    modulo x^8 + x^4 + x^3 + x^2 + 1 (0x11D), XORed with 0xFF."""
    if not data:
        return 0xFF ^ 0xFF  # nothing divided: the initial value, XORed
    bits = int.from_bytes(bytes([data[0] ^ 0xFF]) + data[1:], "big") << 8
    poly = 0x11D
    for shift in range(bits.bit_length() - 9, -1, -1):
        if bits >> (shift + 8) & 1:
            bits ^= poly << shift
    return (bits & 0xFF) ^ 0xFF


@pytest.mark.parametrize("data", [b"123456789", b"\x00", b"\xff" * 9, bytes(range(1, 10)), b"\x01\x07\x80\x00\x12"])
def test_crc_equals_polynomial_division(data: bytes) -> None:
    assert crc8_j1850(data) == crc8_by_division(data)


@pytest.mark.parametrize("frame_id", [0x100, 0x101, 0x7FF, 0x123, 0x0FF, 0x000, 0x456])
def test_the_checksum_covers_both_bytes_of_the_identifier_low_byte_first(frame_id: int) -> None:
    payload = bytes([0x10, 0x27, 0xF4, 0x01, 0x00, 0x00, 0x05, 0xAA])  # byte 7 (the checksum's place) is not covered
    expected = crc8_by_division(bytes([frame_id & 0xFF, frame_id >> 8]) + payload[:7])
    assert command_checksum(frame_id, payload) == expected
    assert command_checksum(frame_id, payload[:7] + b"\x00") == expected


def test_an_encoded_command_frame_is_what_the_dbc_and_the_checksum_say() -> None:
    codec = Codec()
    frame = codec.encode("CMD_TORQUE", {"TorqueRL": 12.34, "TorqueRR": -5.0}, timestamp=2.5)
    rl, rr = struct.unpack_from("<hh", frame.data)  # little-endian signed 16 bit, 0.01 N m per bit
    assert (rl, rr) == (1234, -500)
    assert frame.data[6] & 0x0F == 0  # the first frame's counter
    assert frame.data[CHECKSUM_BYTE] == crc8_by_division(bytes([0x01, 0x01]) + bytes(frame.data[:7]))
    assert frame.arbitration_id == 0x101 and frame.is_extended_id is False and frame.dlc == 8
    imu = {"YawRate": 0.0, "AccelX": 0.0, "AccelY": 0.0}
    assert frame.timestamp == 2.5 and Codec().encode("IMU", imu).timestamp == 0.0
    counters = [codec.encode("CMD_TORQUE", {"TorqueRL": 0.0, "TorqueRR": 0.0}).data[6] & 0x0F for _ in range(16)]
    assert counters == list(range(1, 16)) + [0]  # one counter per frame name, wrapping at 16
    steer = {"SteerAngleCmd": 0.0, "SteerRateCmd": 0.0}
    assert Codec().encode("CMD_STEER", steer).data[6] & 0x0F == 0 and Codec().encode("IMU", imu).data[6] & 0x0F == 0


def test_values_outside_the_range_raise_unless_saturated() -> None:
    codec = Codec()
    with pytest.raises(cantools.database.EncodeError):
        codec.encode("EPS_STATUS", {"SteerAngle": 0.6})
    frame = codec.encode("EPS_STATUS", {"SteerAngle": 0.6}, saturate=True)
    assert struct.unpack_from("<h", frame.data)[0] == 5000  # clipped to the DBC's 0.5 rad
    frame = codec.encode("EPS_STATUS", {"SteerAngle": -7.0}, saturate=True)
    assert struct.unpack_from("<h", frame.data)[0] == -5000
    with pytest.raises(ValueError, match=r"^EPS_STATUS.SteerAngle = nan is invalid: expected a finite number$"):
        codec.encode("EPS_STATUS", {"SteerAngle": float("nan")}, saturate=True)


def eps_frame(raw_angle: int, counter: int) -> can.Message:
    """EPS_STATUS packed by hand: SteerAngle raw (signed 16 bit, 0.1 mrad), counter in the low nibble of byte 2."""
    data = struct.pack("<hB", raw_angle, counter) + b"\x00"
    return can.Message(arbitration_id=0x200, data=data, is_extended_id=False)


def steer_frame(raw_angle: int, counter: int) -> can.Message:
    """CMD_STEER packed by hand with its counter and checksum."""
    payload = struct.pack("<hhxxB", raw_angle, 0, counter)
    return can.Message(arbitration_id=0x100, data=payload + bytes([crc8_by_division(b"\x00\x01" + payload)]),
                       is_extended_id=False)


def test_signals_at_the_range_limits_are_accepted_one_step_beyond_is_dropped() -> None:
    codec = Codec()
    accepted = [codec.decode(eps_frame(raw, k)) for k, raw in enumerate((5000, -5000))]
    assert [v[1]["SteerAngle"] for v in accepted] == pytest.approx([0.5, -0.5])
    assert codec.decode(eps_frame(5001, 2)) is None and codec.decode(eps_frame(-5001, 3)) is None
    assert codec.stats.out_of_range == 2
    vehicle = Codec(node="VEHICLE")  # a command frame packed by hand is a valid one inside the range
    assert vehicle.decode(steer_frame(4000, 0))[1]["SteerAngleCmd"] == pytest.approx(0.4)
    assert vehicle.decode(steer_frame(5001, 1)) is None and vehicle.stats.out_of_range == 1


def test_every_drop_reason_is_counted_once_per_frame() -> None:
    codec = Codec(node="VEHICLE")
    good = Codec().encode("CMD_TORQUE", {"TorqueRL": 1.0, "TorqueRR": 1.0})
    frames = {
        "error_frames": can.Message(is_error_frame=True, arbitration_id=0x20000004, data=bytes(8)),
        "unknown_id": can.Message(arbitration_id=0x555, data=bytes(8), is_extended_id=False),
        "bad_length": can.Message(arbitration_id=0x100, data=bytes(7), is_extended_id=False),
        "bad_checksum": can.Message(arbitration_id=good.arbitration_id, data=bytes(good.data[:7]) + bytes(
            [good.data[7] ^ 0x80]), is_extended_id=False),
        "out_of_range": steer_frame(6000, 0),  # 0.6 rad: beyond the DBC's ±0.5
        "own_id": Codec().encode("IMU", {"YawRate": 0.0, "AccelX": 0.0, "AccelY": 0.0}),
    }
    for reason, frame in frames.items():
        for _ in range(3):
            assert codec.decode(frame) is None, reason
    stats = codec.stats.snapshot()
    for reason in frames:
        assert stats[reason] == 3, reason
    assert codec.stats.dropped == 3 * (len(frames) - 1)  # error frames are not data: not dropped frames


@pytest.mark.parametrize("kind", ["extended", "remote", "fd"])
def test_an_extended_remote_or_fd_frame_on_a_dbc_identifier_is_not_decoded(kind: str) -> None:
    codec = Codec()
    valid = eps_frame(100, 0)
    frame = can.Message(arbitration_id=0x200, data=valid.data, is_extended_id=kind == "extended",
                        is_remote_frame=kind == "remote", is_fd=kind == "fd", dlc=4)
    assert codec.decode(frame) is None and codec.decode(frame) is None and codec.stats.unknown_id == 2
    assert codec.decode(valid) is not None  # the same content as a classic data frame is fine


def test_a_frame_cantools_cannot_decode_is_counted_not_raised() -> None:
    """A multiplexed message whose multiplexer value the DBC does not define: cantools raises, the codec counts."""
    dbc = """VERSION ""
BU_: CAR
BO_ 1024 MUX: 8 CAR
 SG_ Mode M : 0|8@1+ (1,0) [0|255] "" CAR
 SG_ A m1 : 8|16@1+ (1,0) [0|65535] "" CAR
"""
    codec = Codec(db=cantools.database.load_string(dbc, "dbc"))
    for _ in range(2):
        assert codec.decode(can.Message(arbitration_id=1024, data=bytes([7]) + bytes(7), is_extended_id=False)) is None
    assert codec.stats.undecodable == 2 and codec.stats.dropped == 2


def test_frame_stats_add_up() -> None:
    stats = FrameStats(unknown_id=1, bad_length=2, bad_checksum=3, bad_counter=4, undecodable=5, out_of_range=6,
                       error_frames=7, lost=8, own_id=9)
    assert stats.dropped == 1 + 2 + 3 + 4 + 5 + 6 + 9
    assert stats.snapshot() == {"unknown_id": 1, "bad_length": 2, "bad_checksum": 3, "bad_counter": 4, "undecodable": 5,
                                "out_of_range": 6, "error_frames": 7, "lost": 8, "own_id": 9}
    assert set(PROTECTED) == {"CMD_STEER", "CMD_TORQUE"}


def test_own_is_what_the_codecs_node_transmits() -> None:
    """An echo of the bridge's own command on the bus is its own; the vehicle's frames and unknown identifiers are not,
    and a codec of no node owns nothing."""
    bridge, vehicle, nobody = Codec(node="BRIDGE"), Codec(node="VEHICLE"), Codec()
    command = can.Message(arbitration_id=0x100, data=bytes(8), is_extended_id=False)
    eps = can.Message(arbitration_id=0x200, data=bytes(8), is_extended_id=False)
    unknown = can.Message(arbitration_id=0x7FF, data=bytes(8), is_extended_id=False)
    assert [bridge.own(f) for f in (command, eps, unknown)] == [True, False, False]
    assert [vehicle.own(f) for f in (command, eps, unknown)] == [False, True, False]
    assert [nobody.own(f) for f in (command, eps, unknown)] == [False, False, False]


def test_cycle_time_is_one_positive_whole_number_of_milliseconds() -> None:
    """The common GenMsgCycleTime of frames, in seconds; frames that differ, a zero, a fraction or none are refused
    with the frames named."""
    from types import SimpleNamespace

    from moose.canbus.codec import cycle_time
    from moose.params import ParamError

    def db(**times: object) -> SimpleNamespace:
        return SimpleNamespace(get_message_by_name=lambda name: SimpleNamespace(cycle_time=times[name]))

    assert cycle_time(DB, "CMD_STEER", "CMD_TORQUE") == 0.01
    assert cycle_time(db(A=1, B=1), "A", "B") == 0.001
    for bad in (db(A=10, B=20), db(A=0, B=0), db(A=10.5, B=10.5), db(A=None, B=None), db(A=-10, B=-10)):
        with pytest.raises(ParamError, match=r"GenMsgCycleTime of \{'A': .*, 'B': .*\} is invalid: expected one "
                                             r"positive cycle time \(ms\) for all"):
            cycle_time(bad, "A", "B")
