"""Re-plan a bag open-loop: the planners on its recorded state and threats at its planning instants, compared
with what was recorded (``moose bag replan``), and the figure of the comparison.

Each planning instant runs the core's planning step (:class:`moose.planner.step.PlanningStep`), the code
the lockstep loop and the ``weight_fbl`` node run.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Optional

from moose.schema import PlannerMode

from ..graph import BLEND, PLAN_MPC, PLAN_MSF, STATE, THREAT
from ..interfaces import from_rosbags
from .errors import BagError
from .params import read_run_parameters
from .reader import BagReader, ReadReport


def replan(path: str | Path, config: Any = None, planner: Optional[PlannerMode] = None, v_des: Optional[float] = None,
           report: Optional[ReadReport] = None) -> dict[str, Any]:
    """Run the planners open-loop on a bag's recorded state/threat stream at its planning instants.

    Each instant (a recorded /planning/blend) gets the latest recorded estimate and threat;
    the MPC's initial guess is the *re-computed* previous blend, shifted.  ``config`` and ``planner``
    default to the run's, kept in the bag (:mod:`.params`); a bag without them gets the default
    configuration and the combined planner.  ``v_des`` defaults to the run's scenario (its approach speed
    until the first threat, then its v_des), without one to the speed at the first recorded estimate.
    Returns per-step rows (recorded vs re-computed first accelerations, weights, statuses) and a summary
    that says which parameters were used (``parameters``: ``given``, ``bag`` or ``default``).

    The bag must have /perception/state and /planning/blend, and each topic used must carry the graph's type
    (:class:`BagError` otherwise).  A recorded message that fails validation (:mod:`moose_ros.convert`) is
    skipped and counted in ``report`` and in the summary's ``invalid_messages``.
    """
    from moose.config import load_config
    from moose.planner.step import PlanningStep

    used = (STATE, THREAT, PLAN_MPC, PLAN_MSF, BLEND)
    reader = BagReader(path, report)
    try:
        reader.check([STATE.name, BLEND.name], {t.name: t.type for t in used})
        run = read_run_parameters(path)
        source = "given" if config is not None else ("bag" if run is not None else "default")
        config = config if config is not None else (run.config if run is not None else load_config())
        planner = planner or (run.planner if run is not None else "combined")
        step = PlanningStep(config, planner)
        result = _replan(reader, [t.name for t in used if t.name in reader.topics], step, planner, v_des,
                         run.scenario if run is not None and v_des is None else None)
    finally:
        reader.close()
    result["summary"].update({"parameters": source, "scenario": run.scenario.name if run is not None else None,
                              "road_mu": config.vehicle.mu})
    return result


def _replan(reader: BagReader, topics: list[str], step: Any, planner: str, v_des: Optional[float],
            scenario: Any) -> dict[str, Any]:
    import numpy as np

    from .. import convert as cv

    report = reader.report
    estimate = threat = None
    detected = False
    recorded_plans: dict[str, dict[float, Any]] = {"mpc": {}, "msf": {}}
    rows = []
    invalid = 0
    for m in reader.messages(topics):
        msg = from_rosbags(m.msg, m.type_name)
        try:
            if m.topic == STATE.name:
                estimate = cv.estimate_from_msg(msg)
                v_des = round(estimate.vx, 1) if v_des is None and scenario is None else v_des
            elif m.topic == THREAT.name:
                threat = cv.threat_from_msg(msg)
                detected = detected or threat is not None
            elif m.topic in (PLAN_MPC.name, PLAN_MSF.name):
                t, _, plan = cv.stamped_plan_from_msg(msg)
                recorded_plans["mpc" if m.topic == PLAN_MPC.name else "msf"][round(t, 6)] = plan
            else:
                cv.blend_from_msg(msg)
        except cv.InvalidMessage as exc:
            invalid += 1
            report.skip(m.topic, m.type_name, f"invalid: {exc}")
            continue
        if m.topic == BLEND.name and estimate is not None:
            t = cv.time_of(msg)
            speed = scenario.desired_speed(detected) if scenario is not None else v_des
            assert speed is not None  # without a scenario, v_des is set at the first estimate
            record = step.plan(t, estimate, threat, float(speed))
            blend, new_mpc = record.blend, record.mpc
            old_mpc = recorded_plans["mpc"].get(round(t, 6))
            rows.append({
                "t": t,
                "recorded_weight": msg.weight_mpc, "weight": blend.weight_mpc,
                "recorded_ax": msg.accel_x[0], "ax": float(blend.accel[0, 0]),
                "recorded_ay": msg.accel_y[0], "ay": float(blend.accel[0, 1]),
                "recorded_delta": msg.delta_ref, "delta": record.reference.delta,
                "recorded_mpc_status": old_mpc.status if old_mpc is not None else "",
                "mpc_status": new_mpc.status if new_mpc is not None else "",
                "mpc_solve_ms": new_mpc.solve_time_s * 1e3 if new_mpc is not None else math.nan,
            })
    if not rows:
        raise BagError(f"bag {str(reader.path)!r} has no planning instants ({BLEND.name} with {STATE.name})")
    diff = lambda a, b: float(np.sqrt(np.mean([(r[a] - r[b]) ** 2 for r in rows])))  # noqa: E731
    same = [r for r in rows if r["recorded_mpc_status"]]
    summary = {
        "steps": len(rows), "planner": planner,
        "rms_ax": diff("recorded_ax", "ax"), "rms_ay": diff("recorded_ay", "ay"),
        "rms_weight": diff("recorded_weight", "weight"), "rms_delta": diff("recorded_delta", "delta"),
        "mpc_status_agreement": (sum(r["recorded_mpc_status"] == r["mpc_status"] for r in same) / len(same)
                                 if same else None),
        "invalid_messages": invalid,
    }
    return {"summary": summary, "rows": rows}


def plot_replan(rows: list[dict[str, Any]], path: str | Path) -> Path:
    """Recorded vs re-computed blend acceleration, weight and steering reference over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = [r["t"] for r in rows]
    fig, axes = plt.subplots(3, 1, figsize=(7.0, 7.0), sharex=True)
    for ax, (key, label) in zip(axes, (("ay", "v̇_Y* (m/s²)"), ("weight", "w_MPC"), ("delta", "δ* (rad)"))):
        ax.step(t, [r[f"recorded_{key}"] for r in rows], where="post", label="recorded")
        ax.step(t, [r[key] for r in rows], where="post", label="re-computed", linestyle="--")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, frameon=False)
    axes[-1].set_xlabel("t (s)")
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return Path(path)
