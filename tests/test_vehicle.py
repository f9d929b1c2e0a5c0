"""Plant physics: linear bicycle theory, symmetry, actuator limits, low speed, integration accuracy."""
from __future__ import annotations

import numpy as np
import pytest

from moose.params import VehicleParams
from moose.vehicle import DELTA, GAMMA, OMEGA_RL, THETA, VX, VY, X, Y, VehiclePlant, initial_state

P = VehicleParams()


def steady(params: VehicleParams, delta: float, vx: float = 7.0, seconds: float = 4.0) -> np.ndarray:
    plant = VehiclePlant(params)
    state = initial_state(params, vx=vx)
    state[DELTA] = delta
    plant.reset(state)
    for _ in range(int(seconds * 100)):
        plant.step(np.zeros(3), 10)
    return plant.state


@pytest.mark.parametrize("vx", [4.0, 7.0])
def test_small_steer_yaw_rate_matches_linear_bicycle(vx: float) -> None:
    delta = 0.01
    state = steady(P, delta, vx)
    c_f = P.mu * P.Fzf * P.By * P.Cy
    c_r = P.mu * P.Fzr * P.By * P.Cy
    k_us = P.m / P.wheelbase * (P.lr / c_f - P.lf / c_r)
    gamma_theory = state[VX] * delta / (P.wheelbase + k_us * state[VX] ** 2)
    assert state[GAMMA] == pytest.approx(gamma_theory, rel=0.03)


def test_mirror_symmetry() -> None:
    left, right = steady(P, 0.05, seconds=2.0), steady(P, -0.05, seconds=2.0)
    for i in (Y, THETA, VY, GAMMA):
        assert left[i] == pytest.approx(-right[i], abs=1e-9)
    assert left[X] == pytest.approx(right[X], abs=1e-9)


def test_steering_rate_and_angle_limits() -> None:
    p = VehicleParams(delta_rate_max=1.0)
    plant = VehiclePlant(p)
    plant.reset(initial_state(p, vx=5.0))
    plant.step(np.array([50.0, 0.0, 0.0]), 100)  # 0.1 s at the rate limit
    assert plant.state[DELTA] == pytest.approx(0.1, abs=1e-6)
    plant.step(np.array([50.0, 0.0, 0.0]), 1000)
    assert plant.state[DELTA] == pytest.approx(p.delta_max, abs=1e-12)
    plant.step(np.array([-50.0, 0.0, 0.0]), 10)
    assert plant.state[DELTA] == pytest.approx(p.delta_max - 0.01, abs=1e-6)


def test_standstill_stays_at_rest_and_torque_is_clipped() -> None:
    plant = VehiclePlant(P)
    plant.reset(initial_state(P, vx=0.0))
    plant.step(np.zeros(3), 1000)
    assert np.all(plant.state == 0.0)
    plant.step(np.array([0.0, 1e4, 1e4]), 1000)  # clipped to T_max
    state = plant.state
    assert np.all(np.isfinite(state))
    # at most the traction limit mu F_zr / m over one second
    assert 0.0 < state[VX] <= P.mu * P.Fzr / P.m * 1.0 + 1e-6


def test_torque_accelerates_like_the_nominal_plant() -> None:
    plant = VehiclePlant(P)
    plant.reset(initial_state(P, vx=5.0))
    torque = 50.0
    plant.step(np.array([0.0, torque, torque]), 1000)
    j_n = P.J_wr + P.r**2 * P.m / 2 * (1 - 0.05)
    expected = 5.0 + P.r * torque / j_n * 1.0  # P_n(s): wheel speed ramp, v = r omega
    assert plant.state[VX] == pytest.approx(expected, rel=0.03)
    assert plant.state[OMEGA_RL] * P.r > plant.state[VX]  # driving slip


def test_rk4_converges() -> None:
    coarse, fine = VehiclePlant(P, dt=2e-3), VehiclePlant(P, dt=1e-3)
    for plant in (coarse, fine):
        plant.reset(initial_state(P, vx=7.0))
    for _ in range(100):
        coarse.step(np.array([0.3, 20.0, 20.0]), 5)
        fine.step(np.array([0.3, 20.0, 20.0]), 10)
    assert np.max(np.abs(coarse.state - fine.state)) < 1e-3


def test_friction_bounds_lateral_acceleration() -> None:
    for mu in (0.3, 0.8):
        p = VehicleParams(mu=mu)
        plant = VehiclePlant(p)
        plant.reset(initial_state(p, vx=7.0))
        peak = 0.0
        for _ in range(200):
            plant.step(np.array([2.0, 0.0, 0.0]), 10)
            peak = max(peak, abs(plant.imu_specific_force(plant.state, np.array([2.0, 0.0, 0.0]))[1]))
        assert 0.8 * mu * p.g < peak <= 1.02 * mu * p.g


def test_bad_input_is_refused() -> None:
    plant = VehiclePlant(P)
    with pytest.raises(ValueError, match="u = "):
        plant.step(np.array([np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="state = "):
        plant.reset(np.zeros(4))
