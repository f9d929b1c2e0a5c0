"""The latency budget (``moose budget``): for each of the paper's nine cases, the largest latency that can be added
to the run's timing on one path — the command path or the planning path — without changing the outcome.

Every point is a lockstep run of the combined planner exactly as ``moose reproduce`` runs it (the scenario file,
:data:`moose.reproduce.DURATION` after the obstacle appears, seed 0), with ``timing.command_delay_s`` or
``timing.planning_delay_s`` raised by a multiple of the resolution (the motion-control tick), once without and once
with ``timing.compensate``.  The budget of a (case, path, compensation) is the largest added latency L such that
every point from 0 to L has the reference outcome, the case's with no added latency and no compensation (so
compensation is held to the outcome of the uncompensated chain; "–" when compensation alone changes it).  A series
that keeps it over the whole range has a budget of at least the range (``≥``).  :func:`render_table` writes the
table docs/architecture.md carries, :func:`render_summary` the README's line, :func:`plot_budget` the figure of
clearance against added latency.
"""
from __future__ import annotations

import dataclasses
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Callable, Iterable, Optional, Sequence

from .schema import Config
from .timing import describe

PATHS = {"command": "command_delay_s", "planning": "planning_delay_s"}
"""The paths a latency is added to, and the delay of ``timing`` each one raises."""


@dataclasses.dataclass(frozen=True)
class Point:
    """One run: the case, the path, the latency added to it (s), compensation, and what came of it."""

    case: str
    path: str
    added_s: float
    compensate: bool
    outcome: str
    clearance_m: Optional[float]


@dataclasses.dataclass(frozen=True)
class Budget:
    """The budget of a (case, path, compensation)."""

    case: str
    path: str
    compensate: bool
    budget_s: Optional[float]
    """The largest added latency whose outcome, and every smaller one's, is the reference outcome (s); None when
    even no added latency changes it (compensation alone did)."""
    whole_range: bool
    """No point of the range changed the outcome: the budget is at least ``budget_s``."""
    outcome: str
    """The reference outcome: the case's with no added latency and no compensation."""
    first_change: Optional[str]
    """The outcome of the first point past the budget (None with ``whole_range``)."""


def run_point(config: Config, case: str, path: str, added_s: float, compensate: bool, duration: float) -> Point:
    """One lockstep run of ``case`` with ``added_s`` more latency on ``path``."""
    from .metrics import summarize
    from .scenario import load_scenario
    from .simulation import simulate

    timing = config.timing
    timing = dataclasses.replace(timing, compensate=compensate,
                                 **{PATHS[path]: round(getattr(timing, PATHS[path]) + added_s, 9)})
    scenario = dataclasses.replace(load_scenario(case), duration=duration)
    summary = summarize(simulate(dataclasses.replace(config, timing=timing), scenario, planner="combined"))
    return Point(case, path, added_s, compensate, summary["outcome"], summary["min_clearance_m"])


def _run(job: tuple[Config, str, str, float, bool, float]) -> Point:
    return run_point(*job)


def latencies(top_s: float, step_s: float) -> list[float]:
    """0, step, 2 step, … up to ``top_s`` (s), on the step's grid."""
    return [round(k * step_s, 9) for k in range(int(round(top_s / step_s)) + 1)]


def run_points(config: Config, cases: Sequence[str], added: Sequence[float], duration: float, workers: int = 1,
               progress: Optional[Callable[[int, int], None]] = None) -> list[Point]:
    """Every (case, path, added latency, compensation) point, in that order; ``workers`` processes."""
    jobs = [(config, case, path, a, compensate, duration) for case in cases for path in PATHS for compensate in
            (False, True) for a in added]
    points: list[Point] = []
    if workers <= 1:
        for job in jobs:
            points.append(_run(job))
            if progress is not None:
                progress(len(points), len(jobs))
        return points
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
        for point in pool.map(_run, jobs, chunksize=4):
            points.append(point)
            if progress is not None:
                progress(len(points), len(jobs))
    return points


def budgets(points: Iterable[Point]) -> list[Budget]:
    """The budget of every (case, path, compensation) of ``points``, against the outcome of the case's point with no
    added latency and no compensation (so compensation is held to the outcome of the uncompensated chain)."""
    groups: dict[tuple[str, str, bool], list[Point]] = {}
    for p in points:
        groups.setdefault((p.case, p.path, p.compensate), []).append(p)
    out = []
    for (case, path, compensate), series in groups.items():
        series = sorted(series, key=lambda p: p.added_s)
        reference = sorted(groups[(case, path, False)], key=lambda p: p.added_s)[0]
        if reference.added_s != 0.0 or series[0].added_s != 0.0:
            raise ValueError(f"{case} {path}: the latencies must start at 0")
        changed = next((i for i, p in enumerate(series) if p.outcome != reference.outcome), None)
        if changed is None:
            out.append(Budget(case, path, compensate, series[-1].added_s, True, reference.outcome, None))
        else:
            out.append(Budget(case, path, compensate, series[changed - 1].added_s if changed else None, False,
                              reference.outcome, series[changed].outcome))
    return out


def _ms(b: Budget) -> str:
    if b.budget_s is None:
        return "–"
    return f"{'≥ ' if b.whole_range else ''}{b.budget_s * 1e3:.0f}"


def _pick(found: Sequence[Budget], case: str, path: str, compensate: bool) -> Budget:
    return next(b for b in found if (b.case, b.path, b.compensate) == (case, path, compensate))


def render_table(found: Sequence[Budget], config: Config, step_s: float) -> str:
    """The budget table (markdown): one row per case, the budget on each path without and with compensation."""
    t = describe(config.timing)
    lines = [f"Added to the `{t['profile']}` timing (sensor {t['sensor_delay_s'] * 1e3:.0f} ms, planning "
             f"{t['planning_delay_s'] * 1e3:.0f} ms, command {t['command_delay_s'] * 1e3:.0f} ms), in steps of "
             f"{step_s * 1e3:.0f} ms; budget in ms (→ the outcome past it).",
             "",
             "| case | outcome | command path | command, compensated | planning path | planning, compensated |",
             "|---|---|---|---|---|---|"]
    for case in dict.fromkeys(b.case for b in found):
        cells = []
        for path in PATHS:
            for compensate in (False, True):
                b = _pick(found, case, path, compensate)
                cells.append(_ms(b) + (f" (→ {b.first_change})" if b.first_change else ""))
        lines.append(f"| {case} | {_pick(found, case, 'command', False).outcome} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def render_summary(found: Sequence[Budget], points: Sequence[Point], config: Config, case: str, step_s: float) -> str:
    """The README's line on ``case``'s budget."""
    t = describe(config.timing)
    chain = (t["sensor_delay_s"] + t["planning_delay_s"] + t["command_delay_s"]) * 1e3
    base = next(p for p in points if (p.case, p.path, p.compensate, p.added_s) == (case, "command", False, 0.0))
    clearance = "n/a" if base.clearance_m is None else f"{base.clearance_m:.2f} m"

    def budget(path: str, compensate: bool) -> str:
        b = _pick(found, case, path, compensate)
        if b.budget_s is None:
            return f"none (compensation alone makes it a {b.first_change})"
        return f"{_ms(b)} ms" + (f" (then {b.first_change})" if b.first_change else "")

    return (f"- Latency budget of the extreme case ({case}, combined planner, seed 0) on top of the `{t['profile']}` "
            f"timing\n  ({chain:.0f} ms from a sample to the actuators through a plan; {base.outcome}, clearance "
            f"{clearance}), in steps of {step_s * 1e3:.0f} ms:\n  **{budget('command', False)}** on the command path, "
            f"**{budget('planning', False)}** on the planning path;\n  with compensation {budget('command', True)} and "
            f"{budget('planning', True)}.")


def plot_budget(points: Sequence[Point], found: Sequence[Budget], path: str | Path) -> Path:
    """Clearance against added latency, one panel per case; each path without (solid) and with (dashed)
    compensation; a failing point is marked with a cross, each budget with a tick on the axis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(p.case for p in points))
    cols = 3
    rows = (len(cases) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False, sharex=True)
    colour = {"command": "tab:blue", "planning": "tab:orange"}
    for ax, case in zip(axes.flat, cases):
        for name in PATHS:
            for compensate in (False, True):
                series = sorted((p for p in points if (p.case, p.path, p.compensate) == (case, name, compensate)),
                                key=lambda p: p.added_s)
                x = [p.added_s * 1e3 for p in series]
                y = [p.clearance_m if p.clearance_m is not None else float("nan") for p in series]
                style = "--" if compensate else "-"
                label = f"{name}{', compensated' if compensate else ''}"
                ax.plot(x, y, style, color=colour[name], linewidth=1.2, label=label)
                b = _pick(found, case, name, compensate)
                bad = [(xi, yi) for xi, yi, p in zip(x, y, series) if p.outcome != b.outcome]
                if bad:
                    ax.plot(*zip(*bad), "x", color=colour[name], markersize=4)
                if b.budget_s is not None:
                    ax.plot([b.budget_s * 1e3], [0.0], "|", color=colour[name], markersize=12)
        ax.axhline(0.0, color="k", linewidth=0.8)
        ax.set_title(case, fontsize=9)
        ax.grid(True, alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("added latency (ms)")
    for ax in axes[:, 0]:
        ax.set_ylabel("min clearance (m)")
    for ax in list(axes.flat)[len(cases):]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
