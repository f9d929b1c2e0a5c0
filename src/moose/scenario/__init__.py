"""Moose-test scenarios: the paper's experiments (Sec. VI) as validated files.

A scenario puts the ego vehicle on a straight path (y = 0, heading 0) at the
speed ``v_init``; a static obstacle's danger zone (the red boxes of Figs. 7–10,
which bound the CoG) appears suddenly when the time to collision with its near
edge, τ = (x_min − x) / v_x, reaches ``tau``.  The vehicle must stay inside the
``field`` (the plotted extent of the paper's result figures by default).

Files live in ``config/scenarios/*.yaml``; :func:`load_scenario` accepts a
name from that folder or a path, and refuses invalid content with a
:class:`~moose.params.ParamError` naming the field and the value.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Optional

from ..files import load_yaml, read_input
from ..paper import PAPER_FRICTION
from ..params import ParamError, build, check, non_negative, positive, replace
from ..resources import SCENARIO_DIR
from ..schema import Config
from ..signals import Obstacle as Box

PAPER_FIELD = Box(-50.0, 150.0, -5.0, 10.0)
"""The drivable field by default: the plotted extent of the paper's result figures (m)."""

V_MAX_FIELD = 20.0
"""Highest speed a scenario may ask for (m/s): the campus field's limit is about 7 m/s."""


@dataclasses.dataclass(frozen=True)
class PaperReference:
    """What the paper reports for this experiment (for comparison only)."""

    nu: Optional[float] = None
    figure: str = ""
    note: str = ""


@dataclasses.dataclass(frozen=True)
class Scenario:
    """One moose test."""

    name: str
    v_init: float
    """Speed when the obstacle appears (m/s)."""
    v_des: float
    """Desired speed v_des of the planners (m/s)."""
    tau: float
    """Time to collision at which the obstacle appears (s)."""
    obstacle: Box
    """Danger zone of the obstacle: the box the CoG must avoid (m)."""
    field: Box = PAPER_FIELD
    """Drivable field; leaving it counts as a failure (m)."""
    duration: float = 8.0
    """Simulated time after the obstacle appears (s)."""
    lead_time: float = 1.0
    """Straight running before the obstacle appears (s)."""
    mu: Optional[float] = None
    """The road's friction (the plant's); ``None`` keeps the configured ``vehicle.mu``.  In a file,
    ``paper`` is the friction calibrated to the paper's ν (:data:`moose.paper.PAPER_FRICTION`)."""
    description: str = ""
    paper: PaperReference = PaperReference()

    def __post_init__(self) -> None:
        check("name", self.name, lambda v: bool(v.strip()), "a non-empty name")
        for name in ("v_init", "v_des"):
            value = getattr(self, name)
            check(name, value, lambda v: 0.0 < v <= V_MAX_FIELD, f"a speed in (0, {V_MAX_FIELD}] m/s")
        check("tau", self.tau, positive, "a positive time to collision (s)")
        check("duration", self.duration, lambda v: 0.0 < v <= 120.0, "a duration in (0, 120] s")
        check("lead_time", self.lead_time, non_negative, "a non-negative time (s)")
        if self.mu is not None:
            check("mu", self.mu, lambda v: 0.05 <= v <= 1.5, "a friction coefficient in [0.05, 1.5]")
        x_appear = self.x_appear
        start = self.start_x
        if not self.field.contains(start, 0.0):
            raise ParamError(
                f"field = {dataclasses.asdict(self.field)!r} is invalid: the start point ({start:.2f}, 0) is outside it"
            )
        if not self.obstacle.x_min > x_appear:
            raise ParamError(f"obstacle.x_min = {self.obstacle.x_min!r} is invalid: must lie ahead of the vehicle")

    @property
    def x_appear(self) -> float:
        """Nominal CoG position x at which the obstacle appears, x_min − v_init τ (m): where the car
        cruising at ``v_init`` is when :meth:`appears` turns true."""
        return self.obstacle.x_min - self.v_init * self.tau

    @property
    def start_x(self) -> float:
        """CoG position x at the start of the run (m): ``lead_time`` before :attr:`x_appear` at ``v_init``."""
        return self.x_appear - self.v_init * self.lead_time

    @property
    def end_time(self) -> float:
        """Simulated time (s) at which a run of this scenario ends: the lead time, then ``duration`` after it."""
        return self.lead_time + self.duration

    def appears(self, x: float, vx: float) -> bool:
        """Whether the obstacle has appeared for a car at (true) position ``x`` and speed ``vx``: when its
        time to collision with the near edge, (x_min − x) / v_x, has fallen to ``tau`` (or the car is
        there).  Placing the obstacle from the car's actual state gives every planner the same τ."""
        gap = self.obstacle.x_min - x
        return gap <= self.tau * vx or gap <= 0.0

    def configure(self, config: Config) -> Config:
        """``config`` on this scenario's road: ``vehicle.mu`` set to the scenario's μ when it has one."""
        return config if self.mu is None else dataclasses.replace(config, vehicle=replace(config.vehicle, mu=self.mu))

    def desired_speed(self, detected: bool) -> float:
        """v_des of the planners: the approach speed ``v_init`` until the obstacle is detected (every
        planner meets it at the same speed, hence the same ν), ``v_des`` from then on."""
        return self.v_des if detected else self.v_init

    @property
    def danger_zone(self) -> Box:
        """The obstacle as the perception layer reports it."""
        return self.obstacle


def scenario_from_mapping(data: Any, where: str = "scenario") -> Scenario:
    """Validate a parsed scenario file; errors name the field and the value.

    ``mu: paper`` stands for :data:`moose.paper.PAPER_FRICTION`, the friction calibrated to
    reproduce the paper's ν (the paper's own scenarios use it)."""
    if not isinstance(data, dict):
        raise ParamError(f"{where} = {data!r} is invalid: expected a mapping")
    if data.get("mu") == "paper":
        data = {**data, "mu": PAPER_FRICTION}
    return build(Scenario, data, where)


def available_scenarios(directory: Path = SCENARIO_DIR) -> list[str]:
    """Names of the scenario files shipped in ``config/scenarios``."""
    return sorted(p.stem for p in directory.glob("*.yaml"))


def load_scenario(name_or_path: str | Path, directory: Path = SCENARIO_DIR) -> Scenario:
    """Load a scenario by name (``config/scenarios/NAME.yaml``) or by path."""
    path = Path(name_or_path)
    if path.suffix not in (".yaml", ".yml") and len(path.parts) == 1:
        path = directory / f"{name_or_path}.yaml"
    if not path.is_file():
        known = ", ".join(available_scenarios(directory))
        raise ParamError(f"scenario = {str(name_or_path)!r} is unknown: no file {str(path)!r} (shipped: {known})")
    data = load_yaml(read_input(path, "scenario file"), f"scenario file {str(path)!r}")
    return scenario_from_mapping(data, where=path.stem)


def adhoc_scenario(
    speed: float,
    tau: float,
    obstacle_half_width: float,
    obstacle_length: float = 2.0,
    duration: float = 8.0,
    field_margin: Optional[float] = None,
) -> Scenario:
    """A moose test without a file: obstacle centred on the ego path, appearing at τ.

    The field is the paper's figures' (:data:`PAPER_FIELD`); with ``field_margin`` it also
    extends that far beyond the obstacle's sides, |y| ≤ half width + margin, so that a wide obstacle
    (a high ν at a long τ) is judged on the car's maneuver, not on a field narrower than the obstacle.
    """
    check("speed", speed, lambda v: 0.0 < v <= V_MAX_FIELD, f"a speed in (0, {V_MAX_FIELD}] m/s")
    check("tau", tau, positive, "a positive time to collision (s)")
    check("obstacle_half_width", obstacle_half_width, positive, "a positive half width (m)")
    check("obstacle_length", obstacle_length, positive, "a positive length (m)")
    if field_margin is not None:
        check("field_margin", field_margin, non_negative, "a non-negative distance (m)")
    x_min = speed * tau
    field = PAPER_FIELD
    if field_margin is not None:
        side = obstacle_half_width + field_margin
        field = Box(field.x_min, field.x_max, min(field.y_min, -side), max(field.y_max, side))
    return Scenario(
        name=f"adhoc_v{speed:g}_tau{tau:g}_w{obstacle_half_width:g}",
        v_init=speed,
        v_des=speed,
        tau=tau,
        obstacle=Box(x_min, x_min + obstacle_length, -obstacle_half_width, obstacle_half_width),
        field=field,
        duration=duration,
    )


DEFAULT_SCENARIO = "paper_v7_tau1.4"
"""The paper's extreme case (7 m/s, τ = 1.4 s, ν ≈ 0.95): the main job."""
