"""The generated tables of docs/results.md and docs/modelling.md and the README's summary, and the blocks that hold
them.

:func:`render_conditions`, :func:`render_results`, :func:`render_summary` and :func:`render_calibration` write
what docs/results.md, docs/modelling.md and README.md carry between ``<!-- BEGIN name -->`` / ``<!-- END name -->``
markers (:func:`update_document`); the claims and the variants tables are
:func:`moose.reproduce.claims.render_claims` and :func:`moose.reproduce.variants.render_variants`.  They are
generated, never edited by hand.
"""
from __future__ import annotations

import re
from collections import Counter
from pathlib import Path
from typing import Any, Iterable, Optional, Sequence

from ..paper import PAPER_FRICTION
from ..schema import PlannerMode
from .claims import Claim
from .runs import COMPARISON, EXTREME, NINE, PAPER_SOLVER, RELAXED_5, SIX, Run, RunCache

RESULT_RUNS: tuple[tuple[PlannerMode, Optional[str]], ...] = (
    ("combined", None), ("combined", PAPER_SOLVER), ("msf", None), ("mpc", PAPER_SOLVER), ("mpc", None))
"""(planner, MPC solver) of each scenario in the results table: None = the configured (fast) solver."""


def result_runs(cache: RunCache, scenarios: Sequence[str] = NINE + COMPARISON, mu: float = PAPER_FRICTION,
                planners: Sequence[PlannerMode] = ()) -> list[Run]:
    """Every scenario with every planner of :data:`RESULT_RUNS` on the road ``mu``, and then with each of ``planners``
    that :data:`RESULT_RUNS` does not hold (the baselines: rows of the results, no claim)."""
    extra = [(p, None) for p in dict.fromkeys(planners) if p not in {planner for planner, _ in RESULT_RUNS}]
    return [cache.run(name, planner, mu, (("mpc.solver", solver),) if solver is not None else ())
            for name in scenarios for planner, solver in (*RESULT_RUNS, *extra)]


def _fmt(value: Any, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


RESULT_COLUMNS = ("scenario", "planner", "ν paper / here", "τ (s)", "outcome", "clearance (m)", "max abs β (rad)",
                  "max abs y (m)", "final y (m)", "TV δ (rad)", "t at limit (s)", "max δ̇ (rad/s)",
                  "peak δ at x − x_far (m)", "v range (m/s)", "mean w_MPC", "MPC plans through y_safe")


def render_results(runs: Sequence[Run]) -> str:
    """The results table (markdown), one row per run; deterministic for a seed (solve times are in bench/)."""
    lines = ["| " + " | ".join(RESULT_COLUMNS) + " |", "|" + "---|" * len(RESULT_COLUMNS)]
    for r in runs:
        s, m = r.summary, r.measures
        lines.append("| " + " | ".join([
            r.scenario, r.label, f"{_fmt(s['paper_nu'])} / {_fmt(s['nu'])}", _fmt(s["tau_s"]), s["outcome"],
            _fmt(s["min_clearance_m"]), _fmt(s["max_abs_sideslip_rad"]), _fmt(s["max_lateral_offset_m"]),
            _fmt(s["final_lateral_offset_m"]), _fmt(s["steer_total_variation_rad"]),
            _fmt(s["time_at_steer_limit_s"], 1), _fmt(s["peak_steer_rate_rad_s"]), _fmt(s["x_peak_steer_m"], 1),
            f"{_fmt(s['min_speed_mps'])}–{_fmt(s['max_speed_mps'])}", _fmt(s["mean_weight_mpc"]),
            f"{m.barrier_violations} / {m.mpc_threat_plans}" if m.mpc_threat_plans else "–",
        ]) + " |")
    return "\n".join(lines)


def render_conditions(runs: Sequence[Run]) -> str:
    """What every run of the tables shares, from their summaries: the seed and the timing (which the claims, the
    results and the variants all depend on).  Runs that differ in either are an error, not a table."""
    seen = {(r.summary["seed"], tuple(sorted(r.summary["timing"].items()))) for r in runs}
    if len(seen) != 1:
        raise ValueError(f"the runs differ in seed or timing: {sorted(seen)}")
    seed, timing = next(iter(seen))
    t = dict(timing)
    return (f"Seed {seed}; timing `{t['profile']}`: sensor {1e3 * t['sensor_delay_s']:g} ms, planning "
            f"{1e3 * t['planning_delay_s']:g} ms, command {1e3 * t['command_delay_s']:g} ms, delay compensation "
            f"{'on' if t['compensate'] else 'off'}.")


def render_summary(runs: Sequence[Run], found: Sequence[Claim]) -> str:
    """The README's summary (markdown bullets): outcomes per planner, the extreme case, the blend's share and the
    MPC's plans through y_safe, and how many of the paper's claims hold on each road."""
    scenarios = sorted({r.scenario for r in runs})
    lines = [f"- {render_conditions(runs)}"]
    for label in dict.fromkeys(r.label for r in runs):
        counts = Counter(r.summary["outcome"] for r in runs if r.label == label)
        text = ", ".join(f"{n} {outcome}" for outcome, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))
        lines.append(f"- **{label}**: {text} (of {len(scenarios)} scenarios, μ = {runs[0].mu:g}).")
    extreme = [r for r in runs if r.scenario == EXTREME]
    if extreme:
        c = next(r for r in extreme if r.planner == "combined").summary
        alone = ", ".join(f"{r.summary['outcome']} ({r.solver}, {r.measures.barrier_violations} of "
                          f"{r.measures.mpc_threat_plans} plans through y_safe)" for r in extreme if r.planner == "mpc")
        lines.append(f"- Extreme case ({EXTREME}: τ = {c['tau_s']:.2f} s, ν = {c['nu']:.2f} here, "
                     f"{c['paper_nu']:.2f} in the paper), combined: {c['outcome']}, clearance "
                     f"{_fmt(c['min_clearance_m'])} m, max abs δ {c['max_abs_steer_rad']:.2f} rad, max abs β "
                     f"{c['max_abs_sideslip_rad']:.2f} rad, mean w_MPC {_fmt(c['mean_weight_mpc'])};\n  the MPC alone: "
                     f"{alone}.")
    relaxed = [r for r in runs if r.planner == "combined" and r.solver == runs[0].solver
               and r.scenario in RELAXED_5 + SIX]
    if relaxed:
        shares = [r.summary["mean_weight_mpc"] or 0.0 for r in relaxed]
        through = sum(r.measures.barrier_violations for r in relaxed)
        plans = sum(r.measures.mpc_threat_plans for r in relaxed)
        lines.append(f"- The combined planner in the 5 and 6 m/s cases: mean w_MPC {min(shares):.2f}–"
                     f"{max(shares):.2f}; {through} of its MPC's {plans} plans under the threat cross y_safe, the "
                     "paper's hand-over trigger.")
    for mu in (mu for mu, _ in found[0].verdicts) if found else ():
        held = sum(c.verdict(mu).holds for c in found)
        lines.append(f"- The paper's claims at μ = {mu:g}: {held} of {len(found)} hold, {len(found) - held} are "
                     "contradicted ([docs/results.md](docs/results.md#the-papers-claims-generated)).")
    return "\n".join(lines)


CALIBRATION_MU = (0.25, 0.30, PAPER_FRICTION, 0.35, 0.5, 0.8)
"""Frictions of the calibration table."""


def render_calibration(vehicle: Any) -> str:
    """How well eq. (ymax) at each μ of :data:`CALIBRATION_MU` reproduces the paper's fit and its nine ν."""
    from ..calibration import calibration_errors
    from ..paper import PAPER_EXPERIMENTS

    paper = " ".join(f"{e.nu:.2f}".lstrip("0") for e in PAPER_EXPERIMENTS)
    lines = [f"| μ | fit RMS (m) | ν RMS | ν of the nine cases (paper: {paper}) |", "|---|---|---|---|"]
    for mu in CALIBRATION_MU:
        e = calibration_errors(vehicle, mu)
        label = f"**{mu:.2f}** (`PAPER_FRICTION`)" if mu == PAPER_FRICTION else f"{mu:.2f}"
        nus = " ".join(f"{n:.2f}".lstrip("0") for n in e.nu)
        lines.append(f"| {label} | {e.fit_rms:.2f} | {e.nu_rms:.3f} | {nus} |")
    return "\n".join(lines)


def _pattern(name: str) -> re.Pattern[str]:
    return re.compile(rf"(<!-- BEGIN {re.escape(name)} -->\n).*?(<!-- END {re.escape(name)} -->)", re.S)


def blocks_in(path: Path, names: Iterable[str]) -> list[str]:
    """Which of the generated blocks ``names`` the file ``path`` holds."""
    text = path.read_text(encoding="utf-8")
    return [name for name in names if _pattern(name).search(text)]


def update_document(path: Path, blocks: dict[str, str]) -> None:
    """Replace each ``<!-- BEGIN name -->`` … ``<!-- END name -->`` block of ``path`` with its new text."""
    text = path.read_text(encoding="utf-8")
    for name, body in blocks.items():
        pattern = _pattern(name)
        if not pattern.search(text):
            raise ValueError(f"{path}: no '<!-- BEGIN {name} -->' ... '<!-- END {name} -->' block")

        def fill(m: re.Match[str], body: str = body) -> str:
            return m.group(1) + body.rstrip("\n") + "\n" + m.group(2)

        text = pattern.sub(fill, text)
    path.write_text(text, encoding="utf-8")
