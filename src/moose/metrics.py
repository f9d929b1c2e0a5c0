"""The run summary of ``moose simulate`` and ``moose launch``: the verdict and what the run cost.

Every field is computed from the run's recorded data: the outcome from the true state alone
(:func:`moose.verdict.judge`), the threat as the detector measured it at detection, the planners'
statuses and weights from the planning log.  The summary is JSON-safe: a quantity that is not a
finite number is ``null``, and ``notes`` says why.
"""
from __future__ import annotations

from collections import Counter
from typing import Any, Optional

import numpy as np

from .commonroad.assess import assess
from .simulation import SimulationResult
from .timing import describe
from .verdict import DEFAULT_PARAMS, finite_or_none, judge, limits_of


def smoothness(t: np.ndarray, delta: np.ndarray, delta_max: float, t_from: float) -> dict[str, Optional[float]]:
    """Steering smoothness from ``t_from`` on: total variation of δ (rad), time at the steering limit
    (|δ| within 1 mrad of δ_max, s) and the peak steering rate (rad/s)."""
    keep = (t >= t_from) & np.isfinite(delta)
    t, delta = t[keep], delta[keep]
    if t.size < 2:
        return {"steer_total_variation_rad": None, "time_at_steer_limit_s": None, "peak_steer_rate_rad_s": None}
    step = np.diff(delta)
    dt = np.diff(t)
    at_limit = np.abs(delta[:-1]) >= delta_max - 1e-3
    return {
        "steer_total_variation_rad": float(np.sum(np.abs(step))),
        "time_at_steer_limit_s": float(np.sum(dt[at_limit])),
        "peak_steer_rate_rad_s": float(np.max(np.abs(step) / np.maximum(dt, 1e-12))),
    }


def summarize(result: SimulationResult, criticality: bool = False) -> dict[str, Any]:
    """The JSON summary of a run (keys documented in the README).

    With the CommonRoad packages installed it carries the drivability checker's verdict beside ours
    (``commonroad_verdict``, :func:`moose.commonroad.assess.assess`) and, with ``criticality``, commonroad-crime's
    measures of the situation (``criticality``: seconds of computation, so only when asked)."""
    trace, scenario, config = result.trace, result.scenario, result.config
    zone = scenario.danger_zone
    verdict = judge(trace["t"], trace["x"], trace["y"], trace["theta"], trace["vx"], trace["vy"], zone,
                    scenario.field, result.end_time, config.verdict)
    notes: dict[str, str] = {}
    first = result.first_threat
    solves = [r.mpc for r in result.planning if r.mpc is not None]
    solve_ms = np.array([s.solve_time_s * 1e3 for s in solves])
    threatened = [r.blend.weight_mpc for r in result.planning
                  if r.threat is not None and np.isfinite(r.blend.weight_mpc)]
    t, x, y, delta = trace["t"], trace["x"], trace["y"], trace["delta"]
    finite = np.isfinite(x) & np.isfinite(y)
    summary: dict[str, Any] = {
        "scenario": scenario.name,
        "planner": result.planner,
        "seed": result.seed,
        "outcome": verdict.outcome,
        "reason": verdict.reason,
        "collided": verdict.collided,
        "lost_control": verdict.lost_control,
        "left_field": verdict.left_field,
        "complete": verdict.complete,
        "passed_obstacle": verdict.passed_obstacle,
        "min_clearance_m": verdict.min_clearance_m,
        "max_abs_sideslip_rad": verdict.max_abs_sideslip_rad,
        "max_abs_heading_rad": verdict.max_abs_heading_rad,
        "verdict_limits": limits_of(config.verdict),
        "verdict_limits_default": config.verdict == DEFAULT_PARAMS,
        "mu": config.vehicle.mu,
        "mu_planning": config.mu_planning,
        "timing": describe(config.timing),
        "tau_scenario_s": scenario.tau,
        "tau_s": first.tau if first is not None else None,
        "nu": first.nu if first is not None else None,
        "w_m": first.w if first is not None else None,
        "v_detect_mps": None,
        "paper_nu": scenario.paper.nu,
        "max_abs_steer_rad": float(np.nanmax(np.abs(delta))) if np.any(np.isfinite(delta)) else None,
        "x_peak_steer_m": None,
        "max_lateral_offset_m": float(np.max(np.abs(y[finite] - y[finite][0]))) if np.any(finite) else None,
        "final_lateral_offset_m": float(y[finite][-1] - y[finite][0]) if np.any(finite) else None,
        "min_speed_mps": float(np.nanmin(trace["vx"])) if np.any(np.isfinite(trace["vx"])) else None,
        "max_speed_mps": float(np.nanmax(trace["vx"])) if np.any(np.isfinite(trace["vx"])) else None,
        "mpc_solve_ms": {
            "median": float(np.median(solve_ms)) if solve_ms.size else None,
            "p95": float(np.percentile(solve_ms, 95)) if solve_ms.size else None,
            "max": float(np.max(solve_ms)) if solve_ms.size else None,
            "count": int(solve_ms.size),
        },
        "mpc_status_counts": dict(sorted(Counter(s.status for s in solves).items())),
        "mean_weight_mpc": float(np.mean(threatened)) if threatened else None,
        "duration_s": float(t[-1]) if t.size else None,
    }
    summary["commonroad_verdict"], summary["criticality"], commonroad_notes = assess(result, verdict, criticality)
    notes.update(commonroad_notes)
    if first is not None:
        after = np.flatnonzero(t >= first.t)
        if after.size:
            summary["v_detect_mps"] = float(trace["vx"][after[0]])
        summary.update(smoothness(t, delta, config.vehicle.delta_max, first.t))
        window = after[np.isfinite(delta[after])]
        if window.size:
            # where the steering peaks after detection, relative to the zone's far edge (the paper: after passing)
            summary["x_peak_steer_m"] = float(x[window[np.argmax(np.abs(delta[window]))]] - zone.x_max)
    else:
        summary.update(smoothness(t, delta, config.vehicle.delta_max, np.inf))
        notes["tau_s"] = notes["nu"] = "no obstacle was detected"
    if first is not None and not np.isfinite(first.nu):
        notes["nu"] = ("no lateral displacement is possible before the obstacle (τ ≤ 0 or v_x ≤ 0)"
                       if first.nu > 0 else "not a number")
    if first is not None and not np.isfinite(first.tau):
        notes["tau_s"] = "the car was not closing in on the obstacle (v_x ≤ 0)"
    if not threatened:
        any_threat = any(r.threat is not None for r in result.planning)
        notes["mean_weight_mpc"] = ("no planning step had a threat" if not any_threat
                                    else "no planning step with a threat recorded a weight")
    summary = _json_safe(summary, notes)
    summary["notes"] = notes
    return summary


def _json_safe(value: Any, notes: dict[str, str], key: str = "") -> Any:
    """``value`` with every non-finite float replaced by None (and a note, unless one explains it already)."""
    if isinstance(value, dict):
        return {k: _json_safe(v, notes, k) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v, notes, key) for v in value]
    if isinstance(value, (float, np.floating)):
        safe = finite_or_none(float(value))
        if safe is None:
            notes.setdefault(key, f"not a finite number ({float(value)!r})")
        return safe
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    return value
