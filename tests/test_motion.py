"""Motion control on the real plant: speed loop pole placement, anti-windup, EPS tracking, limits."""
from __future__ import annotations

import numpy as np
import pytest

from moose.motion import MotionController, MotionParams
from moose.params import VehicleParams
from moose.signals import Reference, StateEstimate
from moose.vehicle import DELTA, VX, VehiclePlant, initial_state

P = VehicleParams()


def run(reference: Reference, seconds: float, vx0: float = 5.0, params: MotionParams = MotionParams()):
    plant, ctrl = VehiclePlant(P), MotionController(params, P)
    plant.reset(initial_state(P, vx=vx0))
    log = []
    for k in range(int(seconds * 100)):
        s = plant.state
        est = StateEstimate(k * 0.01, s[0], s[1], s[2], s[3], s[4], s[5], s[DELTA])
        u = ctrl.step(reference, est, s[DELTA], 0.01)
        assert abs(u[1]) <= P.T_max and u[1] == u[2]
        plant.step(u, 10)
        log.append((k * 0.01 + 0.01, plant.state[VX], plant.state[DELTA], u[1]))
    return np.array(log)


def test_gains_place_a_double_pole() -> None:
    ctrl = MotionController(MotionParams(pole=1.0), P)
    j_n = P.J_wr + P.r**2 * P.m / 2 * 0.95
    assert ctrl.k_p == pytest.approx(2 * j_n) and ctrl.k_i == pytest.approx(j_n)
    # characteristic polynomial J s^2 + K_p s + K_i has a double root at -1
    assert np.roots([j_n, ctrl.k_p, ctrl.k_i]) == pytest.approx([-1.0, -1.0], abs=1e-6)


def test_speed_step_settles_without_steady_state_error() -> None:
    log = run(Reference(delta=0.0, vx=5.5), 8.0)
    assert log[-1, 1] == pytest.approx(5.5, abs=0.02)
    # the feed-forward ramp makes it quick; the double pole keeps the overshoot small
    assert log[np.searchsorted(log[:, 0], 1.0), 1] > 5.3
    assert np.max(log[:, 1]) < 5.5 + 0.1


def test_saturation_and_anti_windup() -> None:
    log = run(Reference(delta=0.0, vx=9.0), 10.0)
    assert np.any(np.abs(log[:, 3]) >= P.T_max - 1e-9)
    assert np.max(log[:, 1]) < 9.0 + 0.3  # no wind-up overshoot after the saturated climb
    assert log[-1, 1] == pytest.approx(9.0, abs=0.05)


def test_eps_first_order_tracking_and_limit() -> None:
    k = 20.0
    log = run(Reference(delta=0.1, vx=5.0), 1.0, params=MotionParams(k_delta=k))
    t63 = log[np.argmax(log[:, 2] >= 0.1 * (1 - np.exp(-1))), 0]
    assert t63 == pytest.approx(1 / k, abs=0.015)
    assert log[-1, 2] == pytest.approx(0.1, abs=1e-3)
    limited = run(Reference(delta=1.0, vx=5.0), 0.5)
    assert np.max(limited[:, 2]) <= P.delta_max + 1e-12
