"""One interface for the solvers of eq. (planmpc), chosen by name (``mpc.solver``).

A solver is built once per problem (:class:`moose.planner.mpc.cost.Problem`) and parameter set, and
then solves it at every planning instant from an initial guess: :meth:`Solver.solve` takes the
normalised inputs (2 N_p, within [−1, 1]) and the parameter vector and returns a
:class:`SolveResult`.  Solvers register their name with :func:`register`; the names a
configuration may give are :data:`moose.schema.SOLVERS` (the light schema module cannot import
the solvers), and :func:`create` refuses a name that is not registered.
"""
from __future__ import annotations

import abc
import dataclasses
import math
from typing import Callable, Literal, TypeVar

import numpy as np

from ...ccompile import compile_function
from ...schema import MpcParams
from .cost import Problem

SolveStatus = Literal["converged", "capped", "failed"]
"""``converged``: a tolerance of Table II was met (optimality, or a step below the step tolerance,
fmincon's exit flags 1 and 2); ``capped``: an iteration or evaluation cap, or the line search, stopped
it first (exit flag 0); ``failed``: no usable point (the start not finite, or the solver failed)."""


@dataclasses.dataclass(frozen=True)
class SolveResult:
    """One solve: the point reached and how."""

    status: SolveStatus
    u: np.ndarray
    """Normalised inputs (2 N_p), within [−1, 1]; the start when ``failed``."""
    f: float
    """Cost at ``u`` (inf when ``failed``)."""
    f_start: float
    """Cost at the (clipped) start (inf if not finite)."""
    iterations: int
    evaluations: int
    """Cost evaluations the solver used, as it counts them against Table II's cap: every point
    where the cost was evaluated (finite differences and line-search trials included), a value
    with its analytic derivatives counting once, as fmincon counts an objective that returns its
    gradient.  For CasADi's solvers: its calls of the functions that evaluate the cost (alone or
    with the gradient); CasADi does not enforce Table II's evaluation cap."""
    reason: str
    """The solver's own word for why it stopped (e.g. ``max_evals``, ``Solve_Succeeded``)."""

    @classmethod
    def failure(cls, guess: np.ndarray, iterations: int, evaluations: int, reason: str) -> SolveResult:
        return cls("failed", np.array(guess, dtype=float), math.inf, math.inf, iterations, evaluations, reason)


class Solver(abc.ABC):
    """Solves one :class:`Problem` under the input bounds [−1, 1].

    One solve at a time per instance (solvers keep work buffers).  Subclasses register with
    :func:`register` and are built by :func:`create`.
    """

    def __init__(self, problem: Problem, params: MpcParams) -> None:
        self.problem = problem
        self.params = params

    @abc.abstractmethod
    def solve(self, guess: np.ndarray, p: np.ndarray) -> SolveResult:
        """Minimise 𝒥(·, p) from the normalised ``guess`` (2 N_p, within [−1, 1])."""

    @abc.abstractmethod
    def cost(self, u: np.ndarray, p: np.ndarray) -> float:
        """𝒥(u, p), by the fastest evaluation the solver has (compiled C where a compiler works)."""


class CompiledCost:
    """𝒥(u, p) → float: the problem's cost compiled to C (cached per machine), else CasADi's virtual machine."""

    def __init__(self, problem: Problem) -> None:
        self._function = problem.cost_function
        self._compiled = compile_function(self._function)

    @property
    def compiled(self) -> bool:
        """Whether the cost runs as compiled C (no C compiler: CasADi's virtual machine)."""
        return self._compiled is not None

    def __call__(self, u: np.ndarray, p: np.ndarray) -> float:
        if self._compiled is None:
            return float(self._function(u, p))
        return float(self._compiled(u, p)[0][0])


SolverFactory = Callable[[Problem, MpcParams], Solver]
_REGISTRY: dict[str, SolverFactory] = {}
S = TypeVar("S", bound=type[Solver])


def register(*names: str) -> Callable[[S], S]:
    """Class decorator: the solver class answers to ``names`` (it receives its name as ``params.solver``)."""
    def decorate(cls: S) -> S:
        for name in names:
            if name in _REGISTRY:
                raise ValueError(f"mpc solver {name!r} is registered twice")
            _REGISTRY[name] = cls
        return cls
    return decorate


def registered() -> tuple[str, ...]:
    """The registered solver names."""
    return tuple(_REGISTRY)


def create(problem: Problem, params: MpcParams) -> Solver:
    """The solver ``params.solver`` for ``problem``."""
    try:
        factory = _REGISTRY[params.solver]
    except KeyError:
        raise ValueError(f"mpc.solver = {params.solver!r} is not a registered solver "
                         f"(registered: {', '.join(_REGISTRY)})") from None
    return factory(problem, params)
