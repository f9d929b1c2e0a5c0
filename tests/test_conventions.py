"""Sign conventions end to end (REP-103: x forward, y left, z up, yaw counter-clockwise positive).

Each chain runs through every layer a sign could be lost in — the actuator command, the bridge's guard, the
CAN frame (read back with the DBC by cantools, not by the codec), the vehicle-side ECU emulator, the plant,
the sensors, the sensor frames and the bridge's decoding — and is judged against an independent reference:
the linear single-track model in closed form (neutral steer: C_f l_f = C_r l_r for Table I's static loads),
not the plant's own equations.  Neither check is symmetric: a left/right swap in any one layer flips a sign.
"""
from __future__ import annotations

import numpy as np
import pytest

from can_lockstep import Feedback, drive_over_can
from moose.canbus.codec import load_database
from moose.canbus.ecu import VehicleEcu
from moose.canbus.safety import Command, GuardParams
from moose.motion import MotionController
from moose.params import VehicleParams
from moose.planner.fbl import FeedbackLinearization
from moose.schema import FblParams, MotionParams, SensorParams
from moose.signals import EpsSample, ImuSample, Reference, StateEstimate, WheelSpeedSample
from moose.vehicle import DELTA, GAMMA, THETA, VX, Y

pytestmark = [pytest.mark.can]

P = VehicleParams()
DT = 0.01
DBC = load_database()  # an independent reader of the frames on the wire (cantools with the DBC)


def cornering_stiffness(p: VehicleParams) -> tuple[float, float]:
    """C_f, C_r (N/rad): the slope at zero slip of the magic formula F = μ F_z sin(C atan(B α))."""
    return p.mu * p.Fzf * p.By * p.Cy, p.mu * p.Fzr * p.By * p.Cy


def drive(delta: float, t_rl: float, t_rr: float, v0: float, seconds: float, seed: int = 5) -> dict:
    """The car at ``v0`` under constant torques and a steering angle held by the motion controller's EPS law
    (δ̇_cmd = K_δ (δ* − δ_meas)): bridge → virtual CAN → ECU emulator → plant → sensors → CAN → bridge."""
    guard = GuardParams.from_vehicle(P)
    k_delta = MotionParams().k_delta

    def controller(t: float, feedback: Feedback) -> Command:
        return Command(delta, k_delta * (delta - feedback.delta), t_rl, t_rr)

    run = drive_over_can(P, guard, VehicleEcu(timeout=guard.timeout), v0, seconds, controller, seed)
    wire = []
    for frame in run.to_car:
        message = DBC.get_message_by_frame_id(frame.arbitration_id)
        if message.name in ("CMD_TORQUE", "CMD_STEER"):
            wire.append((message.name, DBC.decode_message(frame.arbitration_id, frame.data)))
    return {"wire": wire, "inputs": np.array(list(run.inputs.values())),
            "truth": np.array(list(run.truth.values())), "received": run.records}


def late(records: list, kind: type, t_from: float) -> list:
    return [r for r in records if isinstance(r, kind) and r.t >= t_from]


@pytest.mark.parametrize("t_rl, t_rr", [(100.0, -100.0), (-60.0, 60.0)])
def test_uneven_rear_torques_yaw_the_car_towards_the_weaker_wheel_from_command_to_sensors(t_rl: float,
                                                                                         t_rr: float) -> None:
    """More torque on the left wheel pushes the left side forward: the car turns right (γ < 0)."""
    v0 = 5.0
    run = drive(0.0, t_rl, t_rr, v0, seconds=1.5)
    # on the wire: TorqueRL carries the rear-left command, TorqueRR the rear-right one
    torques = [values for name, values in run["wire"] if name == "CMD_TORQUE"]
    assert torques[-1]["TorqueRL"] == pytest.approx(t_rl, abs=0.1)
    assert torques[-1]["TorqueRR"] == pytest.approx(t_rr, abs=0.1)
    # at the plant: U = [δ̇, T_rl, T_rr]
    assert run["inputs"][-1, 1:] == pytest.approx([t_rl, t_rr], abs=0.1)
    # the closed form: the yaw moment M_z = (F_x,rr − F_x,rl) b/2 with F_x = T/r once the wheels have spun up,
    # neutral steer decouples yaw from side slip: I_zz γ̇ = −(C_f l_f² + C_r l_r²) γ / v + M_z
    c_f, c_r = cornering_stiffness(P)
    assert c_f * P.lf == pytest.approx(c_r * P.lr, rel=1e-9)  # neutral steer, the premise of the closed form
    moment = (t_rr - t_rl) / P.r * P.track / 2
    gamma_ss = moment * v0 / (c_f * P.lf**2 + c_r * P.lr**2)
    truth = run["truth"]
    settled = truth[int(1.0 / DT):]
    assert np.sign(gamma_ss) == np.sign(t_rr - t_rl)
    assert np.mean(settled[:, GAMMA]) == pytest.approx(gamma_ss, rel=0.05)
    assert np.sign(truth[-1, THETA]) == np.sign(gamma_ss) and np.sign(truth[-1, Y]) == np.sign(gamma_ss)
    assert truth[-1, VX] == pytest.approx(v0, abs=0.05)  # equal and opposite torques: no net drive
    # back through the sensors and the bus: the gyro sees γ, the accelerometer the centripetal v γ,
    # the stronger wheel spins faster (its driving slip, and it is on the outside of the turn)
    imu = late(run["received"], ImuSample, 1.0)
    wheels = late(run["received"], WheelSpeedSample, 1.0)
    assert len(imu) >= 45 and len(wheels) >= 45
    assert np.mean([s.yaw_rate for s in imu]) == pytest.approx(gamma_ss, rel=0.1)
    assert np.mean([s.ay for s in imu]) == pytest.approx(v0 * gamma_ss, rel=0.15)
    difference = np.mean([s.omega_rl - s.omega_rr for s in wheels])
    assert np.sign(difference) == np.sign(t_rl - t_rr)
    assert abs(difference) > 10 * SensorParams().wheel_std / np.sqrt(len(wheels))


@pytest.mark.parametrize("delta", [0.02, -0.02])
def test_positive_steering_turns_left_from_command_to_sensors(delta: float) -> None:
    """δ > 0 steers the front wheels to the left: γ > 0, y grows, a_y > 0, the right (outer) wheel turns faster."""
    v0 = 6.0
    run = drive(delta, 0.0, 0.0, v0, seconds=3.0)
    steer = [values for name, values in run["wire"] if name == "CMD_STEER"]
    assert steer[-1]["SteerAngleCmd"] == pytest.approx(delta, abs=1e-3)
    truth = run["truth"]
    held = truth[int(2.0 / DT):]
    assert np.mean(held[:, DELTA]) == pytest.approx(delta, abs=1e-3)
    # neutral steer: the linear single-track model's steady yaw rate is γ = v δ / L
    gamma_theory = np.mean(held[:, VX]) * delta / P.wheelbase
    assert np.mean(held[:, GAMMA]) == pytest.approx(gamma_theory, rel=0.03)
    side = np.sign(delta)
    assert np.sign(truth[-1, Y]) == side and np.sign(truth[-1, THETA]) == side
    eps = late(run["received"], EpsSample, 2.0)
    imu = late(run["received"], ImuSample, 2.0)
    wheels = late(run["received"], WheelSpeedSample, 2.0)
    assert len(eps) >= 90 and len(imu) >= 90 and len(wheels) >= 90
    assert np.mean([s.delta for s in eps]) == pytest.approx(delta, abs=1e-3)
    assert np.mean([s.yaw_rate for s in imu]) == pytest.approx(gamma_theory, rel=0.05)
    assert np.mean([s.ay for s in imu]) == pytest.approx(v0 * gamma_theory, rel=0.1)
    # rolling wheels: ω_rr − ω_rl = γ b / r (the outer wheel's longer path)
    difference = np.mean([s.omega_rr - s.omega_rl for s in wheels])
    assert difference == pytest.approx(gamma_theory * P.track / P.r, rel=0.15)


def test_a_leftward_acceleration_demand_steers_left_through_fbl_and_motion_control() -> None:
    """A planner's v̇_Y > 0 (towards +y) becomes δ* > 0 and an EPS rate command > 0; v̇_Y < 0 the opposite."""
    fbl = FeedbackLinearization(FblParams(), P, t_s=0.2)
    motion = MotionController(MotionParams(), P)
    for heading in (0.0, 0.3, -0.3):
        estimate = StateEstimate(t=0.0, x=0.0, y=0.0, theta=heading, vx=7.0, vy=0.0, gamma=0.0, delta=0.0)
        normal = np.array([-np.sin(heading), np.cos(heading)])  # the car's left, in odom
        for side in (1.0, -1.0):
            reference = fbl.reference(side * 0.5 * normal, estimate)
            assert np.sign(reference.delta) == side
            # at γ = v_y = 0 the rear axle has no slip angle: the front tyre alone gives m a_y, so δ = m a_y / C_f
            # in its linear range
            assert reference.delta == pytest.approx(side * P.m * 0.5 / cornering_stiffness(P)[0], rel=0.02)
            u = motion.step(Reference(reference.delta, 7.0), estimate, 0.0, DT)
            assert np.sign(u[0]) == side and u[1] == u[2]
