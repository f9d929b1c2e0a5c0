"""The runs of ``moose reproduce``, each made once, and what the claims read from a run besides its summary.

:class:`RunCache` runs a paper scenario with a planner, a road μ (the stack's planning μ is the road's) and
parameter settings on demand, and keeps each run's summary and :class:`Measures`; a second request for the
same run — the claims, Observation 2, the variants table and the results table ask for many of the same —
is answered from the cache.  Two scenarios that differ only in name (the comparison cases of Fig. 10 are
the 6 m/s cases of Fig. 8) are one run.  A command holds one cache, and so does a test session.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable, Optional

import numpy as np

from ..config import with_overrides
from ..metrics import summarize
from ..paper import PAPER_FRICTION
from ..params import ParamError
from ..planner import MODE_PLANNERS
from ..scenario import PaperReference, Scenario, load_scenario
from ..schema import Config, PlannerMode
from ..simulation import SimulationResult, simulate
from ..verdict import changed_limits, limits_of

NINE = ("paper_v5_tau5", "paper_v5_tau4", "paper_v5_tau3", "paper_v6_w2.0", "paper_v6_w2.4", "paper_v6_w3.2",
        "paper_v7_tau2.8", "paper_v7_tau2", "paper_v7_tau1.4")
"""The nine experiments of Figs. 7–9."""
COMPARISON = ("compare_nu0.26", "compare_nu0.34")
"""The MPC-versus-combined comparison of Fig. 10."""
RELAXED_5 = NINE[:3]
SIX = NINE[3:6]
SEVEN = NINE[6:]
EXTREME = "paper_v7_tau1.4"
PAPER_SOLVER = "paper_sqp"
"""The MPC solver that behaves like the paper's fmincon SQP under Table II."""
MUS = (PAPER_FRICTION, 0.8)
"""The roads every claim is judged on (road and planning μ alike): the calibration that reproduces the paper's ν,
and dry asphalt."""
DURATION = 10.0
"""Simulated seconds after the obstacle appears: time to pass and return in every case."""
LOCK = 0.95
"""Share of δ_max that counts as steering at (close to) the limit."""
RETURN_BAND = 0.25
"""How close to its initial lateral position (m) the car counts as returned (Observation 2)."""

Settings = tuple[tuple[str, Any], ...]
"""Dotted parameter settings of a run (``(("mpc.solver", "paper_sqp"),)``), applied with
:func:`moose.config.with_overrides`."""


@dataclasses.dataclass(frozen=True)
class Measures:
    """What the claims read from a run besides its summary (None where the run gives no such quantity).

    "Steering command" is the FBL's δ* (the motion controller's reference; the paper's δ), δ_MPC the δ* the
    FBL computes for the MPC's own first acceleration at the same instant and estimate (the paper's δ_MPC)."""

    threat_plans: int
    """Planning instants under the threat."""
    mpc_near_limit: Optional[float]
    """Share of those instants with |δ_MPC| ≥ :data:`LOCK` δ_max (None without MPC plans)."""
    command_near_limit: Optional[float]
    """Share of those instants with |δ*| ≥ :data:`LOCK` δ_max."""
    mpc_variation: Optional[float]
    """Total variation of δ_MPC over those instants (rad)."""
    command_variation: Optional[float]
    """Total variation of δ* over those instants (rad)."""
    mpc_max: Optional[float]
    """Largest |δ_MPC| at those instants (rad)."""
    command_max_threat: Optional[float]
    """Largest |δ*| under the threat, at the motion-control rate (rad)."""
    x_peak_command: Optional[float]
    """x − x_far where |δ*| peaks after detection (m; positive: past the obstacle)."""
    speed_ref_max: Optional[float]
    """Largest speed reference v_x* after detection (m/s)."""
    speed_ref_band: float
    """Largest |v_x* − v_init| before detection: how far the reference strays without a threat (m/s)."""
    return_time: Optional[float]
    """Time from the CoG passing the zone's far edge until it is first within :data:`RETURN_BAND` of its initial
    lateral position (s); None if not within the run."""
    barrier_violations: int
    """MPC plans under the threat whose path crosses y_safe (status ``barrier_violated``)."""
    mpc_threat_plans: int
    """MPC plans under the threat."""


def _variation(values: np.ndarray) -> Optional[float]:
    return float(np.sum(np.abs(np.diff(values)))) if values.size else None


def _share(values: np.ndarray, limit: float) -> Optional[float]:
    return float(np.mean(np.abs(values) >= limit)) if values.size else None


def measure(result: SimulationResult) -> Measures:
    """The :class:`Measures` of one run."""
    trace, zone, delta_max = result.trace, result.scenario.danger_zone, result.config.vehicle.delta_max
    limit = LOCK * delta_max
    threatened = [r for r in result.planning if r.threat is not None]
    with_mpc = [r for r in threatened if r.mpc is not None and np.isfinite(r.delta_mpc)]
    mpc = np.array([r.delta_mpc for r in with_mpc])
    command = np.array([r.reference.delta for r in threatened])
    t, x, y = trace["t"], trace["x"], trace["y"]
    under = trace["threat"] > 0.5
    first = result.first_threat
    after = t >= first.t if first is not None else np.zeros(t.shape, dtype=bool)
    before = ~after
    delta_ref, vx_ref = trace["delta_ref"], trace["vx_ref"]
    x_peak = speed_max = None
    if np.any(after):
        i = int(np.argmax(np.where(after, np.abs(delta_ref), -np.inf)))
        x_peak, speed_max = float(x[i] - zone.x_max), float(np.max(vx_ref[after]))
    passed = np.flatnonzero(x > zone.x_max)
    return_time = None
    if passed.size:
        back = np.flatnonzero(np.abs(y[passed[0]:] - y[0]) <= RETURN_BAND)
        return_time = float(t[passed[0] + back[0]] - t[passed[0]]) if back.size else None
    return Measures(
        threat_plans=len(threatened),
        mpc_near_limit=_share(mpc, limit), command_near_limit=_share(command, limit),
        mpc_variation=_variation(mpc), command_variation=_variation(command),
        mpc_max=float(np.max(np.abs(mpc))) if mpc.size else None,
        command_max_threat=float(np.max(np.abs(delta_ref[under]))) if np.any(under) else None,
        x_peak_command=x_peak, speed_ref_max=speed_max,
        speed_ref_band=float(np.max(np.abs(vx_ref[before] - result.scenario.v_init))) if np.any(before) else 0.0,
        return_time=return_time,
        barrier_violations=sum(r.mpc is not None and r.mpc.status == "barrier_violated" for r in threatened),
        mpc_threat_plans=sum(r.mpc is not None for r in threatened),
    )


@dataclasses.dataclass(frozen=True)
class Run:
    """One simulated run: what was run, its summary and its measures."""

    scenario: str
    planner: PlannerMode
    solver: str
    """The MPC solver (empty for a planner without the MPC: the MSF planner alone, a baseline)."""
    mu: float
    """The road's μ, which the stack plans with."""
    settings: Settings
    summary: dict[str, Any]
    measures: Measures

    @property
    def label(self) -> str:
        return f"{self.planner} ({self.solver})" if self.solver else self.planner


def _physics(scenario: Scenario) -> Scenario:
    """``scenario`` without what does not change a run (its name, description and the paper's reference)."""
    return dataclasses.replace(scenario, name="-", description="", paper=PaperReference())


class RunCache:
    """The runs of one command (or test session) at a seed, from one configuration, each made once.

    The configuration must judge with the default verdict limits (the paper's claims are judged with them): other
    limits are a :class:`~moose.params.ParamError` naming them, before any run."""

    def __init__(self, config: Config, seed: int = 0, progress: Optional[Callable[[str], None]] = None) -> None:
        changed = changed_limits(limits_of(config.verdict))
        if changed:
            raise ParamError(f"verdict: {changed}: the paper's claims are judged with the default verdict limits")
        self.config = config
        self.seed = seed
        self.progress = progress
        self._configs: dict[Settings, Config] = {}
        self._runs: dict[tuple[Any, ...], tuple[dict[str, Any], Measures]] = {}
        self._asked: dict[tuple[str, str, float, Settings], Run] = {}

    def configured(self, settings: Settings = ()) -> Config:
        """The configuration with ``settings``."""
        if settings not in self._configs:
            self._configs[settings] = with_overrides(self.config, dict(settings), where="reproduce") if settings \
                else self.config
        return self._configs[settings]

    def run(self, scenario: str, planner: PlannerMode = "combined", mu: float = PAPER_FRICTION,
            settings: Settings = ()) -> Run:
        """``scenario`` (by name) driven by ``planner`` on a road of ``mu``, for :data:`DURATION` s after the obstacle
        appears, with the configuration's ``settings``."""
        config = self.configured(settings)
        paper = dataclasses.replace(load_scenario(scenario), duration=DURATION, mu=mu)
        key = (_physics(paper), planner, config)
        if key not in self._runs:
            if self.progress is not None:
                self.progress(f"{scenario} {planner} μ = {mu:g} {' '.join(f'{k}={v}' for k, v in settings)}".rstrip())
            result = simulate(config, paper, planner=planner, seed=self.seed)
            self._runs[key] = (summarize(result), measure(result))
        summary, measures = self._runs[key]
        summary = {**summary, "scenario": paper.name, "paper_nu": paper.paper.nu}
        solver = config.mpc.solver if "mpc" in MODE_PLANNERS[planner] else ""
        run = Run(scenario, planner, solver, mu, settings, summary, measures)
        self._asked.setdefault((scenario, planner, mu, settings), run)
        return run

    @property
    def asked(self) -> list[Run]:
        """Every run asked for so far, in the order first asked (a run asked for under two names is listed twice)."""
        return list(self._asked.values())

    def __len__(self) -> int:
        """Runs made so far."""
        return len(self._runs)
