"""Run summary: did the car clear the danger zone, stay in the field, and at what cost."""
from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np

from .simulation import SimulationResult


def clearance_series(result: SimulationResult) -> np.ndarray:
    """Signed CoG clearance to the danger zone along the trace (m, negative inside)."""
    zone = result.scenario.danger_zone
    x, y = result.trace["x"], result.trace["y"]
    return np.array([zone.clearance(float(a), float(b)) for a, b in zip(x, y)])


def summarize(result: SimulationResult) -> dict[str, Any]:
    """The JSON summary of ``moose simulate`` (keys documented in the README)."""
    trace = result.trace
    scenario = result.scenario
    clearance = clearance_series(result)
    field = scenario.field
    inside = (
        (trace["x"] >= field.x_min) & (trace["x"] <= field.x_max)
        & (trace["y"] >= field.y_min) & (trace["y"] <= field.y_max)
    )
    solves = [r.mpc for r in result.planning if r.mpc is not None]
    solve_ms = np.array([s.solve_time_s * 1e3 for s in solves])
    threatened = [r.blend.weight_mpc for r in result.planning if r.threat is not None and np.isfinite(r.blend.weight_mpc)]
    first = result.first_threat
    return {
        "scenario": scenario.name,
        "planner": result.planner,
        "seed": result.seed,
        "collided": bool(np.any(clearance < 0.0)),
        "min_clearance_m": float(np.min(clearance)),
        "left_field": bool(not np.all(inside)),
        "max_abs_steer_rad": float(np.max(np.abs(trace["delta"]))),
        "max_lateral_offset_m": float(np.max(np.abs(trace["y"] - trace["y"][0]))),
        "final_lateral_offset_m": float(trace["y"][-1] - trace["y"][0]),
        "min_speed_mps": float(np.min(trace["vx"])),
        "max_speed_mps": float(np.max(trace["vx"])),
        "tau_s": float(first.tau) if first is not None else None,
        "nu": float(first.nu) if first is not None else None,
        "w_m": float(first.w) if first is not None else None,
        "paper_nu": scenario.paper.nu,
        "mpc_solve_ms": {
            "median": float(np.median(solve_ms)) if solve_ms.size else None,
            "p95": float(np.percentile(solve_ms, 95)) if solve_ms.size else None,
            "max": float(np.max(solve_ms)) if solve_ms.size else None,
            "count": int(solve_ms.size),
        },
        "mpc_status_counts": dict(sorted(Counter(s.status for s in solves).items())),
        "mean_weight_mpc": float(np.mean(threatened)) if threatened else None,
        "duration_s": float(trace["t"][-1]),
    }
