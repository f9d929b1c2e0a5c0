"""FBL: round trip through the plant's own lateral dynamics, saturation, symmetry, low speed."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from moose.params import VehicleParams
from moose.planner.fbl import FeedbackLinearization
from moose.schema import FblParams
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


@pytest.mark.parametrize("delta, vy, gamma, theta",
                         [(0.03, 0.1, 0.1, 0.2), (-0.05, -0.2, -0.2, -0.4), (0.08, 0.0, 0.3, 1.0)])
def test_round_trip_recovers_the_steering_angle(delta: float, vy: float, gamma: float, theta: float) -> None:
    accel, estimate = global_acceleration(delta, vy, gamma, theta)
    fbl = FeedbackLinearization(FblParams(), P, 0.2)
    # the plant keeps cos(delta) and the small -F_yf sin(delta) term; the FBL uses eq. (eomdyn)
    reference = fbl.reference(accel, estimate)
    assert reference.delta == pytest.approx(delta, abs=0.004)
    # the speed reference is v_x one planning period ahead at the plant's own v̇_x (eq. (dvxnl): a_x + v_y γ)
    state = initial_state(P, vx=7.0)
    state[[DELTA, VY, GAMMA, THETA]] = delta, vy, gamma, theta
    vx_dot = VehiclePlant(P).derivatives(state, np.zeros(3))[VX]
    assert reference.vx == pytest.approx(7.0 + 0.2 * vx_dot, abs=1e-9)


def test_saturates_beyond_the_peak_and_at_the_steering_limit() -> None:
    fbl = FeedbackLinearization(FblParams(), P, 0.2)
    straight = StateEstimate(0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0)
    huge = fbl.reference(np.array([0.0, 50.0]), straight).delta
    assert huge == pytest.approx(min(peak_slip(P.By, P.Cy), P.delta_max))
    assert fbl.reference(np.array([0.0, -50.0]), straight).delta == pytest.approx(-huge)


def test_speed_reference_and_standstill() -> None:
    fbl = FeedbackLinearization(FblParams(), P, 0.2)
    ref = fbl.reference(np.array([2.0, 0.0]), StateEstimate(0.0, 0.0, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0))
    assert ref.vx == pytest.approx(5.4)
    stopped = fbl.reference(np.array([-3.0, 1.0]), StateEstimate(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0))
    assert math.isfinite(stopped.delta) and stopped.vx == 0.0


@pytest.mark.parametrize("vx", [3.0, 5.0, 10.0])
def test_round_trip_at_several_speeds(vx: float) -> None:
    """Straight running, pure lateral request: δ* reproduces the acceleration the plant develops at δ*."""
    plant = VehiclePlant(P)
    fbl = FeedbackLinearization(FblParams(), P, 0.2)
    estimate = StateEstimate(0.0, 0.0, 0.0, 0.0, vx, 0.0, 0.0, 0.0)
    for a_y in (0.3, 1.0, 0.95 * P.mu * P.Fzf / P.m):  # at straight running only the front axle pushes
        delta = fbl.reference(np.array([0.0, a_y]), estimate).delta
        state = initial_state(P, vx=vx)
        state[DELTA] = delta
        achieved = plant.imu_specific_force(state, np.zeros(3))[1]
        # the plant's cos(delta) makes the achieved force at most 1 - cos(delta) smaller
        assert achieved == pytest.approx(a_y, rel=1 - math.cos(delta) + 1e-3)


def test_mirror_symmetry() -> None:
    fbl = FeedbackLinearization(FblParams(), P, 0.2)
    for (aX, aY), (theta, vy, gamma) in (((0.5, 2.0), (0.3, 0.1, 0.2)), ((-1.0, 4.0), (-0.7, -0.3, 0.4))):
        left = fbl.reference(np.array([aX, aY]), StateEstimate(0.0, 1.0, 2.0, theta, 6.0, vy, gamma, 0.1))
        right = fbl.reference(np.array([aX, -aY]), StateEstimate(0.0, 1.0, -2.0, -theta, 6.0, -vy, -gamma, -0.1))
        assert right.delta == pytest.approx(-left.delta, abs=1e-12)
        assert right.vx == pytest.approx(left.vx, abs=1e-12)
        assert left.delta != 0.0


def test_steering_grows_with_the_lateral_request_up_to_the_peak() -> None:
    fbl = FeedbackLinearization(FblParams(), P, 0.2)
    estimate = StateEstimate(0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0)
    requests = np.linspace(-12.0, 12.0, 97)
    deltas = np.array([fbl.reference(np.array([0.0, a]), estimate).delta for a in requests])
    assert np.all(np.diff(deltas) >= 0.0)
    peak = min(peak_slip(P.By, P.Cy), P.delta_max)
    assert np.max(np.abs(deltas)) == pytest.approx(peak)
    # beyond what the front axle can give at straight running (mu F_zf / m) the answer is the saturated one
    beyond = np.abs(requests) > P.mu * P.Fzf / P.m
    assert np.all(np.abs(deltas[beyond]) == pytest.approx(peak)) and np.all(np.abs(deltas[~beyond]) < peak)


def test_rotation_to_body_axes() -> None:
    """A global request along the car's own lateral axis is a pure lateral request whatever the heading."""
    fbl = FeedbackLinearization(FblParams(), P, 0.2)
    for theta in (0.0, 0.8, -2.0, math.pi):
        estimate = StateEstimate(0.0, 0.0, 0.0, theta, 6.0, 0.0, 0.0, 0.0)
        lateral = 2.0 * np.array([-math.sin(theta), math.cos(theta)])
        longitudinal = 1.5 * np.array([math.cos(theta), math.sin(theta)])
        ref = fbl.reference(lateral + longitudinal, estimate)
        straight = fbl.reference(np.array([1.5, 2.0]), StateEstimate(0.0, 0.0, 0.0, 0.0, 6.0, 0.0, 0.0, 0.0))
        assert ref.delta == pytest.approx(straight.delta, abs=1e-12)
        assert ref.vx == pytest.approx(6.0 + 0.2 * 1.5, abs=1e-12)


def test_finite_near_standstill() -> None:
    fbl = FeedbackLinearization(FblParams(), P, 0.2)
    for vx in (-0.5, 0.0, 1e-9, 0.3, 1.0):
        for accel in ((0.0, 3.0), (-2.0, -9.0), (1.0, 0.0)):
            ref = fbl.reference(np.array(accel), StateEstimate(0.0, 0.0, 0.0, 0.0, vx, 0.2, 0.5, 0.0))
            assert math.isfinite(ref.delta) and abs(ref.delta) <= P.delta_max
            assert math.isfinite(ref.vx) and ref.vx >= 0.0


def test_the_vehicles_mu_is_the_assumed_tyre() -> None:
    estimate = StateEstimate(0.0, 0.0, 0.0, 0.0, 7.0, 0.0, 0.0, 0.0)
    nominal = FeedbackLinearization(FblParams(), P, 0.2).reference(np.array([0.0, 0.3]), estimate).delta
    slippery_vehicle = dataclasses.replace(P, mu=P.mu / 2)
    slippery = FeedbackLinearization(FblParams(), slippery_vehicle, 0.2).reference(np.array([0.0, 0.3]), estimate).delta
    assert slippery > nominal * 1.8  # half the cornering stiffness: about twice the slip angle
