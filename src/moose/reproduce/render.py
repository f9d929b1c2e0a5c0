"""``moose reproduce``: the paper's experiments and claims, re-run and judged by one command.

Every scenario of the paper runs at the calibrated friction with the combined planner, the MSF
planner alone and the MPC planner alone — the MPC once with the paper's baseline solver (fmincon's
SQP as Table II caps it) and once with the default fast solver.  Each claim of the paper is one
:class:`Claim`: what the paper says, the criterion it is held to here, whether it holds, and the
numbers.  :func:`render_results` and :func:`render_claims` write the tables that docs/design.md
carries, :func:`render_summary` the README's summary, between ``<!-- BEGIN name -->`` /
``<!-- END name -->`` markers (:func:`update_document`): they are generated, never edited by hand.
"""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Any, Callable, Iterable, Literal, Optional, Sequence, Union

from .metrics import summarize
from .paper import PAPER_FRICTION
from .params import ParamError
from .planner import MODE_PLANNERS
from .scenario import load_scenario
from .schema import Config, PlannerMode, SolverName
from .simulation import simulate
from .verdict import changed_limits, limits_of

NINE = ("paper_v5_tau5", "paper_v5_tau4", "paper_v5_tau3", "paper_v6_w2.0", "paper_v6_w2.4", "paper_v6_w3.2",
        "paper_v7_tau2.8", "paper_v7_tau2", "paper_v7_tau1.4")
"""The nine experiments of Figs. 5–7."""
COMPARISON = ("compare_nu0.26", "compare_nu0.34")
"""The MPC-versus-combined comparison of Fig. 8."""
RELAXED_5 = NINE[:3]
SIX = NINE[3:6]
SEVEN = NINE[6:]
EXTREME = "paper_v7_tau1.4"
PAPER_SOLVER: SolverName = "paper_sqp"
"""The MPC solver that behaves like the paper's fmincon SQP under Table II."""
RUNS: tuple[tuple[PlannerMode, Union[SolverName, Literal[""], None]], ...] = (
    ("combined", None), ("msf", None), ("mpc", PAPER_SOLVER), ("mpc", ""))
"""(planner, MPC solver) of each scenario: None = the configured one; "" = the configured (fast) solver, labelled."""
DURATION = 10.0
"""Simulated seconds after the obstacle appears: time to pass and return in every case."""
LOCK = 0.95
"""Share of δ_max that counts as steering at the limit."""


@dataclasses.dataclass(frozen=True)
class Run:
    """One simulated run and its summary."""

    scenario: str
    planner: str
    solver: str
    """The MPC solver (empty for a planner without the MPC: the MSF planner alone, a baseline)."""
    summary: dict[str, Any]

    @property
    def label(self) -> str:
        return self.planner if self.planner != "mpc" else f"mpc ({self.solver})"


@dataclasses.dataclass(frozen=True)
class Claim:
    """A claim of the paper, held to a criterion by the runs."""

    where: str
    paper: str
    criterion: str
    holds: bool
    evidence: str


def run_all(config: Config, scenarios: Sequence[str] = NINE + COMPARISON, seed: int = 0,
            progress: Optional[Callable[[str], None]] = None, planners: Sequence[PlannerMode] = ()) -> list[Run]:
    """Every scenario with every planner of :data:`RUNS`, and then with each of ``planners`` that :data:`RUNS` does
    not hold (the baselines: rows of the results, no claim), at the scenario's friction (the calibrated one).

    The claims are judged with the default verdict limits: a configuration with others is a
    :class:`~moose.params.ParamError` naming them, before any run."""
    changed = changed_limits(limits_of(config.verdict))
    if changed:
        raise ParamError(f"verdict: {changed}: the paper's claims are judged with the default verdict limits")
    runs = []
    extra = [(p, None) for p in dict.fromkeys(planners) if p not in {planner for planner, _ in RUNS}]
    for name in scenarios:
        scenario = dataclasses.replace(load_scenario(name), duration=DURATION)
        for planner, solver in (*RUNS, *extra):
            cfg = config
            if planner == "mpc" and solver:
                cfg = dataclasses.replace(config, mpc=dataclasses.replace(config.mpc, solver=solver))
            label_solver = cfg.mpc.solver if "mpc" in MODE_PLANNERS[planner] else ""
            if progress is not None:
                progress(f"{name} {planner} {label_solver}")
            summary = summarize(simulate(cfg, scenario, planner=planner, seed=seed))
            runs.append(Run(name, planner, label_solver, summary))
    return runs


def _pick(runs: Iterable[Run], scenario: str, planner: str, solver: Optional[str] = None) -> Run:
    for r in runs:
        if r.scenario == scenario and r.planner == planner and (solver is None or r.solver == solver):
            return r
    raise KeyError(f"no run of {scenario} with {planner} {solver or ''}")


def _fmt(value: Any, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def claims(runs: Sequence[Run], fast_solver: str, delta_max: float) -> list[Claim]:
    """The paper's claims, each judged by a stated criterion on ``runs``."""
    out: list[Claim] = []

    def combined(name: str) -> dict[str, Any]:
        return _pick(runs, name, "combined").summary

    def mpc(name: str, solver: str) -> dict[str, Any]:
        return _pick(runs, name, "mpc", solver).summary

    # ν labels
    errors = {n: abs(combined(n)["nu"] - combined(n)["paper_nu"]) for n in NINE}
    worst = max(errors, key=errors.__getitem__)
    out.append(Claim("Figs. 5–7", "ν of the nine experiments as printed",
                     f"abs(ν − ν_paper) ≤ 0.07 at μ = {PAPER_FRICTION} (the calibration)", max(errors.values()) <= 0.07,
                     f"worst {errors[worst]:.3f} ({worst})"))
    # relaxed cases
    ok = [combined(n) for n in RELAXED_5]
    speeds_ok = all(s["outcome"] == "clear" and 0.85 * 5.0 <= s["min_speed_mps"] and s["max_speed_mps"] <= 1.15 * 5.0
                    for s in ok)
    out.append(Claim("Sec. VI-A", "5 m/s: safe avoidance keeping the velocity close to the desired value",
                     "combined clear, speed within ±15 % of 5 m/s", speeds_ok,
                     "; ".join(f"{s['outcome']} {s['min_speed_mps']:.2f}–{s['max_speed_mps']:.2f} m/s" for s in ok)))
    after = [s["x_peak_steer_m"] for s in ok]
    out.append(Claim("Sec. VI-A", "5 m/s: the combined planner's maximum steering occurs after passing the obstacle",
                     "x of max abs δ after detection beyond the zone's far edge",
                     all(a is not None and a > 0 for a in after),
                     "x − x_far = " + ", ".join(_fmt(a, 1) + " m" for a in after)))
    for solver in (PAPER_SOLVER, fast_solver):
        pairs = [(combined(n), mpc(n, solver)) for n in RELAXED_5 + SIX]
        smoother = all(c["time_at_steer_limit_s"] <= m["time_at_steer_limit_s"]
                       and c["steer_total_variation_rad"] < m["steer_total_variation_rad"] for c, m in pairs)
        out.append(Claim("Observation 1", "MPC close to the steering bounds; the combined strategy smoother",
                         f"5 and 6 m/s, MPC {solver}: combined has less steering variation and no more time at "
                         "the limit",
                         smoother, "TV combined/MPC " + ", ".join(
                             f"{c['steer_total_variation_rad']:.2f}/{m['steer_total_variation_rad']:.2f}"
                             for c, m in pairs)))
    # 6 m/s
    for solver in (PAPER_SOLVER, fast_solver):
        rows = [(combined(n), mpc(n, solver)) for n in SIX]
        holds = all(c["outcome"] == "clear" and c["max_abs_steer_rad"] < LOCK * delta_max <= m["max_abs_steer_rad"]
                    for c, m in rows)
        out.append(Claim("Sec. VI-B", "6 m/s: MPC overreacts; combined avoids without an extreme steering command",
                         f"MPC {solver} reaches the steering limit, combined clear below it", holds,
                         "; ".join(f"max abs δ {c['max_abs_steer_rad']:.2f}/{m['max_abs_steer_rad']:.2f} "
                                   f"({c['outcome']})" for c, m in rows)))
    s = combined("paper_v6_w3.2")
    out.append(Claim("Sec. VI-B", "4.5 m/s detection: the planners increase the longitudinal velocity",
                     "combined's top speed after detection ≥ speed at detection + 0.2 m/s",
                     s["max_speed_mps"] >= s["v_detect_mps"] + 0.2,
                     f"{s['v_detect_mps']:.2f} → max {s['max_speed_mps']:.2f} m/s"))
    rises = [(combined(n)["v_detect_mps"], combined(n)["max_speed_mps"]) for n in SEVEN]
    out.append(Claim("Observation 3", "7 m/s: the planners increase the longitudinal velocity",
                     "combined's top speed ≥ speed at detection + 0.2 m/s in all three",
                     all(vmax >= v0 + 0.2 for v0, vmax in rises),
                     ", ".join(f"{v0:.2f} → {vmax:.2f}" for v0, vmax in rises)))
    # the extreme case
    c = combined(EXTREME)
    for solver in (PAPER_SOLVER, fast_solver):
        m = mpc(EXTREME, solver)
        out.append(Claim("Sec. VI-C", "τ = 1.4 s: the MPC cannot find a feasible solution and collides",
                         f"MPC {solver} alone: collision", m["outcome"] == "collision",
                         f"{m['outcome']}, clearance {_fmt(m['min_clearance_m'])} m"))
    out.append(Claim("Sec. VI-C", "τ = 1.4 s: the MSF's solution close to the steering limits avoids the collision",
                     "combined clear with max abs δ ≥ 0.9 δ_max",
                     c["outcome"] == "clear" and c["max_abs_steer_rad"] >= 0.9 * delta_max,
                     f"{c['outcome']}, clearance {_fmt(c['min_clearance_m'])} m, "
                     f"max abs δ {c['max_abs_steer_rad']:.2f} rad"))
    out.append(Claim("Sec. IV (weight)", "τ = 1.4 s: the weight function hands the maneuver to the MSF planner",
                     "combined's mean w_MPC under the threat < 0.1", (c["mean_weight_mpc"] or 0.0) < 0.1,
                     f"mean w_MPC {_fmt(c['mean_weight_mpc'], 3)}"))
    # the blend where the MPC is usable
    shares = {n: combined(n)["mean_weight_mpc"] for n in RELAXED_5 + SIX}
    out.append(Claim("Sec. IV (weight)", "relaxed cases: the MPC's solution carries a share of the blend",
                     "combined's mean w_MPC under the threat ≥ 0.3 at 5 and 6 m/s",
                     all((w or 0.0) >= 0.3 for w in shares.values()),
                     ", ".join(f"{_fmt(w)}" for w in shares.values())))
    # the comparison
    for solver in (PAPER_SOLVER, fast_solver):
        rows = [(combined(n), mpc(n, solver)) for n in COMPARISON]
        holds = all(c["outcome"] == "clear" and m["max_abs_steer_rad"] >= LOCK * delta_max
                    and (m["outcome"] in ("left_field", "collision", "lost_control")
                         or m["max_lateral_offset_m"] > c["max_lateral_offset_m"]) for c, m in rows)
        out.append(Claim("Fig. 8", "MPC overreacts with extreme steering; combined avoids inside the field",
                         f"MPC {solver} at the steering limit and out further than combined (or failed); "
                         "combined clear",
                         holds, "; ".join(f"combined {c['outcome']} {_fmt(c['max_lateral_offset_m'])} m, MPC "
                                          f"{m['outcome']} {_fmt(m['max_lateral_offset_m'])} m" for c, m in rows)))
    return out


RESULT_COLUMNS = ("scenario", "planner", "ν paper / here", "τ (s)", "outcome", "clearance (m)", "max abs β (rad)",
                  "max abs y (m)", "final y (m)", "TV δ (rad)", "t at limit (s)", "max δ̇ (rad/s)",
                  "peak δ at x − x_far (m)", "v range (m/s)", "mean w_MPC")


def render_results(runs: Sequence[Run]) -> str:
    """The results table (markdown), one row per run; deterministic for a seed (solve times are in bench/)."""
    lines = ["| " + " | ".join(RESULT_COLUMNS) + " |", "|" + "---|" * len(RESULT_COLUMNS)]
    for r in runs:
        s = r.summary
        lines.append("| " + " | ".join([
            r.scenario, r.label, f"{_fmt(s['paper_nu'])} / {_fmt(s['nu'])}", _fmt(s["tau_s"]), s["outcome"],
            _fmt(s["min_clearance_m"]), _fmt(s["max_abs_sideslip_rad"]), _fmt(s["max_lateral_offset_m"]),
            _fmt(s["final_lateral_offset_m"]), _fmt(s["steer_total_variation_rad"]),
            _fmt(s["time_at_steer_limit_s"], 1), _fmt(s["peak_steer_rate_rad_s"]), _fmt(s["x_peak_steer_m"], 1),
            f"{_fmt(s['min_speed_mps'])}–{_fmt(s['max_speed_mps'])}", _fmt(s["mean_weight_mpc"]),
        ]) + " |")
    return "\n".join(lines)


def render_claims(found: Sequence[Claim]) -> str:
    """The claims table (markdown)."""
    lines = ["| where | the paper | criterion here | verdict | numbers |", "|---|---|---|---|---|"]
    for c in found:
        verdict = "holds" if c.holds else "**contradicted**"
        lines.append(f"| {c.where} | {c.paper} | {c.criterion} | {verdict} | {c.evidence} |")
    return "\n".join(lines)


def render_summary(runs: Sequence[Run], found: Sequence[Claim]) -> str:
    """The README's summary of the runs (markdown bullets): outcomes per planner, the extreme case, the blend's
    share, and how many of the paper's claims hold."""
    from collections import Counter

    scenarios = sorted({r.scenario for r in runs})
    lines = []
    for label in dict.fromkeys(r.label for r in runs):
        counts = Counter(r.summary["outcome"] for r in runs if r.label == label)
        text = ", ".join(f"{n} {outcome}" for outcome, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])))
        lines.append(f"- **{label}**: {text} (of {len(scenarios)} scenarios).")
    if any(r.scenario == EXTREME for r in runs):
        c = _pick(runs, EXTREME, "combined").summary
        alone = ", ".join(f"{r.summary['outcome']} ({r.solver})" for r in runs
                          if r.scenario == EXTREME and r.planner == "mpc")
        lines.append(f"- Extreme case ({EXTREME}: τ = {c['tau_s']:.2f} s, ν = {c['nu']:.2f} here, "
                     f"{c['paper_nu']:.2f} in the paper), combined: {c['outcome']}, clearance "
                     f"{_fmt(c['min_clearance_m'])} m, max abs δ {c['max_abs_steer_rad']:.2f} rad, max abs β "
                     f"{c['max_abs_sideslip_rad']:.2f} rad, mean w_MPC {_fmt(c['mean_weight_mpc'])}; the MPC alone: "
                     f"{alone} (the paper: a collision).")
    shares = [r.summary["mean_weight_mpc"] or 0.0 for r in runs
              if r.label == "combined" and r.scenario in RELAXED_5 + SIX]
    if shares:
        lines.append(f"- Mean w_MPC of the combined planner in the relaxed 5 and 6 m/s cases: {min(shares):.2f}–"
                     f"{max(shares):.2f}: the blend is the MSF planner's almost throughout.")
    held = sum(c.holds for c in found)
    lines.append(f"- The paper's claims: {held} of {len(found)} hold, {len(found) - held} are contradicted "
                 "(docs/design.md, \"The paper's claims\").")
    return "\n".join(lines)


CALIBRATION_MU = (0.25, 0.30, PAPER_FRICTION, 0.35, 0.5, 0.8)
"""Frictions of the calibration table."""


def render_calibration(vehicle: Any) -> str:
    """How well eq. (ymax) at each μ of :data:`CALIBRATION_MU` reproduces the paper's fit and its nine ν."""
    from .calibration import calibration_errors
    from .paper import PAPER_EXPERIMENTS

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
