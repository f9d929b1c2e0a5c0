"""The paper's baseline solver (moose.planner.mpc.paper_sqp): fmincon's SQP algorithm under Table II.

Every cost evaluation is counted here from outside the solver, by wrapping the cost it is given.
"""
from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from moose.paper import PAPER_FRICTION
from moose.params import VehicleParams, replace
from moose.planner.mpc import MpcPlanner
from moose.planner.mpc.paper_sqp import FD_STEP, SqpOptions, box_qp, fmincon_sqp, solve_spd, sqp_options
from moose.schema import MpcParams, PlanningGrid, SolverCaps
from moose.signals import Obstacle, PlannerInput, StateEstimate, Threat
from solve_time import INSTANT

PAPER = MpcParams(solver="paper_sqp")
KINEMATIC = PlanningGrid(N_p=10, t_s=0.2, a_x_max=6.0, a_y_max=6.0, mu=0.3)
"""The kinematic problem of the MPC notes (bounds ±6 m/s², ε at μ = 0.3)."""


def realistic(mu: float, n_p: int = 10) -> PlanningGrid:
    """The grid a configuration derives for the FPEV2-Kanon at the planning μ (moose.schema.Config.grid)."""
    vehicle = replace(VehicleParams(), mu=mu)
    return PlanningGrid(n_p, 0.2, vehicle.longitudinal_accel_limit, vehicle.lateral_accel_limit, mu)


GRIDS = [KINEMATIC, realistic(PAPER_FRICTION), realistic(0.8)]


class Counted:
    """A cost f(u) that counts its calls and records where it was evaluated."""

    def __init__(self, fn) -> None:
        self.fn = fn
        self.points: list[np.ndarray] = []

    def __call__(self, u: np.ndarray) -> float:
        self.points.append(np.array(u, dtype=float))
        return self.fn(u)

    @property
    def calls(self) -> int:
        return len(self.points)


def threat(w: float, x_min: float, side: int = 1) -> Threat:
    y_lo, y_hi = (-0.5, w) if side > 0 else (-w, 0.5)
    return Threat(0.0, Obstacle(x_min, x_min + 2.0, y_lo, y_hi), x_min / 7.0, w, 1.0, side, 0.0)


def planner_input(v: float, x_obs: float, w: float, side: int = 1, vy: float = 0.0,
                  guess: np.ndarray | None = None) -> PlannerInput:
    return PlannerInput(0.0, StateEstimate(0.0, 0.0, 0.0, 0.0, v, vy, 0.0, 0.0), threat(w, x_obs, side), v, guess)


def mpc_cost(planner: MpcPlanner, inp: PlannerInput) -> tuple[Counted, np.ndarray]:
    """The planner's compiled cost at ``inp`` as f(u), counted, and the planner's initial guess."""
    p = planner.parameters(inp)
    solver = planner.solver
    return Counted(lambda u: solver.cost(u, p)), planner.initial_guess(inp).ravel()


def max_iterations(n: int, max_evals: int = 100) -> int:
    """What the cap allows: the start costs 1 + n evaluations, each iteration at least 1 + n, and the
    last accepted step needs no gradient."""
    return min(10, 1 + (max_evals - 1 - n) // (n + 1))


# --- the QP subproblem -------------------------------------------------------------------------

def random_spd(rng: np.random.Generator, n: int) -> np.ndarray:
    """A random symmetric positive definite n × n matrix, its smallest eigenvalue at least 10⁻³."""
    a = rng.normal(size=(n, n))
    return a @ a.T + 10.0 ** rng.uniform(-3, 1) * np.eye(n)


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 24), st.integers(0, 2**31 - 1))
def test_box_qp_meets_the_kkt_conditions(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    H = random_spd(rng, n)
    g = rng.normal(scale=10.0 ** rng.uniform(-2, 2), size=n)
    x = rng.uniform(-1.0, 1.0, size=n)
    x[rng.random(n) < 0.3] = 1.0
    x[rng.random(n) < 0.3] = -1.0
    lower, upper = -1.0 - x, 1.0 - x
    d = box_qp(H, g, lower, upper)
    assert np.all(d >= lower) and np.all(d <= upper)
    r = H @ d + g  # the model's gradient: zero on free variables, pushing outward on active bounds
    scale = 1e-8 * (1.0 + np.abs(g).max() + np.abs(H).max())
    free = (d > lower) & (d < upper)
    assert np.all(np.abs(r[free]) <= scale)
    assert np.all(r[d == lower] >= -scale) and np.all(r[d == upper] <= scale)
    assert g @ d <= 0.0  # a descent direction


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 24), st.integers(0, 2**31 - 1))
def test_solve_spd_solves_symmetric_positive_definite_systems(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    A = random_spd(rng, n)
    x = rng.normal(size=n)
    b = A @ x
    given_A, given_b = A.copy(), b.copy()
    solved = solve_spd(A, b)
    assert np.allclose(solved, x, rtol=0.0, atol=1e-12 * np.linalg.cond(A) * (1.0 + np.abs(x).max()))
    assert np.array_equal(A, given_A) and np.array_equal(b, given_b)  # the inputs are left as they were


CPU_INDEPENDENT = textwrap.dedent("""
    import sys
    sys.path.insert(0, sys.argv[1])
    from test_paper_sqp import PAPER, mpc_cost, planner_input, realistic
    from moose.planner.mpc import MpcPlanner
    from moose.planner.mpc.paper_sqp import fmincon_sqp, sqp_options
    from solve_time import INSTANT
    for n_p, v, x_obs in ((10, 7.0, 10.0), (10, 6.0, 25.0), (20, 7.0, 18.0)):
        planner = MpcPlanner(PAPER, realistic(0.33, n_p), compute_time_s=INSTANT)
        f, guess = mpc_cost(planner, planner_input(v, x_obs, 2.6))
        result = fmincon_sqp(f, guess, -1.0, 1.0, sqp_options(PAPER))
        print(result.x.tobytes().hex(), result.f.hex())
""")


def test_the_same_bits_whatever_blas_kernels_the_cpu_gives() -> None:
    """OpenBLAS picks its kernels by the CPU (``OPENBLAS_CORETYPE`` forces one) and they sum in different orders:
    with numpy's BLAS in the QP and the BFGS update, the MPC alone's extreme runs differed by up to 0.5 m of
    clearance between an AVX-512 and an AVX2 machine.  The solver's iterates are the same bits with the oldest
    x86-64 kernels (SSE, Nehalem's) and with the ones this CPU gets."""
    outputs = []
    for coretype in (None, "Nehalem"):
        env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
        if coretype:
            env["OPENBLAS_CORETYPE"] = coretype
        run = subprocess.run([sys.executable, "-c", CPU_INDEPENDENT, os.path.dirname(__file__)], env=env,
                             capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stderr
        outputs.append(run.stdout)
    assert outputs[0].count("\n") == 3 and outputs[0] == outputs[1]


# --- the algorithm on functions with known answers ---------------------------------------------

def test_one_quasi_newton_step_solves_a_unit_quadratic_and_counts_as_fmincon() -> None:
    """f = ½‖x − c‖²: H₀ = I is exact, so the first QP step lands on the clipped minimiser.
    Evaluations: f(x₀) + n differences, the accepted trial + n differences: 2 n + 2."""
    c = np.array([0.3, -2.0, 5.0, -0.7])
    f = Counted(lambda x: 0.5 * float(np.sum((x - c) ** 2)))
    result = fmincon_sqp(f, np.zeros(4), -1.0, 1.0)
    np.testing.assert_allclose(result.x, np.clip(c, -1.0, 1.0), atol=1e-6)
    assert result.reason == "optimal" and result.iterations == 1
    assert result.evaluations == f.calls == 2 * 4 + 2


def test_finite_differences_use_fmincons_step_and_honour_the_bounds() -> None:
    """δᵢ = √eps · sign′(xᵢ) · max(|xᵢ|, 1), reversed where x + δ would leave the bounds."""
    x0 = np.array([0.0, -0.5, 1.0, -1.0, 0.999999999])
    f = Counted(lambda x: float(np.sum(x ** 2)))
    fmincon_sqp(f, x0, -1.0, 1.0, SqpOptions(max_iter=0))
    probes = np.array(f.points[1:]) - x0
    np.testing.assert_array_equal(f.points[0], x0)
    assert len(probes) == 5 and np.count_nonzero(probes) == 5  # one variable per probe
    expected = [FD_STEP, -FD_STEP, -FD_STEP, FD_STEP, -FD_STEP]  # the last three reversed at a bound
    np.testing.assert_allclose(np.diag(probes), expected, rtol=1e-9)
    assert np.all(np.abs(np.array(f.points)) <= 1.0)


def test_iteration_cap_and_non_convex_cost() -> None:
    """A non-convex cost (BFGS modified to stay positive definite) stopped by MaxIterations."""
    f = Counted(lambda x: float(np.sum(np.cos(3.0 * x) + 0.1 * x)))
    result = fmincon_sqp(f, np.full(3, 0.05), -1.0, 1.0, SqpOptions(max_iter=4, max_fun_evals=1000))
    assert result.reason in ("max_iter", "optimal", "small_step") and result.iterations <= 4
    assert result.f < result.f_start and result.f == f(result.x)
    assert np.all(np.abs(result.x) <= 1.0)


def test_a_non_finite_start_fails_and_non_finite_trials_are_rejected() -> None:
    bad = fmincon_sqp(lambda x: math.nan, np.zeros(2), -1.0, 1.0)
    assert bad.reason == "not_finite" and bad.evaluations == 1 and bad.f == math.inf
    # the cost is undefined beyond x = 0.5: the full step to c = 1 is rejected, a shorter one taken
    f = Counted(lambda x: math.inf if x[0] > 0.5 else 0.5 * float((x[0] - 1.0) ** 2))
    result = fmincon_sqp(f, np.zeros(1), -1.0, 1.0)
    assert 0.0 < result.x[0] <= 0.5 and math.isfinite(result.f) and result.f < result.f_start


# --- on the MPC's cost: Table II's caps hold ---------------------------------------------------

@pytest.mark.parametrize("grid", GRIDS, ids=["kinematic", "mu0.33", "mu0.8"])
@pytest.mark.parametrize("n_p", [10, 20])
def test_the_cap_leaves_about_four_iterations_at_n_p_10(grid: PlanningGrid, n_p: int) -> None:
    """The notes' problem (v = 7, obstacle 10 m ahead, w = 2.6 m) from a cold start: 21 evaluations
    per gradient at N_p = 10 leave four iterations, 41 at N_p = 20 two."""
    planner = MpcPlanner(PAPER, dataclasses.replace(grid, N_p=n_p), compute_time_s=INSTANT)
    f, guess = mpc_cost(planner, planner_input(7.0, 10.0, 2.6))
    result = fmincon_sqp(f, guess, -1.0, 1.0, sqp_options(PAPER))
    assert result.evaluations == f.calls <= 100
    assert result.iterations == max_iterations(2 * n_p) == {10: 4, 20: 2}[n_p]
    assert result.reason == "max_evals"
    assert result.f < result.f_start


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(GRIDS), st.sampled_from([2, 5, 10, 20]), st.floats(0.0, 9.0), st.floats(2.0, 40.0),
       st.floats(0.5, 4.0), st.sampled_from([1, -1]), st.floats(-1.0, 1.0),
       st.one_of(st.none(), st.tuples(st.floats(-1.0, 1.0), st.floats(-1.0, 1.0))))
def test_caps_bounds_and_descent_on_the_mpc_cost(grid: PlanningGrid, n_p: int, v: float, x_obs: float, w: float,
                                                 side: int, vy: float, held: tuple[float, float] | None) -> None:
    grid = dataclasses.replace(grid, N_p=n_p)
    planner = MpcPlanner(PAPER, grid, compute_time_s=INSTANT)
    guess = None if held is None else np.tile(np.array(held) * [grid.a_x_max, grid.a_y_max], (n_p, 1))
    f, start = mpc_cost(planner, planner_input(v, x_obs, w, side, vy, guess))
    result = fmincon_sqp(f, start, -1.0, 1.0, sqp_options(PAPER))
    assert result.evaluations == f.calls <= 100
    assert result.iterations <= max_iterations(2 * n_p)
    assert all(np.all(np.abs(u) <= 1.0) for u in f.points)  # every evaluation inside the bounds
    assert np.all(np.abs(result.x) <= 1.0)
    assert result.f <= result.f_start and result.f == f.fn(result.x)
    assert result.reason in ("optimal", "small_step", "max_iter", "max_evals")


# --- through the planner ---------------------------------------------------------------------

def test_planner_statuses_with_the_paper_baseline() -> None:
    inp = planner_input(7.0, 10.0, 2.6)
    # 1.4 s ahead: no plan keeps the path above y_safe
    late = MpcPlanner(PAPER, KINEMATIC, compute_time_s=INSTANT).plan(inp)
    assert late.status == "barrier_violated" and late.iterations == 4  # the hand-over trigger outranks "capped"
    assert late.accel[0, 1] == pytest.approx(6.0)  # full steering away, as the other solvers
    early = planner_input(7.0, 40.0, 2.6)  # 5.7 s ahead: the capped plan clears y_safe
    capped = MpcPlanner(PAPER, KINEMATIC, compute_time_s=INSTANT).plan(early)
    assert capped.status == "capped" and capped.iterations == 4
    two_step = MpcPlanner(PAPER, dataclasses.replace(KINEMATIC, N_p=2), compute_time_s=INSTANT).plan(early)
    assert two_step.status == "converged"
    loose = MpcPlanner(dataclasses.replace(PAPER, caps=SolverCaps(max_iter=2, max_fun_evals=1000)), KINEMATIC,
                       compute_time_s=INSTANT)
    assert loose.plan(early).status == "capped" and loose.plan(early).iterations == 2
    nan = dataclasses.replace(inp, estimate=dataclasses.replace(inp.estimate, vx=math.nan))
    failed = MpcPlanner(PAPER, KINEMATIC, compute_time_s=INSTANT).plan(nan)
    assert failed.status == "failed" and failed.cost == math.inf and np.all(np.isfinite(failed.accel))


def test_the_planner_evaluates_the_cost_only_through_the_counted_callable(monkeypatch) -> None:
    """The planner's solver evaluates 𝒥 through ``evaluate`` only: counted there, never above the cap."""
    planner = MpcPlanner(PAPER, realistic(PAPER_FRICTION), compute_time_s=INSTANT)
    solver = planner.solver
    inp = planner_input(6.0, 18.0, 2.4)
    p = planner.parameters(inp)
    original = solver.evaluate
    counted = Counted(lambda u: original(u, p))
    monkeypatch.setattr(solver, "evaluate", lambda u, _p: counted(u))
    result = solver.solve(planner.initial_guess(inp).ravel(), p)
    assert result.evaluations == counted.calls <= 100 and result.iterations <= 4
