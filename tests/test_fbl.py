"""FBL: round trip through the plant's own lateral dynamics, saturation, symmetry, low speed."""
from __future__ import annotations

import math

import numpy as np
import pytest

from moose.fbl import FblParams, FeedbackLinearization
from moose.params import VehicleParams
from moose.signals import StateEstimate
from moose.tire import peak_slip
from moose.vehicle import DELTA, GAMMA, THETA, VX, VY, VehiclePlant, initial_state

P = VehicleParams()


def global_acceleration(delta: float, vy: float, gamma: float, theta: float) -> tuple[np.ndarray, StateEstimate]:
    plant = VehiclePlant(P)
    state = initial_state(P, vx=7.0)
    state[[DELTA, VY, GAMMA, THETA]] = delta, vy, gamma, theta
    xdot = plant.derivatives(state, np.zeros(3))
    ax = xdot[VX] - vy * gamma
    ay = xdot[VY] + 7.0 * gamma
    c, s = math.cos(theta), math.sin(theta)
    estimate = StateEstimate(0.0, 0.0, 0.0, theta, 7.0, vy, gamma, delta)
    return np.array([c * ax - s * ay, s * ax + c * ay]), estimate


@pytest.mark.parametrize("delta, vy, gamma, theta", [(0.03, 0.1, 0.1, 0.2), (-0.05, -0.2, -0.2, -0.4), (0.08, 0.0, 0.3, 1.0)])
def test_round_trip_recovers_the_steering_angle(delta: float, vy: float, gamma: float, theta: float) -> None:
    accel, estimate = global_acceleration(delta, vy, gamma, theta)
    fbl = FeedbackLinearization(FblParams(), P)
    # the plant keeps cos(delta) and the small -F_yf sin(delta) term; the FBL uses eq. (eomdyn)
    assert fbl.reference(accel, estimate).delta == pytest.approx(delta, abs=0.004)


def test_saturates_beyond_the_peak_and_at_the_steering_limit() -> None:
    fbl = FeedbackLinearization(FblParams(), P)
    straight = StateEstimate(0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0)
    huge = fbl.reference(np.array([0.0, 50.0]), straight).delta
    assert huge == pytest.approx(min(peak_slip(P.By, P.Cy), P.delta_max))
    assert fbl.reference(np.array([0.0, -50.0]), straight).delta == pytest.approx(-huge)


def test_speed_reference_and_standstill() -> None:
    fbl = FeedbackLinearization(FblParams(t_s=0.2), P)
    ref = fbl.reference(np.array([2.0, 0.0]), StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0))
    assert ref.vx == pytest.approx(5.4)
    stopped = fbl.reference(np.array([-3.0, 1.0]), StateEstimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert math.isfinite(stopped.delta) and stopped.vx == 0.0
