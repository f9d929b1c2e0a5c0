"""The car's footprint and the real obstacle behind a danger zone (no CommonRoad import).

The paper's danger zone is "the width of the danger zone w, to be avoided by the ego vehicle's center of
gravity" (eq. (nudef)); it says nothing of the obstacle itself.  We read the zone as the obstacle enlarged by
the car at heading 0 (the Minkowski sum of the obstacle and the footprint about the CoG): the CoG stays out of
the zone exactly when a car driving parallel to the road keeps its footprint off the obstacle.  So

* the obstacle of a zone is the zone shrunk by the footprint: ``front`` (CoG to the front bumper) off its near
  edge, ``rear`` off its far edge, half the width off either side (:func:`obstacle_of_zone`);
* the zone of an obstacle is the obstacle grown by the same amounts (:func:`zone_of_obstacle`), the exact
  inverse.

A zone narrower or shorter than the car is not the enlargement of any obstacle.  Along such an axis the obstacle is
a wall :data:`MIN_SIZE` thick, placed so that its own danger zone overhangs the given one equally at both ends (the
closest fit), and :func:`obstacle_of_zone` says so.  The paper's zones are 2 m long, shorter than the car: their
obstacles are such walls, and their danger zones reach ((length − 2 m) + MIN_SIZE) / 2 beyond the paper's at
either end (the independent verdict explains the differences this makes).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Optional

import numpy as np

from ..params import ParamError, VehicleParams
from ..signals import Obstacle as Box

MIN_SIZE = 0.01
"""Side of the post that stands for a zone smaller than the car (m)."""
DT = 0.01
"""The time step of a run as CommonRoad sees it (s): the trace's, the motion-control rate (nothing recorded is
dropped); time step k is the run's time k·dt."""


@dataclasses.dataclass(frozen=True)
class Footprint:
    """The car's body as a rectangle about the CoG, in the body frame (m)."""

    length: float
    width: float
    offset: float
    """How far the rectangle's centre lies ahead of the CoG."""

    @classmethod
    def of(cls, vehicle: VehicleParams) -> "Footprint":
        return cls(vehicle.length, vehicle.width, vehicle.footprint_offset)

    @property
    def front(self) -> float:
        """CoG to the front bumper (m)."""
        return 0.5 * self.length + self.offset

    @property
    def rear(self) -> float:
        """CoG to the rear bumper (m)."""
        return 0.5 * self.length - self.offset

    @property
    def radius(self) -> float:
        """Half the diagonal: the circle about :meth:`centre` with this radius holds the whole footprint (m)."""
        return math.hypot(0.5 * self.length, 0.5 * self.width)

    def centre(self, x: Any, y: Any, theta: Any) -> tuple[Any, Any]:
        """The footprint's centre for the CoG at (x, y) with yaw θ (floats or arrays)."""
        return x + self.offset * np.cos(theta), y + self.offset * np.sin(theta)

    def corners(self, x: float, y: float, theta: float) -> np.ndarray:
        """(4, 2) corners of the footprint with the CoG at (x, y) and yaw ``theta`` (counter-clockwise)."""
        c, s = np.cos(theta), np.sin(theta)
        half = 0.5 * self.width
        local = np.array([[self.front, half], [-self.rear, half], [-self.rear, -half], [self.front, -half]])
        return np.column_stack((x + c * local[:, 0] - s * local[:, 1], y + s * local[:, 0] + c * local[:, 1]))


def zone_of_obstacle(obstacle: Box, footprint: Footprint) -> Box:
    """The danger zone of ``obstacle``: the box the CoG of a car at heading 0 must avoid."""
    half = 0.5 * footprint.width
    return Box(obstacle.x_min - footprint.front, obstacle.x_max + footprint.rear,
               obstacle.y_min - half, obstacle.y_max + half)


def obstacle_of_zone(zone: Box, footprint: Footprint) -> tuple[Box, Optional[str]]:
    """The obstacle whose danger zone is ``zone`` (:func:`zone_of_obstacle` inverted), and None; or, for a zone
    shorter or narrower than the car, the closest fit (a wall :data:`MIN_SIZE` thick along that axis) and a
    sentence saying so."""
    half = 0.5 * footprint.width
    x_min, x_max = zone.x_min + footprint.front, zone.x_max - footprint.rear
    y_min, y_max = zone.y_min + half, zone.y_max - half
    short = []
    if x_max - x_min < MIN_SIZE:
        short.append(f"{zone.x_max - zone.x_min:.2f} m long, the car is {footprint.length:g} m")
    if y_max - y_min < MIN_SIZE:
        short.append(f"{zone.y_max - zone.y_min:.2f} m wide, the car is {footprint.width:g} m")
    if not short:
        return Box(x_min, x_max, y_min, y_max), None
    if x_max - x_min < MIN_SIZE:
        mid = 0.5 * (x_min + x_max)
        x_min, x_max = mid - 0.5 * MIN_SIZE, mid + 0.5 * MIN_SIZE
    if y_max - y_min < MIN_SIZE:
        mid = 0.5 * (y_min + y_max)
        y_min, y_max = mid - 0.5 * MIN_SIZE, mid + 0.5 * MIN_SIZE
    note = (f"the danger zone is smaller than the car ({'; '.join(short)}): it is not the enlargement of any "
            f"obstacle; the obstacle is {MIN_SIZE:g} m thick along that axis, its danger zone overhangs the given "
            "one equally at both ends")
    return Box(x_min, x_max, y_min, y_max), note


def resample(trace: Mapping[str, np.ndarray], dt: float = DT) -> dict[str, np.ndarray]:
    """The trace's t, x, y, θ, v_x, v_y (and δ, γ where it has them) on the grid k·dt from 0 to its last sample
    (linear in time, θ unwrapped first; samples with a non-finite value are left out): the samples themselves
    where they lie on the grid, as a lockstep trace's do."""
    names = [n for n in ("x", "y", "theta", "vx", "vy", "delta", "gamma") if n in trace]
    t = np.asarray(trace["t"], dtype=float)
    columns = {n: np.asarray(trace[n], dtype=float) for n in names}
    ok = np.isfinite(t) & np.all([np.isfinite(columns[n]) for n in names], axis=0)
    if not np.any(ok):
        raise ParamError("the run has no finite sample of the vehicle state to export")
    order = np.argsort(t[ok], kind="stable")
    t = t[ok][order]
    grid = np.arange(int(math.floor(t[-1] / dt + 1e-9)) + 1) * dt
    out = {"t": grid}
    for n in names:
        values = columns[n][ok][order]
        out[n] = np.interp(grid, t, np.unwrap(values) if n == "theta" else values)
    return out
