"""The paper-style result figure (Figs. 7–9): path, steering and speed against x."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import Rectangle

from .simulation import SimulationResult
from .verdict import judge

OUTCOME_COLOUR = {"clear": "tab:green", "incomplete": "tab:gray", "stopped_short": "tab:orange"}
"""Colour of an outcome's label in the figure (failures red)."""


def plot_result(results: Sequence[SimulationResult], path: str | Path) -> Path:
    """Three panels: y–x path with the danger zone; δ_MPC and δ vs x; v_x,ref and v_x vs x.

    Several results (e.g. ``combined`` and ``mpc`` on one scenario, as Fig. 10)
    are overlaid; the obstacle of the first is drawn.  Each run's verdict (:func:`moose.verdict.judge`,
    from its true state) is written on the path panel, green when clear, red for a failure.
    """
    path = Path(path)
    fig, axes = plt.subplots(3, 1, figsize=(7.0, 8.0), sharex=True)
    scenario = results[0].scenario
    box = scenario.obstacle
    ax_path, ax_steer, ax_speed = axes
    ax_path.add_patch(
        Rectangle((box.x_min, box.y_min), box.x_max - box.x_min, box.y_max - box.y_min, color="tab:red", alpha=0.8)
    )
    for ax in axes:
        ax.axvline(0.5 * (box.x_min + box.x_max), color="k", linestyle="--", linewidth=0.8)
        ax.grid(True, alpha=0.3)
    verdicts = []
    for result in results:
        tr = result.trace
        label = result.planner
        verdict = judge(tr["t"], tr["x"], tr["y"], tr["theta"], tr["vx"], tr["vy"], scenario.danger_zone,
                        result.scenario.field, result.end_time, result.config.verdict)
        verdicts.append((label, verdict))
        ax_path.plot(tr["x"], tr["y"], label=f"{label}: {verdict.outcome.upper()}", linewidth=1.8)
        ax_steer.plot(tr["x"], tr["delta"], label=f"δ ({label})", linewidth=1.6)
        ax_steer.plot(tr["x"], tr["delta_mpc"], label=f"δ_MPC ({label})", linewidth=1.0, linestyle=":")
        ax_speed.plot(tr["x"], tr["vx_ref"], label=f"v_x,ref ({label})", linewidth=1.0, linestyle=":")
        ax_speed.plot(tr["x"], tr["vx"], label=f"v_x ({label})", linewidth=1.6)
    first = results[0].first_threat
    title = scenario.name
    if first is not None:
        title += f"   τ = {first.tau:.2f} s, ν = {first.nu:.2f}"
    ax_path.set_title(title)
    for i, (label, verdict) in enumerate(verdicts):  # the verdict of each run, in its colour, on the path panel
        ax_path.text(0.01, 0.95 - 0.1 * i, f"{label}: {verdict.outcome.upper()} — {verdict.reason}",
                     transform=ax_path.transAxes, fontsize=7, va="top",
                     color=OUTCOME_COLOUR.get(verdict.outcome, "tab:red"))
    ax_path.set_ylabel("y_ego (m)")
    ax_path.set_ylim(min(scenario.field.y_min, -5.0), max(scenario.field.y_max, 10.0))
    ax_steer.set_ylabel("δ (rad)")
    ax_steer.set_ylim(-0.35, 0.35)
    ax_speed.set_ylabel("v_x (m/s)")
    ax_speed.set_xlabel("x_ego (m)")
    x0 = float(results[0].trace["x"][0])
    ax_speed.set_xlim(x0, max(float(r.trace["x"][-1]) for r in results))
    for ax in axes:
        ax.legend(loc="best", fontsize=7, frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
