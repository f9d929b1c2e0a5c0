"""Compile a CasADi function (or several, with C that calls them) once per machine; call through ctypes.

A CasADi call from Python costs tens of microseconds of argument conversion,
more than evaluating the plant itself; the generated C called through ctypes
with preallocated buffers costs a few.  Shared objects are cached in
``$MOOSE_CACHE_DIR`` (default ``~/.cache/moose``) under the hash of their C
source, written atomically, so concurrent processes share one build.  Next to
each goes the SHA-256 of the object as it was compiled (``.so.sha256``); a
cached object is loaded only when its bytes hash to that value, from the very
file that was hashed, else it is compiled again (:func:`load_cached`).  When no C
compiler is available the caller falls back to CasADi's virtual machine.
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path
from typing import Any, Callable, Optional, Sequence

import casadi as ca
import numpy as np

from .resources import cache_dir

_P = ctypes.POINTER(ctypes.c_double)
FLAGS = ("-O2", "-ffp-contract=off", "-shared", "-fPIC")
"""Compiler flags: no fused multiply-add contraction, so that a function called by another (the observer's
fused tick, the plant's chunks) computes bit for bit what it computes alone, on every architecture."""
COMPILE_TIMEOUT = 600.0
"""Seconds the C compiler may take before the build counts as failed (a hung compiler).  The largest problem
(N_p = 20, exact Hessian) took more than 120 s on a loaded machine (load average 27), which had made the build of a
correct problem fail."""


class CompiledFunction:
    """A dense CasADi function with vector inputs/outputs, evaluated in compiled C.

    ``fixed`` sets the trailing inputs once (parameters that do not change between calls); a call
    then passes only the leading ones.  Each instance owns its buffers: :meth:`bind` makes an
    instance for one user of a shared library.
    """

    def __init__(self, library: ctypes.CDLL, fn: ca.Function, fixed: Sequence[np.ndarray | float] = ()) -> None:
        name = fn.name()
        self._library, self._fn = library, fn
        self._call = getattr(library, name)
        work = getattr(library, name + "_work")
        sizes = [ctypes.c_longlong() for _ in range(4)]
        work(*[ctypes.byref(s) for s in sizes])
        n_arg, n_res, n_iw, n_w = (max(s.value, 1) for s in sizes)
        self._inputs = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
        self._outputs = [np.zeros(fn.nnz_out(i)) for i in range(fn.n_out())]
        self._arg = (_P * n_arg)(*[a.ctypes.data_as(_P) for a in self._inputs])
        self._res = (_P * n_res)(*[r.ctypes.data_as(_P) for r in self._outputs])
        self._iw = (ctypes.c_longlong * n_iw)()
        self._w = np.zeros(n_w)
        self._wp = self._w.ctypes.data_as(_P)
        n_free = fn.n_in() - len(fixed)
        if n_free < 0:
            raise ValueError(f"fixed = {len(fixed)} inputs is invalid: {name} has {fn.n_in()}")
        matrix = [fn.size2_in(i) > 1 for i in range(fn.n_in())]  # a 2-D array is read in column-major order
        for buffer, is_matrix, value in zip(self._inputs[n_free:], matrix[n_free:], fixed):
            _write(buffer, is_matrix, value)
        self._invoke = self._generate(n_free, matrix)

    def _generate(self, n_free: int, matrix: list[bool]) -> Callable[..., list[np.ndarray]]:
        """The call with the copies into the free inputs' buffers and out of the outputs' written out, one
        statement per buffer.  The closed loop makes about 3,000 calls per simulated 10 s, and a loop over
        the inputs costs more than the compiled function itself (the same technique as ``dataclasses``)."""
        names = [f"a{i}" for i in range(n_free)]
        lines = ["def call(*args):",
                 f"    if len(args) != {n_free}:",
                 f"        raise TypeError(f'{self._fn.name()} takes {n_free} inputs, got {{len(args)}}')"]
        if names:
            lines.append(f"    {', '.join(names)}{',' if n_free == 1 else ''} = args")
        for i, a in enumerate(names):
            if self._inputs[i].size == 1:
                lines.append(f"    if type({a}) is float: b{i}[0] = {a}")
                lines.append(f"    else: b{i}[:] = {a}")
            elif matrix[i]:
                lines.append(f"    b{i}[:] = {a}.ravel(order='F') if type({a}) is ndarray and {a}.ndim > 1 else {a}")
            else:
                lines.append(f"    b{i}[:] = {a}")
        lines.append("    if function(arg, res, iw, w, 0) != 0:")
        lines.append("        raise RuntimeError('compiled CasADi function failed')")
        lines.append(f"    return [{', '.join(f'o{j}.copy()' for j in range(len(self._outputs)))}]")
        scope: dict[str, Any] = {f"b{i}": buffer for i, buffer in enumerate(self._inputs)}
        scope.update({f"o{j}": buffer for j, buffer in enumerate(self._outputs)})
        scope.update(ndarray=np.ndarray, function=self._call, arg=self._arg, res=self._res, iw=self._iw, w=self._wp)
        exec("\n".join(lines), scope)  # generated from the function's signature only
        return scope["call"]

    def bind(self, *fixed: np.ndarray | float) -> "CompiledFunction":
        """A new instance, with buffers of its own, whose last ``len(fixed)`` inputs are ``fixed``."""
        return CompiledFunction(self._library, self._fn, fixed)

    def __call__(self, *args: np.ndarray | float) -> list[np.ndarray]:
        """The outputs (copies) at the free inputs ``args``; a matrix may be a 2-D array or its column-major vector."""
        return self._invoke(*args)


def _write(buffer: np.ndarray, matrix: bool, value: np.ndarray | float) -> None:
    """Copy one input into its buffer (column-major for a matrix)."""
    array = np.asarray(value, dtype=float)
    buffer[:] = array.ravel(order="F") if matrix else array.ravel()


def bind(fn: Callable[..., Any], *fixed: np.ndarray | float) -> Callable[..., Any]:
    """``fn`` with its trailing inputs set to ``fixed``: compiled, or CasADi's function as a closure."""
    if isinstance(fn, CompiledFunction):
        return fn.bind(*fixed)
    return lambda *args: fn(*args, *fixed)


def compile_library(name: str, functions: Sequence[ca.Function], source: str = "") -> Optional[ctypes.CDLL]:
    """The generated C of ``functions`` followed by ``source``, compiled once per machine and loaded.

    ``source`` is C that may call the generated functions.  ``None`` when no C compiler works here.
    """
    compiler = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if compiler is None:
        return None
    generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for fn in functions:
        generator.add(fn)
    text = generator.dump() + source
    digest = hashlib.sha256((text + ca.CasadiMeta.version() + " ".join(FLAGS)).encode()).hexdigest()[:16]
    target = cache_dir() / f"{name}_{digest}.so"
    library = load_cached(target)
    if library is not None:
        return library
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=target.parent) as tmp:
        c_file = Path(tmp) / "f.c"
        c_file.write_text(text)
        built = Path(tmp) / "f.so"
        try:
            subprocess.run([compiler, *FLAGS, str(c_file), "-o", str(built), "-lm"],
                           check=True, capture_output=True, timeout=COMPILE_TIMEOUT)
        except (OSError, subprocess.SubprocessError):
            return None
        data = built.read_bytes()
        stamp = Path(tmp) / "f.sha256"
        stamp.write_text(hashlib.sha256(data).hexdigest() + "\n", encoding="ascii")
        os.replace(stamp, _stamp(target))  # the hash first: a reader in between finds the old file refused
        os.replace(built, target)
    return _load(target, data)


def _stamp(target: Path) -> Path:
    """Where the SHA-256 of the shared object ``target`` is kept."""
    return target.with_name(target.name + ".sha256")


_LOADED: dict[Path, ctypes.CDLL] = {}
"""The shared objects this process has loaded (each verified once), by cache path."""


def load_cached(target: Path) -> Optional[ctypes.CDLL]:
    """The shared object ``target`` loaded, if its bytes hash to the SHA-256 kept next to it; else ``None``.

    The bytes that were hashed are the bytes that are loaded: they are copied into a private folder of the
    cache (created for this load, readable by this user only) and loaded from there, so a file swapped in
    after the check cannot be loaded.  A file whose hash differs from the recorded one (damaged or replaced) is
    reported with a :class:`RuntimeWarning`; a file without a recorded hash (none yet, or built before hashes
    were kept) is not.  Either way the caller compiles it again.  A process loads each cache path once."""
    if target in _LOADED:
        return _LOADED[target]
    try:
        expected = _stamp(target).read_text(encoding="ascii").strip()
        data = target.read_bytes()
    except (OSError, UnicodeDecodeError):
        return None
    actual = hashlib.sha256(data).hexdigest()
    if actual != expected:
        warnings.warn(f"cached compiled code {str(target)!r} does not match its recorded SHA-256 "
                      f"({actual[:16]}... instead of {expected[:16]}...): it is compiled again", RuntimeWarning,
                      stacklevel=2)
        return None
    return _load(target, data)


def _load(target: Path, data: bytes) -> ctypes.CDLL:
    """``data`` (the verified bytes of ``target``) loaded from a private copy."""
    with tempfile.TemporaryDirectory(dir=target.parent) as private:  # mode 0700; a loaded object may be unlinked
        copy = Path(private) / target.name
        copy.write_bytes(data)
        library = _LOADED[target] = ctypes.CDLL(str(copy))
    return library


def compile_function(fn: ca.Function) -> Optional[CompiledFunction]:
    """Compiled version of ``fn``, or ``None`` when no C compiler works here."""
    library = compile_library(fn.name(), [fn])
    return CompiledFunction(library, fn) if library is not None else None
