"""Typed parameter objects and the strict loader for ROS 2 parameter files.

Every block of the core owns a frozen dataclass of its parameters (SI units,
paper defaults).  Values come from a ROS 2 parameter YAML file
(``node_name: {ros__parameters: {...}}``, the ``/**`` wildcard included) through
:func:`build`, which refuses unknown keys, wrong types and out-of-range values
with a :class:`ParamError` naming the field and the value.

:class:`VehicleParams` holds Table I of the paper plus the few plant
quantities the paper does not give (documented in ``docs/modelling.md``).
"""
from __future__ import annotations

import dataclasses
import math
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Mapping, TypeVar

from .errors import ParamError

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

D = TypeVar("D", bound="DataclassInstance")

G = 9.81
"""Gravitational acceleration (m/s^2)."""


def positive(value: float) -> bool:
    return value > 0.0


def non_negative(value: float) -> bool:
    return value >= 0.0


def unit_interval(value: float) -> bool:
    return 0.0 <= value <= 1.0


def at_most(limit: float) -> Callable[[float], bool]:
    """The predicate ``value <= limit``."""
    return lambda value: value <= limit


def check(name: str, value: Any, predicate: Callable[[Any], bool], what: str) -> None:
    """Raise :class:`ParamError` unless ``predicate(value)``; ``what`` says what was expected."""
    if not predicate(value):
        raise ParamError(f"{name} = {value!r} is invalid: expected {what}")


@dataclasses.dataclass(frozen=True)
class VehicleLimits:
    """Hard limits of the FPEV2-Kanon's actuators: constants of the vehicle, not configuration.

    Configuration may only tighten them (:class:`VehicleParams` refuses a looser value); the
    plant, the planners, the maneuver table, the motion controller and the CAN bridge's guard
    all take them from :class:`VehicleParams`, and the DBC's signal ranges must contain them.
    """

    delta_max: float = 0.3
    """Steering angle of the road wheels (rad), Table I."""
    delta_rate_max: float = 1.0
    """Steering rate of the road wheels (rad/s).  Table I prints 2618 rad/s, which is
    25 000 rpm: the speed of the EPS's Maxon motor, not of the road wheels.  1 rad/s (full lock
    0.3 rad in 0.3 s, about a skilled driver's emergency steering input) is our choice for the
    road wheels; docs/modelling.md, "Steering rate"."""
    T_max: float = 200.0
    """Torque of one rear in-wheel motor (N m), Table I."""
    torque_rate_max: float = 2000.0
    """Torque slew rate of one rear motor (N m/s): 0 → T_max in 0.1 s."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            check(f"limits.{f.name}", getattr(self, f.name), positive, "a positive number")


VEHICLE_LIMITS = VehicleLimits()
"""The FPEV2-Kanon's hard limits."""


@dataclasses.dataclass(frozen=True)
class VehicleParams:
    """FPEV2-Kanon single-track parameters: Table I of the paper (SI units).

    ``track``, ``length``, ``width``, ``v_low`` and ``mu`` are not in Table I; see docs/modelling.md.
    """

    m: float = 925.0
    """Vehicle mass (kg)."""
    Izz: float = 617.0
    """Yaw moment of inertia (kg m^2)."""
    J_wr: float = 1.24
    """Rotational inertia of one rear wheel (kg m^2)."""
    r: float = 0.301
    """Wheel radius (m)."""
    lf: float = 0.99
    """CoG to front axle (m)."""
    lr: float = 0.71
    """CoG to rear axle (m)."""
    T_max: float = VEHICLE_LIMITS.T_max
    """Maximum torque of one in-wheel motor (N m); at most :data:`VEHICLE_LIMITS`."""
    delta_max: float = VEHICLE_LIMITS.delta_max
    """Maximum steering angle (rad); at most :data:`VEHICLE_LIMITS`."""
    delta_rate_max: float = VEHICLE_LIMITS.delta_rate_max
    """Maximum steering rate of the road wheels (rad/s); at most :data:`VEHICLE_LIMITS`."""
    torque_rate_max: float = VEHICLE_LIMITS.torque_rate_max
    """Torque slew rate of one rear motor (N m/s); at most :data:`VEHICLE_LIMITS`."""
    Cx: float = 1.5
    """Longitudinal Pacejka shape factor."""
    Bx: float = 8.0
    """Longitudinal Pacejka stiffness factor."""
    Cy: float = 1.4057
    """Lateral Pacejka shape factor."""
    By: float = 7.1138
    """Lateral Pacejka stiffness factor."""
    mu: float = 0.8
    """Tyre-road friction of the road the plant drives on (dry asphalt: 0.8–1.0).  A scenario may set its
    own (the paper's cases run at the calibrated friction, docs/modelling.md, "Friction"); the stack
    assumes the same μ unless ``planning.mu_estimate`` says otherwise."""
    track: float = 1.3
    """Rear track width (m); not in Table I."""
    length: float = 2.5
    """Overall length of the body (m); not in Table I.  Our estimate: Table I's wheelbase l_f + l_r = 1.70 m
    with 0.4 m overhangs front and rear, those of a production car of that wheelbase and mass (a 925 kg
    two-seater); the footprint of the CommonRoad export and the independent verdict (docs/commonroad.md,
    "CommonRoad"), not used by the dynamics."""
    width: float = 1.5
    """Overall width of the body (m); not in Table I.  Our estimate: the track plus a tyre's width and the
    body's margin (0.2 m in all); the footprint's width, like :attr:`length`."""
    v_low: float = 2.0
    """Lower bound of the slip denominators (m/s): low-speed regularisation."""
    g: float = G
    """Gravitational acceleration (m/s^2)."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            check(f"vehicle.{f.name}", getattr(self, f.name), positive, "a positive number")
        for f in dataclasses.fields(VehicleLimits):
            limit = getattr(VEHICLE_LIMITS, f.name)
            check(f"vehicle.{f.name}", getattr(self, f.name), at_most(limit),
                  f"at most the vehicle's hard limit {limit:g} (configuration can only tighten it)")
        check("vehicle.length", self.length, lambda v: v >= self.wheelbase,
              f"a body at least as long as the wheelbase l_f + l_r = {self.wheelbase:g} m")
        check("vehicle.width", self.width, lambda v: v >= self.track,
              f"a body at least as wide as the track {self.track:g} m")

    @property
    def wheelbase(self) -> float:
        """l_f + l_r (m)."""
        return self.lf + self.lr

    @property
    def footprint_offset(self) -> float:
        """How far the centre of the footprint (:attr:`length` × :attr:`width`) lies ahead of the CoG (m):
        (l_f − l_r) / 2, the overhangs being equal front and rear."""
        return 0.5 * (self.lf - self.lr)

    @property
    def Fzf(self) -> float:
        """Static normal load on the front axle (N)."""
        return self.m * self.g * self.lr / self.wheelbase

    @property
    def Fzr(self) -> float:
        """Static normal load on the rear axle (N)."""
        return self.m * self.g * self.lf / self.wheelbase

    @property
    def longitudinal_accel_limit(self) -> float:
        """Largest |v̇_x| the car can give (m/s²), driving or braking: the rear in-wheel motors are the
        only actuators (regenerative braking, F_xf = 0), limited by their torque 2 T_max / r and by
        the rear tyres' grip μ F_zr, acting on the mass plus the wheels' rotational inertia."""
        force = min(2.0 * self.T_max / self.r, self.mu * self.Fzr)
        return force / (self.m + 2.0 * self.J_wr / self.r**2)

    @property
    def lateral_accel_limit(self) -> float:
        """Largest lateral acceleration the tyres can give (m/s²): μ g (eq. (fy) peaks at μ F_z on both axles)."""
        return self.mu * self.g


def _coerce(name: str, value: Any, hint: Any) -> Any:
    """Check ``value`` against the type ``hint``; ints are accepted for floats."""
    origin = typing.get_origin(hint)
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParamError(f"{name} = {value!r} is invalid: expected a number")
        value = float(value)
        if not math.isfinite(value):
            raise ParamError(f"{name} = {value!r} is invalid: expected a finite number")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ParamError(f"{name} = {value!r} is invalid: expected an integer")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ParamError(f"{name} = {value!r} is invalid: expected true or false")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise ParamError(f"{name} = {value!r} is invalid: expected a string")
        return value
    if origin is typing.Literal:
        allowed = typing.get_args(hint)
        if value not in allowed:
            raise ParamError(f"{name} = {value!r} is invalid: expected one of {list(allowed)}")
        return value
    if origin in (tuple, list):
        if not isinstance(value, (list, tuple)):
            raise ParamError(f"{name} = {value!r} is invalid: expected a list")
        args = typing.get_args(hint)
        item = args[0] if args else Any
        if origin is tuple and len(args) > 1 and args[1] is not Ellipsis:
            if len(value) != len(args):
                raise ParamError(f"{name} = {value!r} is invalid: expected {len(args)} items")
            return tuple(_coerce(f"{name}[{i}]", v, a) for i, (v, a) in enumerate(zip(value, args)))
        items = [_coerce(f"{name}[{i}]", v, item) if item is not Any else v for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if isinstance(hint, type) and dataclasses.is_dataclass(hint):
        if not isinstance(value, Mapping):
            raise ParamError(f"{name} = {value!r} is invalid: expected a mapping")
        return build(hint, value, name)
    if origin is typing.Union:
        members = [a for a in typing.get_args(hint) if a is not type(None)]
        if value is None:
            return None
        return _coerce(name, value, members[0])
    return value


def build(cls: type[D], mapping: Mapping[str, Any] | None, where: str) -> D:
    """Instantiate dataclass ``cls`` from ``mapping``, strictly.

    Missing keys take the dataclass default (a missing key without one is a :class:`ParamError` naming it);
    unknown keys and ill-typed values raise :class:`ParamError` naming ``where.key`` and the value.  Range checks
    live in each dataclass's ``__post_init__``; their errors are re-raised with
    the ``where`` prefix.
    """
    mapping = {} if mapping is None else mapping
    if not isinstance(mapping, Mapping):
        raise ParamError(f"{where} = {mapping!r} is invalid: expected a mapping")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(mapping) - names)
    if unknown:
        raise ParamError(
            f"{where}.{unknown[0]} = {mapping[unknown[0]]!r} is unknown; known fields: {sorted(names)}"
        )
    required = [f.name for f in dataclasses.fields(cls) if f.init and f.default is dataclasses.MISSING
                and f.default_factory is dataclasses.MISSING]
    absent = [name for name in required if name not in mapping]
    if absent:
        raise ParamError(f"{where}.{absent[0]} is missing: a required field (required: {', '.join(required)})")
    kwargs = {key: _coerce(f"{where}.{key}", value, hints[key]) for key, value in mapping.items()}
    try:
        return cls(**kwargs)
    except ParamError as exc:
        message = str(exc)
        prefix = where.split(".")[-1] + "."
        if not message.startswith(where) and not message.startswith(prefix):
            message = f"{where}.{message}"
        raise ParamError(message) from None


def replace(obj: D, **changes: Any) -> D:
    """``dataclasses.replace`` that keeps the validation of ``__post_init__``."""
    return dataclasses.replace(obj, **changes)


def to_mapping(obj: Any) -> dict[str, Any]:
    """Plain dict of a parameter dataclass (nested dataclasses included, tuples as lists)."""

    def plain(value: Any) -> Any:
        if dataclasses.is_dataclass(value):
            return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        return value

    return plain(obj)


WILDCARD = "/**"
"""The section of a ROS 2 parameter file that applies to every node, and the only one the core reads."""


def read_ros_params(path: str | Path, node: str | None = None, *, reader: str | None = None) -> dict[str, Any]:
    """Read a ROS 2 parameter file and return the merged ``ros__parameters`` for ``node``.

    The ``/**`` wildcard section applies to every node; a section named after
    ``node`` (with or without a leading ``/``) overrides it key by key.  With
    ``node=None`` only the wildcard section is returned.  ``reader`` names a command that applies
    only the wildcard section (``moose simulate``): any other section of the file is then a
    :class:`ParamError` naming it, instead of being ignored.
    """
    from .files import load_yaml, read_input

    path = Path(path)
    document = load_yaml(read_input(path, "parameter file"), f"parameter file {str(path)!r}")
    if not isinstance(document, Mapping):
        raise ParamError(f"parameter file {str(path)!r}: expected a mapping of node names, got {document!r}")
    if reader is not None:
        for section in document:
            if section != WILDCARD:
                raise ParamError(f"parameter file {str(path)!r}: section {section!r} is not applied by {reader}, "
                                 f"which reads only {WILDCARD!r} (sections named after nodes apply to the node graph: "
                                 "moose launch, moose node)")
    merged: dict[str, Any] = {}
    sections = [WILDCARD] + ([node.lstrip("/"), "/" + node.lstrip("/")] if node else [])
    for section in sections:
        body = document.get(section)
        if body is None:
            continue
        if not isinstance(body, Mapping) or "ros__parameters" not in body:
            raise ParamError(f"parameter file {str(path)!r}: section {section!r} has no ros__parameters")
        params = body["ros__parameters"]
        if not isinstance(params, Mapping):
            raise ParamError(f"parameter file {str(path)!r}: {section}.ros__parameters = {params!r} is not a mapping")
        _deep_merge(merged, params)
    return merged


def _deep_merge(into: dict[str, Any], update: Mapping[str, Any]) -> None:
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(into.get(key), dict):
            _deep_merge(into[key], value)
        elif isinstance(value, Mapping):
            into[key] = {}
            _deep_merge(into[key], value)
        else:
            into[key] = value
