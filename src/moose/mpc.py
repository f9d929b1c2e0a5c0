"""MPC planner on the kinematic model: eqs. (skin), (ysafe), (costs), (jcaldef), (planmpc).

The decision variables are the 2 N_p inputs ũ = [v̇_X, v̇_Y] over the horizon,
normalised to [−1, 1] by (a_x_max, a_y_max) (eq. (utilde); Example emp:eta's
normalisation); the predicted states are functions of them inside the cost
(single shooting, as eq. (planmpc) states).  The NLP is built once per parameter
set and is parametric in the state, v_des, the obstacle's extent, w, the evasion
side, the ego path, ε (i.e. μ) and the input bounds (:data:`PARAMETERS`).

Choices where the paper is silent or inconsistent (docs/design.md, "MPC"):

* eq. (skin) is discretised with the exact zero-order hold
  p⁺ = p + t_s v + t_s²/2 a, v⁺ = v + t_s a (forward Euler would give
  y(k+1) = y(k) whatever the input: the first predicted step could not react).
* Barrier sign: the printed J_safe = −log(y_safe − y) keeps the ego *below* the
  sigmoid, i.e. in the obstacle; Example emp:eta and Fig. barrier describe the ego
  kept above it.  We use the offset toward the evasion side ỹ = s (y − y_path)
  and d = ỹ − y_safe.
* Barrier shape (:func:`j_safe`): −log d as printed (``barrier = "paper"``, the
  default) keeps rewarding distance from y_safe, and at the paper's caps the MPC
  alone overreacts in the extreme case (8 m swerve).  ``barrier = "clipped"``
  subtracts its tangent at a clearance c and is 0 beyond it (C¹): no reward for
  moving further out.  Either way, below the margin d₀ it is continued by its
  second-order Taylor polynomial, so an infeasible start (y_safe ≈ w at
  detection) has a finite cost and a gradient toward the safe side.
* eq. (ysafe) is evaluated in tanh form (no overflow), √(w v_X²) as
  √w √(v_X² + v_reg²); |·| as √(·² + ε_abs²) − ε_abs (smooth at 0).
* The paper's sigmoid never falls again; the car must return to its lane after the
  obstacle.  J_safe is multiplied by a falling sigmoid, ½ at ``pass_margin`` past
  the obstacle's far edge, and a lane-keeping term η_return |ỹ| (not in the
  paper) is added at every step, with or without a threat.  Gating it on being
  past the obstacle was measured worse: the cost jump on passing made braking to
  a stop before the obstacle cheaper than passing.
* J_steer(k+i) uses the input that produces the state k+i, u(k+i−1), normalised.
* v_X ≥ 0: a quadratic penalty on min(v_X, 0) (bounds-only QPs, fast) or linear
  constraints; either way the returned plan is projected onto v_X ≥ 0.
* Solver: the problem has only the input bounds as constraints, so the default is a
  projected Newton method with the exact Hessian (:mod:`moose.projected_newton`,
  compiled C, one call per plan), chosen by measurement against CasADi's
  ``sqpmethod`` (BFGS or exact Hessian, qrqp or qpOASES), IPOPT and the fmincon
  stand-in (bench/bench_mpc.py); Table II's caps are :data:`PAPER_CAPS`.
"""
from __future__ import annotations

import dataclasses
import math
import time
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from .params import G
from .projected_newton import CompilerMissing, NewtonOptions, ProjectedNewton
from .schema import MpcParams, PlanningGrid
from .signals import PlannerInput, PlanResult, PlanStatus


def epsilon(mu: float) -> float:
    """ε = 1/√(8.8 μ g), eq. (ysafe)."""
    return 1.0 / math.sqrt(8.8 * mu * G)


# ---------------------------------------------------------------------------
# Cost terms: floats in, float out; CasADi symbols in, expression out
# ---------------------------------------------------------------------------

def _out(value: Any, *args: Any) -> Any:
    """A CasADi result as a float when no argument was symbolic."""
    if any(isinstance(a, (ca.SX, ca.MX)) for a in args):
        return value
    return float(value)


def smooth_abs(x: Any, eps: float = 0.05) -> Any:
    """|x| regularised at 0: √(x² + eps²) − eps (0 at 0, within eps of |x|)."""
    return _out(ca.sqrt(x * x + eps * eps) - eps, x)


def sigmoid(a: Any) -> Any:
    """1 / (1 + e^a) in tanh form, ½ (1 − tanh(a / 2)): no overflow for any a."""
    return _out(0.5 * (1.0 - ca.tanh(0.5 * a)), a)


def y_safe(x_ego: Any, vX: Any, x_obs: Any, w: Any, eps: Any, v_reg: float = 0.5) -> Any:
    """Sigmoid barrier, eq. (ysafe): w / (1 + exp((x_obs − x_ego − 4 v_X) / (ε √(w v_X²)))).

    ``x_obs`` is the obstacle's near edge; √(w v_X²) is regularised as √w √(v_X² + v_reg²).
    """
    scale = eps * ca.sqrt(w) * ca.sqrt(vX * vX + v_reg * v_reg)
    return _out(w * sigmoid((x_obs - x_ego - 4.0 * vX) / scale), x_ego, vX, x_obs, w, eps)


def j_safe(y_tilde: Any, ysafe: Any, margin: float = 0.3, clearance: float | None = None) -> Any:
    """J_safe, eq. (jbarr), with the intended sign: the ego kept above y_safe.

    ``y_tilde`` is the offset toward the evasion side, s (y − y_path); d = ỹ − y_safe.
    ``clearance`` None is the paper's −log d for d ≥ ``margin``.  A clearance c
    gives the clipped variant −log(d / c) + d / c − 1: the paper's −log d minus
    its tangent at c (the same repulsion near y_safe), 0 with zero slope for d ≥ c,
    so moving further out is no longer rewarded.  Either way, below ``margin`` the
    log branch is continued by its second-order Taylor polynomial at the margin
    (finite, convex and decreasing), so an infeasible start has a finite cost.
    """
    m = margin
    d = y_tilde - ysafe
    dm = d - m
    if clearance is None:
        taylor = -math.log(m) - dm / m + dm * dm / (2.0 * m * m)
        inner = -ca.log(ca.fmax(d, m))
    else:
        c = clearance
        taylor = (-math.log(m / c) + m / c - 1.0) + (1.0 / c - 1.0 / m) * dm + dm * dm / (2.0 * m * m)
        dd = ca.fmin(ca.fmax(d, m), c)
        inner = -ca.log(dd / c) + dd / c - 1.0
    return _out(ca.if_else(d >= m, inner, taylor), y_tilde, ysafe)


def j_stable(vX: Any, vY: Any, v_reg: float = 0.5, eps: float = 0.05) -> Any:
    """J_stable, eq. (jstab): |v_Y / v_X|, v_X regularised as √(v_X² + v_reg²)."""
    return _out(smooth_abs(vY, eps) / ca.sqrt(vX * vX + v_reg * v_reg), vX, vY)


def j_brake(vX: Any, v_des: Any, eps: float = 0.05) -> Any:
    """J_brake, eq. (jvel): |v_X − v_des|."""
    return _out(smooth_abs(vX - v_des, eps), vX, v_des)


def j_steer(vY_dot_normalised: Any, eps: float = 0.05) -> Any:
    """J_steer, eq. (jsteer): |v̇_Y|, on the input normalised by a_y_max."""
    return _out(smooth_abs(vY_dot_normalised, eps), vY_dot_normalised)


def j_return(y_tilde: Any, eps: float = 0.05) -> Any:
    """Lane-keeping term |ỹ| (not in the paper): distance to the ego path (or the lane)."""
    return _out(smooth_abs(y_tilde, eps), y_tilde)


def past_obstacle(x_ego: Any, x_far: Any, margin: float = 1.0) -> Any:
    """0 before the obstacle, 1 past it: a sigmoid ½ at ``x_far + margin``, width ``margin / 4`` (not in the paper)."""
    return _out(sigmoid((x_far + margin - x_ego) / (0.25 * margin)), x_ego, x_far)


# ---------------------------------------------------------------------------
# Prediction and NLP
# ---------------------------------------------------------------------------

PARAMETERS = ("x", "y", "vX", "vY", "v_des", "x_near", "x_far", "w", "side", "y_path", "active",
              "epsilon", "a_x_max", "a_y_max")
"""Order of the NLP's parameter vector (``active`` = 1 with a threat, 0 without)."""


def kinematic_step(state: Any, accel: Any, t_s: float) -> tuple[Any, Any, Any, Any]:
    """eq. (skin) over one period with the input held (exact zero-order hold)."""
    x, y, vX, vY = state
    aX, aY = accel
    h = 0.5 * t_s * t_s
    return x + t_s * vX + h * aX, y + t_s * vY + h * aY, vX + t_s * aX, vY + t_s * aY


def kinematic_rollout(state: np.ndarray, accel: np.ndarray, t_s: float) -> np.ndarray:
    """eq. (skin) with exact zero-order hold: (N+1, 4) states [x, y, v_X, v_Y] from (N, 2) accelerations."""
    accel = np.asarray(accel, dtype=float).reshape(-1, 2)
    out = np.empty((len(accel) + 1, 4))
    out[0] = state
    for k, a in enumerate(accel):
        out[k + 1] = kinematic_step(out[k], a, t_s)
    return out


def _cost_expression(params: MpcParams, n_p: int, t_s: float, u: Any, p: Any) -> tuple[Any, list[Any]]:
    """𝒥 of eq. (jcaldef) with the lane-keeping and speed-floor terms, and the predicted v_X."""
    x, y, vX, vY, v_des, x_near, x_far, w, side, y_path, active, eps, ax_max, ay_max = (
        p[i] for i in range(len(PARAMETERS)))
    e1, e2, e3, e4 = params.eta
    ae, vr = params.abs_eps, params.v_reg
    w_pos = ca.fmax(w, 1e-3)
    cost = 0
    speeds = []
    state = (x, y, vX, vY)
    for k in range(n_p):  # i = 1..N_p: the state produced by u(k+i-1)
        uX, uY = u[2 * k], u[2 * k + 1]
        state = kinematic_step(state, (uX * ax_max, uY * ay_max), t_s)
        xk, yk, vXk, vYk = state
        speeds.append(vXk)
        y_tilde = side * (yk - y_path)
        barrier = j_safe(y_tilde, y_safe(xk, vXk, x_near, w_pos, eps, vr), params.barrier_margin,
                         params.barrier_clearance if params.barrier == "clipped" else None)
        cost += active * e1 * (1.0 - past_obstacle(xk, x_far, params.pass_margin)) * barrier
        cost += e2 * j_stable(vXk, vYk, vr, ae) + e3 * j_brake(vXk, v_des, ae) + e4 * j_steer(uY, ae)
        cost += params.eta_return * j_return(y_tilde, ae)
        if params.speed_floor == "penalty":
            cost += params.reverse_penalty * ca.fmin(vXk, 0.0) ** 2
    return cost, speeds


def _solver_options(params: MpcParams) -> tuple[str, dict[str, Any]]:
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


def _newton_options(params: MpcParams) -> NewtonOptions:
    caps = params.caps
    return NewtonOptions(max_iter=caps.max_iter, max_evals=caps.max_fun_evals, max_ls=params.max_iter_ls,
                         rho=params.ls_beta, eps_active=params.active_set_tol, tol_opt=caps.optimality_tol,
                         tol_step=caps.step_tol)


@dataclasses.dataclass(frozen=True)
class _Nlp:
    solver: Any
    """A :class:`ProjectedNewton`, or a CasADi ``nlpsol``."""
    cost: Any
    n_g: int


@lru_cache(maxsize=16)
def _build(params: MpcParams, n_p: int, t_s: float) -> _Nlp:
    """The NLP of eq. (planmpc), built once per parameter set."""
    u = ca.SX.sym("u", 2 * n_p)
    p = ca.SX.sym("p", len(PARAMETERS))
    cost, speeds = _cost_expression(params, n_p, t_s, u, p)
    cost_fn = ca.Function("mpc_cost", [u, p], [cost])
    if params.solver == "projected_newton":
        try:
            return _Nlp(ProjectedNewton(cost_fn, _newton_options(params)), cost_fn, 0)
        except CompilerMissing as error:
            raise CompilerMissing(f"mpc.solver = projected_newton: {error}; or set mpc.solver to sqp_lbfgs, "
                                  "which runs in CasADi's virtual machine") from error
    nlp: dict[str, Any] = {"x": u, "p": p, "f": cost}
    n_g = 0
    if params.speed_floor == "constraint":
        nlp["g"] = ca.vertcat(*speeds)
        n_g = n_p
    plugin, options = _solver_options(params)
    return _Nlp(ca.nlpsol("mpc", plugin, nlp, options), cost_fn, n_g)


def speed_floor(vX0: float, grid: PlanningGrid) -> np.ndarray:
    """Lower bounds of v_X(k+i), i = 1..N_p: 0, or what full acceleration reaches if that is below 0."""
    i = np.arange(1, grid.N_p + 1)
    return np.minimum(0.0, vX0 + i * grid.t_s * grid.a_x_max)


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
    for k, (uk, floor) in enumerate(zip(column, speed_floor(vX0, grid).tolist())):
        if v + gain * uk < floor:
            uk = column[k] = min((floor - v) / gain, 1.0)
            raised = True
        v += gain * uk
    if raised:
        u[:, 0] = column
    return raised


_CAPPED = ("Maximum_Iterations_Exceeded", "Maximum_Iterations_Reached")
_NEWTON_STATUS: dict[str, PlanStatus] = {
    "converged": "converged", "small_step": "converged",  # step below step_tol: fmincon's exit flag 2
    "max_iter": "capped", "max_evals": "capped", "line_search": "capped",  # a limit of Table II or the search
    "not_finite": "failed"}


class MpcPlanner:
    """The MPC planner of Sec. IV-B: one NLP built once, solved at every planning instant."""

    def __init__(self, params: MpcParams, grid: PlanningGrid) -> None:
        self.params = params
        self.grid = grid
        """Horizon, sampling time, input bounds and planning μ (shared with the MSF planner)."""
        self._nlp = _build(params, grid.N_p, grid.t_s)

    @property
    def scale(self) -> np.ndarray:
        """(a_x_max, a_y_max): normalised input × scale = acceleration (m/s²)."""
        return np.array([self.grid.a_x_max, self.grid.a_y_max])

    def parameters(self, inp: PlannerInput) -> np.ndarray:
        """The NLP's parameter vector (:data:`PARAMETERS`) at a planning instant."""
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
        guess = np.clip(np.nan_to_num(guess, nan=0.0, posinf=1.0, neginf=-1.0), -1.0, 1.0)
        return keep_speed_non_negative(guess, inp.estimate.vX, self.grid)

    @property
    def cost_function(self) -> Any:
        """The CasADi function (u normalised (2 N_p), :meth:`parameters`) → 𝒥 the NLP minimises."""
        return self._nlp.cost

    def cost(self, inp: PlannerInput, u_normalised: np.ndarray) -> float:
        """𝒥 of eq. (jcaldef) (with the lane-keeping and speed-floor terms) for normalised (N_p, 2) inputs."""
        return self._cost(np.asarray(u_normalised, dtype=float).reshape(-1), self.parameters(inp))

    def _cost(self, u: np.ndarray, p: np.ndarray) -> float:
        """𝒥 at flat normalised inputs: compiled with ``projected_newton``, else CasADi's virtual machine."""
        solver = self._nlp.solver
        if isinstance(solver, ProjectedNewton):
            return solver.cost(u, p)
        return float(self._nlp.cost(u, p))

    def plan(self, inp: PlannerInput) -> PlanResult:
        """Solve eq. (planmpc) at one planning instant, from :meth:`initial_guess`.

        The result is never costlier than the start: with a capped line search the SQP
        may accept an increasing step, and the start is then the best point known.
        A non-finite problem or solver failure returns the start with status ``failed``
        and cost ``inf``.
        """
        prm = self.params
        p = self.parameters(inp)
        guess = self.initial_guess(inp)
        start = time.perf_counter()
        status: PlanStatus = "failed"
        iterations = 0
        solution, cost = guess, math.inf
        if np.all(np.isfinite(p)):
            status, iterations, candidate, f, f_start = self._solve(guess, p)
            if status != "failed":
                solution = candidate
                if _raise_braking(solution, p[2], self.grid):
                    f = self._cost(solution.ravel(), p)
                solution, cost = (guess, f_start) if f_start < f else (solution, f)
        elapsed = time.perf_counter() - start
        if status != "failed" and elapsed > prm.time_budget_s:
            status = "over_budget"
        accel = solution * self.scale
        est = inp.estimate
        state = np.array([est.x, est.y, est.vX, est.vY], dtype=float)
        state[~np.isfinite(state)] = 0.0  # a failed plan on a non-finite estimate still predicts finite states
        return PlanResult(accel=accel, status=status, iterations=iterations, solve_time_s=elapsed, cost=cost,
                          predicted=kinematic_rollout(state, accel, self.grid.t_s))

    def _solve(self, guess: np.ndarray, p: np.ndarray) -> tuple[PlanStatus, int, np.ndarray, float, float]:
        """One NLP solve: (status, iterations, normalised (N_p, 2) inputs within the bounds (a new array),
        their cost, cost at the guess)."""
        solver = self._nlp.solver
        if isinstance(solver, ProjectedNewton):
            result = solver.solve(guess.ravel(), p)
            status = _NEWTON_STATUS[result.status]
            if status == "failed":
                return status, result.iterations, guess, math.inf, math.inf
            return status, result.iterations, result.u.reshape(self.grid.N_p, 2), result.f, result.f_start
        args: dict[str, Any] = {"x0": guess.ravel(), "p": p, "lbx": -1.0, "ubx": 1.0}
        if self._nlp.n_g:
            args["lbg"] = speed_floor(p[2], self.grid)
            args["ubg"] = math.inf
        try:
            sol = solver(**args)
            stats = solver.stats()
        except RuntimeError:  # solver error, or CasADi could not report its statistics
            return "failed", 0, guess, math.inf, math.inf
        iterations = int(stats.get("iter_count", 0))
        candidate = np.asarray(sol["x"], dtype=float).reshape(self.grid.N_p, 2)
        f = float(sol["f"])
        if not (np.all(np.isfinite(candidate)) and math.isfinite(f)):
            return "failed", iterations, guess, math.inf, math.inf
        clipped = np.clip(candidate, -1.0, 1.0)  # the QP's bounds hold to its tolerance
        if not np.array_equal(clipped, candidate):
            f = self._cost(clipped.ravel(), p)
        return self._status(stats), iterations, clipped, f, self._cost(guess.ravel(), p)

    @staticmethod
    def _status(stats: dict[str, Any]) -> PlanStatus:
        """converged | capped | failed from the solver's statistics."""
        returned = str(stats.get("return_status", ""))
        if stats.get("success", False) or returned in ("Solve_Succeeded", "Solved_To_Acceptable_Level"):
            return "converged"
        if returned == "Search_Direction_Becomes_Too_Small":
            return "converged"  # step below step_tol: fmincon's exit flag 2 (Table II's step tolerance)
        if returned in _CAPPED or stats.get("unified_return_status") == "SOLVER_RET_LIMITED":
            return "capped"
        return "failed"
