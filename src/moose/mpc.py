"""MPC planner on the kinematic model: eqs. (skin), (ysafe), (costs), (jcaldef), (planmpc).

Decision variables are the normalised inputs ũ ∈ [−1, 1]^(2 N_p) (single
shooting, eq. (planmpc)); the predicted states are functions of them.  Choices
where the paper is silent or inconsistent (docs/design.md, "MPC"):

* Discretisation of eq. (skin): exact zero-order hold, p⁺ = p + t_s v + t_s²/2 a,
  v⁺ = v + t_s a (forward Euler would leave y_1 = y_0 whatever the input).
* Mirrored frame: the lateral offset toward the evasion side ỹ = s (y − y_path)
  (s = Threat.side), so one problem serves both sides.
* Barrier: J_safe = B(ỹ − y_safe) with B(d) = −log d — the ego kept *above*
  the sigmoid, which is what Example 2 and Fig. 4 describe (the printed
  −log(y_safe − y) would keep it below and steer into the obstacle).  Below
  d₀ the logarithm is continued by its second-order Taylor polynomial, so an
  infeasible start (y_safe ≈ w at detection) has finite cost and gradient.
* y_safe, eq. (ysafe), in tanh form (no overflow), x_obs = the obstacle's near
  edge, √(w v_X²) regularised at v_X → 0.  The paper's sigmoid never falls; we
  multiply the barrier by a falling sigmoid past the obstacle's far edge and
  add a lane-return term |ỹ| gated by the same sigmoid (η_return): the paper's
  car returns to its initial lateral position after passing.
* J_steer = |ũ_Y| on the normalised input (Example 2 normalises inputs).
* v_X ≥ 0 by a quadratic penalty (braking guesses otherwise find reversing).
* Solver: CasADi ``sqpmethod`` with the active-set QP solver ``qrqp`` and a
  limited-memory (L-BFGS) Hessian: at the paper's caps it was both faster and
  reached lower cost than a regularised exact Hessian (2.2 ms, cost −3.25) and
  than SciPy SLSQP (bench/bench_mpc.py; docs/design.md has the table).  Its iteration cap is the paper's 10; each iteration
  evaluates the functions at most 1 + ``max_iter_ls`` times, so the paper's
  100 function evaluations are never reached with ``max_iter_ls`` ≤ 9.
"""
from __future__ import annotations

import dataclasses
import math
import time
from functools import lru_cache

import casadi as ca
import numpy as np

from .params import G, VehicleParams, check, non_negative, positive
from .signals import PlannerInput, PlanResult


@dataclasses.dataclass(frozen=True)
class SolverCaps:
    """Stopping criteria of the NLP solver (Table II)."""

    max_iter: int = 10
    max_fun_evals: int = 100
    constraint_tol: float = 1e-3
    optimality_tol: float = 1e-3
    step_tol: float = 1e-3

    def __post_init__(self) -> None:
        check("max_iter", self.max_iter, lambda v: v >= 1, "at least 1")
        check("max_fun_evals", self.max_fun_evals, lambda v: v >= self.max_iter, "at least max_iter")
        for name in ("constraint_tol", "optimality_tol", "step_tol"):
            check(name, getattr(self, name), positive, "a positive tolerance")


PAPER_CAPS = SolverCaps()
"""Table II: 10 iterations, 100 function evaluations, tolerances 1e-3."""


@dataclasses.dataclass(frozen=True)
class MpcParams:
    """MPC planner parameters (paper defaults)."""

    N_p: int = 10
    """Prediction horizon (steps)."""
    t_s: float = 0.2
    """Planning sampling time (s), Table I."""
    eta: tuple[float, float, float, float] = (0.5, 0.25, 0.05, 0.2)
    """Weights of J_safe, J_stable, J_brake, J_steer (Example 2, second set)."""
    eta_return: float = 0.1
    """Weight of the lane-return term after the obstacle (not in the paper)."""
    a_x_max: float = 6.0
    """Bound of v̇_X (m/s²): the normalisation of the first input."""
    a_y_max: float = 6.0
    """Bound of v̇_Y (m/s²): the normalisation of the second input."""
    mu: float = 0.3
    """Friction assumed by the barrier's ε = 1/√(8.8 μ g)."""
    barrier_margin: float = 0.1
    """d₀ (m): below it −log d is continued quadratically."""
    pass_margin: float = 1.0
    """Distance past the obstacle's far edge where the barrier has fallen to half (m)."""
    reverse_penalty: float = 100.0
    """Weight of the v_X < 0 penalty."""
    caps: SolverCaps = PAPER_CAPS
    max_iter_ls: int = 3
    """Line-search iterations per SQP iteration."""
    time_budget_s: float = 0.2
    """Wall-clock budget of one solve (s); above it the status is ``over_budget``."""

    def __post_init__(self) -> None:
        check("N_p", self.N_p, lambda v: 1 <= v <= 100, "an integer in [1, 100]")
        for name in ("t_s", "a_x_max", "a_y_max", "mu", "barrier_margin", "time_budget_s"):
            check(name, getattr(self, name), positive, "a positive number")
        for name in ("eta_return", "pass_margin", "reverse_penalty"):
            check(name, getattr(self, name), non_negative, "a non-negative number")
        check("eta", self.eta, lambda e: all(0.0 <= v <= 1.0 for v in e) and abs(sum(e) - 1.0) < 1e-9,
              "a convex combination: four weights in [0, 1] summing to 1")
        check("max_iter_ls", self.max_iter_ls, lambda v: 0 <= v and self.caps.max_iter * (1 + v) + 1 <= self.caps.max_fun_evals,
              "line-search iterations that keep max_iter (1 + max_iter_ls) + 1 within max_fun_evals")

    @property
    def epsilon(self) -> float:
        """ε = 1/√(8.8 μ g) of eq. (ysafe)."""
        return 1.0 / math.sqrt(8.8 * self.mu * G)


def smooth_abs(x, eps: float = 1e-3):
    """|x| regularised at 0: √(x² + ε²) − ε."""
    return ca.sqrt(x * x + eps * eps) - eps


def sigmoid(a):
    """1 / (1 + e^a) written with tanh (no overflow)."""
    return 0.5 * (1.0 - ca.tanh(0.5 * a))


def y_safe(x_ego, vX, x_obs: float, w: float, epsilon: float):
    """eq. (ysafe): w / (1 + exp((x_obs − x − 4 v_X) / (ε √(w v_X²))))."""
    scale = epsilon * ca.sqrt(w) * ca.sqrt(vX * vX + 0.25)
    return w * sigmoid((x_obs - x_ego - 4.0 * vX) / scale)


def j_safe(offset, ysafe, margin: float):
    """eq. (jbarr) with the intended sign: −log(ỹ − y_safe), continued quadratically below ``margin``."""
    d = offset - ysafe
    dm = d - margin
    taylor = -math.log(margin) - dm / margin + dm * dm / (2.0 * margin * margin)
    return ca.if_else(d >= margin, -ca.log(ca.fmax(d, margin)), taylor)


def j_stable(vX, vY):
    """eq. (jstab): |v_Y / v_X| (v_X regularised at 0)."""
    return smooth_abs(vY) / ca.sqrt(vX * vX + 0.25)


def j_brake(vX, v_des):
    """eq. (jvel): |v_X − v_des|."""
    return smooth_abs(vX - v_des)


def j_steer(u_y_normalised):
    """eq. (jsteer): |v̇_Y| on the normalised input."""
    return smooth_abs(u_y_normalised)


N_PARAM = 11
"""Problem parameters: x, ỹ, v_X, ṽ_Y, v_des, x_min, x_max, w, active, a_x_max, a_y_max."""


@lru_cache(maxsize=8)
def _build(params: MpcParams) -> tuple[ca.Function, ca.Function]:
    n = params.N_p
    u = ca.SX.sym("u", 2 * n)
    p = ca.SX.sym("p", N_PARAM)
    x, y, vX, vY, v_des, x_min, x_max, w, active, ax_max, ay_max = (p[i] for i in range(N_PARAM))
    ts = params.t_s
    e1, e2, e3, e4 = params.eta
    eps = params.epsilon
    cost = 0
    states = [ca.vertcat(x, y, vX, vY)]
    for k in range(n):
        ax = u[2 * k] * ax_max
        ay = u[2 * k + 1] * ay_max
        x = x + ts * vX + 0.5 * ts * ts * ax
        y = y + ts * vY + 0.5 * ts * ts * ay
        vX = vX + ts * ax
        vY = vY + ts * ay
        states.append(ca.vertcat(x, y, vX, vY))
        scale = eps * ca.sqrt(ca.fmax(w, 1e-3)) * ca.sqrt(vX * vX + 0.25)
        passed = sigmoid((x_max + params.pass_margin - x) / scale)  # 1 before, 0 after the obstacle
        barrier = j_safe(y, y_safe(x, vX, x_min, ca.fmax(w, 1e-3), eps), params.barrier_margin)
        cost += active * (e1 * passed * barrier + params.eta_return * (1 - passed) * smooth_abs(y))
        cost += (1 - active) * params.eta_return * smooth_abs(y)
        cost += e2 * j_stable(vX, vY) + e3 * j_brake(vX, v_des) + e4 * j_steer(u[2 * k + 1])
        cost += params.reverse_penalty * ca.fmin(vX, 0) ** 2
    caps = params.caps
    solver = ca.nlpsol(
        "mpc", "sqpmethod", {"x": u, "p": p, "f": cost},
        {
            "qpsol": "qrqp",
            "qpsol_options": {"print_iter": False, "print_header": False, "print_info": False, "error_on_fail": False},
            "hessian_approximation": "limited-memory",
            "max_iter": caps.max_iter,
            "max_iter_ls": params.max_iter_ls,
            "tol_pr": caps.constraint_tol,
            "tol_du": caps.optimality_tol,
            "min_step_size": caps.step_tol * 1e-3,
            "print_header": False, "print_iteration": False, "print_status": False, "print_time": False,
            "error_on_fail": False,
        },
    )
    rollout = ca.Function("rollout", [u, p], [ca.horzcat(*states).T, cost])
    return solver, rollout


class MpcPlanner:
    """The MPC planner: one NLP built once, solved at every planning instant."""

    def __init__(self, params: MpcParams, vehicle: VehicleParams) -> None:
        self.params = params
        self.vehicle = vehicle
        self._solver, self._rollout = _build(params)

    def _problem(self, inp: PlannerInput) -> tuple[np.ndarray, float, float]:
        """Parameter vector in the mirrored frame, the side and the path offset."""
        est, threat, prm = inp.estimate, inp.threat, self.params
        side = float(threat.side) if threat is not None else 1.0
        y_path = threat.y_path if threat is not None else inp.y_lane
        if threat is not None:
            obstacle, w, active = threat.obstacle, threat.w, 1.0
            x_min, x_max = obstacle.x_min, obstacle.x_max
        else:
            x_min = x_max = w = active = 0.0
        p = np.array([est.x, side * (est.y - y_path), est.vX, side * est.vY, inp.v_des,
                      x_min, x_max, w, active, prm.a_x_max, prm.a_y_max])
        return p, side, y_path

    def plan(self, inp: PlannerInput) -> PlanResult:
        prm = self.params
        n = prm.N_p
        p, side, y_path = self._problem(inp)
        scale = np.array([prm.a_x_max, side * prm.a_y_max])
        if inp.initial_guess is not None:
            guess = np.asarray(inp.initial_guess, dtype=float)[:n] / scale
        else:
            guess = np.zeros((n, 2))
        guess = np.clip(np.nan_to_num(guess, nan=0.0), -1.0, 1.0).ravel()
        start = time.perf_counter()
        status = "failed"
        iterations = 0
        solution = guess
        cost = math.inf
        if np.all(np.isfinite(p)):
            try:
                sol = self._solver(x0=guess, p=p, lbx=-1.0, ubx=1.0)
                stats = self._solver.stats()
                iterations = int(stats.get("iter_count", 0))
                candidate = np.asarray(sol["x"], dtype=float).ravel()
                if np.all(np.isfinite(candidate)):
                    solution = np.clip(candidate, -1.0, 1.0)
                    cost = float(sol["f"])
                    status = "converged" if stats.get("success", False) else (
                        "capped" if stats.get("return_status") == "Maximum_Iterations_Exceeded" or iterations >= prm.caps.max_iter
                        else "failed")
            except RuntimeError:
                status = "failed"
        elapsed = time.perf_counter() - start
        if status != "failed" and elapsed > prm.time_budget_s:
            status = "over_budget"
        accel = solution.reshape(n, 2) * scale
        est = inp.estimate
        start_state = np.nan_to_num(np.array([est.x, est.y, est.vX, est.vY]))
        return PlanResult(
            accel=accel, status=status, iterations=iterations, solve_time_s=elapsed,
            cost=cost if status != "failed" else math.inf, predicted=kinematic_rollout(start_state, accel, prm.t_s),
        )


def kinematic_rollout(state: np.ndarray, accel: np.ndarray, t_s: float) -> np.ndarray:
    """eq. (skin) with exact zero-order hold: (N+1, 4) states [x, y, v_X, v_Y] from (N, 2) accelerations."""
    out = np.empty((len(accel) + 1, 4))
    out[0] = state
    for k, a in enumerate(accel):
        x, y, vX, vY = out[k]
        out[k + 1] = (x + t_s * vX + 0.5 * t_s**2 * a[0], y + t_s * vY + 0.5 * t_s**2 * a[1], vX + t_s * a[0], vY + t_s * a[1])
    return out

