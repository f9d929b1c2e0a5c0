"""Compiled CasADi functions (`moose.ccompile`): the same values as CasADi's virtual machine, bound inputs."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from moose.ccompile import CompiledFunction, bind, compile_function


def _function() -> ca.Function:
    """y = A x s + b, z = trace(A) + s: a matrix, a vector, a scalar and a vector input."""
    A, x, s, b = ca.SX.sym("A", 3, 2), ca.SX.sym("x", 2), ca.SX.sym("s"), ca.SX.sym("b", 3)
    return ca.Function("moose_test_ccompile", [A, x, s, b], [A @ x * s + b, A[0, 0] + A[1, 1] + s])


def _reference(A: np.ndarray, x: np.ndarray, s: float, b: np.ndarray) -> list[np.ndarray]:
    return [A @ x * s + b, np.array([A[0, 0] + A[1, 1] + s])]


@pytest.fixture(scope="module")
def compiled() -> CompiledFunction:
    fn = compile_function(_function())
    if fn is None:
        pytest.skip("no C compiler on this machine: the closed loop runs on CasADi's virtual machine")
    return fn


A = np.array([[1.0, 2.0], [3.0, 4.0], [5.0, 6.0]])  # not symmetric: a row-major copy would give other values


def test_compiled_matches_numpy(compiled: CompiledFunction) -> None:
    x, b = np.array([0.5, -1.0]), np.array([1.0, 2.0, 3.0])
    for s in (2.0, np.float64(-0.25), 3):  # a Python float, a NumPy scalar, an int
        for got, want in zip(compiled(A, x, s, b), _reference(A, x, float(s), b)):
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # a matrix given as its column-major vector is the same matrix
    np.testing.assert_allclose(compiled(A.ravel(order="F"), x, 2.0, b)[0], _reference(A, x, 2.0, b)[0])


def test_outputs_are_copies(compiled: CompiledFunction) -> None:
    x, b = np.array([0.5, -1.0]), np.zeros(3)
    first = compiled(A, x, 1.0, b)[0]
    compiled(A, x, 10.0, b)
    np.testing.assert_allclose(first, A @ x)


def test_bound_instances_keep_their_own_trailing_inputs(compiled: CompiledFunction) -> None:
    x = np.array([1.0, 1.0])
    one, two = compiled.bind(2.0, np.ones(3)), compiled.bind(-1.0, np.zeros(3))
    a, b = one(A, x)[0], two(A, x)[0]
    np.testing.assert_allclose(a, A @ x * 2.0 + 1.0)
    np.testing.assert_allclose(b, -(A @ x))
    np.testing.assert_allclose(one(A, x)[0], a)  # the other instance's call did not touch its buffers
    np.testing.assert_allclose(compiled(A, x, 3.0, np.zeros(3))[0], A @ x * 3.0)  # nor the unbound one's


def test_one_and_no_free_inputs(compiled: CompiledFunction) -> None:
    """The generated call for every arity: one free input left, and none."""
    x, b = np.array([0.5, -1.0]), np.array([1.0, 2.0, 3.0])
    one = compiled.bind(x, 2.0, b)
    np.testing.assert_allclose(one(A)[0], A @ x * 2.0 + b)
    none = compiled.bind(A, x, 2.0, b)
    np.testing.assert_allclose(none()[1], [A[0, 0] + A[1, 1] + 2.0])
    with pytest.raises(TypeError, match="takes 0 inputs, got 1"):
        none(A)


def test_wrong_number_of_inputs_is_an_error(compiled: CompiledFunction) -> None:
    with pytest.raises(TypeError, match="takes 2 inputs, got 4"):
        compiled.bind(1.0, np.zeros(3))(A, np.zeros(2), 1.0, np.zeros(3))
    with pytest.raises(ValueError, match="fixed = 5 inputs is invalid"):
        compiled.bind(1.0, 2.0, 3.0, 4.0, 5.0)


def test_bind_on_casadi_virtual_machine() -> None:
    """Without a compiler the caller keeps CasADi's function; ``bind`` appends the trailing inputs."""
    bound = bind(_function(), 2.0, np.ones(3))
    x = np.array([0.5, -1.0])
    y, z = bound(A, x)
    np.testing.assert_allclose(np.asarray(y).ravel(), A @ x * 2.0 + 1.0)
    np.testing.assert_allclose(float(z), A[0, 0] + A[1, 1] + 2.0)
