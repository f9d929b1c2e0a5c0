"""What a sweep is: its axes, how they are sampled, and the base configuration; and its validated cases.

:meth:`SweepSpec.cases` checks everything before a single case runs — every scenario is built, every
``--set`` combination is applied to the configuration, every target ν is turned into a width — so a
bad input is a :class:`~moose.params.ParamError` naming the axis and the value, never a failed case.

The target-ν axis: the half width is w = ν · y_max(τ, v) (:meth:`moose.maneuver.MaxSteeringTable.reach`,
eq. (nudef) solved for w) for the car that is simulated: the road's μ and the case's vehicle.  With a
deliberate mismatch (``--set planning.mu_estimate=…``) the geometry stays that of the road, and the
detector's ν (the ``nu`` column) is the one the stack believes.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any, Optional, get_args

from ..config import config_as_ros_params, with_overrides
from ..paper import PAPER_FRICTION
from ..params import ParamError, replace
from ..schema import Config, PlannerMode
from .axes import MAX_CASES, Axis, Case, Sampling, combinations
from .case import case_scenario

PLANNERS: tuple[PlannerMode, ...] = get_args(PlannerMode)

SCENARIO_AXES = ("speed", "tau", "half_width", "nu", "length", "duration", "field_margin", "mu", "planner", "seed")
"""Axis names of the scenario; the configuration's are ``set.<group>.<key>``."""

DEFAULTS: dict[str, tuple[Any, ...]] = {
    "length": (2.0,), "duration": (8.0,), "field_margin": (5.0,), "planner": ("combined",), "seed": (0,),
}
"""Values of the axes that are not given (μ: the configuration's ``vehicle.mu``)."""

FLAGS = {"speed": "--speed", "tau": "--tau", "half_width": "--obstacle-half-width", "nu": "--nu",
         "length": "--obstacle-length", "duration": "--duration", "field_margin": "--field-margin", "mu": "--mu",
         "planner": "--planner", "seed": "--seeds"}
"""The command-line flag of each scenario axis (for error messages)."""


@dataclasses.dataclass(frozen=True)
class SweepSpec:
    """A sweep, complete: the same spec always gives the same cases, in the same order."""

    axes: tuple[Axis, ...]
    config: Config
    samples: Optional[int] = None
    sampling: Sampling = "lhs"
    sampling_seed: int = 0
    criticality: bool = False
    """Every row also carries commonroad-crime's measures of its situation (``criticality.*``)."""

    def describe(self) -> dict[str, Any]:
        """The spec as JSON-safe data (the manifest's ``spec``); its hash identifies the sweep (``criticality`` is
        there only when asked, so a sweep recorded before it existed keeps its hash)."""
        described = {
            "axes": {axis.name: axis.describe() for axis in self.axes},
            "samples": self.samples,
            "sampling": self.sampling if self.samples is not None else "grid",
            "sampling_seed": self.sampling_seed,
            "config": config_as_ros_params(self.config),
        }
        if self.criticality:
            described["criticality"] = True
        return described

    @property
    def hash(self) -> str:
        text = json.dumps(self.describe(), sort_keys=True, default=repr)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def _axis(self, name: str) -> Optional[Axis]:
        return next((a for a in self.axes if a.name == name), None)

    def cases(self) -> list[Case]:
        """Every case, validated (a :class:`ParamError` names the first bad input)."""
        axes = {a.name: a for a in self.axes}
        for name in axes:
            if name not in SCENARIO_AXES and not name.startswith("set."):
                raise ParamError(f"axis {name!r} is unknown: expected one of {list(SCENARIO_AXES)} or set.GROUP.KEY")
        for name in ("speed", "tau"):
            if name not in axes:
                raise ParamError(f"{FLAGS[name]} is missing: a sweep needs values of {FLAGS[name]}")
        if ("half_width" in axes) == ("nu" in axes):
            raise ParamError("give exactly one of --obstacle-half-width and --nu (a target lateral steering index)")
        if "set.vehicle.mu" in axes:
            raise ParamError("--set vehicle.mu: the road's friction is the --mu axis")
        for name in ("planner", "seed"):
            if name in axes and axes[name].sampled:
                raise ParamError(f"{FLAGS[name]} cannot be sampled: give a list")
        for value in axes["planner"].values if "planner" in axes else ():
            if value not in PLANNERS:
                raise ParamError(f"--planner {value!r} is invalid: expected one of {', '.join(PLANNERS)}")
        if self.samples is not None and not (isinstance(self.samples, int) and 1 <= self.samples <= MAX_CASES):
            raise ParamError(f"--samples {self.samples!r} is invalid: expected an integer in [1, {MAX_CASES}]")
        full = dict(axes)
        for name, defaults in DEFAULTS.items():
            full.setdefault(name, Axis(name, defaults))
        full.setdefault("mu", Axis("mu", (self.config.vehicle.mu,)))
        full["mu"] = _friction_axis(full["mu"])
        for axis in full.values():
            if axis.name in ("planner", "seed") or axis.name.startswith("set."):
                continue
            for value in axis.values:
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    raise ParamError(f"{FLAGS[axis.name]} {value!r} is invalid: expected a number")
        order = ["mu", *sorted(n for n in full if n.startswith("set.")), "speed", "tau",
                 "half_width" if "half_width" in full else "nu", "length", "duration", "field_margin", "seed",
                 "planner"]
        crossed = [full[n] for n in order if not full[n].sampled]
        sampled = [full[n] for n in order if full[n].sampled]
        cases: list[Case] = []
        seen: set[str] = set()
        configs: dict[tuple[tuple[str, Any], ...], Config] = {}
        for count, values in enumerate(combinations(crossed, sampled, self.samples, self.sampling, self.sampling_seed)):
            if count >= MAX_CASES:
                raise ParamError(f"the sweep has more than {MAX_CASES} cases: check the steps of its ranges")
            overrides = tuple(sorted((n[4:], v) for n, v in values.items() if n.startswith("set.")))
            if overrides not in configs:
                configs[overrides] = with_overrides(self.config, dict(overrides))
            case = self._case(values, overrides, configs[overrides])
            if case.id not in seen:
                seen.add(case.id)
                cases.append(case)
        return cases

    def _case(self, values: dict[str, Any], overrides: tuple[tuple[str, Any], ...], config: Config) -> Case:
        speed, tau, mu = float(values["speed"]), float(values["tau"]), float(values["mu"])
        nu = float(values["nu"]) if "nu" in values else None
        if nu is not None:
            if not nu > 0.0:
                raise ParamError(f"--nu {nu!r} is invalid: expected a positive lateral steering index")
            half_width = nu * _reach(config, mu, tau, speed)
        else:
            half_width = float(values["half_width"])
        margin = values["field_margin"]
        seed = values["seed"]
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ParamError(f"seed {seed!r} is invalid: expected a non-negative integer")
        case = Case(speed=speed, tau=tau, half_width=half_width, nu=nu, length=float(values["length"]),
                    duration=float(values["duration"]), field_margin=None if margin is None else float(margin),
                    mu=mu, planner=values["planner"], seed=seed, overrides=overrides)
        try:
            case_scenario(case)
        except ParamError as exc:
            raise ParamError(f"case v = {speed:g} m/s, tau = {tau:g} s, half width = {half_width:.3g} m, "
                             f"mu = {mu:g}: {exc}") from None
        return case


def _friction_axis(axis: Axis) -> Axis:
    """``paper`` in the μ axis is the friction calibrated to the paper's ν (:data:`moose.paper.PAPER_FRICTION`)."""
    if axis.sampled:
        return axis
    return dataclasses.replace(axis, values=tuple(PAPER_FRICTION if v == "paper" else v for v in axis.values))


def _reach(config: Config, mu: float, tau: float, speed: float) -> float:
    """y_max(τ, v) of the simulated car (the road's μ): the width of ν = 1."""
    from ..maneuver import MaxSteeringTable

    if not 0.05 <= mu <= 1.5:
        raise ParamError(f"--mu {mu!r} is invalid: expected a friction coefficient in [0.05, 1.5]")
    table = MaxSteeringTable.build(replace(config.vehicle, mu=mu), config.maneuver)
    reach = float(table.reach(tau, speed)) if tau > 0.0 and speed > 0.0 else 0.0
    if not reach > 1e-6:
        raise ParamError(f"--nu at v = {speed:g} m/s, tau = {tau:g} s: no lateral displacement is reachable, "
                         "so no width has this nu")
    return reach
