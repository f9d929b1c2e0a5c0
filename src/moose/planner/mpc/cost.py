"""The MPC's optimisation problem: eqs. (skin), (ysafe), (costs), (jcaldef), (planmpc).

The decision variables are the 2 N_p inputs ũ = [v̇_X, v̇_Y] over the horizon, normalised to
[−1, 1] by (a_x_max, a_y_max) (eq. (utilde); Example 2's normalisation); the predicted
states are functions of them inside the cost (single shooting, as eq. (planmpc) states).  The
problem is built once per parameter set (:func:`build_problem`) and is parametric in the state,
v_des, the obstacle's extent, w, the evasion side, the ego path, ε (i.e. μ) and the input bounds
(:data:`PARAMETERS`).

Choices where the paper is silent or inconsistent (docs/modelling.md, "MPC"):

* eq. (skin) is discretised with the exact zero-order hold of :mod:`moose.planner.kinematics`
  (forward Euler would give y(k+1) = y(k) whatever the input: the first predicted step could
  not react).
* Barrier sign: the printed J_safe = −log(y_safe − y) keeps the ego *below* the
  sigmoid, i.e. in the obstacle; Example 2 and Fig. 5 (the barrier) describe the ego
  kept above it.  We use the offset toward the evasion side ỹ = s (y − y_path)
  and d = ỹ − y_safe.
* Barrier shape (:func:`j_safe`): −log d as printed (``barrier = "paper"``, the
  default) keeps rewarding distance from y_safe; ``barrier = "clipped"`` subtracts its
  tangent at a clearance c and is 0 beyond it (C¹).  Either way, below the margin d₀ it is
  continued by its second-order Taylor polynomial, so an infeasible start (y_safe ≈ w at
  detection) has a finite cost and a gradient toward the safe side.
* eq. (ysafe) is evaluated in tanh form (no overflow), √(w v_X²) as
  √w √(v_X² + v_reg²); |·| as √(·² + ε_abs²) − ε_abs (smooth at 0).
* The paper's sigmoid never falls again; the car must return to its lane after the
  obstacle.  J_safe is multiplied by a falling sigmoid, ½ at ``pass_margin`` past
  the obstacle's far edge, and a lane-keeping term η_return |ỹ| (not in the
  paper) is added at every step, with or without a threat.
* J_steer(k+i) uses the input that produces the state k+i, u(k+i−1), normalised.
* v_X ≥ 0: a quadratic penalty on min(v_X, 0) (bounds-only problem) or linear
  constraints on the predicted speeds (:attr:`Problem.speeds`).
"""
from __future__ import annotations

import dataclasses
import math
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from ...params import G
from ...schema import MpcParams
from ..kinematics import kinematic_step
from ..logistic import logistic


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


def y_safe(x_ego: Any, vX: Any, x_obs: Any, w: Any, eps: Any, v_reg: float = 0.5) -> Any:
    """Sigmoid barrier, eq. (ysafe): w / (1 + exp((x_obs − x_ego − 4 v_X) / (ε √(w v_X²)))), the logistic σ(−a).

    ``x_obs`` is the obstacle's near edge; √(w v_X²) is regularised as √w √(v_X² + v_reg²).
    """
    scale = eps * ca.sqrt(w) * ca.sqrt(vX * vX + v_reg * v_reg)
    return _out(w * logistic(-(x_obs - x_ego - 4.0 * vX) / scale, ca), x_ego, vX, x_obs, w, eps)


def barrier_gap(predicted: np.ndarray, x_near: float, x_far: float, w: float, side: float, y_path: float,
                eps: float, v_reg: float = 0.5) -> np.ndarray:
    """d = ỹ − y_safe, eq. (ysafe), at the predicted steps k + 1 … k + N_p that have not passed the zone's far edge
    (m; negative: the path is on the obstacle's side of the barrier).

    ``predicted`` is a plan's (N_p + 1, 4) states [x, y, v_X, v_Y] (row 0 the measured state, not a prediction);
    ỹ = side (y − y_path) and y_safe are the cost's own (:func:`y_safe` with ``x_near`` and the regularising
    ``v_reg``), so a path the cost calls infeasible is one this calls infeasible.  Steps past ``x_far`` are left
    out: there the obstacle is passed and the cost switches J_safe off (:func:`past_obstacle`)."""
    steps = np.asarray(predicted, dtype=float)[1:]
    ahead = steps[steps[:, 0] <= x_far]
    w_pos = max(w, 1e-3)
    return np.array([side * (y - y_path) - y_safe(x, vX, x_near, w_pos, eps, v_reg) for x, y, vX, _ in ahead.tolist()])


def violates_barrier(gap: np.ndarray) -> bool:
    """The paper's hand-over trigger: the plan's predicted path crosses y_safe (d < 0, :func:`barrier_gap`) at some
    step of the horizon before the zone's far edge — the point where the printed J_safe = −log d has no value and
    the paper's solver "fails to provide a solution" (Sec. IV)."""
    return bool(np.any(gap < 0.0))


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
    """0 before the obstacle, 1 past it: the logistic of x_ego, ½ at ``x_far + margin``, width ``margin / 4`` (not in
    the paper)."""
    return _out(logistic((x_ego - (x_far + margin)) / (0.25 * margin), ca), x_ego, x_far)


# ---------------------------------------------------------------------------
# Parameters and the speed floor
# ---------------------------------------------------------------------------

PARAMETERS = ("x", "y", "vX", "vY", "v_des", "x_near", "x_far", "w", "side", "y_path", "active",
              "epsilon", "a_x_max", "a_y_max")
"""Order of the problem's parameter vector (``active`` = 1 with a threat, 0 without)."""
P_VX, P_AX_MAX = PARAMETERS.index("vX"), PARAMETERS.index("a_x_max")


def speed_floor(vX0: float, n_p: int, t_s: float, a_x_max: float) -> np.ndarray:
    """Lower bounds of v_X(k+i), i = 1..N_p: 0, or what full acceleration reaches if that is below 0."""
    i = np.arange(1, n_p + 1)
    return np.minimum(0.0, vX0 + i * t_s * a_x_max)


# ---------------------------------------------------------------------------
# The problem of eq. (planmpc)
# ---------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True, eq=False)
class Problem:
    """eq. (planmpc) for one parameter set: 𝒥 as a CasADi expression of the normalised inputs
    ``u`` (2 N_p, ordered [v̇_X(k), v̇_Y(k), v̇_X(k+1), …]) and the parameters ``p`` (:data:`PARAMETERS`)."""

    N_p: int
    t_s: float
    u: ca.SX
    p: ca.SX
    cost: ca.SX
    """𝒥 of eq. (jcaldef), with the lane-keeping term and (``speed_floor: penalty``) the speed penalty."""
    speeds: ca.SX
    """Predicted v_X(k+i), i = 1..N_p: the linear constraints of ``speed_floor: constraint``."""
    cost_function: ca.Function
    """(u, p) → 𝒥."""

    @property
    def n(self) -> int:
        """Number of decision variables, 2 N_p."""
        return 2 * self.N_p

    def speed_lower_bounds(self, p: np.ndarray) -> np.ndarray:
        """:func:`speed_floor` at the parameters ``p``."""
        return speed_floor(float(p[P_VX]), self.N_p, self.t_s, float(p[P_AX_MAX]))


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


@lru_cache(maxsize=16)
def build_problem(params: MpcParams, n_p: int, t_s: float) -> Problem:
    """The problem of eq. (planmpc), built once per parameter set and grid."""
    u = ca.SX.sym("u", 2 * n_p)
    p = ca.SX.sym("p", len(PARAMETERS))
    cost, speeds = _cost_expression(params, n_p, t_s, u, p)
    return Problem(n_p, t_s, u, p, cost, ca.vertcat(*speeds), ca.Function("mpc_cost", [u, p], [cost]))
