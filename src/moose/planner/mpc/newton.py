"""``mpc.solver: projected_newton`` (the default): :mod:`moose.planner.mpc.projected_newton` on eq. (planmpc).

The problem has only the input bounds as constraints, so a general SQP spends most of its time
on QPs that here reduce to the active set of a box.  The projected Newton method uses the exact
Hessian and is compiled together with the cost into one shared object: one plan is one C call.
"""
from __future__ import annotations

import numpy as np

from ...schema import MpcParams
from .cost import Problem
from .projected_newton import CompilerMissing, NewtonOptions, NewtonStatus, ProjectedNewton
from .solver import Solver, SolveResult, SolveStatus, register

STATUS: dict[NewtonStatus, SolveStatus] = {
    "converged": "converged",  # ‖u − P(u − ∇f)‖∞ ≤ optimality_tol: fmincon's exit flag 1 (never a short step alone)
    "max_iter": "capped", "max_evals": "capped", "line_search": "capped",  # a limit of Table II or the search
    "not_finite": "failed"}


def newton_options(params: MpcParams) -> NewtonOptions:
    """Table II's caps and tolerances with the line search and active set of ``params``."""
    caps = params.caps
    return NewtonOptions(max_iter=caps.max_iter, max_evals=caps.max_fun_evals, max_ls=params.max_iter_ls,
                         rho=params.ls_beta, eps_active=params.active_set_tol, tol_opt=caps.optimality_tol,
                         tol_step=caps.step_tol)


@register("projected_newton")
class ProjectedNewtonSolver(Solver):
    """Projected Newton with the exact Hessian, compiled C (raises :class:`CompilerMissing` without a compiler)."""

    def __init__(self, problem: Problem, params: MpcParams) -> None:
        super().__init__(problem, params)
        try:
            self._newton = ProjectedNewton(problem.cost_function, newton_options(params))
        except CompilerMissing as error:
            raise CompilerMissing(f"mpc.solver = projected_newton: {error}; or set mpc.solver to sqp_lbfgs "
                                  "or paper_sqp, which run without a compiler") from error

    def solve(self, guess: np.ndarray, p: np.ndarray) -> SolveResult:
        result = self._newton.solve(guess, p)
        status = STATUS[result.status]
        if status == "failed":
            return SolveResult.failure(guess, result.iterations, result.evaluations, result.status)
        return SolveResult(status, result.u, result.f, result.f_start, result.iterations, result.evaluations,
                           result.status)

    def cost(self, u: np.ndarray, p: np.ndarray) -> float:
        return self._newton.cost(u, p)
