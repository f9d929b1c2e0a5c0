"""The moose test a command or a node names: ``moose simulate``'s scenario flags or a node's parameters, read one
way (:func:`scenario_from_args`)."""
from __future__ import annotations

import dataclasses
from typing import Any, Optional, Protocol

from ..params import ParamError, VehicleParams
from . import DEFAULT_SCENARIO, Scenario, adhoc_scenario, load_scenario


class ScenarioArgs(Protocol):
    """What names a moose test: ``moose simulate``'s scenario flags (:func:`moose.cli.common.add_scenario_arguments`)
    or a node's :class:`moose_ros.parameters.ScenarioParams`.  Optional too, read when present: ``commonroad`` (a
    CommonRoad file), ``config`` (the parameter file whose vehicle reads it) and ``field_margin``."""

    @property
    def scenario(self) -> Optional[str]: ...
    @property
    def speed(self) -> Optional[float]: ...
    @property
    def tau(self) -> Optional[float]: ...
    @property
    def obstacle_half_width(self) -> Optional[float]: ...
    @property
    def obstacle_length(self) -> float: ...
    @property
    def duration(self) -> Optional[float]: ...
    @property
    def mu(self) -> Optional[float]: ...


def scenario_from_args(args: ScenarioArgs, vehicle: Optional[VehicleParams] = None) -> Scenario:
    """The scenario ``args`` names: a CommonRoad file, an ad-hoc test (``speed``, ``tau`` and
    ``obstacle_half_width`` together) or a scenario by name or path (default :data:`DEFAULT_SCENARIO`), then
    ``duration`` and ``mu`` applied.  A CommonRoad file is read with ``vehicle``'s footprint (default: that of the
    ``config`` file, or the default configuration's); a combination of these sources is a
    :class:`~moose.params.ParamError`."""
    adhoc = [args.speed, args.tau, args.obstacle_half_width]
    commonroad = getattr(args, "commonroad", None)
    if commonroad is not None and (args.scenario or any(v is not None for v in adhoc)):
        raise ParamError("--commonroad cannot be combined with --scenario or the ad-hoc flags")
    if commonroad is not None:
        from ..commonroad import require

        require("--commonroad")
        from ..commonroad.scenario import load as load_commonroad

        if vehicle is None:
            from ..config import load_config

            vehicle = load_config(getattr(args, "config", None), "moose").vehicle
        scenario = load_commonroad(commonroad, vehicle)
    elif any(v is not None for v in adhoc):
        if args.scenario:
            raise ParamError("--scenario cannot be combined with the ad-hoc flags --speed/--tau/--obstacle-half-width")
        if args.speed is None or args.tau is None or args.obstacle_half_width is None:
            raise ParamError("an ad-hoc moose test needs --speed, --tau and --obstacle-half-width")
        scenario = adhoc_scenario(args.speed, args.tau, args.obstacle_half_width, args.obstacle_length,
                                  field_margin=getattr(args, "field_margin", None))
    else:
        scenario = load_scenario(args.scenario or DEFAULT_SCENARIO)
    changes: dict[str, Any] = {}
    if args.duration is not None:
        changes["duration"] = args.duration
    if args.mu is not None:
        changes["mu"] = args.mu
    return dataclasses.replace(scenario, **changes) if changes else scenario
