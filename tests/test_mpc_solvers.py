"""The MPC's solvers behind one interface (moose.planner.mpc.solver): registry, and the same contract for each."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from moose.planner.mpc import MpcPlanner, Solver, SolveResult, build_problem, create, register, registered
from moose.schema import SOLVERS, MpcParams, PlanningGrid
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat
from solve_time import INSTANT

GRID = PlanningGrid(N_p=10, t_s=0.2, a_x_max=6.0, a_y_max=6.0, mu=0.3)


def test_the_registry_holds_exactly_the_names_a_configuration_may_give() -> None:
    assert sorted(registered()) == sorted(SOLVERS)


def test_unknown_and_duplicate_names_are_refused() -> None:
    params = MpcParams()
    object.__setattr__(params, "solver", "fmincon")  # past the schema's validation
    with pytest.raises(ValueError, match="'fmincon' is not a registered solver"):
        create(build_problem(MpcParams(), GRID.N_p, GRID.t_s), params)
    with pytest.raises(ValueError, match="registered twice"):
        register("paper_sqp")(Solver)


def reference_minimum(cost: ca.Function, p: np.ndarray, starts: list[np.ndarray]) -> float:
    """The least cost scipy's L-BFGS-B finds in the box |u| ≤ 1 from ``starts``, with CasADi's exact gradient of the
    problem's cost: an optimum found by a solver this project does not ship."""
    from scipy.optimize import minimize

    u = ca.SX.sym("u", starts[0].size)
    f = cost(u, p)
    value_and_gradient = ca.Function("fg", [u], [f, ca.gradient(f, u)])

    def fg(x: np.ndarray) -> tuple[float, np.ndarray]:
        value, gradient = value_and_gradient(x)
        return float(value), np.asarray(gradient, dtype=float).ravel()

    return min(minimize(fg, x0, jac=True, method="L-BFGS-B", bounds=[(-1.0, 1.0)] * x0.size,
                        options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 5000}).fun for x0 in starts)


REACHED = {"converged": 1e-6, "capped": 0.02}
"""Of the decrease from the start's cost to the optimum, the share a result may leave: none (to rounding) when the
solver converged, 2 % when it stopped at its iteration or time cap (the real-time budget, Table II)."""


@pytest.mark.parametrize("name", SOLVERS)
def test_every_solver_keeps_the_contract_and_reaches_the_optimum(name: str) -> None:
    """Bounds, a cost that is the problem's cost at the returned point, the start's cost, a status — and a cost at
    the optimum that a reference solver (scipy) finds: a solver that returned its start would keep 100 % of the
    decrease it owes."""
    planner = MpcPlanner(MpcParams(solver=name), GRID, compute_time_s=INSTANT)
    reference = build_problem(MpcParams(), GRID.N_p, GRID.t_s).cost_function  # CasADi's virtual machine
    threat = Threat(0.0, Obstacle(12.0, 14.0, -0.5, 2.4), 2.0, 2.4, 0.5, 1, 0.0)
    inp = PlannerInput(0.0, StateEstimate(0.0, 0.0, 0.2, 0.0, 6.0, 0.3, 0.0, 0.0), threat, 6.0, None)
    p, guess = planner.parameters(inp), planner.initial_guess(inp).ravel()
    result = planner.solver.solve(guess.copy(), p)
    assert isinstance(result, SolveResult)
    assert result.status in ("converged", "capped")
    assert result.u.shape == (2 * GRID.N_p,) and np.all(np.abs(result.u) <= 1.0)
    assert result.f == pytest.approx(float(reference(result.u, p)), rel=1e-9)
    assert result.f_start == pytest.approx(float(reference(guess, p)), rel=1e-9)
    assert result.iterations >= 1 and result.evaluations >= 1 and result.reason
    assert planner.solver.cost(result.u, p) == pytest.approx(result.f, rel=1e-12)
    # the optimum: from the start, from no input, and from the solver's answer (so it is never above the answer)
    optimum = reference_minimum(reference, p, [guess, np.zeros_like(guess), result.u])
    owed = result.f_start - optimum
    assert owed > 100.0  # this start is far from the optimum: a solver that does nothing is far from it too
    assert result.f - optimum <= REACHED[result.status] * owed, (result.status, result.f, optimum, result.f_start)
    if name == "paper_sqp":
        assert result.iterations <= 4 and result.evaluations <= 100


def test_a_failure_returns_the_start_with_infinite_cost() -> None:
    failed = SolveResult.failure(np.zeros(4), 0, 1, "not_finite")
    assert failed.status == "failed" and failed.f == math.inf and failed.f_start == math.inf
    assert np.array_equal(failed.u, np.zeros(4))
