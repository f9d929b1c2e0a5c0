"""Plant physics: linear bicycle theory, symmetry, actuator limits, low speed, integration accuracy."""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
import pytest

from moose.params import ParamError, VehicleParams
from moose.vehicle import (
    DELTA,
    GAMMA,
    OMEGA_RL,
    OMEGA_RR,
    THETA,
    VX,
    VY,
    VehiclePlant,
    X,
    Y,
    initial_state,
    slip_time_constant,
)
from moose.vehicle import (
    RK4_STABILITY as RK4_LIMIT,
)

P = VehicleParams()


def steady(params: VehicleParams, delta: float, vx: float = 7.0, seconds: float = 4.0,
           torque: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    plant = VehiclePlant(params)
    state = initial_state(params, vx=vx)
    state[DELTA] = delta
    plant.reset(state)
    plant.step(np.array([0.0, *torque]), int(seconds * 1000))
    return plant.state


def test_straight_running_is_an_equilibrium() -> None:
    plant = VehiclePlant(P)
    xdot = plant.derivatives(initial_state(P, x=1.0, y=2.0, theta=0.5, vx=6.0), np.zeros(3))
    assert xdot[X] == pytest.approx(6.0 * np.cos(0.5)) and xdot[Y] == pytest.approx(6.0 * np.sin(0.5))
    assert np.all(xdot[THETA:] == 0.0)


@pytest.mark.parametrize("vx", [4.0, 7.0])
def test_small_steer_yaw_rate_matches_linear_bicycle(vx: float) -> None:
    delta = 0.01
    state = steady(P, delta, vx)
    c_f = P.mu * P.Fzf * P.By * P.Cy  # cornering stiffness: slope of eq. (fy) at alpha = 0
    c_r = P.mu * P.Fzr * P.By * P.Cy
    # understeer gradient (rad per m/s^2): zero here, since static loads make C_f / C_r = l_r / l_f (neutral steer)
    k_us = P.m / P.wheelbase * (P.lr / c_f - P.lf / c_r)
    v = state[VX]
    gamma_theory = v * delta / (P.wheelbase + k_us * v**2)
    beta_theory = gamma_theory * (P.lr / v - P.m * P.lf * v / (P.wheelbase * c_r))
    assert state[GAMMA] == pytest.approx(gamma_theory, rel=0.005)
    assert state[VY] / v == pytest.approx(beta_theory, rel=0.02, abs=2e-6)
    # steady cornering: the IMU's lateral specific force is the centripetal v_x gamma
    plant = VehiclePlant(P)
    assert plant.imu_specific_force(state, np.zeros(3))[1] == pytest.approx(v * state[GAMMA], rel=1e-3)


def magic(slip: float, mu_fz: float, B: float, C: float) -> float:
    return mu_fz * math.sin(C * math.atan(B * slip))


def reference_derivative(t: float, s: np.ndarray, p: VehicleParams, delta_of_t: Callable[[float], float],
                         torques: tuple[float, float]) -> np.ndarray:
    """The single-track model written as vector mechanics, independently of moose.vehicle: each tyre's force in
    its own frame, rotated into the body frame, applied at its contact point (front axle at (l_f, 0), rear wheels
    at (−l_r, ±b/2)); contact-point velocities v + γ × p; Newton–Euler in the rotating body frame.  The slip
    definitions are the plant's documented ones (bounded denominators, β ≈ v_y / v̄)."""
    x, y, theta, vx, vy, gamma, w_rl, w_rr = s
    delta = delta_of_t(t)
    v_bar = max(vx, p.v_low)
    points = {"front": (p.lf, 0.0), "rl": (-p.lr, p.track / 2), "rr": (-p.lr, -p.track / 2)}
    velocity = {k: (vx - gamma * py, vy + gamma * px) for k, (px, py) in points.items()}
    alpha_f = delta - velocity["front"][1] / v_bar
    alpha_r = -velocity["rl"][1] / v_bar  # both rear wheels share the lateral velocity
    forces = {"front": np.array([-math.sin(delta), math.cos(delta)]) * magic(alpha_f, p.mu * p.Fzf, p.By, p.Cy)}
    omega = {"rl": w_rl, "rr": w_rr}
    wheel_force = {}
    for k in ("rl", "rr"):
        v_w = velocity[k][0]
        slip = (p.r * omega[k] - v_w) / max(abs(v_w), p.r * abs(omega[k]), p.v_low)
        wheel_force[k] = magic(slip, 0.5 * p.mu * p.Fzr, p.Bx, p.Cx)
        forces[k] = np.array([wheel_force[k], 0.5 * magic(alpha_r, p.mu * p.Fzr, p.By, p.Cy)])
    total = sum(forces.values())
    moment = sum(px * forces[k][1] - py * forces[k][0] for k, (px, py) in points.items())
    t_rl, t_rr = (min(max(T, -p.T_max), p.T_max) for T in torques)
    return np.array([
        vx * math.cos(theta) - vy * math.sin(theta), vx * math.sin(theta) + vy * math.cos(theta), gamma,
        total[0] / p.m + vy * gamma, total[1] / p.m - vx * gamma, moment / p.Izz,
        (t_rl - p.r * wheel_force["rl"]) / p.J_wr, (t_rr - p.r * wheel_force["rr"]) / p.J_wr,
    ])


SEGMENTS = [  # (seconds, EPS rate command, T_rl, T_rr): steering both ways into the stop, uneven drive, braking
    (0.6, 0.6, 80.0, 20.0), (0.5, -1.5, -30.0, 60.0), (0.4, 5.0, 250.0, -250.0), (0.5, -0.3, -150.0, -150.0),
]


@pytest.mark.parametrize("mu, v0", [(0.8, 8.0), (0.3, 6.0), (1.0, 1.0)])
def test_the_plant_follows_an_independent_model_and_integrator(mu: float, v0: float) -> None:
    """Against scipy's DOP853 at tight tolerances on the independently written model above: every state,
    after every input segment, to 1e-5 of its scale (RK4 at 1 kHz is far more accurate than that)."""
    from scipy.integrate import solve_ivp

    p = VehicleParams(mu=mu)
    plant = VehiclePlant(p)
    plant.reset(initial_state(p, vx=v0))
    t0, delta0 = 0.0, 0.0
    for seconds, rate, t_rl, t_rr in SEGMENTS:
        start = plant.state
        slope = min(max(rate, -p.delta_rate_max), p.delta_rate_max)

        def delta_of_t(t: float, t0: float = t0, delta0: float = delta0, slope: float = slope) -> float:
            return min(max(delta0 + slope * (t - t0), -p.delta_max), p.delta_max)

        sol = solve_ivp(reference_derivative, (t0, t0 + seconds), start[:DELTA], method="DOP853", rtol=1e-10,
                        atol=1e-10, max_step=2e-3, args=(p, delta_of_t, (t_rl, t_rr)))
        end = plant.step(np.array([rate, t_rl, t_rr]), int(round(seconds * 1000)))
        t0 += seconds
        delta0 = delta_of_t(t0)
        assert end[DELTA] == pytest.approx(delta0, abs=1e-12)
        scale = np.maximum(np.abs(sol.y[:, -1]), 1.0)
        assert np.max(np.abs(end[:DELTA] - sol.y[:, -1]) / scale) < 1e-5, (end[:DELTA], sol.y[:, -1])
        # the IMU's specific force is the sum of the tyre forces over the mass
        u = np.array([rate, t_rl, t_rr])
        xdot = reference_derivative(t0, end[:DELTA], p, delta_of_t, (t_rl, t_rr))
        assert plant.imu_specific_force(end, u) == pytest.approx(
            (xdot[VX] - end[VY] * end[GAMMA], xdot[VY] + end[VX] * end[GAMMA]), abs=1e-9)
        assert plant.specific_force == pytest.approx(plant.imu_specific_force(end, u), abs=1e-9)
        assert plant.derivatives(end, u)[:DELTA] == pytest.approx(xdot, abs=1e-9)
    assert plant.t == pytest.approx(sum(s[0] for s in SEGMENTS))


@pytest.mark.parametrize("t_rl, t_rr", [(100.0, -100.0), (-50.0, 50.0)])
def test_uneven_rear_torques_yaw_the_car_towards_the_weaker_wheel(t_rl: float, t_rr: float) -> None:
    """Closed form, linear single-track model with a direct yaw moment M_z = (T_rr − T_rl) b / (2 r): at neutral
    steer (C_f l_f = C_r l_r, Table I's static loads) yaw decouples from side slip, and the steady yaw rate is
    γ = M_z v / (C_f l_f² + C_r l_r²).  More torque on the left wheel turns the car right (γ < 0, REP-103)."""
    c_f, c_r = P.mu * P.Fzf * P.By * P.Cy, P.mu * P.Fzr * P.By * P.Cy
    assert c_f * P.lf == pytest.approx(c_r * P.lr)
    v = 5.0
    state = steady(P, 0.0, v, seconds=1.5, torque=(t_rl, t_rr))
    moment = (t_rr - t_rl) * P.track / (2 * P.r)
    assert state[GAMMA] == pytest.approx(moment * v / (c_f * P.lf**2 + c_r * P.lr**2), rel=0.03)
    assert np.sign(state[THETA]) == np.sign(state[Y]) == np.sign(t_rr - t_rl)
    assert np.sign(state[OMEGA_RL] - state[OMEGA_RR]) == np.sign(t_rl - t_rr)


def test_steering_rate_and_angle_limits() -> None:
    p = VehicleParams(delta_rate_max=1.0)
    plant = VehiclePlant(p)
    plant.reset(initial_state(p, vx=5.0))
    plant.step(np.array([50.0, 0.0, 0.0]), 100)  # 0.1 s at the rate limit
    assert plant.state[DELTA] == pytest.approx(0.1, abs=1e-9)
    history = [plant.step(np.array([50.0, 0.0, 0.0]), 1)[DELTA] for _ in range(400)]
    assert max(history) == p.delta_max  # reaches the stop exactly, never beyond
    assert np.all(np.diff(history) >= 0.0)  # no chattering at the stop
    assert history[199] == pytest.approx(p.delta_max, abs=1e-12)
    plant.step(np.array([-50.0, 0.0, 0.0]), 10)
    assert plant.state[DELTA] == pytest.approx(p.delta_max - 0.01, abs=1e-9)


def test_the_limit_is_reached_inside_a_step_without_overshoot() -> None:
    start = initial_state(P, vx=7.0)
    start[DELTA] = P.delta_max - 0.0004  # the limit lies 0.4 ms into the next 1 ms step
    plant = VehiclePlant(P)
    plant.reset(start)
    plant.step(np.array([1e4, 0.0, 0.0]), 1)  # the command is clipped at the rate limit
    assert plant.state[DELTA] == P.delta_max
    plant.step(np.array([1e4, 0.0, 0.0]), 1)
    assert plant.state[DELTA] == P.delta_max
    plant.step(np.array([-100.0, 0.0, 0.0]), 1)
    assert plant.state[DELTA] == pytest.approx(P.delta_max - P.delta_rate_max * 1e-3, abs=1e-12)


def test_reset_refuses_a_steering_angle_beyond_the_limit() -> None:
    state = initial_state(P)
    state[DELTA] = P.delta_max + 0.01
    with pytest.raises(ValueError, match="DELTA"):
        VehiclePlant(P).reset(state)


def test_standstill_stays_at_rest_and_torque_is_clipped() -> None:
    plant = VehiclePlant(P)
    plant.reset(initial_state(P, vx=0.0))
    plant.step(np.zeros(3), 1000)
    assert np.all(plant.state == 0.0)
    plant.step(np.array([0.0, 1e4, 1e4]), 1000)  # clipped to T_max
    state = plant.state
    assert np.all(np.isfinite(state))
    # at most the traction limit mu F_zr / m over one second, at most T_max per wheel
    assert 0.0 < state[VX] <= min(P.mu * P.Fzr, 2 * P.T_max / P.r) / P.m * 1.0 + 1e-6
    clipped = VehiclePlant(P)
    clipped.reset(initial_state(P, vx=0.0))
    clipped.step(np.array([0.0, P.T_max, P.T_max]), 1000)
    assert clipped.state == pytest.approx(state, abs=1e-12)


def test_wheel_slip_decays_without_oscillation_at_standstill() -> None:
    """The v_low bound keeps the stiff slip ODE stable under RK4 at 1 kHz (mu = 1, worst case)."""
    p = VehicleParams(mu=1.0)
    plant = VehiclePlant(p)
    state = initial_state(p)
    state[[OMEGA_RL, OMEGA_RR]] = 2.0  # spinning wheels on a car at rest
    plant.reset(state)
    slips = []
    for _ in range(16):
        s = plant.step(np.zeros(3), 1)
        slips.append(p.r * s[OMEGA_RL] - s[VX])
    slips = np.array(slips)
    assert np.all(np.isfinite(slips)) and np.all(slips > 0.0) and np.all(np.diff(slips) < 0.0)
    # once the slip is small, each step multiplies it by RK4's amplification factor
    # R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24 at z = -dt / tau_lambda (|R| < 1: stable)
    z = -1e-3 / slip_time_constant(p, p.v_low)
    assert -RK4_LIMIT < z < -1.0  # a stiff case: explicit Euler (|1 + z| < 1 needs z > -2) is near its edge
    amplification = 1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24
    assert np.all(slips[9:] / slips[8:-1] == pytest.approx(amplification, rel=0.01))
    assert plant.state[VX] < 0.05  # the wheels' momentum only nudges the car


def test_slip_time_constant_matches_the_linearised_plant() -> None:
    plant = VehiclePlant(P)
    state = initial_state(P, vx=8.0)
    u = np.zeros(3)
    eps = 1e-6
    # Jacobian of the (wheel, v_x) subsystem by central differences of the plant's own derivatives
    rows = []
    for i in (OMEGA_RL, OMEGA_RR, VX):
        dp, dm = state.copy(), state.copy()
        dp[i] += eps
        dm[i] -= eps
        rows.append((plant.derivatives(dp, u) - plant.derivatives(dm, u))[[OMEGA_RL, OMEGA_RR, VX]] / (2 * eps))
    jac = np.array(rows).T
    fastest = -np.min(np.linalg.eigvals(jac).real)
    assert fastest == pytest.approx(1.0 / slip_time_constant(P, 8.0), rel=0.02)


def test_unstable_step_is_refused() -> None:
    with pytest.raises(ParamError, match="dt = "):
        VehiclePlant(P, dt=0.02)
    with pytest.raises(ParamError, match="dt = "):
        VehiclePlant(VehicleParams(mu=3.0, v_low=2.0))
    VehiclePlant(VehicleParams(mu=3.0, v_low=3.0))  # a higher bound restores stability


def test_torque_accelerates_like_the_nominal_plant() -> None:
    plant = VehiclePlant(P)
    plant.reset(initial_state(P, vx=5.0))
    torque = 50.0
    plant.step(np.array([0.0, torque, torque]), 1000)
    j_n = P.J_wr + P.r**2 * P.m / 2 * (1 - 0.05)
    expected = 5.0 + P.r * torque / j_n * 1.0  # P_n(s): wheel speed ramp, v = r omega
    assert plant.state[VX] == pytest.approx(expected, rel=0.03)
    assert plant.state[OMEGA_RL] * P.r > plant.state[VX]  # driving slip


def test_rk4_converges_with_fourth_order() -> None:
    def run(dt: float) -> np.ndarray:
        plant = VehiclePlant(P, dt=dt)
        plant.reset(initial_state(P, vx=7.0))
        plant.step(np.array([0.2, 60.0, 20.0]), int(round(1.0 / dt)))
        return plant.state

    reference, fine, coarse = run(2.5e-4), run(1e-3), run(2e-3)
    scale = np.maximum(np.abs(reference), 1.0)
    e_fine = np.max(np.abs(fine - reference) / scale)
    e_coarse = np.max(np.abs(coarse - reference) / scale)
    assert e_fine < 1e-5
    assert 8.0 < e_coarse / e_fine < 32.0  # 2^4 = 16 for a fourth-order method


def test_friction_bounds_lateral_acceleration() -> None:
    peaks = {}
    for mu in (0.3, 0.8):
        p = VehicleParams(mu=mu)
        plant = VehiclePlant(p)
        plant.reset(initial_state(p, vx=10.0))  # fast enough that delta_max saturates both axles
        peak = 0.0
        for _ in range(200):
            plant.step(np.array([2.0, 0.0, 0.0]), 10)
            peak = max(peak, abs(plant.specific_force[1]))
        peaks[mu] = peak
        assert 0.95 * mu * p.g < peak <= mu * p.g * (1 + 1e-9)
    assert peaks[0.8] / peaks[0.3] == pytest.approx(0.8 / 0.3, rel=0.03)


def test_bad_input_is_refused() -> None:
    plant = VehiclePlant(P)
    with pytest.raises(ValueError, match="u = "):
        plant.step(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="n = "):
        plant.step(np.zeros(3), 0)
    with pytest.raises(ValueError, match="state = "):
        plant.reset(np.zeros(4))


def test_state_time_and_steps_of_the_plant_object() -> None:
    plant = VehiclePlant(P)
    start = initial_state(P, x=1.0, y=-2.0, theta=0.3, vx=6.0)
    assert list(start) == pytest.approx([1.0, -2.0, 0.3, 6.0, 0.0, 0.0, 6.0 / P.r, 6.0 / P.r, 0.0])  # rolling wheels
    plant.reset(start, t=4.0)
    start[X] = 99.0
    assert plant.state[X] == 1.0 and plant.t == 4.0  # reset copied the state
    view = plant.state
    view[X] = 50.0
    assert plant.state[X] == 1.0  # the property is a copy
    with pytest.raises(RuntimeError, match="after the first step"):
        _ = plant.specific_force
    u = np.array([0.3, 80.0, 40.0])
    chunked = plant.step(u, 23)  # two chunks of ten and three single steps
    assert plant.t == pytest.approx(4.023)
    single = VehiclePlant(P)
    single.reset(initial_state(P, x=1.0, y=-2.0, theta=0.3, vx=6.0))
    for _ in range(23):
        single.step(u, 1)
    assert chunked == pytest.approx(single.state, abs=1e-12)
    assert plant.specific_force == pytest.approx(single.specific_force, abs=1e-12)
    assert plant.step(u, np.int64(2)).shape == (9,)


@pytest.mark.parametrize("n", [True, 1.0, -1, "2"])
def test_a_bad_number_of_steps_is_refused(n: object) -> None:
    with pytest.raises(ValueError, match=r"^n = .* is invalid: expected a positive number of steps$"):
        VehiclePlant(P).step(np.zeros(3), n)  # type: ignore[arg-type]


@pytest.mark.parametrize("u", [np.zeros(2), np.zeros((3, 1)), np.array([0.0, np.inf, 0.0])])
def test_bad_inputs_are_refused(u: np.ndarray) -> None:
    with pytest.raises(ValueError, match=r"(?s)^u = .* is invalid: expected 3 finite plant inputs$"):
        VehiclePlant(P).step(u)


@pytest.mark.parametrize("state", [np.zeros(8), np.full(9, np.nan)])
def test_bad_states_are_refused(state: np.ndarray) -> None:
    with pytest.raises(ValueError, match=r"(?s)^state = .* is invalid: expected 9 finite values$"):
        VehiclePlant(P).reset(state)


@pytest.mark.parametrize("dt", [0.0, -1e-3, math.inf, math.nan, "0.001"])
def test_a_bad_step_is_refused(dt: object) -> None:
    with pytest.raises(ParamError, match=r"^dt = .* is invalid: expected a positive step \(s\)$"):
        VehiclePlant(P, dt=dt)  # type: ignore[arg-type]


def test_the_stability_bound_of_the_step_is_sharp() -> None:
    tau = slip_time_constant(P, P.v_low)
    VehiclePlant(P, dt=RK4_LIMIT * tau * (1 - 1e-9))
    with pytest.raises(ParamError, match="RK4 needs dt <"):
        VehiclePlant(P, dt=RK4_LIMIT * tau)
    # τ_λ grows with the slip denominator: v̄ / (k_x (r² / J + 2 / m)), k_x = μ F_zr / 2 · B_x C_x
    assert slip_time_constant(P, 4.0) == pytest.approx(2.0 * slip_time_constant(P, 2.0))
    assert slip_time_constant(VehicleParams(mu=0.4), 2.0) == pytest.approx(2.0 * tau)


def test_steering_rests_at_the_stop_and_leaves_it_at_once() -> None:
    plant = VehiclePlant(P)
    state = initial_state(P, vx=5.0)
    state[DELTA] = -P.delta_max
    plant.reset(state)
    assert plant.derivatives(plant.state, np.array([-0.5, 0.0, 0.0]))[DELTA] == 0.0  # pushing into the stop
    assert plant.derivatives(plant.state, np.array([0.5, 0.0, 0.0]))[DELTA] == 0.5  # away from it
    assert plant.derivatives(plant.state, np.array([9.0, 0.0, 0.0]))[DELTA] == P.delta_rate_max  # saturated
    state[DELTA] = P.delta_max
    assert VehiclePlant(P).derivatives(state, np.array([0.5, 0.0, 0.0]))[DELTA] == 0.0
    assert VehiclePlant(P).derivatives(state, np.array([-9.0, 0.0, 0.0]))[DELTA] == -P.delta_rate_max


def test_a_new_plant_is_at_rest_at_time_zero_with_no_force_yet() -> None:
    plant = VehiclePlant(P)
    assert plant.t == 0.0 and list(plant.state) == [0.0] * 9
    with pytest.raises(RuntimeError, match="after the first step"):
        _ = plant.specific_force
    plant.reset([0, 0, 0, 5, 0, 0, 16, 16, 0])  # integers are taken as numbers
    assert plant.state.dtype == np.float64
    before = plant.t
    plant.step(np.zeros(3))  # one step by default
    assert plant.t == pytest.approx(before + plant.dt)


def test_the_casadi_step_is_the_plants_step() -> None:
    from moose.vehicle import rk4_step_function, vehicle_vector

    plant = VehiclePlant(P)
    start = initial_state(P, vx=6.0)
    plant.reset(start)
    u = np.array([0.4, 70.0, -20.0])
    expected = plant.step(u, 1)
    step = np.asarray(rk4_step_function()(start, u, vehicle_vector(P), plant.dt), dtype=float).ravel()
    assert step == pytest.approx(expected, abs=1e-12)


def test_the_refused_step_names_the_bound() -> None:
    bound = RK4_LIMIT * slip_time_constant(P, P.v_low)
    with pytest.raises(ParamError, match=rf"RK4 needs dt < {bound:.3g} s for the wheel-slip time constant"):
        VehiclePlant(P, dt=0.02)
