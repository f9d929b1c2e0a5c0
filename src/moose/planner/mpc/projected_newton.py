"""Projected Newton method for a smooth cost under box bounds, compiled to C.

min f(u, p) s.t. lb ≤ u ≤ ub (Bertsekas 1982): exact Hessian on the variables off
their bounds, regularised in proportion to the distance from stationarity and made
positive definite by a sufficient multiple of the identity (Nocedal & Wright,
Alg. 3.3), Armijo backtracking along the projection arc, and the projected gradient
where Newton's direction fails; ``converged`` only at a point stationary to
``tol_opt``.  The cost is a CasADi function; its gradient and Hessian come from
CasADi's automatic differentiation, and the iteration itself (``projected_newton.c``)
is compiled together with the generated C of the cost and its derivatives into one
shared object (``ccompile``), so one solve is one C call.  The algorithm and the way
evaluations are counted are stated at the top of ``projected_newton.c``.

This is the MPC planner's solver (``mpc.solver = projected_newton``): the paper's
problem, eq. (planmpc), has only the input bounds as constraints, and a general
SQP spends most of its time on QPs that here reduce to the active set of a box.
"""
from __future__ import annotations

import ctypes
import dataclasses
from importlib import resources
from typing import Literal

import casadi as ca
import numpy as np

from ...ccompile import CompiledFunction, compile_library
from ...params import check, positive

NewtonStatus = Literal["converged", "max_iter", "max_evals", "line_search", "not_finite"]
"""Why the iteration stopped, in the order of the C enum ``PN_*``: ``converged`` only when ‖u − P(u − ∇f)‖∞ ≤
``tol_opt`` (a short step is not a stop); ``line_search``: no decrease along Newton's direction nor the projected
gradient."""
STATUSES: tuple[NewtonStatus, ...] = ("converged", "max_iter", "max_evals", "line_search", "not_finite")

_P = ctypes.POINTER(ctypes.c_double)


@dataclasses.dataclass(frozen=True)
class NewtonOptions:
    """Stopping criteria and line search of :class:`ProjectedNewton`."""

    max_iter: int = 10
    """Iteration cap."""
    max_evals: int = 100
    """Cap on cost evaluations (the start included)."""
    max_ls: int = 8
    """Backtracking steps per iteration (1 + max_ls trials at most)."""
    rho: float = 0.3
    """Backtracking factor of the step length."""
    sigma: float = 1e-4
    """Armijo sufficient-decrease constant."""
    eps_active: float = 0.1
    """ε of the ε-active set (in units of u): a variable this close to a bound, its gradient pushing out, is held."""
    tol_opt: float = 1e-3
    """Stop when ‖u − P(u − ∇f)‖∞ is at most this."""
    tol_step: float = 1e-3
    """A Newton step the line search shortened below this ‖Δu‖∞ counts as a failed direction: the iteration
    searches along the projected gradient too (not a stopping test)."""
    shift: float = 1e-3
    """β of Alg. 3.3 relative to max(1, max |H_ii|): the first shift tried on a non-positive diagonal."""
    regularisation: float = 0.1
    """c: c ‖u − P(u − ∇f)‖∞ is added to the Hessian's diagonal (0: the plain Newton step)."""

    def __post_init__(self) -> None:
        for name in ("max_iter", "max_evals", "max_ls"):
            check(name, getattr(self, name), lambda v: isinstance(v, int) and v >= 0, "an integer ≥ 0")
        check("max_evals", self.max_evals, lambda v: v >= 1, "an integer ≥ 1 (the start is one evaluation)")
        check("rho", self.rho, lambda v: 0.0 < v < 1.0, "a factor in (0, 1)")
        check("sigma", self.sigma, lambda v: 0.0 < v < 1.0, "a constant in (0, 1)")
        for name in ("eps_active", "tol_opt", "tol_step", "shift"):
            check(name, getattr(self, name), positive, "a positive number")
        check("regularisation", self.regularisation, lambda v: v >= 0.0, "a non-negative number")

    def vector(self) -> np.ndarray:
        """The options in the order of the C enum ``OPT_*``."""
        return np.array([self.max_iter, self.max_evals, self.max_ls, self.rho, self.sigma, self.eps_active,
                         self.tol_opt, self.tol_step, self.shift, self.regularisation], dtype=float)


@dataclasses.dataclass(frozen=True)
class NewtonResult:
    """One solve: the point reached and how."""

    u: np.ndarray
    f: float
    """Cost at ``u`` (inf if the start was not finite)."""
    f_start: float
    """Cost at the (clipped) start."""
    iterations: int
    evaluations: int
    status: NewtonStatus
    optimality: float
    """‖u − P(u − ∇f)‖∞ at the last point where the gradient was evaluated."""


class CompilerMissing(RuntimeError):
    """No working C compiler: the solver cannot be built."""


class ProjectedNewton:
    """The solver for one cost function ``cost(u, p) → f`` (CasADi, SX or expandable MX; u and p dense vectors).

    One solve at a time per instance: the arguments pass through buffers the instance owns.
    """

    def __init__(self, cost: ca.Function, options: NewtonOptions = NewtonOptions()) -> None:
        self.options = options
        if cost.is_a("MXFunction"):
            cost = cost.expand()  # the derivatives are generated as SX expressions
        self.n = cost.nnz_in(0)
        self.n_p = cost.nnz_in(1)
        u = ca.SX.sym("u", self.n)
        p = ca.SX.sym("p", self.n_p)
        f = cost(u, p)
        hessian, gradient = ca.hessian(f, u)
        functions = [ca.Function("pn_cost", [u, p], [f]),
                     ca.Function("pn_derivatives", [u, p], [f, gradient, ca.densify(hessian)])]
        source = f"#define PN_N {self.n}\n" + resources.files(__package__).joinpath("projected_newton.c").read_text()
        library = compile_library(f"pn_{cost.name()}_{self.n}", functions, source)
        if library is None:
            raise CompilerMissing("the projected Newton solver is compiled C and no working C compiler could "
                                  "build it (set CC, or install gcc)")
        self._cost = CompiledFunction(library, functions[0])
        self._solve = library.pn_solve
        self._solve.restype = ctypes.c_int
        self._solve.argtypes = [_P] * 7
        n_info = int(library.pn_n_info())
        assert int(library.pn_n()) == self.n and int(library.pn_n_opt()) == len(options.vector())
        self._opt = options.vector()
        self._u = np.zeros(self.n)
        self._info = np.zeros(n_info)
        self._u0 = np.zeros(self.n)
        self._p = np.zeros(self.n_p)
        self._lb = np.full(self.n, -1.0)
        self._ub = np.full(self.n, 1.0)
        self._args = [a.ctypes.data_as(_P) for a in (self._u0, self._p, self._lb, self._ub, self._opt, self._u,
                                                       self._info)]

    def cost(self, u: np.ndarray, p: np.ndarray) -> float:
        """f(u, p), evaluated by the compiled cost."""
        return float(self._cost(np.asarray(u, dtype=float).ravel(), np.asarray(p, dtype=float))[0][0])

    def solve(self, u0: np.ndarray, p: np.ndarray, lb: np.ndarray | float | None = None,
              ub: np.ndarray | float | None = None) -> NewtonResult:
        """Minimise from ``u0`` (clipped into [lb, ub]) for the parameters ``p``; bounds left out keep
        the last ones given (initially [−1, 1], the MPC's normalised inputs)."""
        self._u0[:] = u0
        self._p[:] = p
        if lb is not None or ub is not None:
            self.set_bounds(self._lb if lb is None else lb, self._ub if ub is None else ub)
        code = self._solve(*self._args)
        if code < 0:
            raise MemoryError("projected Newton: the work space could not be allocated")
        info = self._info
        return NewtonResult(u=self._u.copy(), f=float(info[0]), f_start=float(info[1]), iterations=int(info[2]),
                            evaluations=int(info[3]), status=STATUSES[code], optimality=float(info[5]))

    def set_bounds(self, lb: np.ndarray | float, ub: np.ndarray | float) -> None:
        """The box [lb, ub] of the following solves."""
        lb = np.broadcast_to(np.asarray(lb, dtype=float), self.n)
        ub = np.broadcast_to(np.asarray(ub, dtype=float), self.n)
        if np.any(~(lb <= ub)):
            raise ValueError(f"bounds: lb > ub (or NaN) at {np.flatnonzero(~(lb <= ub)).tolist()}")
        self._lb[:] = lb
        self._ub[:] = ub
