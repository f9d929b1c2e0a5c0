"""``mpc.solver: paper_sqp``: the paper's baseline, fmincon's SQP algorithm under Table II.

The paper solves eq. (planmpc) with ``fmincon``'s SQP algorithm (MATLAB R2017b) with the caps of
Table II: 10 iterations, 100 function evaluations, tolerances 1e-3.  The cost is given without
its gradient, so fmincon estimates it by finite differences, and every one of those evaluations
counts against the 100.  :func:`fmincon_sqp` does what the MATLAB documentation describes for
that algorithm on a bound-constrained problem (docs/modelling.md, "MPC", says what is the same and
what differs):

* the start is moved into the bounds; f(x₀) is one evaluation;
* gradient by forward differences, one evaluation per variable: step
  δᵢ = √eps · sign′(xᵢ) · max(|xᵢ|, TypicalX = 1) (sign′(0) = 1), reversed where x + δ would
  leave the bounds (the sqp algorithm's finite differences honour the bounds);
* quasi-Newton Hessian H, the identity at the start, BFGS-updated with the Lagrangian's
  gradient difference (for bound constraints the gradient difference of f); where qᵀs ≤ 0 the
  most negative element of q ∘ s is halved until qᵀs is at least a small negative tolerance,
  then q is moved along s on the elements with qᵢsᵢ < 0 until qᵀs > 0 (the documentation's
  two-phase modification), so H stays positive definite;
* search direction: the QP min ½ dᵀH d + gᵀd subject to lb − x ≤ d ≤ ub − x, solved exactly
  (:func:`box_qp`, a primal active-set method);
* line search on the merit function, which for a problem whose iterates honour the bounds is f
  itself: α = 1, ½, ¼, … until f(x + α d) ≤ f(x) + 10⁻⁴ α gᵀd; a non-finite trial value is
  rejected and the step halved (the sqp algorithm's robustness to non-double results);
* stopping, checked at the start and after each iteration: the first-order optimality measure
  (the gradient with the components pushing out of an active bound removed, ∞-norm) at most
  OptimalityTolerance · max(1, ‖∇f(x₀)‖∞) (relative, as for fmincon's sqp): ``optimal``
  (exit flag 1); a step, or a line-search trial step, shorter than
  StepTolerance · (1 + ‖x‖₂): ``small_step`` (exit flag 2); MaxIterations: ``max_iter``;
  the evaluation cap: ``max_evals`` (both exit flag 0).

The evaluation cap is hard: an evaluation the cap does not allow is never made.  When the cap
falls inside a finite-difference gradient, the iterate just accepted is returned; when it falls
inside a line search, the last accepted iterate.  Every accepted iterate lowers f, so the result
is never worse than the start.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable, Literal

import numpy as np

from ...params import check, positive
from ...schema import MpcParams
from .cost import Problem
from .solver import CompiledCost, Solver, SolveResult, SolveStatus, register

SqpReason = Literal["optimal", "small_step", "max_iter", "max_evals", "not_finite"]
STATUS: dict[SqpReason, SolveStatus] = {
    "optimal": "converged", "small_step": "converged",  # fmincon's exit flags 1 and 2
    "max_iter": "capped", "max_evals": "capped",  # exit flag 0
    "not_finite": "capped"}  # a non-finite gradient stops it at a finite iterate (a non-finite start: failed)

FD_STEP = math.sqrt(np.finfo(float).eps)
"""fmincon's default FiniteDifferenceStepSize for forward differences, √eps."""


@dataclasses.dataclass(frozen=True)
class SqpOptions:
    """fmincon's options that matter here; the defaults are Table II and fmincon's defaults."""

    max_iter: int = 10
    """MaxIterations (Table II)."""
    max_fun_evals: int = 100
    """MaxFunctionEvaluations (Table II), finite differences and line-search trials included."""
    optimality_tol: float = 1e-3
    """OptimalityTolerance (Table II), relative to max(1, ‖∇f(x₀)‖∞)."""
    step_tol: float = 1e-3
    """StepTolerance (Table II), relative: ‖Δx‖₂ < step_tol (1 + ‖x‖₂)."""
    fd_step: float = FD_STEP
    """FiniteDifferenceStepSize v: δ = v sign′(x) max(|x|, typical_x)."""
    typical_x: float = 1.0
    """TypicalX."""
    armijo: float = 1e-4
    """Sufficient-decrease constant of the line search (MathWorks does not publish its own)."""

    def __post_init__(self) -> None:
        check("max_iter", self.max_iter, lambda v: isinstance(v, int) and v >= 0, "an integer ≥ 0")
        check("max_fun_evals", self.max_fun_evals, lambda v: isinstance(v, int) and v >= 1, "an integer ≥ 1")
        for name in ("optimality_tol", "step_tol", "fd_step", "typical_x"):
            check(name, getattr(self, name), positive, "a positive number")
        check("armijo", self.armijo, lambda v: 0.0 < v < 0.5, "a constant in (0, 0.5)")


@dataclasses.dataclass(frozen=True)
class SqpResult:
    """One run of :func:`fmincon_sqp`."""

    x: np.ndarray
    f: float
    """f at ``x`` (inf if the start was not finite)."""
    f_start: float
    iterations: int
    evaluations: int
    reason: SqpReason
    optimality: float
    """First-order optimality measure at the last point whose gradient was estimated (inf if none)."""


class _EvaluationCap(Exception):
    """The next evaluation would exceed the cap."""


# The linear algebra below is elementwise operations and numpy's pairwise sums only, never BLAS or LAPACK: OpenBLAS
# picks its kernels by the CPU, and they sum in different orders (AVX-512 against AVX2 kernels changed the MPC's
# extreme runs by up to 0.5 m of clearance: docs/modelling.md, "MPC").  These give the same bits on every CPU.

def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """aᵀb."""
    return float(np.add.reduce(a * b))


def _matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A x."""
    return np.add.reduce(A * x, axis=1)


def _norm(x: np.ndarray) -> float:
    """‖x‖₂."""
    return math.sqrt(_dot(x, x))


def solve_spd(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with A x = b, A symmetric positive definite: Gauss-Jordan elimination without pivoting (stable for such A)
    on [A | b], each step one outer product."""
    n = len(b)
    M = np.empty((n, n + 1))
    M[:, :n], M[:, n] = A, b
    for k in range(n):
        row = M[k] / M[k, k]
        M -= np.multiply.outer(M[:, k], row)
        M[k] = row
    return M[:, n].copy()


def box_qp(H: np.ndarray, g: np.ndarray, lower: np.ndarray, upper: np.ndarray,
           max_iter: int | None = None) -> np.ndarray:
    """argmin ½ dᵀH d + gᵀd subject to lower ≤ d ≤ upper, H symmetric positive definite, lower ≤ 0 ≤ upper.

    A primal active-set method (Nocedal & Wright, Numerical Optimization, 2nd ed., Alg. 16.3)
    from d = 0 with the bounds that hold there as the working set: each step solves the
    equality-constrained QP on the free variables, moves to it or to the first bound in the way
    (which joins the working set), and at a minimiser of the working set releases the bound with
    the most negative multiplier.  Every step lowers the model, so the result is a descent
    direction whatever stops it.
    """
    n = len(g)
    d = np.zeros(n)
    at_lower = lower >= 0.0
    at_upper = ~at_lower & (upper <= 0.0)
    working = at_lower | at_upper
    for _ in range(max_iter if max_iter is not None else 10 * n + 10):
        free = ~working
        target = d.copy()
        if free.any():
            rows = H[free]
            target[free] = solve_spd(rows[:, free], -(g[free] + _matvec(rows[:, working], d[working])))
        step = target - d
        ratio, blocking = 1.0, -1
        for i in np.flatnonzero(free & (step != 0.0)):
            limit = ((upper[i] if step[i] > 0.0 else lower[i]) - d[i]) / step[i]
            if limit < ratio:
                ratio, blocking = limit, int(i)
        if blocking < 0:  # the minimiser on the working set: release a bound whose multiplier is negative
            d = target
            gradient = _matvec(H, d) + g
            multipliers = np.where(at_lower, gradient, -gradient)  # ≥ 0 at the QP's minimiser
            multipliers[free] = np.inf
            release = int(np.argmin(multipliers))
            if multipliers[release] >= -1e-12 * (1.0 + float(np.max(np.abs(g), initial=0.0))):  # round-off
                return d
            working[release] = at_lower[release] = at_upper[release] = False
        else:  # the first bound in the way joins the working set
            d = d + max(ratio, 0.0) * step
            on_upper = bool(step[blocking] > 0.0)
            d[blocking] = upper[blocking] if on_upper else lower[blocking]
            working[blocking] = True
            at_upper[blocking], at_lower[blocking] = on_upper, not on_upper
    return d


def _first_order_optimality(x: np.ndarray, g: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> float:
    """‖g‖∞ without the components that push out of an active bound (their multipliers absorb them)."""
    held = ((x <= lb) & (g > 0.0)) | ((x >= ub) & (g < 0.0))
    return float(np.max(np.abs(np.where(held, 0.0, g)), initial=0.0))


def _bfgs_update(H: np.ndarray, s: np.ndarray, q: np.ndarray) -> np.ndarray:
    """BFGS update of H with the step s and gradient difference q, modified as the MATLAB
    documentation describes for fmincon's SQP so that H stays positive definite; H unchanged if
    no modification makes qᵀs positive (s = 0)."""
    q = q.copy()
    qs = _dot(q, s)
    if qs <= 0.0:
        tolerance = -1e-5 * abs(qs)  # "a small negative tolerance"
        for _ in range(64 * len(q)):
            if qs >= tolerance:
                break
            products = q * s
            i = int(np.argmin(products))
            if products[i] >= 0.0:
                break
            q[i] *= 0.5
            qs = _dot(q, s)
        if qs <= 0.0:
            wrong = q * s < 0.0
            v = np.where(wrong, s, 0.0)
            vs = _dot(v, s)
            if vs <= 0.0:
                return H
            q += (2.0 * (1e-8 * _dot(s, s) - qs) / vs) * v  # w systematically large enough: qᵀs > 0
            qs = _dot(q, s)
            if qs <= 0.0:
                return H
    Hs = _matvec(H, s)
    return H + np.outer(q, q) / qs - np.outer(Hs, Hs) / _dot(s, Hs)


def fmincon_sqp(f: Callable[[np.ndarray], float], x0: np.ndarray, lb: np.ndarray | float,
                ub: np.ndarray | float, options: SqpOptions = SqpOptions()) -> SqpResult:
    """Minimise ``f`` over lb ≤ x ≤ ub from ``x0`` as fmincon's SQP algorithm with finite-difference
    gradients does (module docstring).  ``f`` is called at most ``options.max_fun_evals`` times."""
    x = np.asarray(x0, dtype=float).copy()
    n = len(x)
    lb = np.broadcast_to(np.asarray(lb, dtype=float), n)
    ub = np.broadcast_to(np.asarray(ub, dtype=float), n)
    np.clip(x, lb, ub, out=x)
    evaluations = 0

    def evaluate(point: np.ndarray) -> float:
        nonlocal evaluations
        if evaluations >= options.max_fun_evals:
            raise _EvaluationCap
        evaluations += 1
        return float(f(point))

    def gradient(point: np.ndarray, f_point: float) -> np.ndarray:
        g = np.empty(n)
        probe = point.copy()
        for i in range(n):
            delta = options.fd_step * (1.0 if point[i] >= 0.0 else -1.0) * max(abs(point[i]), options.typical_x)
            if not lb[i] <= point[i] + delta <= ub[i]:
                delta = -delta
            probe[i] = point[i] + delta
            g[i] = (evaluate(probe) - f_point) / (probe[i] - point[i])
            probe[i] = point[i]
        return g

    def result(reason: SqpReason, optimality: float = math.inf) -> SqpResult:
        return SqpResult(x, fx, f_start, iterations, evaluations, reason, optimality)

    iterations = 0
    fx = f_start = evaluate(x)
    if not math.isfinite(fx):
        fx = f_start = math.inf
        return result("not_finite")
    try:
        g = gradient(x, fx)
    except _EvaluationCap:
        return result("max_evals")
    if not np.all(np.isfinite(g)):
        return result("not_finite")
    tolerance = options.optimality_tol * max(1.0, float(np.max(np.abs(g), initial=0.0)))
    H = np.eye(n)
    while True:
        optimality = _first_order_optimality(x, g, lb, ub)
        if optimality <= tolerance:
            return result("optimal", optimality)
        if iterations >= options.max_iter:
            return result("max_iter", optimality)
        d = box_qp(H, g, lb - x, ub - x)
        slope = _dot(g, d)
        step_limit = options.step_tol * (1.0 + _norm(x))
        length = _norm(d)  # the QP's solution is a descent direction: g·d < 0
        alpha = 1.0
        try:
            while True:
                if alpha < 1.0 and alpha * length < step_limit:
                    return result("small_step", optimality)
                trial = np.clip(x + alpha * d, lb, ub)
                f_trial = evaluate(trial)
                if math.isfinite(f_trial) and f_trial <= fx + options.armijo * alpha * slope:
                    break
                alpha *= 0.5
        except _EvaluationCap:
            return result("max_evals", optimality)
        s = trial - x
        x, fx = trial, f_trial
        iterations += 1
        if _norm(s) < step_limit:
            return result("small_step", optimality)
        try:
            g_new = gradient(x, fx)
        except _EvaluationCap:
            return result("max_evals", optimality)
        if not np.all(np.isfinite(g_new)):
            return result("not_finite", optimality)
        H = _bfgs_update(H, s, g_new - g)
        g = g_new


def sqp_options(params: MpcParams) -> SqpOptions:
    """Table II's caps and tolerances of ``params`` (the line-search settings are fmincon's, not ``params``')."""
    caps = params.caps
    return SqpOptions(max_iter=caps.max_iter, max_fun_evals=caps.max_fun_evals,
                      optimality_tol=caps.optimality_tol, step_tol=caps.step_tol)


@register("paper_sqp")
class PaperSqpSolver(Solver):
    """:func:`fmincon_sqp` on the problem's compiled cost (CasADi's virtual machine without a compiler)."""

    def __init__(self, problem: Problem, params: MpcParams) -> None:
        super().__init__(problem, params)
        self.options = sqp_options(params)
        self.evaluate = CompiledCost(problem)
        """𝒥(u, p): the only way the solver evaluates the cost."""

    def solve(self, guess: np.ndarray, p: np.ndarray) -> SolveResult:
        evaluate = self.evaluate
        result = fmincon_sqp(lambda u: evaluate(u, p), guess, -1.0, 1.0, self.options)
        if not math.isfinite(result.f_start):
            return SolveResult.failure(guess, result.iterations, result.evaluations, result.reason)
        return SolveResult(STATUS[result.reason], result.x, result.f, result.f_start, result.iterations,
                           result.evaluations, result.reason)

    def cost(self, u: np.ndarray, p: np.ndarray) -> float:
        return self.evaluate(u, p)
