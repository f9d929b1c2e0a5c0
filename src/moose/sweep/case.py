"""One case of a sweep: its scenario and configuration, the run, and its row of results.

A case runs exactly what ``moose simulate`` runs for the same inputs
(``moose simulate --speed V --tau T --obstacle-half-width W --obstacle-length L --duration D
--field-margin M --mu MU --planner P --seed S`` with the ``--set`` parameters): the same scenario from
:func:`moose.scenario.adhoc_scenario`, the same :func:`moose.simulation.simulate` and
:func:`moose.metrics.summarize`.  The row is the case's inputs (``input.*``, ``set.*``), the whole
summary (nested fields flattened with dots, ``mpc_solve_ms.median``, ``timing.profile``; the status
counts and notes as JSON text), and how the case ran: ``status`` (:data:`STATUSES`), ``error``, ``wall_s``, ``worker``
(host:pid) and ``worker_max_rss_mb`` (the worker's peak resident memory so far).

A case that raises is recorded with its traceback; one that runs longer than its time limit is
stopped by an exception raised in its thread (:class:`CaseTimeout`), so a case never takes its
worker or the sweep with it.
"""
from __future__ import annotations

import ctypes
import dataclasses
import json
import os
import socket
import threading
import time
import traceback
from functools import lru_cache
from typing import Any, Literal, Optional

from ..config import with_overrides
from ..schema import Config
from .axes import Case

Status = Literal["done", "error", "timeout", "crashed"]
STATUSES: tuple[Status, ...] = ("done", "error", "timeout", "crashed")
"""``done``: the run finished and was judged (its ``outcome`` says how it went); ``error``: the case
raised; ``timeout``: it ran past its time limit; ``crashed``: its worker process died under it."""

MACHINE_COLUMNS = ("wall_s", "worker", "worker_max_rss_mb", "mpc_solve_ms.median", "mpc_solve_ms.p95",
                   "mpc_solve_ms.max")
"""Columns that measure the machine, not the case: they differ between two runs of the same case."""


class CaseTimeout(BaseException):
    """Raised in a case's thread when its time limit passes (a BaseException: no ``except Exception`` of
    the code under test swallows it)."""


@lru_cache(maxsize=64)
def case_config(base: Config, overrides: tuple[tuple[str, Any], ...]) -> Config:
    """The base configuration with the case's ``--set`` parameters."""
    return with_overrides(base, dict(overrides)) if overrides else base


def case_scenario(case: Case) -> Any:
    """The case's moose test, built as ``moose simulate`` builds an ad-hoc test from its flags."""
    from ..scenario import adhoc_scenario

    scenario = adhoc_scenario(case.speed, case.tau, case.half_width, case.length, field_margin=case.field_margin)
    return dataclasses.replace(scenario, duration=case.duration, mu=case.mu)


def flatten(summary: dict[str, Any]) -> dict[str, Any]:
    """A run summary as row columns: the solve times, the timing and the criticality measures with dotted names
    (``criticality.ttc_s``; without them ``criticality`` is null and the notes say why), mappings of counts and
    notes as JSON."""
    row: dict[str, Any] = {}
    for key, value in summary.items():
        if key in ("mpc_solve_ms", "timing") or (key == "criticality" and value is not None):
            row.update({f"{key}.{k}": v for k, v in value.items()})
        elif isinstance(value, (dict, list)):
            row[key] = json.dumps(value, sort_keys=True)
        else:
            row[key] = value
    return row


def worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def max_rss_mb() -> Optional[float]:
    """The peak resident memory of this process so far (MB), or None where the platform does not say."""
    try:
        import resource
    except ImportError:
        return None
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux


class _Deadline:
    """Raise :class:`CaseTimeout` in the calling thread after ``seconds`` (at its next Python bytecode)."""

    def __init__(self, seconds: Optional[float]) -> None:
        self._seconds = seconds
        self._thread = threading.get_ident()
        self._lock = threading.Lock()
        self._active = False
        self._timer: Optional[threading.Timer] = None

    def _fire(self) -> None:
        with self._lock:
            if self._active:
                ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(self._thread), ctypes.py_object(CaseTimeout))

    def __enter__(self) -> "_Deadline":
        if self._seconds is not None:
            self._active = True
            self._timer = threading.Timer(self._seconds, self._fire)
            self._timer.daemon = True
            self._timer.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        with self._lock:
            self._active = False
        if self._timer is not None:
            self._timer.cancel()


def failed_row(case: Case, status: Status, error: str, wall_s: Optional[float], worker: str) -> dict[str, Any]:
    """The row of a case that has no summary."""
    return {"case_id": case.id, **case.inputs, "status": status, "error": error, "wall_s": wall_s, "worker": worker,
            "worker_max_rss_mb": max_rss_mb() if worker == worker_name() else None}


def run_case(case: Case, base: Config, timeout: Optional[float] = None, criticality: bool = False) -> dict[str, Any]:
    """Run one case and return its row; never raises for a failure of the case itself.  With ``criticality`` the
    row carries commonroad-crime's measures of the case's situation (:mod:`moose.commonroad.criticality`: computed
    once per situation in a process, so the planners and seeds of a situation share them)."""
    from ..metrics import summarize
    from ..simulation import simulate

    start = time.perf_counter()
    try:
        with _Deadline(timeout):
            config = case_config(base, case.overrides)
            result = simulate(config, case_scenario(case), case.planner, case.seed)
            summary = summarize(result, criticality=criticality)
    except CaseTimeout:
        return failed_row(case, "timeout", f"stopped after the time limit of {timeout:g} s",
                          time.perf_counter() - start, worker_name())
    except Exception:  # noqa: BLE001 - a failing case is a result, recorded with its traceback
        return failed_row(case, "error", traceback.format_exc(), time.perf_counter() - start, worker_name())
    wall = time.perf_counter() - start
    return {"case_id": case.id, **case.inputs, **flatten(summary), "status": "done", "error": None,
            "wall_s": wall, "worker": worker_name(), "worker_max_rss_mb": max_rss_mb()}
