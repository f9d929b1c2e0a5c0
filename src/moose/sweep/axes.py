"""The axes of a sweep and the cases they span: lists, ranges, full grid or Latin-hypercube/random sampling.

An axis is written on the command line as

* a list ``4,5,6`` (YAML scalars: numbers, ``true``/``false``, names such as ``ipopt``);
* a stepped range ``LO:HI:STEP``, inclusive of HI when the steps land on it (``1:5:0.5``);
* an open range ``LO:HI``: sampled, only with ``--samples N``.

Lists and stepped ranges are *crossed* (every value with every other axis); open ranges are *sampled*
jointly, N points by Latin hypercube (default) or uniformly at random, from a seeded generator, and
every sampled point is crossed with the listed axes (so all planners and frictions meet the same
threats).  Every case is a :class:`Case`: its inputs alone decide its result, and its :attr:`Case.id`
is a hash of them, which is how ``--resume`` knows what is done.
"""
from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import math
from typing import Any, Iterable, Literal, Optional, Sequence

import numpy as np
import yaml

from ..params import ParamError
from ..schema import PlannerMode

Sampling = Literal["grid", "lhs", "random"]

MAX_CASES = 1_000_000
"""A sweep larger than this is refused (a typo in a step, not an experiment)."""


@dataclasses.dataclass(frozen=True)
class Axis:
    """One axis: explicit ``values`` (crossed) or an open range ``low``..``high`` (sampled)."""

    name: str
    values: tuple[Any, ...] = ()
    low: Optional[float] = None
    high: Optional[float] = None

    @property
    def sampled(self) -> bool:
        return self.low is not None

    def describe(self) -> Any:
        """JSON-safe form (the manifest's)."""
        return {"range": [self.low, self.high]} if self.sampled else list(self.values)


def _scalar(text: str, name: str) -> Any:
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        value = text
    if value is None or isinstance(value, (list, dict)):
        raise ParamError(f"{name} = {text!r} is invalid: expected a number or a name")
    if isinstance(value, float) and not math.isfinite(value):
        raise ParamError(f"{name} = {text!r} is invalid: expected a finite number")
    return value


def _number(text: str, name: str) -> float:
    value = _scalar(text.strip(), name)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParamError(f"{name} = {text!r} is invalid: expected a number")
    return value


def parse_axis(name: str, text: str, label: Optional[str] = None) -> Axis:
    """``text`` of the command line as an :class:`Axis`; errors name ``label`` (the flag, default ``name``)
    and the text."""
    axis_name, name = name, label or name
    text = text.strip()
    if not text:
        raise ParamError(f"{name} = {text!r} is invalid: the axis has no values")
    if ":" in text:
        parts = text.split(":")
        if len(parts) not in (2, 3) or any(not p.strip() for p in parts):
            raise ParamError(f"{name} = {text!r} is invalid: expected LO:HI (sampled) or LO:HI:STEP")
        low, high = _number(parts[0], name), _number(parts[1], name)
        if not low <= high:
            raise ParamError(f"{name} = {text!r} is an invalid range: LO = {low!r} is above HI = {high!r}")
        if len(parts) == 2:
            return Axis(axis_name, low=float(low), high=float(high))
        step = _number(parts[2], name)
        if not step > 0:
            raise ParamError(f"{name} = {text!r} is an invalid range: STEP = {step!r} must be positive")
        count = math.floor((high - low) / step + 1e-9) + 1
        if count > MAX_CASES:
            raise ParamError(f"{name} = {text!r} is an invalid range: {count} values")
        integral = all(isinstance(v, int) for v in (low, high, step))
        grid = [low + k * step if integral else round(low + k * step, 12) for k in range(count)]
        return Axis(axis_name, tuple(grid))
    values = tuple(_scalar(part.strip(), name) for part in text.split(","))
    if any(v == "" for v in values):
        raise ParamError(f"{name} = {text!r} is invalid: an empty value in the list")
    if len(set(map(repr, values))) != len(values):
        raise ParamError(f"{name} = {text!r} is invalid: a value is listed twice")
    return Axis(axis_name, values)


@dataclasses.dataclass(frozen=True)
class Case:
    """One moose test of a sweep: every input that decides its result."""

    speed: float
    """Speed at detection and desired speed (m/s)."""
    tau: float
    """Time to collision at which the obstacle appears (s)."""
    half_width: float
    """Danger-zone half width (m), centred on the ego path (the far edge is w from the path)."""
    nu: Optional[float]
    """The target ν the half width was derived from (None when the half width was given)."""
    length: float
    """Danger-zone length (m)."""
    duration: float
    """Simulated time after the obstacle appears (s)."""
    field_margin: Optional[float]
    """Room beside the obstacle (m), :func:`moose.scenario.adhoc_scenario`."""
    mu: float
    """The road's friction."""
    planner: PlannerMode
    seed: int
    overrides: tuple[tuple[str, Any], ...] = ()
    """``--set`` parameters, sorted by key."""

    @property
    def inputs(self) -> dict[str, Any]:
        """The inputs as row columns (``input.*`` and ``set.*``)."""
        row = {
            "input.speed_mps": self.speed, "input.tau_s": self.tau, "input.half_width_m": self.half_width,
            "input.nu": self.nu, "input.length_m": self.length, "input.duration_s": self.duration,
            "input.field_margin_m": self.field_margin, "input.mu": self.mu, "input.planner": self.planner,
            "input.seed": self.seed,
        }
        row.update({f"set.{key}": value for key, value in self.overrides})
        return row

    @property
    def id(self) -> str:
        """A hash of the inputs: equal inputs, equal id, in any process."""
        text = json.dumps(self.inputs, sort_keys=True, default=repr)
        return hashlib.sha256(text.encode()).hexdigest()[:16]


def unit_samples(n: int, dims: int, method: Sampling, rng: np.random.Generator) -> np.ndarray:
    """(n, dims) points in [0, 1)^dims: Latin hypercube (one point per stratum of every axis) or uniform."""
    if method == "random":
        return rng.random((n, dims))
    strata = np.stack([rng.permutation(n) for _ in range(dims)], axis=1)
    return (strata + rng.random((n, dims))) / n


def sampled_points(axes: Sequence[Axis], n: int, method: Sampling, seed: int) -> list[tuple[float, ...]]:
    """``n`` joint draws of the sampled axes (in order), from a generator seeded with ``seed``."""
    if not axes:
        return [()]
    unit = unit_samples(n, len(axes), method, np.random.default_rng(seed))
    low = np.array([a.low for a in axes])
    high = np.array([a.high for a in axes])
    return [tuple(float(v) for v in row) for row in low + unit * (high - low)]


def combinations(crossed: Sequence[Axis], sampled: Sequence[Axis], samples: Optional[int], method: Sampling,
                 seed: int) -> Iterable[dict[str, Any]]:
    """Every assignment of the axes: the product of the crossed axes' values with the sampled points."""
    if sampled and samples is None:
        names = ", ".join(a.name for a in sampled)
        raise ParamError(f"{names}: an open range LO:HI is sampled and needs --samples N (or give a step, LO:HI:STEP)")
    if samples is not None and not sampled:
        raise ParamError(f"--samples {samples}: no axis is an open range LO:HI to sample")
    points = sampled_points(sampled, samples or 1, method, seed)
    for point in points:
        drawn = dict(zip((a.name for a in sampled), point))
        for values in itertools.product(*(a.values for a in crossed)):
            yield {**drawn, **dict(zip((a.name for a in crossed), values))}
