"""MPC planner on the kinematic model, Sec. IV-B: eqs. (skin), (ysafe), (costs), (jcaldef), (planmpc).

* :mod:`moose.planner.mpc.cost` — the problem: cost terms, the prediction on :mod:`moose.planner.kinematics`,
  𝒥 as a CasADi function;
* :mod:`moose.planner.mpc.solver` — the solver interface (:class:`Solver`, :class:`SolveResult`) and the
  registry of solvers by name (``mpc.solver``):
  ``projected_newton`` (:mod:`moose.planner.mpc.newton`, the default), ``sqp_lbfgs``, ``sqp_exact``,
  ``ipopt`` (:mod:`moose.planner.mpc.nlpsol`) and ``paper_sqp`` (:mod:`moose.planner.mpc.paper_sqp`, the paper's
  fmincon baseline);
* :mod:`moose.planner.mpc.planner` — :class:`MpcPlanner`, one planning instant.
"""
from __future__ import annotations

from . import newton, nlpsol, paper_sqp  # noqa: F401  (register the solvers)
from .cost import (
    PARAMETERS,
    Problem,
    barrier_gap,
    build_problem,
    epsilon,
    j_brake,
    j_return,
    j_safe,
    j_stable,
    j_steer,
    past_obstacle,
    speed_floor,
    violates_barrier,
    y_safe,
)
from .planner import MpcPlanner, keep_speed_non_negative
from .solver import Solver, SolveResult, SolveStatus, create, register, registered

__all__ = [
    "MpcPlanner", "PARAMETERS", "Problem", "SolveResult", "SolveStatus", "Solver", "barrier_gap", "build_problem",
    "create", "epsilon", "j_brake", "j_return", "j_safe", "j_stable", "j_steer", "keep_speed_non_negative",
    "past_obstacle", "register", "registered", "speed_floor", "violates_barrier", "y_safe",
]
