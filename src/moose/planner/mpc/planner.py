"""The MPC planner of Sec. IV-B: eq. (planmpc) solved at every planning instant.

:class:`MpcPlanner` turns a :class:`moose.signals.PlannerInput` into the problem's parameters
(:data:`moose.planner.mpc.cost.PARAMETERS`) and an initial guess, lets the configured solver
(:mod:`moose.planner.mpc.solver`) minimise the cost of :mod:`moose.planner.mpc.cost`, and returns the plan in
m/s² with its predicted states.  The returned plan is projected onto v_X ≥ 0 and is never
costlier than its start.  A plan whose predicted path crosses the barrier y_safe before the zone's far
edge is reported ``barrier_violated`` (:func:`moose.planner.mpc.cost.violates_barrier`): the paper's solver
"fails to provide a solution" there, and the weight function treats it so.
"""
from __future__ import annotations

import math
import time
from functools import lru_cache
from typing import Optional

import casadi as ca
import numpy as np

from ...schema import MpcParams, PlanningGrid
from ...signals import PlannerInput, PlanResult, PlanStatus
from ...timing import over_budget
from ..kinematics import kinematic_rollout
from . import solver as solvers
from .cost import P_VX, barrier_gap, build_problem, epsilon, speed_floor, violates_barrier


@lru_cache(maxsize=16)
def _build(params: MpcParams, n_p: int, t_s: float) -> solvers.Solver:
    """The solver of eq. (planmpc), built once per parameter set and grid (the problem is parametric
    in the planning inputs and the bounds)."""
    return solvers.create(build_problem(params, n_p, t_s), params)


def keep_speed_non_negative(u: np.ndarray, vX0: float, grid: PlanningGrid) -> np.ndarray:
    """Normalised (N_p, 2) inputs with each v̇_X raised just enough that v_X stays above :func:`speed_floor`."""
    out = np.array(u, dtype=float)
    _raise_braking(out, vX0, grid)
    return out


def _raise_braking(u: np.ndarray, vX0: float, grid: PlanningGrid) -> bool:
    """:func:`keep_speed_non_negative` in place on normalised (N_p, 2) inputs; True if an input was raised.

    A plain loop: on ten floats it is several times faster than NumPy's small-array calls.
    """
    if not math.isfinite(vX0):
        return False
    gain = grid.t_s * grid.a_x_max
    column = u[:, 0].tolist()
    v, raised = vX0, False
    for k, (uk, floor) in enumerate(zip(column, speed_floor(vX0, grid.N_p, grid.t_s, grid.a_x_max).tolist())):
        if v + gain * uk < floor:
            uk = column[k] = min((floor - v) / gain, 1.0)
            raised = True
        v += gain * uk
    if raised:
        u[:, 0] = column
    return raised


class MpcPlanner:
    """The MPC planner of Sec. IV-B (a :class:`moose.planner.Planner`): one problem and solver built once,
    solved at every planning instant."""

    def __init__(self, params: MpcParams, grid: PlanningGrid, compute_time_s: Optional[float] = None) -> None:
        self.params = params
        self.grid = grid
        """Horizon, sampling time, input bounds and planning μ (shared with the MSF planner)."""
        self.compute_time_s = compute_time_s
        """What a solve is charged against ``time_budget_s`` (:func:`moose.timing.over_budget`): in lockstep the
        timing model's compute time (``timing.planning_delay_s``), so that no outcome depends on the machine's
        speed; ``None`` (a real-time run) charges the measured wall time."""
        self._solver = _build(params, grid.N_p, grid.t_s)

    @property
    def solver(self) -> solvers.Solver:
        """The solver ``params.solver`` (shared by the planners of one parameter set and grid)."""
        return self._solver

    @property
    def scale(self) -> np.ndarray:
        """(a_x_max, a_y_max): normalised input × scale = acceleration (m/s²)."""
        return np.array([self.grid.a_x_max, self.grid.a_y_max])

    def parameters(self, inp: PlannerInput) -> np.ndarray:
        """The problem's parameter vector (:data:`moose.planner.mpc.cost.PARAMETERS`) at a planning instant."""
        est, threat, grid = inp.estimate, inp.threat, self.grid
        if threat is not None:
            box = threat.obstacle
            geometry = (box.x_min, box.x_max, threat.w, float(threat.side), threat.y_path, 1.0)
        else:  # lane keeping: no barrier, the lane is the path
            geometry = (0.0, 0.0, 1.0, 1.0, inp.y_lane, 0.0)
        return np.array([est.x, est.y, est.vX, est.vY, inp.v_des, *geometry,
                         epsilon(grid.mu), grid.a_x_max, grid.a_y_max], dtype=float)

    def initial_guess(self, inp: PlannerInput) -> np.ndarray:
        """Normalised (N_p, 2) starting point: the shifted previous blend, else zeros (keep speed and heading).

        A shorter guess is padded with its last row, non-finite entries become 0, values are
        clipped to [−1, 1] and braking is reduced where it would predict v_X < 0.
        """
        n = self.grid.N_p
        guess = np.zeros((n, 2))
        if inp.initial_guess is not None:
            given = np.asarray(inp.initial_guess, dtype=float).reshape(-1, 2)[:n]
            if len(given):
                guess[:len(given)] = given
                guess[len(given):] = given[-1]
            guess = guess / self.scale
        guess = np.clip(guess, -1.0, 1.0)  # ±inf → ±1; NaN stays NaN …
        guess[np.isnan(guess)] = 0.0  # … and becomes 0 (np.nan_to_num's checks cost more than the rest)
        return keep_speed_non_negative(guess, inp.estimate.vX, self.grid)

    @property
    def cost_function(self) -> ca.Function:
        """The CasADi function (u normalised (2 N_p), :meth:`parameters`) → 𝒥 the solver minimises."""
        return self._solver.problem.cost_function

    def cost(self, inp: PlannerInput, u_normalised: np.ndarray) -> float:
        """𝒥 of eq. (jcaldef) (with the lane-keeping and speed-floor terms) for normalised (N_p, 2) inputs."""
        return self._solver.cost(np.asarray(u_normalised, dtype=float).reshape(-1), self.parameters(inp))

    def reset(self) -> None:
        """Nothing to forget: a plan depends on its input alone (the warm start comes in as
        ``initial_guess``; the solver keeps no state between solves)."""

    def plan(self, inp: PlannerInput) -> PlanResult:
        """Solve eq. (planmpc) at one planning instant, from :meth:`initial_guess`.

        The result is never costlier than the start: with a capped line search an SQP may
        accept an increasing step, and the start is then the best point known.  A non-finite
        problem or solver failure returns the start with status ``failed`` and cost ``inf``.
        A solve over ``time_budget_s`` (:attr:`compute_time_s`) is ``over_budget``; ``solve_time_s`` is the wall
        time either way.
        """
        p = self.parameters(inp)
        guess = self.initial_guess(inp)
        start = time.perf_counter()
        status: PlanStatus = "failed"
        iterations = 0
        solution, cost = guess, math.inf
        if np.all(np.isfinite(p)):
            result = self._solver.solve(guess.ravel(), p)
            status, iterations = result.status, result.iterations
            if status != "failed":
                solution, f = result.u.reshape(self.grid.N_p, 2).copy(), result.f
                if _raise_braking(solution, p[P_VX], self.grid):
                    f = self._solver.cost(solution.ravel(), p)
                solution, cost = (guess, result.f_start) if result.f_start < f else (solution, f)
        elapsed = time.perf_counter() - start
        accel = solution * self.scale
        est = inp.estimate
        state = np.array([est.x, est.y, est.vX, est.vY], dtype=float)
        state[~np.isfinite(state)] = 0.0  # a failed plan on a non-finite estimate still predicts finite states
        predicted = kinematic_rollout(state, accel, self.grid.t_s)
        if status != "failed" and over_budget(elapsed if self.compute_time_s is None else self.compute_time_s,
                                              self.params.time_budget_s):
            status = "over_budget"  # late is no plan, whatever its path
        elif status != "failed" and inp.threat is not None and violates_barrier(self.barrier_gap(inp, predicted)):
            status = "barrier_violated"
        return PlanResult(accel=accel, status=status, iterations=iterations, solve_time_s=elapsed, cost=cost,
                          predicted=predicted)

    def barrier_gap(self, inp: PlannerInput, predicted: np.ndarray) -> np.ndarray:
        """d = ỹ − y_safe along ``predicted`` for the threat of ``inp`` (:func:`moose.planner.mpc.cost.barrier_gap`,
        with this problem's ε and regularisation); empty without a threat."""
        threat = inp.threat
        if threat is None:
            return np.zeros(0)
        box = threat.obstacle
        return barrier_gap(predicted, box.x_min, box.x_max, threat.w, float(threat.side), threat.y_path,
                           epsilon(self.grid.mu), self.params.v_reg)
