"""Projected Newton solver (moose.planner.mpc.projected_newton): box-constrained optima against references,
negative curvature, caps, statuses, bounds, bad input."""
from __future__ import annotations

import functools
import itertools

import casadi as ca
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from moose.params import ParamError
from moose.planner.mpc.projected_newton import NewtonOptions, ProjectedNewton

GENEROUS = NewtonOptions(max_iter=100, max_evals=5000, tol_opt=1e-6, tol_step=1e-12)


def quadratic(n: int) -> ProjectedNewton:
    """½ uᵀ Q u + cᵀ u with Q = A Aᵀ + I/10 and c in the parameters (A row-major, then c)."""
    u = ca.SX.sym("u", n)
    p = ca.SX.sym("p", n * n + n)
    a = ca.reshape(p[: n * n], n, n)
    q = a @ a.T + 0.1 * ca.SX.eye(n)
    cost = ca.Function("quadratic", [u, p], [0.5 * ca.dot(u, q @ u) + ca.dot(p[n * n:], u)])
    return ProjectedNewton(cost, GENEROUS)


def box_qp_minimum(q: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The minimiser of ½ uᵀ Q u + cᵀ u over [−1, 1]ⁿ (Q positive definite), by its KKT conditions alone.

    Every split of the inputs into lower bound, upper bound and free is tried (3ⁿ): the free ones solve
    Q_FF u_F = −(c_F + Q_FB u_B); the point is the optimum when it lies in the box and the gradient pushes
    every bound input outwards.  Strict convexity makes it unique.  (An iterative reference such as SciPy's
    L-BFGS-B stopped 1.7 away from stationarity on one of these problems.)"""
    n = len(c)
    found = []
    for split in itertools.product((-1, 0, 1), repeat=n):
        u = np.array(split, dtype=float)
        free = u == 0
        if free.any():
            u[free] = np.linalg.solve(q[np.ix_(free, free)], -(c[free] + q[np.ix_(free, ~free)] @ u[~free]))
        g = q @ u + c
        if np.all(np.abs(u) <= 1 + 1e-12) and np.all(g[~free] * u[~free] <= 1e-12):
            found.append(u)
    assert len(found) == 1, found
    return found[0]


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 10_000))
@example(137)  # the problem on which the earlier L-BFGS-B reference stopped short of the optimum
def test_box_constrained_quadratic_reaches_the_optimum(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 6
    solver = quadratic(n)
    a = rng.normal(size=(n, n))
    c = 3.0 * rng.normal(size=n)
    q = a @ a.T + 0.1 * np.eye(n)
    p = np.concatenate([a.ravel(order="F"), c])  # CasADi reshapes column-major
    result = solver.solve(rng.uniform(-1, 1, n), p)
    expected = box_qp_minimum(q, c)
    assert result.status == "converged"
    np.testing.assert_allclose(result.u, expected, atol=1e-4)
    assert result.f == pytest.approx(0.5 * result.u @ q @ result.u + c @ result.u, rel=1e-12, abs=1e-12)
    assert result.iterations <= 2 * n  # Newton on a quadratic: one step per change of the active set


def rosenbrock(options: NewtonOptions = GENEROUS) -> ProjectedNewton:
    u = ca.SX.sym("u", 2)
    p = ca.SX.sym("p", 1)
    return ProjectedNewton(ca.Function("rosenbrock", [u, p], [(1 - u[0]) ** 2 + p[0] * (u[1] - u[0] ** 2) ** 2]),
                           options)


def test_rosenbrock_inside_and_on_the_bounds() -> None:
    solver = rosenbrock()
    inside = solver.solve(np.array([-1.2, 1.0]), np.array([100.0]), lb=np.array([-2.0, -2.0]), ub=2.0)
    np.testing.assert_allclose(inside.u, [1.0, 1.0], atol=1e-5)  # Rosenbrock's valley is not convex
    assert inside.status == "converged" and inside.f < 1e-9
    bounded = solver.solve(np.array([-1.2, 1.0]), np.array([100.0]), lb=-2.0, ub=np.array([0.5, 2.0]))
    np.testing.assert_allclose(bounded.u, [0.5, 0.25], atol=1e-5)  # u₀ on its bound, u₁ = u₀²
    assert bounded.optimality <= 1e-6


def test_an_mx_cost_is_expanded() -> None:
    u = ca.MX.sym("u", 2)
    p = ca.MX.sym("p", 2)
    solver = ProjectedNewton(ca.Function("mx_cost", [u, p], [ca.sumsqr(u - p)]), GENEROUS)
    np.testing.assert_allclose(solver.solve(np.zeros(2), np.array([0.5, 3.0])).u, [0.5, 1.0], atol=1e-9)


def test_negative_curvature_is_followed_to_the_bound() -> None:
    """−u₀² + u₁²: a saddle at 0; from u₀ slightly positive the minimum on the box is u₀ = 1."""
    u = ca.SX.sym("u", 2)
    p = ca.SX.sym("p", 1)
    solver = ProjectedNewton(ca.Function("saddle", [u, p], [-u[0] ** 2 + u[1] ** 2]), GENEROUS)
    result = solver.solve(np.array([1e-3, 0.5]), np.zeros(1))
    np.testing.assert_allclose(result.u, [1.0, 0.0], atol=1e-9)
    assert result.f == pytest.approx(-1.0) and result.f < result.f_start


def test_caps_and_statuses() -> None:
    start, p = np.array([-1.2, 1.0]), np.array([100.0])
    capped = rosenbrock(NewtonOptions(max_iter=2, max_evals=100)).solve(start, p, lb=-2.0, ub=2.0)
    assert capped.status == "max_iter" and capped.iterations == 2
    assert capped.f < capped.f_start
    evals = rosenbrock(NewtonOptions(max_iter=50, max_evals=4)).solve(start, p, lb=-2.0, ub=2.0)
    assert evals.status == "max_evals" and evals.evaluations == 4
    at_optimum = rosenbrock().solve(np.array([1.0, 1.0]), p, lb=-2.0, ub=2.0)
    assert at_optimum.status == "converged" and at_optimum.iterations == 0 and at_optimum.evaluations == 1


def test_every_iteration_decreases_the_cost_within_the_evaluation_cap() -> None:
    solver = rosenbrock(NewtonOptions(max_iter=10, max_evals=100, max_ls=8))
    previous = np.inf
    for k in range(1, 11):
        solver_k = rosenbrock(NewtonOptions(max_iter=k, max_evals=100, max_ls=8))
        result = solver_k.solve(np.array([-1.2, 1.0]), np.array([100.0]), lb=-2.0, ub=2.0)
        assert result.f <= previous and result.evaluations <= 1 + k * 9
        previous = result.f
    assert solver.solve(np.array([-1.2, 1.0]), np.array([100.0]), lb=-2.0, ub=2.0).f == previous


def test_a_start_where_the_cost_is_not_finite_fails_cleanly() -> None:
    u = ca.SX.sym("u", 2)
    p = ca.SX.sym("p", 1)
    solver = ProjectedNewton(ca.Function("logs", [u, p], [-ca.log(u[0]) - ca.log(u[1])]), GENEROUS)
    failed = solver.solve(np.array([-0.5, 0.5]), np.zeros(1))
    assert failed.status == "not_finite" and failed.f == np.inf
    ok = solver.solve(np.array([0.5, 0.5]), np.zeros(1))  # trials outside the domain are rejected, not taken
    np.testing.assert_allclose(ok.u, [1.0, 1.0], atol=1e-12)
    assert np.isfinite(ok.f)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.floats(-5.0, 5.0), min_size=6, max_size=6), st.floats(0.0, 10.0))
def test_results_stay_inside_the_bounds(start: list[float], scale: float) -> None:
    u = ca.SX.sym("u", 6)
    p = ca.SX.sym("p", 1)
    cost = ca.Function("wavy", [u, p], [ca.sum1(ca.sin(p[0] * u) + 0.1 * (u - 3.0) ** 2)])
    solver = ProjectedNewton(cost, NewtonOptions())
    lb, ub = np.array([-1.0, -2.0, 0.0, -0.5, -1.0, 1.0]), np.array([1.0, 0.0, 2.0, 0.5, 3.0, 1.0])
    result = solver.solve(np.array(start), np.array([scale]), lb, ub)
    assert np.all(result.u >= lb) and np.all(result.u <= ub) and result.u[5] == 1.0
    assert result.f <= result.f_start and np.isfinite(result.f)


def test_bad_input_is_named() -> None:
    with pytest.raises(ParamError, match="rho"):
        NewtonOptions(rho=1.5)
    with pytest.raises(ParamError, match="max_evals"):
        NewtonOptions(max_evals=0)
    with pytest.raises(ParamError, match="regularisation"):
        NewtonOptions(regularisation=-1.0)
    with pytest.raises(ValueError, match="lb > ub"):
        rosenbrock().solve(np.zeros(2), np.array([100.0]), lb=1.0, ub=0.0)


KINKED_N = 6


@functools.cache
def kinked() -> tuple[ca.Function, ProjectedNewton]:
    """½ uᵀ Q u + cᵀ u + 10⁴ Σ min(u − s, 0)² (Q = A + Aᵀ, indefinite; A, c, s in the parameters) and its solver with
    the MPC's caps: the penalty's curvature switches on at u = s, where the exact Hessian sees one side only (as the
    MPC's speed floor at v_X = 0)."""
    n = KINKED_N
    u = ca.SX.sym("u", n)
    p = ca.SX.sym("p", n * n + 2 * n)
    a = ca.reshape(p[: n * n], n, n)
    c, s = p[n * n: n * n + n], p[n * n + n:]
    f = 0.5 * ca.dot(u, (a + a.T) @ u) + ca.dot(c, u) + 1e4 * ca.sumsqr(ca.fmin(u - s, 0.0))
    gradient = ca.Function("kinked_gradient", [u, p], [ca.gradient(f, u)])  # CasADi's virtual machine
    return gradient, ProjectedNewton(ca.Function("kinked", [u, p], [f]), NewtonOptions())


@settings(max_examples=40, deadline=None, derandomize=True, database=None)
@given(st.integers(0, 2**32 - 1))
def test_converged_exactly_at_a_stationary_point(seed: int) -> None:
    """Started on the kink, with the MPC's caps (10 iterations, tolerances 1e-3): ``converged`` if and only if
    ‖u − P(u − ∇f)‖∞ ≤ tol_opt at the returned point (∇f by CasADi's virtual machine), which ``optimality``
    reports."""
    rng = np.random.default_rng(seed)
    n = KINKED_N
    gradient, solver = kinked()
    a, c, s = rng.normal(size=(n, n)), 3.0 * rng.normal(size=n), rng.uniform(-0.5, 0.5, n)
    p = np.concatenate([a.ravel(order="F"), c, s])
    result = solver.solve(s, p)
    g = np.asarray(gradient(result.u, p), dtype=float).ravel()
    measure = float(np.max(np.abs(np.clip(result.u - g, -1.0, 1.0) - result.u)))
    assert (result.status == "converged") == (measure <= solver.options.tol_opt), (result.status, measure)
    assert result.optimality == pytest.approx(measure, rel=1e-9, abs=1e-12)
