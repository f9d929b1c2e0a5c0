"""The MPC's solvers side by side against the paper's baseline (``paper_sqp``, fmincon's SQP under Table II).

Problems: for each planning grid, three closed-loop-like sequences on the kinematic model in the
paper's geometries, each a detection (cold start: no initial guess) followed by warm-started steps
(the previous solution shifted by one step), 4 s long:

* relaxed: v = 5 m/s, τ = 4 s (near edge 20 m ahead), w = 3.2 m;
* comparison: v = 6 m/s, τ = 3 s (18 m), w = 2.4 m;
* extreme: v = 7 m/s, τ = 1.4 s (9.8 m), w = 2.0 m.

Grids (``moose.schema.Config.grid`` of the shipped configuration with the vehicle's μ replaced):
μ = 0.33 (the paper calibration, ``moose.paper.PAPER_FRICTION``) and μ = 0.8, whose bounds come
from the FPEV2-Kanon (a_x from the rear motors and tyres, a_y = μ g), and, for continuity with
earlier figures, the old kinematic bounds ±6 m/s² at μ = 0.3.

Each geometry gives two sequences: one driven by the configured planner (projected Newton) and
one by the paper baseline, so the warm starts are each one's own; every solver then gets the same
problems and the same starting points, the configured cost and Table II's caps.  Printed per
solver: median/p99 wall time of ``MpcPlanner.plan`` (solve and its Python wrapping), the mean cost
reached, the share of problems where it is ≤ the paper baseline's (relative 1e-6) and at most
Table II's 1e-3 above it, the worst difference, the share ending above the cost of its start, the
baseline's median time over the solver's (one run), and the statuses.  For the baseline: its
iterations and cost evaluations (cold and warm starts), and why it stopped.  SciPy's SLSQP with
the same caps and finite differences counted (the stand-in of earlier figures) is printed as a
cross-check of the baseline.  Timings on a shared machine: the load average is printed first.
Run: ``python bench/bench_mpc.py [--repeats R] [--full]``.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import os
import sys
import time
from collections import Counter
from typing import Iterator

import numpy as np
from scipy.optimize import minimize

from moose.config import load_config
from moose.paper import PAPER_FRICTION
from moose.params import replace
from moose.planner.kinematics import kinematic_rollout
from moose.planner.mpc import MpcPlanner
from moose.schema import MpcParams, PlanningGrid, SolverCaps
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat

CONFIG = load_config()
STEPS = 20

SCENARIOS = {
    # name: (v0 = v_des, near edge, w)
    "relaxed (v=5, tau=4, w=3.2)": (5.0, 20.0, 3.2),
    "comparison (v=6, tau=3, w=2.4)": (6.0, 18.0, 2.4),
    "extreme (v=7, tau=1.4, w=2)": (7.0, 9.8, 2.0),
}


def grid_at(mu: float, n_p: int) -> PlanningGrid:
    """The configuration's planning grid with the road's (and so the planning) μ set to ``mu``."""
    config = dataclasses.replace(CONFIG, vehicle=replace(CONFIG.vehicle, mu=mu),
                                 planning=replace(CONFIG.planning, N_p=n_p, mu_estimate=0.0))
    return config.grid


def grids(n_p: int) -> dict[str, PlanningGrid]:
    return {
        f"mu = {PAPER_FRICTION} (paper calibration)": grid_at(PAPER_FRICTION, n_p),
        "mu = 0.8": grid_at(0.8, n_p),
        "kinematic +-6 m/s^2, mu = 0.3 (old bounds)": PlanningGrid(n_p, CONFIG.planning.t_s, 6.0, 6.0, 0.3),
    }


def threat_for(x_near: float, w: float, v: float) -> Threat:
    return Threat(0.0, Obstacle(x_near, x_near + 2.0, -w, w), x_near / v, w, 0.5, 1, 0.0)


def sequence(params: MpcParams, grid: PlanningGrid, v: float, x_near: float, w: float) -> list[PlannerInput]:
    """Detection and warm-started receding-horizon steps driven by a planner with ``params``."""
    planner = MpcPlanner(params, grid)
    threat = threat_for(x_near, w, v)
    state = np.array([0.0, 0.0, v, 0.0])
    guess = None
    out = []
    for k in range(STEPS):
        est = StateEstimate(grid.t_s * k, state[0], state[1], 0.0, state[2], state[3], 0.0, 0.0)
        inp = PlannerInput(grid.t_s * k, est, threat if state[0] < x_near + 4.0 else None, v, guess)
        out.append(inp)
        result = planner.plan(inp)
        state = kinematic_rollout(state, result.accel[:1], grid.t_s)[1]
        guess = np.vstack([result.accel[1:], result.accel[-1:]])
    return out


class _EvaluationCap(Exception):
    pass


def slsqp(planner: MpcPlanner, inp: PlannerInput, caps: SolverCaps) -> tuple[float, np.ndarray]:
    """SLSQP with forward-difference gradients on the planner's compiled cost, the cap counted: (s, u)."""
    x0 = planner.initial_guess(inp).ravel()
    p = planner.parameters(inp)
    cost_at = planner.solver.cost
    evaluations = 0
    best = [x0.copy()]

    def cost(u: np.ndarray) -> float:
        nonlocal evaluations
        evaluations += 1
        if evaluations > caps.max_fun_evals:
            raise _EvaluationCap
        return cost_at(u, p)

    start = time.perf_counter()
    try:
        res = minimize(cost, x0, method="SLSQP", bounds=[(-1.0, 1.0)] * len(x0),
                       callback=lambda xk: best.__setitem__(0, xk.copy()),
                       options={"maxiter": caps.max_iter, "ftol": caps.optimality_tol})
        u = res.x
    except _EvaluationCap:
        u = best[0]
    return time.perf_counter() - start, np.clip(u, -1.0, 1.0)


def percentiles(times: list[float]) -> tuple[float, float]:
    t = np.array(times) * 1e3
    return float(np.median(t)), float(np.percentile(t, 99))


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Silence C-level stdout (qpOASES prints a banner when it is created)."""
    sys.stdout.flush()
    saved = os.dup(1)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 1)
        try:
            yield
        finally:
            os.dup2(saved, 1)
            os.close(saved)


BASELINE = "paper_sqp: fmincon SQP, FD (baseline)"
DEFAULT = "projected_newton (default)"


def variants(base: MpcParams, full: bool) -> dict[str, MpcParams]:
    sqp = dataclasses.replace(base, solver="sqp_lbfgs", ls_beta=0.5)
    out = {
        BASELINE: dataclasses.replace(base, solver="paper_sqp"),
        DEFAULT: base,
        "sqp_lbfgs/qrqp": sqp,
        "sqp_exact/qrqp": dataclasses.replace(sqp, solver="sqp_exact"),
        "ipopt, capped": dataclasses.replace(base, solver="ipopt"),
    }
    if full:
        out["sqp_lbfgs, v_X>=0 constr./qpOASES"] = dataclasses.replace(sqp, speed_floor="constraint", qpsol="qpoases")
        out["ipopt, converged (ref.)"] = dataclasses.replace(
            base, solver="ipopt", caps=SolverCaps(max_iter=500, max_fun_evals=10_000))
    return out


def baseline_report(planner: MpcPlanner, problems: list[PlannerInput]) -> str:
    """Iterations, evaluations and stop reasons of the baseline (cold starts apart)."""
    cold_it, warm_it, evals, reasons = [], [], [], Counter()
    for inp in problems:
        result = planner.solver.solve(planner.initial_guess(inp).ravel(), planner.parameters(inp))
        (cold_it if inp.initial_guess is None else warm_it).append(result.iterations)
        evals.append(result.evaluations)
        reasons[result.reason] += 1
    hist = " ".join(f"{k}:{v}" for k, v in sorted(Counter(warm_it).items()))
    return (f"  baseline: iterations cold {sorted(cold_it)}, warm {{{hist}}} (mean {np.mean(cold_it + warm_it):.1f}); "
            f"evaluations mean {np.mean(evals):.0f}, max {max(evals)}; stopped by "
            + ", ".join(f"{k} {v}" for k, v in reasons.most_common()))


def run_grid(label: str, grid: PlanningGrid, repeats: int, full: bool) -> None:
    base = CONFIG.mpc
    drivers = (base, dataclasses.replace(base, solver="paper_sqp"))
    problems = [inp for v, x_near, w in SCENARIOS.values() for driver in drivers
                for inp in sequence(driver, grid, v, x_near, w)]
    print(f"\n{label}: N_p = {grid.N_p}, t_s = {grid.t_s} s, a_x_max = {grid.a_x_max:.2f}, "
          f"a_y_max = {grid.a_y_max:.2f} m/s^2; {len(problems)} problems x {repeats} repeats")
    reference = MpcPlanner(base, grid)
    results: dict[str, tuple[list[float], np.ndarray, Counter]] = {}
    for name, params in variants(base, full).items():
        with quiet_stdout():
            planner = MpcPlanner(params, grid)
            planner.plan(problems[0])
        times: list[float] = []
        costs = np.zeros(len(problems))
        statuses: Counter = Counter()
        for r in range(repeats):
            for i, inp in enumerate(problems):
                result = planner.plan(inp)
                times.append(result.solve_time_s)
                if r == 0:
                    costs[i] = reference.cost(inp, result.accel / reference.scale)
                    statuses[result.status] += 1
        results[name] = (times, costs, statuses)
        if name == BASELINE:
            baseline_planner = planner
    slsqp_times: list[float] = []
    slsqp_costs = np.zeros(len(problems))
    for _ in range(repeats):
        for i, inp in enumerate(problems):
            elapsed, u = slsqp(reference, inp, base.caps)
            slsqp_times.append(elapsed)
            slsqp_costs[i] = reference.cost(inp, u.reshape(-1, 2))
    results["SciPy SLSQP, FD, same caps (cross-check)"] = (slsqp_times, slsqp_costs, Counter())

    b_times, b_costs, _ = results[BASELINE]
    b_med = percentiles(b_times)[0]
    start_costs = np.array([reference.cost(inp, reference.initial_guess(inp)) for inp in problems])
    print(f"{'solver':40} {'median ms':>9} {'p99 ms':>7} {'mean cost':>9} {'<=base':>6} {'<=+1e-3':>7} "
          f"{'worst diff':>10} {'>start':>6} {'base/solver':>11}  statuses")
    for name, (times, costs, statuses) in results.items():
        med, p99 = percentiles(times)
        diff = costs - b_costs
        share = np.mean(diff <= 1e-6 * np.maximum(1.0, np.abs(b_costs))) * 100
        within = np.mean(diff <= 1e-3) * 100
        worse = np.mean(costs > start_costs + 1e-9 * np.maximum(1.0, np.abs(start_costs))) * 100
        st = " ".join(f"{k}:{v}" for k, v in sorted(statuses.items()))
        print(f"{name:40} {med:9.2f} {p99:7.2f} {np.mean(costs):9.3f} {share:5.0f}% {within:6.0f}% "
              f"{diff.max():+10.3f} {worse:5.0f}% {b_med / med:10.1f}x  {st}")
    print(baseline_report(baseline_planner, problems))
    d_times, d_costs, _ = results[DEFAULT]
    diff = d_costs - b_costs
    print(f"  paper baseline p99 {percentiles(b_times)[1]:.2f} ms of the {base.time_budget_s * 1e3:.0f} ms budget; "
          f"projected Newton {b_med / percentiles(d_times)[0]:.1f}x faster (medians), cost lower on "
          f"{np.mean(diff < -1e-6 * np.maximum(1.0, np.abs(b_costs))) * 100:.0f}% of the problems, "
          f"mean {np.mean(d_costs):.3f} vs {np.mean(b_costs):.3f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--full", action="store_true", help="also N_p = 20 and two more solver variants")
    args = parser.parse_args()
    caps = CONFIG.mpc.caps
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs; {args.repeats} repeats; "
          f"Table II caps: {caps.max_iter} iterations, {caps.max_fun_evals} evaluations, tolerances "
          f"{caps.optimality_tol:g}/{caps.step_tol:g}/{caps.constraint_tol:g}")
    for n_p in ((CONFIG.planning.N_p, 20) if args.full else (CONFIG.planning.N_p,)):
        for label, grid in grids(n_p).items():
            run_grid(label, grid, args.repeats, args.full)


if __name__ == "__main__":
    main()
