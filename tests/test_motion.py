"""Motion control on the real plant: speed loop pole placement, anti-windup, EPS tracking, limits."""
from __future__ import annotations

import math

import numpy as np
import pytest

from moose.motion import MotionController
from moose.params import ParamError, VehicleParams
from moose.schema import MotionParams
from moose.signals import Reference, StateEstimate
from moose.vehicle import DELTA, VX, VehiclePlant, initial_state

P = VehicleParams()
DT = 0.01
MOTION = MotionParams()


def run(reference: Reference, seconds: float, vx0: float = 5.0, params: MotionParams = MOTION,
        vehicle: VehicleParams = P) -> np.ndarray:
    """Closed loop at 100 Hz on the plant; rows (t, v_x, δ, T, δ̇_cmd)."""
    plant, ctrl = VehiclePlant(vehicle), MotionController(params, vehicle)
    plant.reset(initial_state(vehicle, vx=vx0))
    log = [(0.0, vx0, 0.0, 0.0, 0.0)]
    for k in range(int(round(seconds / DT))):
        s = plant.state
        est = StateEstimate(k * DT, s[0], s[1], s[2], s[3], s[4], s[5], s[DELTA])
        u = ctrl.step(reference, est, s[DELTA], DT)
        assert abs(u[1]) <= vehicle.T_max and u[1] == u[2]  # TDL: equal split within the motor limit
        assert abs(u[0]) <= vehicle.delta_rate_max
        plant.step(u, 10)
        log.append(((k + 1) * DT, plant.state[VX], plant.state[DELTA], u[1], u[0]))
    return np.array(log)


def test_gains_place_a_double_pole() -> None:
    ctrl = MotionController(MotionParams(pole=1.0), P)
    j_n = P.J_wr + P.r**2 * P.m / 2 * 0.95
    assert ctrl.J_n == pytest.approx(j_n)
    # characteristic polynomial J_n s^2 + K_p s + K_i has a double root at -1
    assert np.roots([j_n, ctrl.k_p, ctrl.k_i]) == pytest.approx([-1.0, -1.0], abs=1e-6)
    fast = MotionController(MotionParams(pole=2.5), P)
    assert np.roots([j_n, fast.k_p, fast.k_i]) == pytest.approx([-2.5, -2.5], abs=1e-6)


def test_feedback_loop_has_the_designed_double_pole_dynamics() -> None:
    """Bare PI (no feed-forward), small step: v follows 1 − e^{−t} + t e^{−t} of the nominal design."""
    step = 0.3
    log = run(Reference(delta=0.0, vx=5.0 + step), 10.0, params=MotionParams(feed_forward=False))
    assert np.max(np.abs(log[:, 3])) < P.T_max  # linear regime: the motors never saturate
    t = log[:, 0]
    design = 5.0 + step * (1.0 - np.exp(-t) + t * np.exp(-t))
    assert np.max(np.abs(log[:, 1] - design)) < 0.06 * step
    fine = np.linspace(0.0, 3.0, 30001)
    response = 1.0 - np.exp(-fine) * (1.0 - fine)
    for share in (0.63, 0.9):  # design: 0.43 s and 0.78 s
        t_design = fine[np.argmax(response >= share)]
        t_run = t[np.argmax(log[:, 1] >= 5.0 + share * step)]
        assert t_run == pytest.approx(t_design, abs=0.06), share
    assert np.max(log[:, 1]) == pytest.approx(5.0 + step * (1 + math.exp(-2)), abs=0.03 * step)  # the PI zero
    assert log[-1, 1] == pytest.approx(5.0 + step, abs=2e-3 * step)  # integral action: no steady-state error


def test_feed_forward_delivers_a_feasible_request_without_lag() -> None:
    # the FBL's v_x* = v_x + t_s a with a = 1 m/s^2 (feasible: below r T_max / J_n)
    log = run(Reference(delta=0.0, vx=5.2), 3.0)
    t = log[:, 0]
    assert log[np.searchsorted(t, 0.3), 1] > 5.0 + 0.9 * 0.2
    assert np.max(log[:, 1]) < 5.2 + 0.01
    assert log[-1, 1] == pytest.approx(5.2, abs=2e-3)


@pytest.mark.parametrize("feed_forward", [False, True])
def test_saturation_and_anti_windup(feed_forward: bool) -> None:
    log = run(Reference(delta=0.0, vx=9.0), 10.0, params=MotionParams(feed_forward=feed_forward))
    saturated = np.abs(log[1:, 3]) >= P.T_max - 1e-9
    assert np.sum(saturated) * DT > 1.5  # a long saturated climb
    # after saturation the PI restarts from the error T_max / K_p with an empty integrator:
    # the overshoot is at most e^-2 of it (double pole at -1) instead of the whole wound-up integral
    k_p = MotionController(MotionParams(), P).k_p
    bound = math.exp(-2) * P.T_max / k_p * P.r
    assert np.max(log[:, 1]) - 9.0 < bound + 0.02
    assert log[-1, 1] == pytest.approx(9.0, abs=0.01)


def test_braking_is_symmetric_to_driving() -> None:
    up = run(Reference(delta=0.0, vx=6.0), 4.0, vx0=5.0)
    down = run(Reference(delta=0.0, vx=4.0), 4.0, vx0=5.0)
    assert down[:, 1] - 5.0 == pytest.approx(-(up[:, 1] - 5.0), abs=0.02)
    assert np.min(down[:, 3]) >= -P.T_max


def test_eps_tracks_a_step_with_the_designed_time_constant() -> None:
    k = 20.0
    step = 0.04  # k * step = 0.8 rad/s: below the rate limit, the loop is linear
    log = run(Reference(delta=step, vx=5.0), 1.0, params=MotionParams(k_delta=k))
    # the plant integrates the held rate exactly: delta_n = delta* (1 - (1 - k dt)^n)
    n = np.arange(len(log))
    assert log[:, 2] == pytest.approx(step * (1.0 - (1.0 - k * DT) ** n), abs=1e-12)
    tau = -DT / math.log(1.0 - k * DT)  # 45 ms; 1/k = 50 ms in continuous time
    t63 = log[np.argmax(log[:, 2] >= step * (1 - math.exp(-1))), 0]
    assert tau - 1e-9 <= t63 < tau + DT
    assert log[-1, 2] == pytest.approx(step, abs=1e-6)


def test_steering_limits() -> None:
    limited = run(Reference(delta=1.0, vx=5.0), 1.0)
    assert np.max(limited[:, 2]) == pytest.approx(P.delta_max, abs=1e-4)
    assert np.max(limited[:, 2]) <= P.delta_max
    slow = VehicleParams(delta_rate_max=0.5)
    log = run(Reference(delta=-0.2, vx=5.0), 1.0, vehicle=slow)
    assert np.min(log[:, 4]) == pytest.approx(-0.5)  # the command is clipped at the rate limit
    assert log[np.searchsorted(log[:, 0], 0.2), 2] == pytest.approx(-0.1, abs=1e-9)


def test_reset_forgets_the_integrator_and_the_ramp() -> None:
    vehicle_state = StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0)
    used, fresh = MotionController(MotionParams(), P), MotionController(MotionParams(), P)
    for _ in range(50):
        used.step(Reference(0.0, 8.0), vehicle_state, 0.0, DT)
    used.reset()
    for _ in range(3):
        assert used.step(Reference(0.05, 5.5), vehicle_state, 0.0, DT) == pytest.approx(
            fresh.step(Reference(0.05, 5.5), vehicle_state, 0.0, DT))


def test_invalid_parameters_and_steps_are_refused() -> None:
    with pytest.raises(ParamError, match="pole = -1"):
        MotionParams(pole=-1.0)
    with pytest.raises(ParamError, match="accel_margin = 0"):
        MotionParams(accel_margin=0.0)
    ctrl = MotionController(MotionParams(k_delta=20.0), P)
    estimate = StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0)
    with pytest.raises(ValueError, match="dt = 0.1"):
        ctrl.step(Reference(0.0, 5.0), estimate, 0.0, 0.1)  # K_delta dt = 2: the discrete EPS loop rings


def test_torque_slews_at_the_motors_rate_limit() -> None:
    # a 2 m/s step asks for full torque at once; the motors (and the CAN guard) allow 2000 N m/s
    log = run(Reference(delta=0.0, vx=7.0), 1.0)
    torque = log[1:, 3]
    assert np.max(np.abs(np.diff(np.concatenate([[0.0], torque])))) <= P.torque_rate_max * DT + 1e-9
    assert np.max(torque) == pytest.approx(P.T_max)  # it gets there: 0.1 s at the rate limit
    slow = VehicleParams(torque_rate_max=500.0)
    log = run(Reference(delta=0.0, vx=7.0), 0.3, vehicle=slow)
    assert log[-1, 3] == pytest.approx(500.0 * 0.3, abs=1e-6)  # still ramping: 150 N m after 0.3 s


def test_the_feed_forward_ramp_asks_for_at_most_its_share_of_the_torque() -> None:
    """accel_margin = 0.5: the reference ramps at r · 0.5 T_max / J_n, so the nominal plant needs half the torque;
    the car follows the ramp with the torque near 0.5 T_max, well below the motors' limit."""
    params = MotionParams(accel_margin=0.5)
    log = run(Reference(delta=0.0, vx=9.0), 3.0, params=params)
    j_n = P.J_wr + P.r**2 * P.m / 2 * (1 - params.slip_nominal)
    slope = P.r * 0.5 * P.T_max / j_n  # 0.73 m/s²
    t = log[:, 0]
    ramping = (t > 0.5) & (t < 2.5)
    assert np.max(np.abs(log[ramping, 3])) < 0.6 * P.T_max
    assert np.mean(log[ramping, 3]) == pytest.approx(0.5 * P.T_max, rel=0.1)
    acceleration = np.polyfit(t[ramping], log[ramping, 1], 1)[0]
    assert acceleration == pytest.approx(slope, rel=0.1)


def test_the_step_must_keep_the_discrete_eps_loop_monotone() -> None:
    ctrl = MotionController(MotionParams(k_delta=20.0), P)
    estimate = StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0)
    ctrl.step(Reference(0.1, 5.0), estimate, 0.0, 0.05)  # K_δ dt = 1 exactly: allowed (deadbeat)
    for dt in (0.0, -0.01, 0.0500001):
        with pytest.raises(ValueError, match=rf"^dt = {dt!r} is invalid: expected 0 < dt <= 1/k_delta = 0.05$"):
            ctrl.step(Reference(0.1, 5.0), estimate, 0.0, dt)
