"""MPC planner: cost terms against their formulas, Example 2, receding-horizon behaviour,
statuses, v_X ≥ 0 and mirror symmetry."""
from __future__ import annotations

import dataclasses
import functools
import math

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from moose.params import G, ParamError
from moose.planner.kinematics import kinematic_rollout
from moose.planner.mpc import (
    MpcPlanner,
    build_problem,
    epsilon,
    j_brake,
    j_safe,
    j_stable,
    j_steer,
    past_obstacle,
    y_safe,
)
from moose.planner.mpc.projected_newton import CompilerMissing
from moose.schema import PAPER_CAPS, MpcParams, PlanningGrid, SolverCaps
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat
from solve_time import INSTANT
from test_mpc_solvers import reference_minimum

GRID = PlanningGrid(N_p=10, t_s=0.2, a_x_max=6.0, a_y_max=6.0, mu=0.3)
"""The kinematic problem of the MPC notes (bounds ±6 m/s², ε at μ = 0.3): these tests are about the optimisation."""
DEFAULT = MpcParams()
EQUAL = (0.25, 0.25, 0.25, 0.25)
SOLVED = ("converged", "capped", "barrier_violated")
"""The statuses of a solve that returned a plan in time (``barrier_violated``: converged or capped, through y_safe)."""
COST = build_problem(DEFAULT, GRID.N_p, GRID.t_s).cost_function
"""The problem's cost of (inputs scaled to ±1, parameters), CasADi's: what a reference solver minimises."""


def threat(w: float = 2.6, x_min: float = 10.0, side: int = 1, length: float = 2.0, y_path: float = 0.0) -> Threat:
    """A danger zone straddling the path whose far edge on the evasion side is w away."""
    y_lo, y_hi = (y_path - 0.5, y_path + w) if side > 0 else (y_path - w, y_path + 0.5)
    return Threat(0.0, Obstacle(x_min, x_min + length, y_lo, y_hi), x_min / 7.0, w, 1.0, side, y_path)


def state(v: float = 7.0, x: float = 0.0, y: float = 0.0, vy: float = 0.0) -> StateEstimate:
    return StateEstimate(0.0, x, y, 0.0, v, vy, 0.0, 0.0)  # θ = 0: body = global velocities


def receding_horizon(params: MpcParams, th: Threat | None, s0: list[float], v_des: float, steps: int,
                     clear_after: float = 2.0) -> tuple[np.ndarray, list]:
    """Closed loop on the kinematic model: the first input applied, the rest shifted as the next guess."""
    planner = MpcPlanner(params, GRID, compute_time_s=INSTANT)
    s = np.array(s0, dtype=float)
    guess = None
    traj, results = [s.copy()], []
    for k in range(steps):
        active = th if th is not None and s[0] < th.obstacle.x_max + clear_after else None
        result = planner.plan(PlannerInput(k * GRID.t_s, state(s[2], s[0], s[1], s[3]), active, v_des, guess))
        s = kinematic_rollout(s, result.accel[:1], GRID.t_s)[1]
        traj.append(s.copy())
        results.append(result)
        guess = np.vstack([result.accel[1:], result.accel[-1:]])
    return np.array(traj), results


# --- cost terms --------------------------------------------------------------------------------

def test_y_safe_is_the_sigmoid_of_eq_ysafe() -> None:
    eps = epsilon(0.3)
    assert eps == pytest.approx(1.0 / math.sqrt(8.8 * 0.3 * G))
    w, x_obs = 2.0, 30.0
    for x, v in ((0.0, 5.0), (8.0, 5.0), (12.0, 6.0), (20.0, 3.0)):
        reference = w / (1.0 + math.exp((x_obs - x - 4 * v) / (eps * math.sqrt(w * v * v))))
        assert y_safe(x, v, x_obs, w, eps, v_reg=1e-9) == pytest.approx(reference, rel=1e-9)
    # half of w exactly 4 v_X before the obstacle (Fig. 5), whatever the regularisation
    assert y_safe(x_obs - 4 * 5.0, 5.0, x_obs, w, eps) == pytest.approx(w / 2)
    # the tanh form does not overflow where exp would
    assert y_safe(-1e6, 5.0, x_obs, w, eps) == 0.0
    assert y_safe(1e6, 5.0, x_obs, w, eps) == pytest.approx(w)
    assert math.isfinite(y_safe(0.0, 0.0, x_obs, w, eps))  # v_X = 0 is regular


def test_paper_barrier_is_minus_log_continued_below_the_margin() -> None:
    m = 0.3
    d = np.linspace(-5.0, 10.0, 3001)
    j = np.array([j_safe(v, 0.0, m) for v in d])
    assert np.all(np.isfinite(j)) and np.all(np.diff(j) < 0.0)  # rewards every metre of distance
    np.testing.assert_allclose(j[d >= m], -np.log(d[d >= m]), rtol=1e-12)
    dm = -2.0 - m
    assert j_safe(-2.0, 0.0, m) == pytest.approx(-math.log(m) - dm / m + dm**2 / (2 * m * m))
    assert j_safe(2.5, 2.0, m) < j_safe(1.5, 2.0, m)  # the sign: above y_safe is cheaper


def test_clipped_barrier_repels_from_y_safe_and_does_not_reward_beyond_the_clearance() -> None:
    m, c = 0.3, 1.0
    d = np.linspace(-5.0, 3.0, 8001)
    j = np.array([j_safe(v, 0.0, m, c) for v in d])
    assert np.all(np.isfinite(j))
    assert np.all(np.diff(j[d <= c]) < 0.0)  # pushes toward the safe side everywhere below c
    assert np.all(j[d >= c] == 0.0)
    inner = (d >= m) & (d < c)
    np.testing.assert_allclose(j[inner], -np.log(d[inner] / c) + d[inner] / c - 1.0, rtol=1e-12)
    second = np.diff(j, 2)
    assert np.all(second > -1e-9)  # convex
    slope = np.diff(j) / np.diff(d)
    h = d[1] - d[0]
    assert np.max(np.abs(np.diff(slope))) <= 1.01 * h / m**2  # C¹: slope changes only through curvature ≤ 1/m²
    # below the margin: the second-order Taylor polynomial of the log branch
    dm = -2.0 - m
    assert j_safe(-2.0, 0.0, m, c) == pytest.approx(-math.log(m) + m - 1 + (1 - 1 / m) * dm + dm**2 / (2 * m * m))
    # the sign: the ego above y_safe is cheaper than below it
    assert j_safe(2.5, 2.0, m, c) < j_safe(1.5, 2.0, m, c)


def test_absolute_values_are_smooth_approximations() -> None:
    for x in (-3.0, -0.4, 0.0, 0.7, 5.0):
        assert j_steer(x) == pytest.approx(abs(x), abs=0.05)
        assert j_brake(7.0 + x, 7.0) == pytest.approx(abs(x), abs=0.05)
    assert j_steer(0.0) == 0.0
    assert j_stable(7.0, 1.4) == pytest.approx(0.2, abs=0.01)
    assert math.isfinite(j_stable(0.0, 1.0))  # |v_Y / v_X| regularised at v_X = 0
    assert past_obstacle(0.0, 12.0) < 1e-6 and past_obstacle(12.0, 12.0) < 0.02
    assert past_obstacle(13.0, 12.0) == pytest.approx(0.5) and past_obstacle(16.0, 12.0) > 0.99


def fly(x: float, y: float, vx: float, vy: float, ax: float, ay: float, t_s: float, n: int = 400) -> tuple:
    """The kinematic model eq. (skin) integrated over one planning step by the trapezoidal rule (exact velocity),
    not by the closed-form zero-order hold the planner uses."""
    dt = t_s / n
    for _ in range(n):
        vx_next, vy_next = vx + dt * ax, vy + dt * ay
        x, y = x + 0.5 * dt * (vx + vx_next), y + 0.5 * dt * (vy + vy_next)
        vx, vy = vx_next, vy_next
    return x, y, vx, vy


def reference_cost(params: MpcParams, s0: np.ndarray, u: np.ndarray, th: Threat, v_des: float) -> float:
    """𝒥 of eq. (jcaldef) written out from the paper's formulas (NumPy, for one threat), on states predicted
    by an independent integration of eq. (skin)."""
    p, g = params, GRID
    eps = 1.0 / math.sqrt(8.8 * g.mu * G)
    e1, e2, e3, e4 = p.eta
    total = 0.0
    x, y, vx, vy = s0
    for ux, uy in u:
        x, y, vx, vy = fly(x, y, vx, vy, ux * g.a_x_max, uy * g.a_y_max, g.t_s)
        yt = th.side * (y - th.y_path)
        ys = th.w / (1 + math.exp((th.obstacle.x_min - x - 4 * vx) / (eps * math.sqrt(th.w * (vx**2 + p.v_reg**2)))))
        d, m, c = yt - ys, p.barrier_margin, p.barrier_clearance
        if p.barrier == "paper":  # −log d, its Taylor polynomial at m below m
            barrier = -math.log(d) if d >= m else -math.log(m) - (d - m) / m + (d - m) ** 2 / (2 * m * m)
        elif d >= c:
            barrier = 0.0
        elif d >= m:
            barrier = -math.log(d / c) + d / c - 1
        else:
            barrier = -math.log(m / c) + m / c - 1 + (1 / c - 1 / m) * (d - m) + (d - m) ** 2 / (2 * m * m)
        fall = 1.0 - 1.0 / (1.0 + math.exp(-(x - th.obstacle.x_max - p.pass_margin) / (p.pass_margin / 4)))
        sabs = lambda z: math.sqrt(z * z + p.abs_eps**2) - p.abs_eps  # noqa: E731
        total += e1 * fall * barrier + e2 * sabs(vy) / math.sqrt(vx**2 + p.v_reg**2) + e3 * sabs(vx - v_des)
        total += e4 * sabs(uy) + p.eta_return * sabs(yt) + p.reverse_penalty * min(vx, 0.0) ** 2
    return total


CLIPPED = MpcParams(barrier="clipped")


@settings(max_examples=30, deadline=None)
@given(st.lists(st.floats(-1.0, 1.0), min_size=20, max_size=20), st.sampled_from([1, -1]),
       st.floats(0.5, 9.0), st.floats(-1.0, 1.0), st.sampled_from([DEFAULT, CLIPPED]))
def test_cost_is_eq_jcaldef_over_the_predicted_states(u: list[float], side: int, v: float, y: float,
                                                      params: MpcParams) -> None:
    planner = MpcPlanner(params, GRID, compute_time_s=INSTANT)
    th = threat(w=2.2, x_min=12.0, side=side, y_path=0.3)
    uu = np.array(u).reshape(10, 2)
    s0 = np.array([1.0, y, v, 0.4])
    inp = PlannerInput(0.0, state(v, 1.0, y, 0.4), th, 6.0, None)
    assert planner.cost(inp, uu) == pytest.approx(reference_cost(params, s0, uu, th, 6.0), rel=1e-8, abs=1e-8)


# --- Example 2 (emp:eta) ---------------------------------------------------------------------------

@pytest.mark.parametrize("eta", [EQUAL, (0.5, 0.25, 0.05, 0.2)])
def test_example_eta_steers_at_the_bound_without_braking(eta: tuple[float, float, float, float]) -> None:
    """N_p = 2, u(k) = u(k+1), v_X = v_des = 5, x = y = y_obs = 0, x_obs = w = 1 (2 m long zone).

    The paper prints [0.00, 0.53] (equal weights) and [−0.35, 1.00].  With the barrier
    keeping the ego above y_safe, y_safe is ≈ w at both predicted steps whatever the
    braking (x_obs − x − 4 v_X ≪ 0), no input reaches it, and both sets steer at the bound;
    braking cannot lower the barrier, so J_brake and J_stable keep the speed.
    """
    planner = MpcPlanner(MpcParams(eta=eta), dataclasses.replace(GRID, N_p=2), compute_time_s=INSTANT)
    inp = PlannerInput(0.0, state(5.0), threat(w=1.0, x_min=1.0), 5.0, None)
    grid = np.linspace(-1.0, 1.0, 81)
    costs = np.array([[planner.cost(inp, [[a, b], [a, b]]) for b in grid] for a in grid])
    i, j = np.unravel_index(np.argmin(costs), costs.shape)
    assert grid[j] == 1.0 and abs(grid[i]) <= 0.05  # held input: full steering, no braking
    result = planner.plan(inp)  # the solver on the free two-step problem agrees
    assert result.status == "barrier_violated"  # no input reaches y_safe: the paper's "fails to provide a solution"
    np.testing.assert_allclose(result.accel / 6.0, [[0.0, 1.0], [0.0, 1.0]], atol=0.05)
    assert result.cost <= costs[i, j] + 1e-9


# --- receding horizon --------------------------------------------------------------------------

def test_relaxed_case_clears_the_zone_and_returns_to_the_lane() -> None:
    """v = 5 m/s, zone 25–27 m ahead, w = 2 m, Example 2's first weight set, every plan
    solved to convergence (docs/modelling.md, "MPC": at the paper's caps the capped first plan
    decides between this manoeuvre and a crawl in front of the zone)."""
    th = threat(w=2.0, x_min=25.0)
    converged = MpcParams(eta=EQUAL, caps=SolverCaps(max_iter=200, max_fun_evals=2000))
    traj, results = receding_horizon(converged, th, [0.0, 0.0, 5.0, 0.0], 5.0, steps=60)
    beside = (traj[:, 0] >= th.obstacle.x_min) & (traj[:, 0] <= th.obstacle.x_max)
    assert beside.any() and np.all(traj[beside, 1] > th.w)  # the CoG passes outside the danger zone
    assert traj[:, 2].min() > 4.0  # without stopping
    assert traj[-1, 0] > 40.0 and abs(traj[-1, 1]) < 0.2 and traj[-1, 2] == pytest.approx(5.0, abs=0.1)
    assert all(r.status == "converged" for r in results)


@pytest.mark.parametrize("eta", [EQUAL, DEFAULT.eta], ids=["equal", "default"])
def test_relaxed_case_at_the_paper_caps_never_enters_the_zone(eta: tuple[float, float, float, float]) -> None:
    """At the paper's caps MPC alone may slow down to a crawl in front of the zone instead of
    passing (η₃ = 0.05 makes braking cheap, and braking lowers y_safe; with the equal weights
    it depends on the capped first plan: docs/modelling.md), but it never enters it and never reverses."""
    th = threat(w=2.0, x_min=25.0)
    traj, results = receding_horizon(MpcParams(eta=eta), th, [0.0, 0.0, 5.0, 0.0], 5.0, steps=60)
    inside = [th.obstacle.contains(x, y) for x, y in traj[:, :2]]
    assert not any(inside)
    assert traj[:, 2].min() >= 0.0
    assert all(r.status in SOLVED for r in results)


@pytest.mark.parametrize("params", [DEFAULT, CLIPPED], ids=["paper", "clipped"])
def test_extreme_case_evades_to_the_safe_side(params: MpcParams) -> None:
    """The notes' problem (v = 7, x_obs = 10 m, w = 2.6 m): infeasible at detection.  With the
    clipped barrier the car is back in its lane at speed 12 s later; the paper's −log d keeps
    rewarding distance while the obstacle is near, and the car swings out further."""
    th = threat()
    traj, results = receding_horizon(params, th, [0.0, 0.0, 7.0, 0.0], 7.0, steps=60)
    beside = (traj[:, 0] >= th.obstacle.x_min) & (traj[:, 0] <= th.obstacle.x_max)
    assert beside.any() and np.all(traj[beside, 1] > th.w)
    assert results[0].accel[0, 1] == pytest.approx(6.0)  # full steering away at detection
    if params.barrier == "clipped":
        assert abs(traj[-1, 1]) < 0.3 and traj[-1, 2] == pytest.approx(7.0, abs=0.2)
    else:
        clipped, _ = receding_horizon(CLIPPED, th, [0.0, 0.0, 7.0, 0.0], 7.0, steps=60)
        assert traj[:, 1].max() > clipped[:, 1].max() + 1.0


def test_infeasible_start_has_a_finite_cost_and_steers_away() -> None:
    for side in (1, -1):
        th = threat(w=2.6, x_min=5.0, side=side)  # τ = 0.7 s: y_safe ≈ w over the whole horizon
        planner = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT)
        inp = PlannerInput(0.0, state(7.0), th, 7.0, None)
        assert y_safe(0.0, 7.0, 5.0, 2.6, epsilon(GRID.mu)) > 2.5  # the log is undefined at the start
        result = planner.plan(inp)
        assert math.isfinite(result.cost) and np.all(np.isfinite(result.accel))
        assert result.status == "barrier_violated"  # the best plan there is still crosses y_safe
        assert side * result.accel[0, 1] == pytest.approx(6.0)
        assert result.cost < planner.cost(inp, np.zeros((10, 2)))


def test_lane_keeping_without_a_threat() -> None:
    traj, results = receding_horizon(DEFAULT, None, [0.0, 1.5, 5.0, 0.0], 6.0, steps=40)
    assert results[0].accel[0, 1] < 0.0 and results[0].accel[0, 0] > 0.0
    assert abs(traj[-1, 1]) < 0.1 and traj[-1, 2] == pytest.approx(6.0, abs=0.1)
    assert np.all(np.abs(traj[:, 1]) <= 1.5 + 1e-9)  # no overshoot beyond the start


# --- statuses, robustness ----------------------------------------------------------------------

def test_statuses() -> None:
    inp = PlannerInput(0.0, state(y=4.0), threat(), 7.0, None)  # beside the zone's far edge: y_safe is below
    capped = MpcPlanner(MpcParams(caps=SolverCaps(max_iter=1, max_fun_evals=10)), GRID,
                        compute_time_s=INSTANT).plan(inp)
    assert capped.status == "capped" and capped.iterations == 1
    converged = MpcPlanner(MpcParams(caps=SolverCaps(max_iter=200, max_fun_evals=2000), max_iter_ls=8),
                           GRID, compute_time_s=INSTANT).plan(inp)
    assert converged.status == "converged" and converged.iterations < 200
    late = MpcPlanner(MpcParams(time_budget_s=1e-9), GRID).plan(inp)
    assert late.status == "over_budget" and np.all(np.isfinite(late.accel))
    for bad in (dataclasses.replace(state(), x=float("nan")), dataclasses.replace(state(), y=float("inf"))):
        failed = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT).plan(
            PlannerInput(0.0, bad, threat(), 7.0, np.full((10, 2), 9.0)))
        assert failed.status == "failed" and failed.cost == math.inf
        assert np.all(np.isfinite(failed.accel)) and np.all(np.isfinite(failed.predicted))
        assert np.all(np.abs(failed.accel) <= 6.0)  # the clipped initial guess
    nan_guess = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT).plan(
        PlannerInput(0.0, state(), threat(), 7.0, np.full((10, 2), np.nan)))
    assert nan_guess.status in SOLVED and math.isfinite(nan_guess.cost)


def test_a_plan_through_the_barrier_is_reported_as_the_papers_failure() -> None:
    """Sec. IV: the MPC "fails to provide a solution" where its predicted path crosses y_safe (d < 0 at a step of
    the horizon before the zone's far edge): status ``barrier_violated``, whatever the solver's own word."""
    planner = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT)
    th = threat()  # 7 m/s, 10 m ahead (τ = 1.4 s): y_safe ≈ w over the whole horizon
    on_path = planner.plan(PlannerInput(0.0, state(), th, 7.0, None))
    gap = planner.barrier_gap(PlannerInput(0.0, state(), th, 7.0, None), on_path.predicted)
    assert on_path.status == "barrier_violated" and np.min(gap) < 0.0
    # d = ỹ − y_safe at the predicted steps, by the formula of eq. (ysafe) with the cost's regularisation
    eps = epsilon(GRID.mu)
    expected = [y - y_safe(x, vx, 10.0, 2.6, eps, DEFAULT.v_reg) for x, y, vx, _ in on_path.predicted[1:]
                if x <= th.obstacle.x_max]
    np.testing.assert_allclose(gap, expected, rtol=1e-12)
    beside = planner.plan(PlannerInput(0.0, state(y=4.0), th, 7.0, None))  # above w already
    assert beside.status in ("converged", "capped")
    mirrored = planner.plan(PlannerInput(0.0, state(y=-4.0), threat(side=-1), 7.0, None))
    assert mirrored.status == beside.status  # ỹ is the offset toward the evasion side
    # no threat, no barrier: lane keeping is never a violation
    assert planner.plan(PlannerInput(0.0, state(y=1.0), None, 7.0, None)).status in ("converged", "capped")
    # late is late, whatever the path
    late = MpcPlanner(MpcParams(time_budget_s=1e-9), GRID).plan(PlannerInput(0.0, state(), th, 7.0, None))
    assert late.status == "over_budget"


def test_the_barrier_ends_at_the_far_edge() -> None:
    """Steps past the zone's far edge do not count (the cost switches J_safe off there): a car past the obstacle,
    back on its path, violates nothing; the same car before it does."""
    from moose.planner.mpc import barrier_gap, violates_barrier

    straight = kinematic_rollout(np.array([12.5, 0.0, 7.0, 0.0]), np.zeros((10, 2)), 0.2)
    eps = epsilon(GRID.mu)
    assert barrier_gap(straight, 10.0, 12.0, 2.6, 1.0, 0.0, eps).size == 0
    assert not violates_barrier(barrier_gap(straight, 10.0, 12.0, 2.6, 1.0, 0.0, eps))
    before = kinematic_rollout(np.array([0.0, 0.0, 7.0, 0.0]), np.zeros((10, 2)), 0.2)
    gap = barrier_gap(before, 10.0, 12.0, 2.6, 1.0, 0.0, eps)
    assert gap.size == int(np.sum(before[1:, 0] <= 12.0)) and violates_barrier(gap)
    assert not violates_barrier(np.array([0.0, 0.3]))  # on y_safe is not through it


def test_result_shapes_bounds_and_prediction() -> None:
    for n_p in (2, 10, 20):
        params, grid = DEFAULT, dataclasses.replace(GRID, N_p=n_p)
        result = MpcPlanner(params, grid, compute_time_s=INSTANT).plan(
            PlannerInput(0.0, state(), threat(), 7.0, np.zeros((3, 2))))
        assert result.accel.shape == (n_p, 2) and result.predicted.shape == (n_p + 1, 4)
        assert np.all(np.abs(result.accel) <= 6.0 + 1e-12)
        np.testing.assert_allclose(result.predicted, kinematic_rollout(np.array([0, 0, 7.0, 0]), result.accel, 0.2))
        assert result.cost == pytest.approx(MpcPlanner(params, grid, compute_time_s=INSTANT).cost(
            PlannerInput(0.0, state(), threat(), 7.0, None), result.accel / 6.0))


# derandomize: the same 25 examples in every run, so that CI judges the code, not the draw; a random draw found the
# false convergence pinned below (one example in about three runs of 25)
@settings(max_examples=25, deadline=None, derandomize=True, database=None)
@given(st.floats(0.0, 3.0), st.floats(1.0, 8.0), st.floats(-1.0, 0.2), st.floats(-1.0, 1.0))
def test_speed_never_negative_and_never_worse_than_the_start(v: float, x_obs: float, ux: float, uy: float) -> None:
    planner = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT)
    guess = np.tile([ux * 6.0, uy * 6.0], (10, 1))  # braking guesses find reversing without the floor
    inp = PlannerInput(0.0, state(v), threat(w=2.0, x_min=x_obs), 0.0, guess)
    result = planner.plan(inp)
    assert result.predicted[:, 2].min() >= -1e-12
    start = planner.cost(inp, planner.initial_guess(inp))
    # the decrease owed: down to the local minimum that scipy's L-BFGS-B reaches from the plan (never above the plan)
    owed = start - reference_minimum(COST, planner.parameters(inp), [(result.accel / 6.0).ravel()])
    assert result.cost <= start + 1e-12
    if owed > 1e-9 * max(1.0, start):  # a plan that stayed at the start would keep all of it
        assert start - result.cost >= 1e-3 * owed, (result.status, start, result.cost, owed)
    assert np.all(np.abs(result.accel) <= 6.0 + 1e-12)


def test_projected_newton_does_not_stop_on_a_tiny_step_far_from_a_minimum() -> None:
    """v = 1 m/s, the obstacle 1 m ahead, a braking-and-steering guess: the start brakes to v_X = 0 exactly, where the
    speed-floor penalty's curvature switches on, so the exact Hessian there misses it and the Newton step must be cut
    to 5e-4.  The solver once stopped on that short step and reported it converged, at 34.79 with
    ‖u − P(u − ∇f)‖∞ = 1.5; scipy's L-BFGS-B goes on from that plan to 5.3.  (The plan's path crosses y_safe either
    way, so the weight function hands over to the MSF.)"""
    planner = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT)
    inp = PlannerInput(0.0, state(1.0), threat(w=2.0, x_min=1.0), 0.0, np.tile([-3.0, 3.0], (10, 1)))
    result = planner.plan(inp)
    start = planner.cost(inp, planner.initial_guess(inp))
    owed = start - reference_minimum(COST, planner.parameters(inp), [(result.accel / 6.0).ravel()])
    assert start - result.cost >= 1e-3 * owed, (result.status, start, result.cost, owed)


def stationarity(u: np.ndarray, p: np.ndarray) -> float:
    """‖u − P(u − ∇𝒥(u))‖∞ on the box [−1, 1], ∇𝒥 by CasADi's virtual machine (not the solver's compiled gradient):
    0 exactly at a first-order (KKT) point of eq. (planmpc)."""
    g = np.asarray(GRADIENT(u, p), dtype=float).ravel()
    return float(np.max(np.abs(np.clip(u - g, -1.0, 1.0) - u)))


def _gradient() -> ca.Function:
    u, p = ca.SX.sym("u", COST.nnz_in(0)), ca.SX.sym("p", COST.nnz_in(1))
    return ca.Function("gradient", [u, p], [ca.gradient(COST(u, p), u)])


GRADIENT = _gradient()



@functools.cache
def solver_planner(name: str) -> MpcPlanner:
    return MpcPlanner(MpcParams(solver=name), GRID, compute_time_s=INSTANT)


# derandomized as above
@pytest.mark.parametrize("name", ["projected_newton", "sqp_lbfgs"])
@settings(max_examples=20, deadline=None, derandomize=True, database=None)
@given(st.floats(0.0, 8.0), st.floats(1.0, 25.0), st.floats(1.5, 3.2), st.floats(-1.0, 0.2), st.floats(-1.0, 1.0))
def test_converged_is_reported_only_at_a_stationary_point(name: str, v: float, x_obs: float, w: float, ux: float,
                                                          uy: float) -> None:
    """``converged`` means first-order optimality to Table II's 1e-3, ‖u − P(u − ∇𝒥)‖∞ ≤ 1e-3 at the returned plan,
    at every step of a receding horizon (the first plan from a constant guess, the next ones warm-started from the
    shifted plan, as in the closed loop, where the car may come to a stop at the speed floor's kink).  For the
    projected Newton method, whose own test is this measure, also the converse: a plan reported ``capped`` is not
    stationary (else it had converged).  (The paper's baseline is left out: like fmincon it reports a short step as
    converged, exit flag 2.)"""
    planner = solver_planner(name)
    tol = DEFAULT.caps.optimality_tol
    s, guess = np.array([0.0, 0.0, v, 0.0]), np.tile([ux * 6.0, uy * 6.0], (GRID.N_p, 1))
    th = threat(w=w, x_min=x_obs)
    for k in range(15):
        inp = PlannerInput(k * GRID.t_s, state(s[2], s[0], s[1], s[3]), th if s[0] < th.obstacle.x_max + 2.0 else None,
                           v, guess)
        p = planner.parameters(inp)
        result = planner.solver.solve(planner.initial_guess(inp).ravel(), p)
        measure = stationarity(result.u, p)
        if result.status == "converged":
            assert measure <= tol * (1 + 1e-9), (k, result.reason, measure)
        elif name == "projected_newton":
            assert result.status == "capped" and measure > tol * (1 - 1e-9), (k, result.status, result.reason, measure)
        accel = result.u.reshape(-1, 2) * planner.scale
        s = kinematic_rollout(s, accel[:1], GRID.t_s)[1]
        guess = np.vstack([accel[1:], accel[-1:]])


def test_mirrored_side_gives_the_mirrored_solution() -> None:
    planner = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT)
    for x_min in (6.0, 12.0, 20.0):
        left = planner.plan(PlannerInput(0.0, state(6.0, y=1.0, vy=0.3), threat(w=2.4, x_min=x_min, y_path=1.2), 6.0,
                                         None))
        right = planner.plan(PlannerInput(0.0, state(6.0, y=1.4, vy=-0.3),
                                          threat(w=2.4, x_min=x_min, side=-1, y_path=1.2), 6.0, None))
        np.testing.assert_allclose(left.accel[:, 0], right.accel[:, 0], atol=1e-7)
        np.testing.assert_allclose(left.accel[:, 1], -right.accel[:, 1], atol=1e-7)
        assert left.cost == pytest.approx(right.cost, rel=1e-9)


def test_warm_start_from_the_previous_solution_is_not_worse() -> None:
    planner = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT)
    cold = planner.plan(PlannerInput(0.0, state(), threat(), 7.0, None))
    warm = planner.plan(PlannerInput(0.0, state(), threat(), 7.0, cold.accel))
    assert warm.cost <= cold.cost + 1e-12


@pytest.mark.parametrize("change", [dict(solver="sqp_lbfgs"), dict(solver="sqp_exact"), dict(solver="ipopt"),
                                    dict(solver="sqp_lbfgs", speed_floor="constraint", qpsol="qpoases"),
                                    dict(solver="paper_sqp")])
def test_solver_variants_solve_the_same_problem(change: dict) -> None:
    inp = PlannerInput(0.0, state(), threat(), 7.0, None)
    base = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT)
    other = MpcPlanner(MpcParams(**change), GRID, compute_time_s=INSTANT).plan(inp)
    assert other.status in SOLVED
    assert other.accel[0, 1] == pytest.approx(6.0, abs=0.3)  # the same manoeuvre: full steering away
    assert base.cost(inp, other.accel / 6.0) < base.cost(inp, np.zeros((10, 2)))


def test_problem_is_built_once() -> None:
    a, b = MpcPlanner(DEFAULT, GRID, compute_time_s=INSTANT), MpcPlanner(MpcParams(), GRID, compute_time_s=INSTANT)
    assert a.solver is b.solver  # same parameter set: one problem and solver, parametric in the planning inputs
    assert PAPER_CAPS == SolverCaps(10, 100, 1e-3, 1e-3, 1e-3)


def test_without_a_c_compiler_the_default_solver_names_the_way_out(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("MOOSE_CACHE_DIR", str(tmp_path))  # nothing cached: the library must be built
    monkeypatch.setenv("CC", str(tmp_path / "no-such-compiler"))
    with pytest.raises(CompilerMissing, match="mpc.solver.*sqp_lbfgs"):
        MpcPlanner(MpcParams(eta_return=0.125), GRID, compute_time_s=INSTANT)  # a parameter set not built before
    for solver in ("sqp_lbfgs", "paper_sqp"):  # these evaluate the cost in CasADi's virtual machine instead
        assert MpcPlanner(MpcParams(eta_return=0.125, solver=solver), GRID, compute_time_s=INSTANT).plan(
            PlannerInput(0.0, state(), threat(), 7.0, None)).status in SOLVED


def test_parameters_are_validated() -> None:
    with pytest.raises(ParamError, match="eta"):
        MpcParams(eta=(0.5, 0.5, 0.5, 0.5))
    with pytest.raises(ParamError, match="max_iter_ls"):
        MpcParams(max_iter_ls=20)
    with pytest.raises(ParamError, match="barrier_clearance"):
        MpcParams(barrier_clearance=0.2)
    with pytest.raises(ParamError, match="barrier = 'log'"):
        MpcParams(barrier="log")
    with pytest.raises(ParamError, match="solver"):
        MpcParams(solver="fmincon")  # type: ignore[arg-type]
    with pytest.raises(ParamError, match="speed_floor"):
        MpcParams(speed_floor="constraint")  # with qrqp
    with pytest.raises(ParamError, match="speed_floor"):
        MpcParams(speed_floor="constraint", solver="paper_sqp", qpsol="qpoases")  # bounds only
    with pytest.raises(ParamError, match="max_fun_evals"):
        SolverCaps(max_iter=10, max_fun_evals=5)
