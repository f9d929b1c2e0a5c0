"""The bridge core to the millisecond: the frame schedule, lateness, status and heartbeat contents, sample stamps,
GPS pairing, and its refusal of a DBC whose cycle times or ranges do not fit — frames read back by cantools."""
from __future__ import annotations

import math
import re

import can
import cantools
import pytest

from moose.canbus.bridge import GPS_PAIR_WINDOW, BridgeCore
from moose.canbus.codec import Codec, load_database
from moose.canbus.ecu import VehicleEcu
from moose.canbus.health import HealthParams
from moose.canbus.safety import Command, GuardParams
from moose.params import ParamError
from moose.resources import DBC_FILE
from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample

DB = load_database()


def names(frames: list[can.Message]) -> list[str]:
    return [DB.get_message_by_frame_id(f.arbitration_id).name for f in frames]


def decoded(frame: can.Message) -> dict:
    return DB.decode_message(frame.arbitration_id, frame.data)


def test_command_frames_keep_their_phase_within_half_a_period() -> None:
    bridge = BridgeCore()
    assert bridge.command_period == 0.01 and bridge.status_period == 0.1
    due = lambda t: bool(bridge.command_frames(t))  # noqa: E731
    assert due(0.0)
    assert not due(0.0)  # the same instant again: no second pair of frames
    assert not due(0.0049)
    assert due(0.005)  # half a period early is on time (a sender that wakes early)
    assert due(0.016)  # the next is due at 0.02, not 0.015 + 0.01: the phase is kept
    assert not due(0.0149 + 0.01)
    assert due(0.032)  # 2 ms late: still the 0.03 slot, the next at 0.04
    assert due(0.035)
    assert not due(0.044)


def test_a_caller_more_than_half_a_period_behind_restarts_the_schedule() -> None:
    bridge = BridgeCore()
    assert bridge.command_frames(0.0)  # next due 0.01
    assert bridge.command_frames(0.022)  # 12 ms late: restart from 0.022, next at 0.032
    assert not bridge.command_frames(0.023) and not bridge.command_frames(0.0269)
    assert bridge.command_frames(0.027)
    late = BridgeCore()
    assert late.command_frames(0.0) and late.command_frames(0.015)  # the slot 0.01 + 0.01 = 0.02 is t + 0.005
    assert not late.command_frames(0.016)  # next at 0.025, not 0.02


def test_a_clock_that_steps_back_restarts_the_schedule() -> None:
    bridge = BridgeCore()
    assert bridge.command_frames(10.0)
    assert bridge.command_frames(5.0)  # more than a period back: frames keep coming
    assert not bridge.command_frames(5.001) and bridge.command_frames(5.01)


def test_non_finite_times_send_nothing_and_change_nothing() -> None:
    bridge = BridgeCore()
    assert bridge.tick(math.nan) == [] and bridge.tick(math.inf) == []
    assert names(bridge.tick(0.0)) == ["CMD_STEER", "CMD_TORQUE", "BRIDGE_HEARTBEAT", "BRIDGE_STATUS"]
    assert bridge.max_command_gap == 0.0


def test_frames_carry_the_time_of_their_tick() -> None:
    bridge = BridgeCore()
    assert all(f.timestamp == 3.25 for f in bridge.tick(3.25))


def test_lateness_is_judged_against_the_timeout_less_one_period() -> None:
    bridge = BridgeCore()
    assert bridge.late_after == pytest.approx(GuardParams().timeout - 0.01)
    bridge.note_sent(10.0)
    bridge.note_sent(10.02)
    assert bridge.max_command_gap == pytest.approx(0.02) and bridge.late_commands == 0
    bridge.note_sent(10.02 + bridge.late_after)  # exactly the allowed gap: on time
    assert bridge.late_commands == 0 and bridge.heartbeat_state() != "fault"
    bridge.note_sent(10.02 + 2 * bridge.late_after + 0.001)
    assert bridge.late_commands == 1 and bridge.heartbeat_state() == "fault"
    rounding = BridgeCore()  # the round-off allowance (1 ns) is on the on-time side too
    rounding.note_sent(0.0)
    rounding.note_sent(rounding.late_after + 1e-9)
    assert rounding.late_commands == 0
    ticks = BridgeCore()
    ticks.command_frames(0.0)
    ticks.command_frames(ticks.late_after)
    assert ticks.late_commands == 0
    ticks.command_frames(2 * ticks.late_after + 0.001)
    assert ticks.late_commands == 1


def test_the_heartbeat_counts_from_one_and_wraps() -> None:
    bridge = BridgeCore()
    alive = []
    for k in range(258):
        frames = bridge.status_frames(0.1 * k)
        alive.append(decoded(frames[0])["Alive"])
    assert alive[:3] == [1, 2, 3] and alive[254:258] == [255, 0, 1, 2]


def test_status_counters_saturate_and_bad_frames_add_up() -> None:
    bridge = BridgeCore()
    s = bridge.codec.stats
    s.unknown_id, s.bad_length, s.undecodable, s.out_of_range = 1, 20, 300, 4000
    s.error_frames, s.bad_counter, s.bad_checksum = 5, 6, 7
    status = decoded(bridge.status_frames(0.0)[1])
    assert (status["BadFrame"], status["ErrorFrames"], status["BadCounter"], status["BadChecksum"]) == (4321, 5, 6, 7)
    s.error_frames, s.bad_counter, s.bad_checksum, s.out_of_range = 256, 65536, 65536, 70000
    status = decoded(bridge.status_frames(0.1)[1])
    counters = (status["ErrorFrames"], status["BadCounter"], status["BadChecksum"], status["BadFrame"])
    assert counters == (255, 65535, 65535, 65535)


def test_every_receive_overflow_is_counted() -> None:
    bridge = BridgeCore()
    bridge.note_rx_overflow()
    bridge.note_rx_overflow()
    assert bridge.rx_overflows == 2


def test_samples_carry_the_values_of_their_signals_and_the_stamp_given() -> None:
    bridge, ecu = BridgeCore(), VehicleEcu()
    samples = [ImuSample(0.0, 0.5, -1.25, 0.031), WheelSpeedSample(0.0, 20.5, 21.25), EpsSample(0.0, -0.04)]
    frames = ecu.frames(samples, 0.0)
    imu, wheels, eps = (bridge.on_frame(f, 1.0, stamp=7.5) for f in frames)
    assert isinstance(imu, ImuSample) and imu.t == 7.5
    assert (imu.ax, imu.ay, imu.yaw_rate) == pytest.approx((0.5, -1.25, 0.031), abs=1e-3)
    assert wheels.t == 7.5 and (wheels.omega_rl, wheels.omega_rr) == pytest.approx((20.5, 21.25), abs=0.01)
    assert eps.t == 7.5 and eps.delta == pytest.approx(-0.04, abs=1e-4)
    again = ecu.frames([EpsSample(0.0, 0.01)], 0.0)
    assert bridge.on_frame(again[0], 2.0).t == 2.0  # no stamp given: the receive time


def test_a_fix_pairs_its_two_frames_by_counter_within_the_window() -> None:
    bridge, ecu = BridgeCore(), VehicleEcu()
    position, velocity = ecu.frames([GpsSample(1.0, 0.8, 12.5, -3.25, 6.5, 0.75)], 1.0)
    assert bridge.on_frame(position, 0.0) is None
    fix = bridge.on_frame(velocity, GPS_PAIR_WINDOW)  # exactly the window apart: still one fix
    assert isinstance(fix, GpsSample)
    assert (fix.x, fix.y, fix.vX, fix.vY) == pytest.approx((12.5, -3.25, 6.5, 0.75), abs=0.01)
    assert fix.t_measured == pytest.approx(fix.t - 0.2, abs=1e-3)
    position, velocity = ecu.frames([GpsSample(2.0, 1.8, 1.0, 1.0, 1.0, 1.0)], 2.0)
    bridge.on_frame(position, 10.0)
    assert bridge.on_frame(velocity, 10.0 + GPS_PAIR_WINDOW + 0.001) is None  # too far apart
    other = ecu.frames([GpsSample(3.0, 2.8, 2.0, 2.0, 2.0, 2.0)], 3.0)
    bridge.on_frame(other[0], 20.0)
    next_fix = ecu.frames([GpsSample(4.0, 3.8, 3.0, 3.0, 3.0, 3.0)], 4.0)
    assert bridge.on_frame(next_fix[1], 20.01) is None  # the velocity of another fix (another counter)
    position, velocity = ecu.frames([GpsSample(5.0, 4.8, 4.0, 4.0, 4.0, 4.0)], 5.0)
    bridge.on_frame(position, 30.0)
    assert isinstance(bridge.on_frame(velocity, 30.01), GpsSample)
    _, lone = ecu.frames([GpsSample(6.0, 5.8, 5.0, 5.0, 5.0, 5.0)], 6.0)
    assert bridge.on_frame(lone, 31.0) is None  # its position frame lost: the last position is used up


def test_the_measured_angle_reaches_the_guard_end_stop() -> None:
    bridge, ecu = BridgeCore(), VehicleEcu()
    bridge.on_frame(ecu.frames([EpsSample(0.0, 0.295)], 0.0)[0], 0.0)
    bridge.on_command(Command(0.3, 1.0, 0.0, 0.0))
    steer = decoded(bridge.command_frames(0.0)[0])
    assert steer["SteerRateCmd"] == pytest.approx(0.5, abs=1e-3)  # (δ_max − 0.295) / 10 ms, not 1 rad/s


def test_traffic_after_a_reopen_resets_the_backoff() -> None:
    bridge, ecu = BridgeCore(), VehicleEcu()
    health = bridge.health
    health.on_io_failure("send failed", 0.0)
    health.on_open(0.1)
    for k in range(12):  # 1.1 s of received traffic after the reopen
        bridge.on_frame(ecu.frames([EpsSample(0.0, 0.0)], 0.1 * k)[0], 0.1 + 0.1 * k)
    health.on_io_failure("send failed", 2.0)
    assert health.reopen_at == pytest.approx(2.0 + HealthParams().backoff_initial)  # back to the initial back-off


def test_a_stalled_caller_ages_the_command_by_its_clock() -> None:
    bridge = BridgeCore()
    bridge.on_command(Command(0.0, 0.0, 50.0, 50.0))
    for k in range(5):
        bridge.command_frames(0.01 * k)
    assert not bridge.guard.timed_out
    frames = bridge.command_frames(1.0)  # one second without a tick: the command is a second old
    assert bridge.guard.timed_out and decoded(frames[1])["TorqueRL"] < 50.0


def dbc_with(**changes: str) -> cantools.database.Database:
    """config/kanon.dbc with some lines replaced (``old=new`` given as keyword pairs by name)."""
    text = DBC_FILE.read_text()
    for old, new in changes.values():
        assert old in text
        text = text.replace(old, new)
    return cantools.database.load_string(text, "dbc")


@pytest.mark.parametrize("change, match", [
    (("BA_ \"GenMsgCycleTime\" BO_ 256 10;", "BA_ \"GenMsgCycleTime\" BO_ 256 20;"), "CMD_STEER"),
    (("BA_ \"GenMsgCycleTime\" BO_ 257 10;", "BA_ \"GenMsgCycleTime\" BO_ 257 20;"), "CMD_TORQUE"),
    (("BA_ \"GenMsgCycleTime\" BO_ 768 100;", "BA_ \"GenMsgCycleTime\" BO_ 768 50;"), "BRIDGE_HEARTBEAT"),
    (("BA_ \"GenMsgCycleTime\" BO_ 769 100;", "BA_ \"GenMsgCycleTime\" BO_ 769 50;"), "BRIDGE_STATUS"),
])
def test_frames_sent_together_must_share_their_cycle_time(change: tuple, match: str) -> None:
    with pytest.raises(ParamError, match=rf"^GenMsgCycleTime of .*'{match}'.* is invalid: expected one positive cycle "
                                         r"time \(ms\) for all$"):
        BridgeCore(codec=Codec(db=dbc_with(c=change)))


def test_a_zero_or_missing_cycle_time_is_refused_and_one_millisecond_is_a_cycle() -> None:
    zero = {"a": ("BO_ 256 10;", "BO_ 256 0;"), "b": ("BO_ 257 10;", "BO_ 257 0;")}
    with pytest.raises(ParamError, match="GenMsgCycleTime"):
        BridgeCore(codec=Codec(db=dbc_with(**zero)))
    missing = {"a": ("BA_ \"GenMsgCycleTime\" BO_ 256 10;\n", ""), "b": ("BA_ \"GenMsgCycleTime\" BO_ 257 10;\n", "")}
    with pytest.raises(ParamError, match="GenMsgCycleTime"):
        BridgeCore(codec=Codec(db=dbc_with(**missing)))
    fast = BridgeCore(codec=Codec(db=dbc_with(a=("BO_ 256 10;", "BO_ 256 1;"), b=("BO_ 257 10;", "BO_ 257 1;"))))
    assert fast.command_period == 0.001 and fast.guard.period == 0.001


def test_the_guard_runs_at_the_dbc_command_period() -> None:
    slow = BridgeCore(codec=Codec(db=dbc_with(a=("BO_ 256 10;", "BO_ 256 20;"), b=("BO_ 257 10;", "BO_ 257 20;"))))
    assert slow.command_period == 0.02 and slow.guard.period == 0.02
    slow.on_command(Command(0.0, 0.0, 200.0, 200.0))
    torque = decoded(slow.command_frames(0.0)[1])["TorqueRL"]
    assert torque == pytest.approx(GuardParams().torque_rate_limit * 0.02)  # the rate limit per 20 ms output


def test_a_dbc_range_that_cannot_carry_a_limit_on_either_side_is_refused() -> None:
    line = 'SG_ SteerAngleCmd : 0|16@1- (0.0001,0) [-0.5|0.5] "rad" VEHICLE'
    for narrow in ("[-0.2|0.5]", "[-0.5|0.2]"):
        db = dbc_with(a=(line, line.replace("[-0.5|0.5]", narrow)))
        with pytest.raises(ParamError, match=re.escape("delta_max = 0.3 is invalid: CMD_STEER.SteerAngleCmd")):
            BridgeCore(codec=Codec(db=db))
