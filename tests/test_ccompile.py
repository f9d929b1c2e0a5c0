"""Compiled CasADi functions (`moose.ccompile`): the same values as CasADi's virtual machine, bound inputs."""
from __future__ import annotations

import shutil
import warnings
from pathlib import Path

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


@pytest.mark.parametrize("damage", ["replaced", "truncated", "no hash"])
def test_cached_object_is_loaded_only_when_its_hash_matches(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                           damage: str) -> None:
    """A cached .so that is not the one compiled (another library under its name, a cut copy) is not loaded:
    it is compiled again, with a warning; one without a recorded hash (built before hashes were kept) silently."""
    x = ca.SX.sym("x")
    good, evil = ca.Function("moose_test_tamper", [x], [2 * x]), ca.Function("moose_test_tamper", [x], [-x])
    for name, fn in (("good", good), ("evil", evil)):  # each built in a cache of its own
        monkeypatch.setenv("MOOSE_CACHE_DIR", str(tmp_path / name))
        if compile_function(fn) is None:
            pytest.skip("no C compiler on this machine")
    cache = tmp_path / "cache"  # a path this process has never loaded (the loader would reuse a loaded one)
    shutil.copytree(tmp_path / "good", cache)
    (target,) = cache.glob("*.so")
    (evil_so,) = (tmp_path / "evil").glob("*.so")
    if damage == "replaced":
        shutil.copyfile(evil_so, target)  # a valid library exporting the same symbol
    elif damage == "truncated":
        target.write_bytes(target.read_bytes()[:4096])
    else:
        target.with_name(target.name + ".sha256").unlink()
    monkeypatch.setenv("MOOSE_CACHE_DIR", str(cache))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        compiled = compile_function(good)
    assert compiled is not None and float(compiled(3.0)[0][0]) == 6.0
    messages = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert len(messages) == (damage != "no hash")
    assert all("does not match its recorded SHA-256" in m and str(target) in m for m in messages)
    assert compile_function(good) is not None  # rebuilt: its hash now matches
