"""What a lockstep graph run must reproduce: ``moose simulate`` of the same scenario with the same configuration and
timing (issue 22: to 1 mm of clearance and 1e-3 in τ and ν), shared by the graph tests that check what a graph
computes (``moose launch --lockstep``, :mod:`moose_ros.lockstep`)."""
from __future__ import annotations

import copy
import functools
from typing import Any, Optional

import pytest

from moose.config import load_config, with_overrides
from moose.metrics import summarize
from moose.scenario import Scenario
from moose.simulation import simulate

CLEARANCE_TOLERANCE = 1e-3
"""m: the graph's minimum clearance against the loop's (the messages' nanosecond stamps against the loop's
k · Δt in floating point are the only difference on the topic graphs; measured 0.05 mm on the extreme case)."""
THREAT_TOLERANCE = 1e-3
"""τ (s) and ν against the loop's."""


def reference(scenario: Scenario, planner: str = "combined",
              settings: Optional[dict[str, Any]] = None) -> dict[str, Any]:
    """The summary of ``moose simulate`` for ``scenario`` (seed 0, the shipped configuration with ``settings``,
    ``GROUP.KEY: value`` as ``--set`` gives them), made once per test process for the same inputs (the graph tests
    of a file run in one worker; four of them compare with the extreme case's run)."""
    return copy.deepcopy(_reference(scenario, planner, tuple(sorted((settings or {}).items()))))


@functools.lru_cache(maxsize=None)
def _reference(scenario: Scenario, planner: str, settings: tuple[tuple[str, Any], ...]) -> dict[str, Any]:
    return summarize(simulate(with_overrides(load_config(), dict(settings)), scenario, planner))  # type: ignore[arg-type]


def assert_reproduces(summary: dict[str, Any], lockstep: dict[str, Any]) -> None:
    """The graph's summary is the loop's: outcome, clearance, τ, ν and the number of MPC solves."""
    assert summary["lockstep"] is True
    assert summary["outcome"] == lockstep["outcome"], (summary["reason"], lockstep["reason"])
    assert summary["collided"] is lockstep["collided"] and summary["left_field"] is lockstep["left_field"]
    assert summary["min_clearance_m"] == pytest.approx(lockstep["min_clearance_m"], abs=CLEARANCE_TOLERANCE)
    assert summary["tau_s"] == pytest.approx(lockstep["tau_s"], abs=THREAT_TOLERANCE)
    assert summary["nu"] == pytest.approx(lockstep["nu"], abs=THREAT_TOLERANCE)
    assert summary["mpc_solve_ms"]["count"] == lockstep["mpc_solve_ms"]["count"]
    assert summary["timing"] == lockstep["timing"]
