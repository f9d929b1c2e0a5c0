"""The vehicle-side ECU emulator: its command timeouts to the millisecond, which signal drives which actuator, and
which sensor value leaves in which signal — frames built and read back with cantools and the DBC, not the codec."""
from __future__ import annotations

import math

import can
import numpy as np
import pytest

from moose.canbus.codec import Codec, command_checksum, load_database
from moose.canbus.ecu import ECU_TIMEOUT, VehicleEcu
from moose.minimum_risk import ActuatorLimits, MinimumRiskManeuver
from moose.params import VehicleParams
from moose.schema import MinimumRiskParams
from moose.signals import EpsSample, GpsSample, ImuSample, WheelSpeedSample
from moose.vehicle import DELTA, GAMMA, OMEGA_RL, OMEGA_RR, THETA, VX, VY, VehiclePlant, X, initial_state

DB = load_database()


def command(name: str, counter: int, **signals: float) -> can.Message:
    """A command frame built from the DBC by cantools, with its CRC (E2E profile 1, identifier included)."""
    message = DB.get_message_by_name(name)
    values = {s.name: 0.0 for s in message.signals}
    values.update(signals, Counter=counter, Checksum=0)
    data = bytearray(message.encode(values))
    data[7] = command_checksum(message.frame_id, bytes(data))
    return can.Message(arbitration_id=message.frame_id, data=bytes(data), is_extended_id=False)


def read(frame: can.Message) -> tuple[str, dict]:
    return DB.get_message_by_frame_id(frame.arbitration_id).name, DB.decode_message(frame.arbitration_id, frame.data)


def test_commands_drive_their_own_actuators_until_each_times_out() -> None:
    ecu = VehicleEcu(timeout=0.05)
    assert not ecu.steering_alive(0.0) and not ecu.torque_alive(0.0)
    assert list(ecu.plant_input(0.0)) == [0.0, 0.0, 0.0]  # nothing received: EPS still, no torque
    ecu.on_frame(command("CMD_STEER", 0, SteerAngleCmd=0.1, SteerRateCmd=0.4), 1.0)
    ecu.on_frame(command("CMD_TORQUE", 0, TorqueRL=30.0, TorqueRR=-12.5), 1.02)
    assert list(ecu.plant_input(1.02)) == pytest.approx([0.4, 30.0, -12.5])
    assert ecu.steering_alive(1.05) and list(ecu.plant_input(1.05)) == pytest.approx([0.4, 30.0, -12.5])  # exactly
    assert not ecu.steering_alive(1.051) and ecu.torque_alive(1.051)  # each command has its own age
    assert list(ecu.plant_input(1.051)) == pytest.approx([0.0, 30.0, -12.5])
    assert ecu.commands_lost is True and ecu.minimum_risk is False  # level 1 only: no maneuver configured
    assert ecu.torque_alive(1.07) and not ecu.torque_alive(1.0701)
    assert list(ecu.plant_input(1.071)) == [0.0, 0.0, 0.0]
    ecu.on_frame(command("CMD_TORQUE", 1, TorqueRL=5.0, TorqueRR=6.0), 1.1)  # a fresh command revives it
    assert list(ecu.plant_input(1.1)) == pytest.approx([0.0, 5.0, 6.0])


def test_the_timeouts_allow_a_nanosecond_of_round_off() -> None:
    ecu = VehicleEcu(timeout=0.05)
    ecu.on_frame(command("CMD_STEER", 0, SteerAngleCmd=0.0, SteerRateCmd=0.2), 0.0)
    ecu.on_frame(command("CMD_TORQUE", 0, TorqueRL=1.0, TorqueRR=1.0), 0.0)
    assert ecu.steering_alive(0.05 + 1e-9) and ecu.torque_alive(0.05 + 1e-9)
    assert not ecu.steering_alive(0.05 + 2e-9) and not ecu.torque_alive(0.05 + 2e-9)


def test_a_frame_the_ecu_refuses_does_not_refresh_the_command() -> None:
    ecu = VehicleEcu()
    ecu.on_frame(command("CMD_TORQUE", 0, TorqueRL=40.0, TorqueRR=40.0), 0.0)
    bad = command("CMD_TORQUE", 1, TorqueRL=90.0, TorqueRR=90.0)
    data = bytearray(bad.data)
    data[7] ^= 0x01  # a corrupted checksum
    ecu.on_frame(can.Message(arbitration_id=bad.arbitration_id, data=bytes(data), is_extended_id=False), 0.04)
    assert list(ecu.plant_input(0.04)) == pytest.approx([0.0, 40.0, 40.0])
    assert list(ecu.plant_input(0.06)) == [0.0, 0.0, 0.0]  # aged from 0.0, not from the refused frame
    assert ecu.codec.stats.bad_checksum == 1


def test_the_default_timeout_is_five_command_cycles() -> None:
    assert ECU_TIMEOUT == 0.05 and VehicleEcu().timeout == 0.05
    assert DB.get_message_by_name("CMD_TORQUE").cycle_time * 5 == 1000 * ECU_TIMEOUT


@pytest.mark.parametrize("timeout", [0.0, -0.01, math.inf, math.nan, True, "0.05"])
def test_a_bad_timeout_is_refused(timeout: object) -> None:
    with pytest.raises(ValueError, match=r"^timeout = .* is invalid: expected a positive number of seconds$"):
        VehicleEcu(timeout=timeout)  # type: ignore[arg-type]


def test_each_sensor_value_leaves_in_its_own_signal() -> None:
    ecu = VehicleEcu()
    frames = ecu.frames([ImuSample(1.0, 0.5, -1.25, 0.031), WheelSpeedSample(1.0, 20.5, 21.25),
                         EpsSample(1.0, -0.0425), GpsSample(1.0, 0.8, 12.5, -3.25, 6.5, 0.75)], 1.0)
    decoded = dict(read(f) for f in frames)
    assert list(decoded) == ["IMU", "WHEEL_SPEEDS", "EPS_STATUS", "GPS_POSITION", "GPS_VELOCITY"]
    imu = decoded["IMU"]
    assert (imu["AccelX"], imu["AccelY"], imu["YawRate"]) == pytest.approx((0.5, -1.25, 0.031), abs=1e-3)
    wheels = decoded["WHEEL_SPEEDS"]
    assert (wheels["OmegaRL"], wheels["OmegaRR"]) == pytest.approx((20.5, 21.25), abs=0.01)
    assert decoded["EPS_STATUS"]["SteerAngle"] == pytest.approx(-0.0425, abs=1e-4)
    assert (decoded["GPS_POSITION"]["PosX"], decoded["GPS_POSITION"]["PosY"]) == pytest.approx((12.5, -3.25), abs=0.01)
    velocity = decoded["GPS_VELOCITY"]
    assert (velocity["VelX"], velocity["VelY"]) == pytest.approx((6.5, 0.75), abs=0.01)
    assert velocity["FixAge"] == pytest.approx(0.2, abs=1e-3)  # delivered at 1.0 s, measured at 0.8 s
    assert decoded["GPS_POSITION"]["Counter"] == velocity["Counter"]  # one fix: one counter
    assert all(f.timestamp == 1.0 for f in frames)


def test_sensor_values_beyond_the_dbc_range_saturate_and_non_finite_ones_are_not_sent() -> None:
    ecu = VehicleEcu()
    imu = DB.get_message_by_name("IMU").get_signal_by_name("YawRate")
    (name, values), = [read(f) for f in ecu.encode(ImuSample(0.0, 0.0, 0.0, 1e6), 0.0)]
    assert values["YawRate"] == pytest.approx(imu.maximum, abs=abs(imu.scale))
    (name, values), = [read(f) for f in ecu.encode(WheelSpeedSample(0.0, -1e4, 1e4), 0.0)]
    assert (values["OmegaRL"], values["OmegaRR"]) == pytest.approx((-300.0, 300.0))
    (name, values), = [read(f) for f in ecu.encode(EpsSample(0.0, 2.0), 0.0)]
    assert values["SteerAngle"] == pytest.approx(0.5)
    position, velocity = [read(f)[1] for f in ecu.encode(GpsSample(1.0, -100.0, 1e9, -1e9, 99.0, -99.0), 1.0)]
    assert (position["PosX"], position["PosY"]) == pytest.approx((134217.727, -134217.728))
    assert (velocity["VelX"], velocity["VelY"], velocity["FixAge"]) == pytest.approx((30.0, -30.0, 60.0))
    unsendable = [ImuSample(0.0, math.nan, 0.0, 0.0), WheelSpeedSample(0.0, math.nan, 1.0), EpsSample(0.0, math.inf),
                  GpsSample(1.0, 0.8, math.inf, 0.0, 0.0, 0.0), GpsSample(1.0, math.nan, 1.0, 0.0, 0.0, 0.0)]
    for k, sample in enumerate(unsendable, start=1):
        assert ecu.encode(sample, 1.0) == [] and ecu.unsendable == k
    with pytest.raises(TypeError, match="has no frame"):
        ecu.encode(object(), 0.0)


def test_the_ecu_receives_with_the_vehicle_node_and_ignores_its_own_frames() -> None:
    ecu = VehicleEcu()
    assert ecu.codec.node == "VEHICLE"
    own = Codec().encode("IMU", {"YawRate": 0.1, "AccelX": 0.0, "AccelY": 0.0})
    ecu.on_frame(own, 0.0)
    assert ecu.codec.stats.own_id == 1 and list(ecu.plant_input(0.0)) == [0.0, 0.0, 0.0]
    shared = Codec(node="VEHICLE")
    assert VehicleEcu(codec=shared).codec is shared


# -- level 2 of the timeout: the ECUs' own minimum-risk maneuver


def ecu_with_maneuver() -> tuple[VehicleEcu, MinimumRiskManeuver]:
    maneuver = MinimumRiskManeuver(MinimumRiskParams(), ActuatorLimits.from_vehicle(VehicleParams()), 0.01)
    return VehicleEcu(maneuver=maneuver), maneuver


def test_an_ecu_never_commanded_does_not_run_the_maneuver() -> None:
    ecu, _ = ecu_with_maneuver()
    assert ecu.commanded is False and ecu.minimum_risk is False and ecu.commands_lost is False
    ecu.encode(EpsSample(0.0, 0.2), 0.0)
    ecu.encode(WheelSpeedSample(0.0, 20.0, 20.0), 0.0)
    assert list(ecu.plant_input(0.0)) == [0.0, 0.0, 0.0] and ecu.minimum_risk is False  # parked, not braking
    assert ecu.commands_lost is False  # never commanded: nothing was lost


def lost_after_one_command(torque: float = 50.0) -> tuple[VehicleEcu, MinimumRiskManeuver]:
    """An ECU commanded once at t = 0 (steering rate 0.3 rad/s, ``torque`` on both motors), stale from 0.05 s."""
    ecu, maneuver = ecu_with_maneuver()
    ecu.on_frame(command("CMD_STEER", 0, SteerAngleCmd=0.2, SteerRateCmd=0.3), 0.0)
    ecu.on_frame(command("CMD_TORQUE", 0, TorqueRL=torque, TorqueRR=torque), 0.0)
    assert ecu.commanded is True
    return ecu, maneuver


def test_the_maneuver_starts_from_what_the_actuators_applied() -> None:
    """Commanded but never applied (no plant input before the loss): the motors were at 0 N m, so the braking
    torque ramps from 0 at the torque-rate limit, not from the command that never acted."""
    ecu, maneuver = lost_after_one_command()
    ecu.encode(WheelSpeedSample(0.1, 20.0, 20.0), 0.1)
    _, t_rl, t_rr = ecu.plant_input(0.1)
    assert t_rl == t_rr == pytest.approx(-maneuver.limits.torque_rate_limit * 0.01)


def test_the_ecu_brakes_in_proportion_to_the_mean_wheel_speed() -> None:
    """Below T_brake the braking torque is k_ω times the mean of the two rear wheel speeds."""
    ecu, maneuver = lost_after_one_command(torque=0.0)
    for k in range(30):  # long enough for the torque-rate limit to settle
        t = 0.06 + 0.01 * k
        ecu.encode(WheelSpeedSample(t, 0.4, 0.6), t)
        _, t_rl, t_rr = ecu.plant_input(t)
    assert t_rl == t_rr == pytest.approx(-maneuver.params.brake_gain * 0.5)


def test_wheel_speeds_that_arrive_late_are_braked_on() -> None:
    """No wheel speed for longer than the stop time: the ECU does not brake blind, and does not take the silence for
    a standstill — braking starts once speeds arrive."""
    ecu, maneuver = lost_after_one_command(torque=0.0)
    for k in range(40):
        assert list(ecu.plant_input(0.06 + 0.01 * k))[1:] == [0.0, 0.0]
    ecu.encode(WheelSpeedSample(0.46, 20.0, 20.0), 0.46)
    assert ecu.plant_input(0.46)[1] == pytest.approx(-maneuver.limits.torque_rate_limit * 0.01)


def test_without_the_eps_angle_the_ecu_ramps_its_reference_from_the_angle_it_last_measured() -> None:
    """The EPS angle goes silent with the commands: the steering reference ramps from the last measured 0.2 rad to 0
    at δ̇_max (rate −δ̇_max), instead of holding the angle (rate 0)."""
    ecu, maneuver = lost_after_one_command()
    ecu.encode(EpsSample(0.02, 0.2), 0.02)
    rates = [ecu.plant_input(0.06 + 0.01 * k)[0] for k in range(6)]  # the angle is fresh until 0.07 s, then stale
    assert ecu.minimum_risk is True
    assert rates == pytest.approx([-maneuver.limits.steer_rate_limit] * 6)


def test_the_ecus_own_measurements_count_up_to_the_timeout() -> None:
    ecu, maneuver = lost_after_one_command(torque=0.0)
    ecu.encode(WheelSpeedSample(0.06, 20.0, 20.0), 0.06)
    assert ecu.plant_input(0.11)[1] < 0.0  # exactly 50 ms old: still fresh, braking
    ecu, maneuver = lost_after_one_command(torque=0.0)
    ecu.encode(WheelSpeedSample(0.06, 20.0, 20.0), 0.06)
    assert ecu.plant_input(0.1101)[1] == 0.0  # older: not braking blind


def test_a_lost_stream_starts_the_maneuver_from_the_ecus_own_measurements() -> None:
    ecu, maneuver = ecu_with_maneuver()
    limits, p = maneuver.limits, maneuver.params
    ecu.on_frame(command("CMD_STEER", 0, SteerAngleCmd=0.2, SteerRateCmd=0.3), 0.0)
    ecu.on_frame(command("CMD_TORQUE", 0, TorqueRL=50.0, TorqueRR=50.0), 0.0)
    assert list(ecu.plant_input(0.0)) == pytest.approx([0.3, 50.0, 50.0]) and not ecu.minimum_risk
    # the torque stream stays fresh, the steering stream goes stale: level 2 for both actuators
    ecu.on_frame(command("CMD_TORQUE", 1, TorqueRL=50.0, TorqueRR=50.0), 0.05)
    ecu.encode(EpsSample(0.06, 0.03), 0.06)
    ecu.encode(WheelSpeedSample(0.06, 20.0, 22.0), 0.06)
    rate, t_rl, t_rr = ecu.plant_input(0.06)
    assert ecu.minimum_risk is True and ecu.commands_lost is True
    # steer back from the measured angle: −K_δ·δ_meas = −0.6 rad/s, inside the rate limit (a reference ramp
    # would ask for −δ̇_max)
    assert p.eps_gain * 0.03 < limits.steer_rate_limit and rate == pytest.approx(-p.eps_gain * 0.03)
    # brake: the torque falls from the last command at the torque-rate limit, the same on both wheels
    assert t_rl == t_rr == pytest.approx(50.0 - limits.torque_rate_limit * 0.01)
    for k in range(200):
        ecu.encode(WheelSpeedSample(0.07 + 0.01 * k, 20.0, 22.0), 0.07 + 0.01 * k)
        ecu.encode(EpsSample(0.07 + 0.01 * k, 0.0), 0.07 + 0.01 * k)
        rate, t_rl, t_rr = ecu.plant_input(0.07 + 0.01 * k)
    brake = min(p.brake_gain * 21.0, p.brake_fraction * limits.torque_max)
    assert (rate, t_rl, t_rr) == pytest.approx((0.0, -brake, -brake))  # straight, full regenerative braking
    # fresh commands on both streams end it
    ecu.on_frame(command("CMD_STEER", 1, SteerAngleCmd=0.0, SteerRateCmd=0.1), 2.1)
    ecu.on_frame(command("CMD_TORQUE", 2, TorqueRL=5.0, TorqueRR=6.0), 2.1)
    assert list(ecu.plant_input(2.1)) == pytest.approx([0.1, 5.0, 6.0]) and ecu.minimum_risk is False
    assert ecu.commands_lost is False


def test_without_measurements_the_maneuver_does_not_brake_blind() -> None:
    ecu, maneuver = ecu_with_maneuver()
    ecu.on_frame(command("CMD_STEER", 0, SteerAngleCmd=0.0, SteerRateCmd=0.0), 0.0)
    ecu.on_frame(command("CMD_TORQUE", 0, TorqueRL=0.0, TorqueRR=0.0), 0.0)
    ecu.encode(WheelSpeedSample(0.0, 20.0, 20.0), 0.0)  # older than the timeout at t = 1
    assert list(ecu.plant_input(1.0)) == [0.0, 0.0, 0.0] and ecu.minimum_risk


def drive_until_the_commands_stop(ecu: VehicleEcu) -> np.ndarray:
    """6 m/s; 20 ms of commands (steer left at 2 rad/s, 20 N m), then nothing for 10 s."""
    vehicle = VehicleParams()
    plant = VehiclePlant(vehicle, dt=1e-3)
    plant.reset(initial_state(vehicle, vx=6.0))
    ecu.on_frame(command("CMD_STEER", 0, SteerAngleCmd=0.1, SteerRateCmd=2.0), 0.0)
    ecu.on_frame(command("CMD_TORQUE", 0, TorqueRL=20.0, TorqueRR=20.0), 0.0)
    ecu.on_frame(command("CMD_STEER", 1, SteerAngleCmd=0.1, SteerRateCmd=2.0), 0.02)
    for k in range(1000):
        t = 0.01 * k
        s = plant.state
        ecu.encode(EpsSample(t, s[DELTA]), t)
        ecu.encode(WheelSpeedSample(t, s[OMEGA_RL], s[OMEGA_RR]), t)
        plant.step(ecu.plant_input(t), 10)
    return plant.state


def test_a_car_whose_commands_stop_is_straightened_and_stopped_by_its_ecus() -> None:
    s = drive_until_the_commands_stop(ecu_with_maneuver()[0])
    assert math.hypot(s[VX], s[VY]) < 0.05 and abs(s[DELTA]) < 0.01 and abs(s[GAMMA]) < 0.01
    assert abs(s[THETA]) < 0.3 and s[X] < 25.0  # it steered left for 70 ms, then back: a short, straight stop


def test_without_level_two_the_car_coasts_on_an_arc() -> None:
    s = drive_until_the_commands_stop(VehicleEcu())
    assert math.hypot(s[VX], s[VY]) > 5.0 and s[DELTA] > 0.05 and s[THETA] > 1.5  # still turning left
