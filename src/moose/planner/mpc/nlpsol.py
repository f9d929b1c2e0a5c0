"""``mpc.solver: sqp_lbfgs | sqp_exact | ipopt``: CasADi's ``nlpsol`` on eq. (planmpc).

``sqp_lbfgs``: ``sqpmethod`` with a BFGS Hessian (limited memory); ``sqp_exact``: ``sqpmethod`` with
the exact Hessian, regularised to be positive definite; ``ipopt``: interior point (a reference).
The QP solver of ``sqpmethod`` is ``mpc.qpsol``; with ``speed_floor: constraint`` the predicted
speeds are linear constraints (qpOASES or IPOPT).  Gradients come from automatic differentiation.
"""
from __future__ import annotations

import math
from typing import Any

import casadi as ca
import numpy as np

from ...schema import MpcParams
from .cost import Problem
from .solver import CompiledCost, Solver, SolveResult, SolveStatus, register

_CAPPED = ("Maximum_Iterations_Exceeded", "Maximum_Iterations_Reached", "Search_Direction_Becomes_Too_Small")
"""Stopped by a cap, or by a step below Table II's step tolerance: no stationary point (on bench_mpc.py's 180
closed-loop problems, none of the 84 plans sqpmethod ended on a short step was stationary to 1e-3)."""
_COST_CALLS = ("n_call_nlp_f", "n_call_nlp_fg", "n_call_nlp_grad_f", "n_call_nlp_jac_fg")
"""CasADi's counters of the functions that evaluate the cost (alone or with its gradient)."""


def nlpsol_options(params: MpcParams) -> tuple[str, dict[str, Any]]:
    """CasADi plugin and options for ``params.solver`` with Table II's caps and tolerances."""
    caps = params.caps
    quiet = {"print_time": False, "error_on_fail": False}
    if params.solver == "ipopt":
        return "ipopt", {**quiet, "ipopt": {
            "max_iter": caps.max_iter, "tol": caps.optimality_tol, "constr_viol_tol": caps.constraint_tol,
            "acceptable_tol": caps.optimality_tol, "print_level": 0, "sb": "yes"}}
    if params.qpsol == "qrqp":
        qp: dict[str, Any] = {"print_iter": False, "print_header": False, "print_info": False}
    else:
        qp = {"printLevel": "none"}
    options: dict[str, Any] = {
        **quiet,
        "qpsol": params.qpsol,
        "qpsol_options": {**qp, "error_on_fail": False},
        "max_iter": caps.max_iter,
        "max_iter_ls": params.max_iter_ls,
        "beta": params.ls_beta,
        "tol_pr": caps.constraint_tol,
        "tol_du": caps.optimality_tol,
        "min_step_size": caps.step_tol,
        "print_header": False, "print_iteration": False, "print_status": False,
    }
    if params.solver == "sqp_exact":
        options.update(hessian_approximation="exact", convexify_strategy="regularize")
    else:
        options.update(hessian_approximation="limited-memory")
    return "sqpmethod", options


def nlpsol_status(stats: dict[str, Any]) -> SolveStatus:
    """converged | capped | failed from CasADi's statistics."""
    returned = str(stats.get("return_status", ""))
    if returned in _CAPPED or stats.get("unified_return_status") == "SOLVER_RET_LIMITED":
        return "capped"
    if stats.get("success", False) or returned in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
        return "converged"
    return "failed"


@register("sqp_lbfgs", "sqp_exact", "ipopt")
class NlpsolSolver(Solver):
    """A CasADi ``nlpsol`` built once for the problem."""

    def __init__(self, problem: Problem, params: MpcParams) -> None:
        super().__init__(problem, params)
        nlp: dict[str, Any] = {"x": problem.u, "p": problem.p, "f": problem.cost}
        self._constrained = params.speed_floor == "constraint"
        if self._constrained:
            nlp["g"] = problem.speeds
        plugin, options = nlpsol_options(params)
        self._nlpsol = ca.nlpsol("mpc", plugin, nlp, options)
        self._cost = CompiledCost(problem)

    def solve(self, guess: np.ndarray, p: np.ndarray) -> SolveResult:
        args: dict[str, Any] = {"x0": guess, "p": p, "lbx": -1.0, "ubx": 1.0}
        if self._constrained:
            args["lbg"] = self.problem.speed_lower_bounds(p)
            args["ubg"] = math.inf
        try:
            sol = self._nlpsol(**args)
            stats = self._nlpsol.stats()
        except RuntimeError as error:  # solver error, or CasADi could not report its statistics
            return SolveResult.failure(guess, 0, 0, f"RuntimeError: {error}")
        iterations = int(stats.get("iter_count", 0))
        evaluations = sum(int(stats.get(key, 0)) for key in _COST_CALLS)
        reason = str(stats.get("return_status", ""))
        u = np.asarray(sol["x"], dtype=float).ravel()
        f = float(sol["f"])
        if not (np.all(np.isfinite(u)) and math.isfinite(f)):
            return SolveResult.failure(guess, iterations, evaluations, reason or "not_finite")
        clipped = np.clip(u, -1.0, 1.0)  # the QP's bounds hold to its tolerance
        if not np.array_equal(clipped, u):
            f = self.cost(clipped, p)
        return SolveResult(nlpsol_status(stats), clipped, f, self.cost(guess, p), iterations, evaluations, reason)

    def cost(self, u: np.ndarray, p: np.ndarray) -> float:
        return self._cost(u, p)
