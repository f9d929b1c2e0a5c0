"""MPC solve time against the fmincon stand-in (SciPy SLSQP, finite differences) on the same problem.

Problem sequence (per horizon N_p): the notes' problem (x = y = 0, v_X = 7, v_des = 7,
obstacle at x_obs = 10 m, w = 2.6 m), solved cold, then 14 receding-horizon steps on the
kinematic model, each warm-started with the previous solution shifted.  Both solvers get the
same cost (our CasADi rollout), the same bounds and Table II's caps (10 iterations, 100
function evaluations, tolerances 1e-3); SLSQP runs on the same sequence of states.
Printed: median/p95/p99 solve times, the speed-up ratio, and the mean cost each reaches.
Run: ``python bench/bench_mpc.py``.
"""
from __future__ import annotations

import time

import numpy as np
from scipy.optimize import minimize

from moose.mpc import MpcParams, MpcPlanner, kinematic_rollout
from moose.params import VehicleParams
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat

REPEATS = 5
STEPS = 15


def problems(n_p: int) -> list[tuple[PlannerInput, np.ndarray | None]]:
    """The receding-horizon sequence our MPC produces (states and warm starts)."""
    params = MpcParams(N_p=n_p)
    planner = MpcPlanner(params, VehicleParams())
    threat = Threat(0.0, Obstacle(10.0, 12.0, -2.6, 2.6), 10 / 7, 2.6, 1.0, 1, 0.0)
    state = np.array([0.0, 0.0, 7.0, 0.0])
    guess = None
    out = []
    for k in range(STEPS):
        est = StateEstimate(0.2 * k, state[0], state[1], 0.0, state[2], state[3], 0.0, 0.0)
        inp = PlannerInput(0.2 * k, est, threat, 7.0, guess)
        out.append((inp, guess))
        result = planner.plan(inp)
        state = kinematic_rollout(state, result.accel[:1], params.t_s)[1]
        guess = np.vstack([result.accel[1:], result.accel[-1:]])
    return out


def slsqp(planner: MpcPlanner, inp: PlannerInput) -> tuple[float, float]:
    """SLSQP with finite-difference gradients on the MPC's own cost; returns (seconds, cost)."""
    params = planner.params
    p, side, _ = planner._problem(inp)
    scale = np.array([params.a_x_max, side * params.a_y_max])
    x0 = np.zeros(2 * params.N_p) if inp.initial_guess is None else np.clip(inp.initial_guess / scale, -1, 1).ravel()
    rollout = planner._rollout

    def cost(u: np.ndarray) -> float:
        return float(rollout(u, p)[1])

    start = time.perf_counter()
    res = minimize(cost, x0, method="SLSQP", bounds=[(-1.0, 1.0)] * len(x0),
                   options={"maxiter": params.caps.max_iter, "ftol": params.caps.optimality_tol})
    return time.perf_counter() - start, cost(np.clip(res.x, -1, 1))


def main() -> None:
    print(f"{'N_p':>4} {'solver':>22} {'median ms':>10} {'p95 ms':>8} {'p99 ms':>8} {'mean cost':>10}")
    for n_p in (10, 20):
        seq = problems(n_p)
        planner = MpcPlanner(MpcParams(N_p=n_p), VehicleParams())
        ours, base, ours_cost, base_cost = [], [], [], []
        for _ in range(REPEATS):
            for inp, _guess in seq:
                result = planner.plan(inp)
                ours.append(result.solve_time_s)
                ours_cost.append(result.cost)
                seconds, c = slsqp(planner, inp)
                base.append(seconds)
                base_cost.append(c)
        for name, times, costs in (("casadi sqpmethod/qrqp", ours, ours_cost), ("scipy SLSQP (FD)", base, base_cost)):
            t = np.array(times) * 1e3
            print(f"{n_p:>4} {name:>22} {np.median(t):10.2f} {np.percentile(t, 95):8.2f} "
                  f"{np.percentile(t, 99):8.2f} {np.mean(costs):10.3f}")
        ratio = np.median(base) / np.median(ours)
        lower = np.mean(np.array(ours_cost) <= np.array(base_cost) + 1e-6)
        print(f"{n_p:>4} {'speed-up (median)':>22} {ratio:10.1f}x   mean cost ours - SLSQP = "
              f"{np.mean(ours_cost) - np.mean(base_cost):+.3f} (ours equal or lower on {100 * lower:.0f}% of solves)")


if __name__ == "__main__":
    main()
