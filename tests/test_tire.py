"""Slip angles and tyre forces, eqs. (alphas) and (fy): one definition for the plant, the observer and the table."""
from __future__ import annotations

import math

import numpy as np
import pytest

from moose.maneuver import _coefficients, _rates
from moose.observer import StateObserver
from moose.params import VehicleParams
from moose.schema import ObserverParams
from moose.signals import EpsSample, StateEstimate
from moose.state import DELTA, GAMMA, VY
from moose.tire import Axles, lateral_forces, slip_angles
from moose.vehicle import VehiclePlant, initial_state

P = VehicleParams()
# (v_x, v_y, γ, δ): straight, cornering both ways, sliding, and a crawl below v_low (denominator bounded)
STATES = [(7.0, 0.0, 0.0, 0.0), (6.0, 0.3, 0.4, 0.1), (5.0, -0.4, -0.5, -0.2), (8.0, 1.2, 0.9, 0.35),
          (0.5, 0.05, 0.1, 0.3)]


def test_slip_angles_are_eq_alphas_as_printed() -> None:
    # eq. (alphas): α_f = δ − β − l_f γ / v_x, α_r = l_r γ / v_x − β with β ≈ v_y / v_x (rounding aside)
    axles = Axles.of(P, P.mu)
    for vx, vy, gamma, delta in STATES:
        beta = vy / vx
        alpha_f, alpha_r = slip_angles(vy, gamma, delta, vx, axles)
        assert alpha_f == pytest.approx(delta - beta - P.lf * gamma / vx, rel=1e-12, abs=1e-15)
        assert alpha_r == pytest.approx(P.lr * gamma / vx - beta, rel=1e-12, abs=1e-15)


def test_lateral_forces_are_eq_fy_and_peak_at_mu_fz() -> None:
    axles = Axles.of(P, 0.8)
    fyf, fyr = lateral_forces(0.3, 0.4, 0.1, 6.0, axles)
    alpha_f, alpha_r = slip_angles(0.3, 0.4, 0.1, 6.0, axles)
    assert fyf == pytest.approx(0.8 * P.Fzf * math.sin(P.Cy * math.atan(P.By * alpha_f)), rel=1e-14)
    assert fyr == pytest.approx(0.8 * P.Fzr * math.sin(P.Cy * math.atan(P.By * alpha_r)), rel=1e-14)
    peak = math.tan(math.pi / (2.0 * P.Cy)) / P.By  # the front slip α_f = δ at rest in yaw and v_y = 0
    assert lateral_forces(0.0, 0.0, peak, 6.0, axles)[0] == pytest.approx(0.8 * P.Fzf, rel=1e-12)


@pytest.mark.parametrize("vx, vy, gamma, delta", STATES)
def test_the_plant_the_observer_and_the_table_share_one_tyre_law(vx: float, vy: float, gamma: float,
                                                                 delta: float) -> None:
    v_bar = max(vx, P.v_low)
    fyf, fyr = lateral_forces(vy, gamma, delta, v_bar, Axles.of(P, P.mu))
    # the plant, eq. (eom): its IMU's lateral specific force is (F_yf cos δ + F_yr) / m (F_xf = 0)
    state = initial_state(P, vx=vx)
    state[VY], state[GAMMA], state[DELTA] = vy, gamma, delta
    plant = VehiclePlant(P)
    assert plant.imu_specific_force(state, np.zeros(3))[1] == pytest.approx((fyf * math.cos(delta) + fyr) / P.m,
                                                                           rel=1e-12, abs=1e-12)
    # the observer's process model: one explicit Euler step of 1 s (a steering sample predicts to its time)
    observer = StateObserver(ObserverParams(), P, StateEstimate(0.0, 0.0, 0.0, 0.0, vx, vy, gamma, delta))
    observer.update(EpsSample(1.0, delta))
    moved = observer.estimate()
    assert moved.vy - vy == pytest.approx((fyf * math.cos(delta) + fyr) / P.m - vx * gamma, rel=1e-9, abs=1e-12)
    assert moved.gamma - gamma == pytest.approx((fyf * math.cos(delta) * P.lf - fyr * P.lr) / P.Izz, rel=1e-9,
                                                abs=1e-12)
    # the maneuver table, eq. (eomdyn) at its constant speed (no bound: the table's speeds are positive)
    fyf_t, fyr_t = lateral_forces(vy, gamma, delta, vx, Axles.of(P, P.mu))
    vy_dot, gamma_dot, _, _ = _rates(np.array([vy, gamma, 0.0, 0.0]), vx, delta, _coefficients(P, P.mu), np)
    assert vy_dot == pytest.approx((fyf_t + fyr_t) / P.m - vx * gamma, rel=1e-12, abs=1e-12)
    assert gamma_dot == pytest.approx((fyf_t * P.lf - fyr_t * P.lr) / P.Izz, rel=1e-12, abs=1e-12)
