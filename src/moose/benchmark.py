"""The open benchmark (``moose benchmark``): every planner over the paper region at two frictions, and the leaderboard.

The cases are a sweep (:mod:`moose.sweep`) of :data:`AXES`: v 4–8 m/s × τ 1–5 s (0.5) × ν 0.1–1.0 (0.1) ×
μ ∈ {0.33 (the paper calibration), 0.8} × the planners (the paper's three and the baselines
:mod:`moose.planner.baseline`), seed 0, 8 s after the obstacle appears: 450 cells per friction and planner.  The
leaderboard (:func:`leaderboard`, one :class:`Entry` per friction and planner) holds:

* **envelope**: the share of the region inside the planner's safe envelope — at each speed and τ, the cells from
  the lowest ν up to the last before its first failure (ν is the paper's measure of criticality: a planner is
  safe up to some ν, and a safe cell above a failure is luck, not an envelope);
* **clear**: the share of cells whose outcome is ``clear`` (:mod:`moose.verdict`), anywhere;
* **no collision**: the share of cells without a collision (a stop before the obstacle, a loss of control or
  leaving the field after passing it count here, not in ``clear``);
* **mean clearance**: the mean of ``min_clearance_m`` over the clear cells (the margin a planner keeps when it
  passes; none without a clear cell);
* **worst sideslip**: the largest |β| of any cell (``max_abs_sideslip_rad``);
* **steering effort**: the mean total variation of δ after the detection (``steer_total_variation_rad``).

A cell whose case did not finish (``error``, ``timeout``, ``crashed``) counts as neither clear nor collision-free,
and the leaderboard says how many there were.
"""
from __future__ import annotations

import dataclasses
import math
from collections import defaultdict
from pathlib import Path
from typing import Any, Optional, Sequence

from .schema import PLANNER_MODES

AXES: dict[str, str] = {"speed": "4:8:1", "tau": "1:5:0.5", "nu": "0.1:1.0:0.1", "mu": "paper,0.8",
                        "planner": ",".join(PLANNER_MODES)}
"""The benchmark's sweep, as ``moose sweep`` flags (the paper region of docs/maps.md, every planner)."""

HEADER = ("μ", "planner", "envelope (%)", "clear (%)", "no collision (%)", "mean clearance (m)",
          "worst sideslip (rad)", "steering effort (rad)", "cells")


@dataclasses.dataclass(frozen=True)
class Entry:
    """One planner at one friction."""

    mu: float
    planner: str
    cells: int
    unfinished: int
    """Cells whose case ended in error, timeout or crashed."""
    envelope: float
    """Share of the cells inside the safe envelope (0..1)."""
    clear: float
    no_collision: float
    mean_clearance_m: Optional[float]
    worst_sideslip_rad: Optional[float]
    steering_effort_rad: Optional[float]
    envelope_nu: dict[tuple[float, float], float]
    """(speed, τ) → the largest ν of the envelope there (0 when the lowest ν already fails)."""


def _mean(values: Sequence[float]) -> Optional[float]:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return sum(finite) / len(finite) if finite else None


def leaderboard(rows: Sequence[dict[str, Any]]) -> list[Entry]:
    """The leaderboard of a benchmark's rows (a sweep's, :meth:`moose.sweep.store.RunFolder.rows`): per friction, the
    planners ordered by envelope, then clear share."""
    groups: dict[tuple[float, str], list[dict[str, Any]]] = defaultdict(list)
    for row in rows:
        groups[(float(row["input.mu"]), str(row["input.planner"]))].append(row)
    entries = []
    for (mu, planner), group in groups.items():
        done = [r for r in group if r["status"] == "done"]
        clear = [r for r in done if r["outcome"] == "clear"]
        columns: dict[tuple[float, float], list[tuple[float, bool]]] = defaultdict(list)
        for r in group:
            safe = r["status"] == "done" and r["outcome"] == "clear"
            columns[(float(r["input.speed_mps"]), float(r["input.tau_s"]))].append((float(r["input.nu"]), safe))
        inside, reach = 0, {}
        for key, cells in columns.items():
            nu_max = 0.0
            for nu, safe in sorted(cells):
                if not safe:
                    break
                inside, nu_max = inside + 1, nu
            reach[key] = nu_max
        sideslips = [r["max_abs_sideslip_rad"] for r in done if r.get("max_abs_sideslip_rad") is not None]
        entries.append(Entry(
            mu=mu, planner=planner, cells=len(group), unfinished=len(group) - len(done),
            envelope=inside / len(group), clear=len(clear) / len(group),
            no_collision=sum(r["outcome"] != "collision" for r in done) / len(group),
            mean_clearance_m=_mean([r["min_clearance_m"] for r in clear]),
            worst_sideslip_rad=max(sideslips) if sideslips else None,
            steering_effort_rad=_mean([r["steer_total_variation_rad"] for r in done]),
            envelope_nu=reach))
    return sorted(entries, key=lambda e: (e.mu, -e.envelope, -e.clear, e.planner))


def _fmt(value: Optional[float], spec: str) -> str:
    return "–" if value is None else format(value, spec)


def render_leaderboard(entries: Sequence[Entry]) -> str:
    """The leaderboard as a markdown table (generated: README.md's ``leaderboard`` block)."""
    lines = ["| " + " | ".join(HEADER) + " |", "|" + "---|" * len(HEADER)]
    for e in entries:
        cells = f"{e.cells}" + (f" ({e.unfinished} unfinished)" if e.unfinished else "")
        lines.append("| " + " | ".join([
            f"{e.mu:g}", e.planner, f"{100 * e.envelope:.1f}", f"{100 * e.clear:.1f}", f"{100 * e.no_collision:.1f}",
            _fmt(e.mean_clearance_m, ".2f"), _fmt(e.worst_sideslip_rad, ".2f"), _fmt(e.steering_effort_rad, ".2f"),
            cells]) + " |")
    return "\n".join(lines)


def plot_leaderboard(entries: Sequence[Entry], path: Path) -> Path:
    """The leaderboard's figure: per friction, each planner's safe envelope over τ (the largest safe ν, mean over the
    speeds) and its shares of clear and collision-free cells."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .sweep.maps import PLANNER_STYLE

    mus = sorted({e.mu for e in entries})
    fig, axes = plt.subplots(2, len(mus), figsize=(5.2 * len(mus), 7.4), squeeze=False, layout="constrained")
    for j, mu in enumerate(mus):
        here = [e for e in entries if e.mu == mu]
        top, bottom = axes[0, j], axes[1, j]
        for e in here:
            taus = sorted({tau for _, tau in e.envelope_nu})
            mean = [np.mean([nu for (v, t), nu in e.envelope_nu.items() if t == tau]) for tau in taus]
            colour, style = PLANNER_STYLE.get(e.planner, ("k", "-"))
            top.plot(taus, mean, color=colour, linestyle=style, marker="o", markersize=3, label=e.planner)
        top.set(title=f"μ = {mu:g}: safe envelope", xlabel="τ (s)", ylabel="largest safe ν (mean over v 4–8 m/s)",
                ylim=(0.0, 1.05))
        top.grid(alpha=0.3)
        top.legend(fontsize=8)
        x = np.arange(len(here))
        bottom.bar(x - 0.2, [100 * e.clear for e in here], 0.4, label="clear", color="#2ca02c")
        bottom.bar(x + 0.2, [100 * e.no_collision for e in here], 0.4, label="no collision", color="#9ecae1")
        bottom.set_xticks(x, [e.planner for e in here], fontsize=8)
        bottom.set(title=f"μ = {mu:g}: cells of the region", ylabel="%", ylim=(0, 100))
        bottom.legend(fontsize=8)
    fig.suptitle("moose benchmark: every planner over the paper region (v 4–8 m/s, τ 1–5 s, ν 0.1–1.0)", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
