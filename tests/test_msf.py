"""MSF planner on the kinematic model: clears the danger zone, follows the scaled maneuver, mirrors, returns."""
from __future__ import annotations

import math

import numpy as np
import pytest

from moose.detector import ObstacleDetector
from moose.maneuver import MaxSteeringTable
from moose.msf import MsfPlanner, zoh_rollout
from moose.params import ParamError, VehicleParams
from moose.schema import Config, MsfParams
from moose.signals import Obstacle, PlannerInput, StateEstimate
from moose.schema import DetectorParams, ManeuverParams

VEHICLE = VehicleParams(mu=0.3)
GRID = Config(vehicle=VEHICLE).grid
T_S = 0.2


@pytest.fixture(scope="module")
def table() -> MaxSteeringTable:
    return MaxSteeringTable.build(VEHICLE, ManeuverParams())


def estimate_of(t: float, s: np.ndarray) -> StateEstimate:
    """A kinematic state [x, y, v_X, v_Y] as an estimate (no sideslip)."""
    return StateEstimate(t, s[0], s[1], math.atan2(s[3], s[2]), math.hypot(s[2], s[3]), 0.0, 0.0, 0.0)


def closed_loop(table: MaxSteeringTable, v: float, zone: Obstacle, steps: int = 40,
                params: MsfParams = MsfParams()) -> tuple[np.ndarray, list]:
    """Detector + MSF re-planning at 5 Hz on the kinematic model, applying the first input each time.

    Returns the states every 10 ms (the exact zero-order-hold parabolas between plans) and the plans.
    """
    detector = ObstacleDetector(DetectorParams(), table)
    planner = MsfPlanner(params, GRID, table)
    state = np.array([0.0, 0.0, v, 0.0])
    fine, plans = [state], []
    for k in range(steps):
        t = k * T_S
        est = estimate_of(t, state)
        plan = planner.plan(PlannerInput(t, est, detector.update(t, est, [zone]), v, None))
        plans.append(plan)
        assert np.all(np.abs(plan.accel) <= 6.0 + 1e-12)
        np.testing.assert_allclose(plan.predicted[0], state)
        for j in range(1, 21):  # exact motion inside the step
            fine.append(zoh_rollout(state, plan.accel[:1], 0.01 * j)[1])
        state = plan.predicted[1]
    return np.array(fine), plans


CASES = [(v, tau, nu) for v in (5.0, 6.0, 7.0) for tau in (1.4, 2.0, 3.0) for nu in (0.2, 0.5, 0.9)]


@pytest.mark.parametrize("v, tau, nu", CASES)
def test_clears_the_danger_zone_and_follows_the_scaled_maneuver(
    table: MaxSteeringTable, v: float, tau: float, nu: float
) -> None:
    w = nu * table.y_max(tau, v)  # eq. (nudef) solved for the width
    zone = Obstacle(v * tau, v * tau + 2.0, -w, w)  # symmetric: the detector evades left
    path, _ = closed_loop(table, v, zone)
    t = 0.01 * np.arange(len(path))
    # never inside the danger zone (checked every 10 ms), with room to spare beside it
    inside = (path[:, 0] >= zone.x_min) & (path[:, 0] <= zone.x_max) & (path[:, 1] <= zone.y_max)
    assert not np.any(inside)
    # beside it the offset is the margin beyond w, or (full maneuver, kappa = 1) what y_max(tau) allows
    beside = (path[:, 0] >= zone.x_min) & (path[:, 0] <= zone.x_max)
    room = min(MsfParams().margin, table.y_max(tau, v) - w)
    assert np.min(path[beside, 1]) > w + 0.8 * room
    # up to the obstacle the lateral offset is at least the maneuver scaled by nu: nu * y_max(t)
    early = t <= tau
    assert np.all(path[early, 1] >= nu * table.y_max(t[early], v) - 0.03)
    # no braking: the speed stays at v_des (the maneuver is without braking)
    assert np.all(np.abs(path[:, 2] - v) < 1e-9)


@pytest.mark.parametrize("v, tau, nu", [(7.0, 1.4, 0.9), (7.0, 1.4, 1.1)])
def test_full_maneuver_when_nu_is_large(table: MaxSteeringTable, v: float, tau: float, nu: float) -> None:
    # kappa = 1: the reference is y_max itself; the kinematic car follows it closely
    w = nu * table.y_max(tau, v)
    planner = MsfPlanner(MsfParams(), GRID, table)
    assert planner.scale(w, tau, v) == 1.0
    path, _ = closed_loop(table, v, Obstacle(v * tau, v * tau + 2.0, -w, w), steps=8)
    t = 0.01 * np.arange(len(path))
    np.testing.assert_allclose(path[t <= tau, 1], table.y_max(t[t <= tau], v), atol=0.03)


def test_unreachable_width_holds_the_peak_of_the_maneuver(table: MaxSteeringTable) -> None:
    # w far beyond y_max: full maneuver; past half a turn y_max falls, the reference must not follow it back
    v = 4.1
    path, _ = closed_loop(table, v, Obstacle(60.0, 62.0, -30.0, 30.0), steps=45)
    t = 0.01 * np.arange(len(path))
    peak_time = float(table.t[np.argmax(table.y_max(table.t, v))])
    assert peak_time < 5.0
    peak = table.y_max(peak_time, v)
    assert np.all(path[t >= peak_time + 1.0, 1] > 0.97 * peak)


def test_scale_is_at_least_nu(table: MaxSteeringTable) -> None:
    planner = MsfPlanner(MsfParams(), GRID, table)
    for v in (3.0, 5.0, 7.0, 10.0):
        for tau in (0.5, 1.4, 2.0, 3.0, 5.0):
            for nu in (0.05, 0.2, 0.5, 0.9):
                w = nu * table.y_max(tau, v)
                kappa = planner.scale(w, tau, v)
                assert nu <= kappa <= 1.0
                if kappa < 1.0:  # reaches w + margin at f tau exactly
                    assert kappa * table.y_max(0.6 * tau, v) == pytest.approx(w + 0.5)


def test_mirror(table: MaxSteeringTable) -> None:
    # 0.5 m less to the right: the detector picks the right side; the mirrored zone gives the left
    right, _ = closed_loop(table, 6.0, Obstacle(18.0, 20.0, -2.0, 2.5))
    left, _ = closed_loop(table, 6.0, Obstacle(18.0, 20.0, -2.5, 2.0))
    assert np.min(right[:, 1]) < -2.4
    np.testing.assert_allclose(left[:, 1], -right[:, 1], atol=1e-9)
    np.testing.assert_allclose(left[:, 0], right[:, 0], atol=1e-9)


def test_returns_to_the_lane_after_passing(table: MaxSteeringTable) -> None:
    path, plans = closed_loop(table, 6.0, Obstacle(18.0, 20.0, -2.4, 2.4), steps=70)
    statuses = [p.status for p in plans]
    first_idle = statuses.index("idle")
    assert set(statuses[:first_idle]) == {"ok"} and set(statuses[first_idle:]) == {"idle"}
    x_clear = path[20 * first_idle, 0]
    assert x_clear >= 22.0  # cleared 2 m past the far end (the detector's pass margin)
    assert np.max(path[:, 1]) > 2.9  # w + margin
    assert abs(path[-1, 1]) < 0.05 and abs(path[-1, 3]) < 0.05  # back in the lane, 8 s later


def test_idle_keeps_the_lane_and_speed(table: MaxSteeringTable) -> None:
    planner = MsfPlanner(MsfParams(), GRID, table)
    plan = planner.plan(PlannerInput(0.0, estimate_of(0.0, np.array([0.0, 0.0, 6.0, 0.0])), None, 6.0, None))
    assert plan.status == "idle" and plan.iterations == 0
    np.testing.assert_array_equal(plan.accel, np.zeros((10, 2)))
    # offset to the left and slow: steer back toward y_lane, speed up, settle without overshoot
    est = estimate_of(0.0, np.array([0.0, 1.8, 5.0, 0.0]))
    plan = planner.plan(PlannerInput(0.0, est, None, 6.0, None, y_lane=1.0))
    assert plan.accel[0, 1] == pytest.approx(-0.8)  # omega_return^2 * (1.0 - 1.8)
    assert plan.accel[0, 0] == pytest.approx(0.5)  # k_speed * (6 - 5)
    y = plan.predicted[:, 1]
    assert np.all(np.diff(y) <= 1e-12) and np.all(y >= 1.0)
    assert np.all(np.diff(plan.predicted[:, 2]) > 0.0) and np.all(plan.predicted[:, 2] < 6.0)


def test_new_obstacle_restarts_the_maneuver(table: MaxSteeringTable) -> None:
    planner = MsfPlanner(MsfParams(), GRID, table)
    detector = ObstacleDetector(DetectorParams(), table)
    est = estimate_of(0.0, np.array([0.0, 0.0, 6.0, 0.0]))
    first = detector.update(0.0, est, [Obstacle(18.0, 20.0, -2.0, 2.0)])
    a0 = planner.plan(PlannerInput(0.0, est, first, 6.0, None)).accel
    # the same situation 1 s later with a new obstacle gives the same plan as at its detection
    est1 = estimate_of(1.0, np.array([6.0, 0.0, 6.0, 0.0]))
    second = ObstacleDetector(DetectorParams(), table).update(1.0, est1, [Obstacle(24.0, 26.0, -2.0, 2.0)])
    a1 = planner.plan(PlannerInput(1.0, est1, second, 6.0, None)).accel
    np.testing.assert_allclose(a1, a0, atol=1e-12)


def test_zoh_rollout_is_exact_for_piecewise_constant_acceleration() -> None:
    rng = np.random.default_rng(0)
    accel = rng.uniform(-6.0, 6.0, (10, 2))
    state = np.array([1.0, -2.0, 6.0, 0.5])
    out = zoh_rollout(state, accel, T_S)
    # independent: fine semi-analytic integration (velocity exact, position by the trapezoidal rule)
    n = 2000
    dt = T_S / n
    p, vel = state[:2].copy(), state[2:].copy()
    for k in range(10):
        for _ in range(n):
            v_next = vel + dt * accel[k]
            p = p + 0.5 * dt * (vel + v_next)
            vel = v_next
        np.testing.assert_allclose(out[k + 1], np.concatenate([p, vel]), atol=1e-9)


@pytest.mark.parametrize("field, value", [("margin", -0.1),
                                          ("reach_fraction", 1.5), ("omega_evade", 0.0)])
def test_bad_parameters_name_the_field(field: str, value: float) -> None:
    with pytest.raises(ParamError, match=field):
        MsfParams(**{field: value})
