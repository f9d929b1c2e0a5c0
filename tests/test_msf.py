"""MSF planner on the kinematic model: clears the danger zone, follows the scaled maneuver, mirrors, returns."""
from __future__ import annotations

import math

import numpy as np
import pytest

from moose.detector import ObstacleDetector
from moose.maneuver import MaxSteeringTable
from moose.paper import PAPER_FRICTION
from moose.params import ParamError, VehicleParams
from moose.planner.kinematics import kinematic_rollout
from moose.planner.msf import MsfPlanner
from moose.schema import Config, DetectorParams, ManeuverParams, MsfParams
from moose.signals import Obstacle, PlannerInput, StateEstimate

VEHICLE = VehicleParams(mu=PAPER_FRICTION)
GRID = Config(vehicle=VEHICLE).grid
T_S = 0.2
MSF = MsfParams()
SCURVE = MsfParams(profile="scurve")


@pytest.fixture(scope="module")
def table() -> MaxSteeringTable:
    return MaxSteeringTable.build(VEHICLE, ManeuverParams())


def estimate_of(t: float, s: np.ndarray) -> StateEstimate:
    """A kinematic state [x, y, v_X, v_Y] as an estimate (no sideslip)."""
    return StateEstimate(t, s[0], s[1], math.atan2(s[3], s[2]), math.hypot(s[2], s[3]), 0.0, 0.0, 0.0)


def closed_loop(table: MaxSteeringTable, v: float, zone: Obstacle, steps: int = 40,
                params: MsfParams = MSF) -> tuple[np.ndarray, list]:
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
        assert np.all(np.abs(plan.accel) <= [GRID.a_x_max + 1e-12, GRID.a_y_max + 1e-12])
        np.testing.assert_allclose(plan.predicted[0], state)
        for j in range(1, 21):  # exact motion inside the step
            fine.append(kinematic_rollout(state, plan.accel[:1], 0.01 * j)[1])
        state = plan.predicted[1]
    return np.array(fine), plans


CASES = [(v, tau, nu) for v in (5.0, 6.0, 7.0) for tau in (1.4, 2.0, 3.0) for nu in (0.2, 0.5, 0.8)]


def planned(table: MaxSteeringTable, v: float, tau: float, nu: float,
            params: MsfParams = SCURVE) -> tuple[MsfPlanner, Obstacle, float]:
    w = nu * table.reach(tau, v)  # eq. (nudef) solved for the width
    return MsfPlanner(params, GRID, table), Obstacle(v * tau, v * tau + 2.0, -w, w), w


@pytest.mark.parametrize("profile", ["scurve", "nu_scaled"])
@pytest.mark.parametrize("v, tau, nu", CASES)
def test_clears_the_danger_zone_with_the_margin(table: MaxSteeringTable, v: float, tau: float, nu: float,
                                                profile: str) -> None:
    planner, zone, w = planned(table, v, tau, nu)
    path, _ = closed_loop(table, v, zone, params=MsfParams(profile=profile))
    inside = (path[:, 0] >= zone.x_min) & (path[:, 0] <= zone.x_max) & (path[:, 1] <= zone.y_max)
    assert not np.any(inside)  # never inside the danger zone (checked every 10 ms)
    # beside it: the margin beyond w whenever the full maneuver can give it
    beside = (path[:, 0] >= zone.x_min) & (path[:, 0] <= zone.x_max)
    room = min(MsfParams().margin, table.y_max(tau, v) - w)
    assert np.min(path[beside, 1]) >= w + room - 0.02


@pytest.mark.parametrize("v, tau, nu", CASES)
def test_the_s_curve_is_continuous_and_ends_straight(table: MaxSteeringTable, v: float, tau: float, nu: float) -> None:
    planner, zone, w = planned(table, v, tau, nu)
    e = planner.evasion(zone, 0.0, w, tau, v)
    s = np.arange(0.0, 2.0 * e.s1 + 1.0, 0.001)
    ref = np.array([planner.evasion_reference(u, e)[:2] for u in s])
    # no jump in position or lateral velocity (the old reference dropped its velocity to 0)
    assert np.max(np.abs(np.diff(ref[:, 0]))) < 0.001 * 1.1 * np.max(np.abs(ref[:, 1])) + 1e-9
    assert np.max(np.abs(np.diff(ref[:, 1]))) < 0.001 * 1.2 * GRID.a_y_max
    # nor in the lateral acceleration: the counter-steer's flip is spread over the steering's swing
    accel = np.diff(ref[:, 1]) / 0.001
    assert np.max(np.abs(np.diff(accel))) < 0.05 * GRID.a_y_max
    # it arrives at its target moving straight, and stays
    assert ref[-1, 0] == pytest.approx(e.target) and ref[-1, 1] == 0.0
    assert np.all(np.diff(ref[:, 0]) >= -1e-12)  # never back toward the obstacle
    # the target is w + margin unless the full maneuver needs more room to stop its lateral motion
    assert e.target >= w + MsfParams().margin - 1e-9 or e.s1 == pytest.approx(tau) or e.kappa == 1.0


@pytest.mark.parametrize("profile", ["scurve", "nu_scaled"])
@pytest.mark.parametrize("v, tau, nu", CASES)
def test_the_kinematic_car_follows_the_s_curve(table: MaxSteeringTable, v: float, tau: float, nu: float,
                                               profile: str) -> None:
    # on the planners' own model the feed-forward is exact: the car flies the reference
    params = MsfParams(profile=profile)
    _, zone, w = planned(table, v, tau, nu)
    planner = MsfPlanner(params, GRID, table)
    e = planner.evasion(zone, 0.0, w, tau, v)
    path, _ = closed_loop(table, v, zone, params=params)
    t = 0.01 * np.arange(len(path))
    evading = t <= tau
    ref = np.array([planner.evasion_reference(u, e)[0] for u in t[evading]])
    assert np.max(np.abs(path[evading, 1] - ref)) < 0.05


@pytest.mark.parametrize("v, tau, nu", CASES)
def test_the_nu_scaled_evasion_is_nu_times_y_max_to_the_near_edge(table: MaxSteeringTable, v: float, tau: float,
                                                                  nu: float) -> None:
    """``nu_scaled``: ỹ_ref = κ y_max(s) with κ = (w + m) / y_max(τ) — eq. (nudef)'s ν of the target — so the
    reference is beside the far edge, with the margin, at the near edge; then the counter-steer stops the lateral
    motion, continuously in position, velocity and acceleration, and its acceleration is the largest of the
    evasion: the steering's largest swing comes at the near edge and after it."""
    planner = MsfPlanner(MsfParams(profile="nu_scaled"), GRID, table)
    w = nu * table.reach(tau, v)
    e = planner.evasion(Obstacle(v * tau, v * tau + 2.0, -w, w), 0.0, w, tau, v)
    target = w + MsfParams().margin
    assert e.kappa == pytest.approx(min(target / table.y_max(tau, v), 1.0))
    early = np.linspace(0.0, e.s1, 25)
    np.testing.assert_allclose([planner.evasion_reference(u, e)[0] for u in early], e.kappa * table.y_max(early, v),
                               atol=1e-12)
    if e.kappa < 1.0:
        assert e.s1 == tau and planner.evasion_reference(tau, e)[0] == pytest.approx(target)
    else:  # the full maneuver, on until it reaches the target (or its peak)
        assert e.s1 >= tau and table.y_max(e.s1, v) >= target - 1e-6 or e.s1 == pytest.approx(
            float(table.t[np.argmax(table.y_max(table.t, v))]), abs=0.01)
    s = np.arange(0.0, e.s1 + 4.0, 0.001)
    ref = np.array([planner.evasion_reference(u, e)[:2] for u in s])
    accel = np.diff(ref[:, 1]) / 0.001
    assert np.max(np.abs(np.diff(ref[:, 0]))) < 0.001 * 1.1 * np.max(np.abs(ref[:, 1])) + 1e-9
    assert np.max(np.abs(np.diff(accel))) < 0.05 * GRID.a_y_max  # no jump: the steering swings, it cannot jump
    assert np.all(np.diff(ref[:, 0]) >= -1e-12) and ref[-1, 1] == pytest.approx(0.0, abs=1e-9)
    assert ref[-1, 0] == pytest.approx(e.target) and e.target >= target - 1e-9
    before, after = s[:-1] <= e.s1, s[:-1] > e.s1
    assert np.max(np.abs(accel[after])) >= np.max(np.abs(accel[before])) - 1e-6


def test_counter_steer_ramps_holds_and_releases_to_a_stop() -> None:
    from moose.planner.msf import counter_steer

    stop = counter_steer(2.0, 1.5, 0.8, 3.0, 0.4, 0.3)  # swing 0.4 s to −3 m/s², hold, release over 0.3 s
    (t0, a0), (t1, a1), (t2, a2), (t3, a3) = stop.knots
    assert (t0, a0, t1, a1, a2, a3) == (0.0, 0.8, 0.4, -3.0, -3.0, 0.0) and t3 - t2 == pytest.approx(0.3)
    p, v, a = stop.at(t3)
    assert v == pytest.approx(0.0, abs=1e-12) and a == 0.0 and p == pytest.approx(stop.end)
    # the velocity is the integral of the acceleration: v0 + areas of the trapezoids
    assert 1.5 + 0.4 * (0.8 - 3.0) / 2 - 3.0 * (t2 - t1) - 3.0 * 0.3 / 2 == pytest.approx(0.0, abs=1e-12)
    assert stop.at(t3 + 5.0)[:2] == pytest.approx((stop.end, 0.0))
    slow = counter_steer(2.0, 0.2, 0.0, 3.0, 0.4, 0.3)  # too slow to hold: a softer counter-steer, no hold
    assert len(slow.knots) == 4 and slow.knots[1][0] == slow.knots[2][0] and slow.at(slow.knots[-1][0])[1] == (
        pytest.approx(0.0, abs=1e-12))
    assert counter_steer(2.0, 0.0, -1.0, 3.0, 0.4, 0.3).end == 2.0  # at rest laterally: nothing to stop


def test_arrival_at_the_near_edge_follows_the_speed_law() -> None:
    """τ is the time to the near edge at the speed of detection; the MSF arrives when its own speed law takes it
    there (the paper's third 6 m/s case: detected at 4.5 m/s with 6 m/s desired)."""
    from moose.planner.msf import arrival_time

    assert arrival_time(3.0, 6.0, 6.0, 0.5) == 3.0
    t = arrival_time(3.0, 4.5, 6.0, 0.5)
    x = 6.0 * t + (4.5 - 6.0) * (1.0 - math.exp(-0.5 * t)) / 0.5  # v(t) = v_des + (v0 − v_des) e^(−k t), integrated
    assert x == pytest.approx(13.5, abs=1e-9) and 2.4 < t < 3.0
    assert arrival_time(3.0, 6.0, 4.5, 0.5) > 3.0
    assert arrival_time(3.0, 6.0, 0.0, 0.5) == math.inf  # stops 12 m on, 18 m short of the edge
    assert arrival_time(math.inf, 6.0, 4.5, 0.5) == math.inf


def test_scale_grows_with_the_threat(table: MaxSteeringTable) -> None:
    planner = MsfPlanner(SCURVE, GRID, table)
    zone = Obstacle(20.0, 22.0, -1.0, 1.0)
    for v in (3.0, 5.0, 7.0, 10.0):
        for tau in (0.5, 1.4, 2.0, 3.0, 5.0):
            kappas = []
            for nu in (0.05, 0.2, 0.5, 0.9):
                w = nu * table.reach(tau, v)
                e = planner.evasion(zone, 0.0, w, tau, v)
                assert nu <= e.kappa <= 1.0  # y_max is convex early: arriving and stopping needs more than nu
                if e.kappa < 1.0:  # the symmetric S-curve: arrives at w + margin at f tau exactly
                    assert e.s1 == pytest.approx(0.5 * tau) and e.target == pytest.approx(w + 0.5)
                    assert 2.0 * e.kappa * table.y_max(e.s1, v) == pytest.approx(w + 0.5)
                kappas.append(e.kappa)
            assert kappas == sorted(kappas)


@pytest.mark.parametrize("v, tau, nu", [(7.0, 1.4, 0.9), (7.0, 1.4, 1.1)])
def test_full_maneuver_when_nu_is_large(table: MaxSteeringTable, v: float, tau: float, nu: float) -> None:
    # kappa = 1: the reference is y_max itself up to the counter-steer, which starts no earlier than
    # the reference can be beside the zone's far edge (with the margin) at the near edge
    planner, zone, w = planned(table, v, tau, nu)
    e = planner.evasion(zone, 0.0, w, tau, v)
    assert e.kappa == 1.0 and 0.5 * tau <= e.s1 <= tau
    y_tau = planner.evasion_reference(tau, e)[0]
    assert y_tau >= w + 0.5 - 1e-6 or e.s1 == pytest.approx(tau)
    assert e.target == pytest.approx(2.0 * table.y_max(e.s1, v))
    s = np.arange(0.0, e.s1 - 0.5 * e.swing, 0.01)  # up to the counter-steer's transition
    np.testing.assert_allclose([planner.evasion_reference(u, e)[0] for u in s], table.y_max(s, v), atol=1e-12)


def test_the_counter_steer_starts_by_the_peak_of_the_maneuver(table: MaxSteeringTable) -> None:
    # w far beyond y_max: full maneuver; past half a turn y_max falls, so the counter-steer starts at its peak
    v, tau = 4.1, 8.0
    planner = MsfPlanner(SCURVE, GRID, table)
    e = planner.evasion(Obstacle(40.0, 42.0, -30.0, 30.0), 0.0, 30.0, tau, v)
    peak_time = float(table.t[np.argmax(table.y_max(table.t, v))])
    assert peak_time < 5.0 and e.s1 == pytest.approx(peak_time)


def test_speed_is_kept_along_the_path(table: MaxSteeringTable) -> None:
    # "without braking": |v| is regulated, so swerving adds little speed; holding v_X at 7 m/s would
    # add sqrt(7^2 + v_Y^2) - 7 (0.6 m/s at v_Y = 3 m/s).  What remains is the zero-order hold: a
    # constant acceleration over 0.2 s lengthens the velocity it turns
    planner, zone, _ = planned(table, 7.0, 2.0, 0.8)
    path, _ = closed_loop(table, 7.0, zone, steps=30, params=SCURVE)
    speed = np.hypot(path[:, 2], path[:, 3])
    assert np.max(np.abs(path[:, 3])) > 2.5
    assert np.max(speed) < 7.0 + 0.25 and np.min(speed) > 7.0 - 0.3  # measured 7.23


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
    assert np.max(path[:, 1]) > 2.85  # w + margin (2.9 m), less the feedback's lag
    assert abs(path[-1, 1]) < 0.05 and abs(path[-1, 3]) < 0.05  # back in the lane, 8 s later
    # a calm return: the cosine S-curve peaks at return_share * mu g (the feedback adds a little)
    peak = max(abs(p.accel[0, 1]) for p in plans[first_idle:])
    assert 0.8 * MsfParams().return_share * GRID.a_y_max < peak < 1.2 * MsfParams().return_share * GRID.a_y_max


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


@pytest.mark.parametrize("field, value", [("margin", -0.1), ("reach_fraction", 1.5), ("omega_track", 0.0),
                                          ("return_share", 1.5), ("profile", "sigmoid")])
def test_bad_parameters_name_the_field(field: str, value: object) -> None:
    with pytest.raises(ParamError, match=field):
        MsfParams(**{field: value})
