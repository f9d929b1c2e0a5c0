"""An independent verdict of a run: commonroad-drivability-checker's collision check of the car's footprint against
the obstacle and its road-compliance check against the road, beside our verdict (:func:`moose.verdict.judge`: the
CoG path in the danger zone, a CoG sample outside the field).

The checks are the drivability checker's collision library (``commonroad_dc.pycrcc``) on the shapes the checker
builds from a run's export (:func:`moose.commonroad.scenario.export_run`), built here directly from the run: the
footprint at every 10 ms time step, an oriented rectangle about its centre (``create_collision_object`` of the
exported ego), the obstacle with its real size, an axis-aligned rectangle (``create_collision_object`` of the
exported obstacle), and the road boundary of the lanelets (``create_road_boundary_obstacle``, ``obb_rectangles``),
which for the straight rectangular road of a moose test is a rectangle :data:`BOUNDARY_THICKNESS` thick along
each side edge, open at both ends.  The car left the road when its footprint touches the boundary.  That these are
the checker's own shapes, and give its answers at every time step, is tested against the checker's construction
from the export (``tests/test_commonroad.py``); building them directly costs no commonroad-io objects (the
checker's construction took 35 ms of a run's 60, and importing it 0.5 s per process: every run of a sweep is judged,
:mod:`moose.sweep`).  The checker is asked only at the time steps where a contact is possible: where the circle
about the footprint's centre that holds the footprint (:attr:`~moose.commonroad.geometry.Footprint.radius`)
reaches the obstacle or a side edge; at the others the footprint cannot touch either.

Where the two verdicts differ, :func:`compare` says why, and only with a reason it has checked at the instant the
two part (a reason it cannot check is reported as unexplained):
* the footprint touches the obstacle while the CoG is outside the danger zone.  The zone is the obstacle enlarged
  by the car at heading 0; if the CoG is also outside the zone of the exported obstacle, the footprint at heading 0
  would not touch it, so the contact comes from the car's yaw (its corners reach further sideways); otherwise from
  the obstacle's zone being larger than the run's (a zone shorter or narrower than the car,
  :func:`moose.commonroad.geometry.obstacle_of_zone`);
* the CoG enters the danger zone while the footprint stays off the obstacle: a zone larger than the obstacle's
  (the same fit, the other way), a yawed footprint that no longer covers the enlarged corner, or a CoG path that
  crosses a corner of the zone between two samples (ours checks the segments, the checker the samples);
* the footprint leaves the road while the CoG stays inside the field: the field bounds the CoG (the paper's), the
  road the whole car;
* the CoG leaves the field while the footprint never touches the road's edge: not possible for a car that drives
  off the road continuously, so unexplained.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Optional

import commonroad_dc.pycrcc as pycrcc
import numpy as np

from ..params import VehicleParams
from ..scenario import Scenario
from ..signals import Obstacle as Box
from ..verdict import Verdict, segment_hits_box
from .geometry import DT, Footprint, obstacle_of_zone, resample, zone_of_obstacle

BOUNDARY_THICKNESS = 1e-5
"""Thickness of the road boundary's rectangles as ``create_road_boundary_obstacle`` builds them (m)."""
REACH_MARGIN = 1e-6
"""How much nearer than the circle about the footprint a time step is still checked (m): rounding, never a
contact missed."""


@dataclasses.dataclass(frozen=True)
class CommonRoadVerdict:
    """The drivability checker's findings and how they compare with ours."""

    collision: bool
    """The footprint touches the obstacle at some time step."""
    collision_t_s: Optional[float]
    """The first such time (s)."""
    road_compliant: bool
    """The footprint never touches the road's boundary."""
    off_road_t_s: Optional[float]
    """The first time it does (s)."""
    agrees: bool
    """Both verdicts say the same about the collision and about leaving the field."""
    explained: bool
    """Every difference has a checked reason (:attr:`differences`)."""
    differences: tuple[str, ...]
    """Why they differ, one sentence per difference ("unexplained: …" where no reason checks out)."""

    def as_dict(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "differences": list(self.differences)}


def _first(hits: np.ndarray) -> Optional[int]:
    return int(np.argmax(hits)) if bool(np.any(hits)) else None


def road_boundary(field: Box) -> Any:
    """The road boundary of a straight road along x over ``field`` as the checker builds it
    (``create_road_boundary_obstacle(scenario, method="obb_rectangles")``): a shape group of two rectangles
    :data:`BOUNDARY_THICKNESS` thick centred on the side edges y_min and y_max, from x_min to x_max."""
    group = pycrcc.ShapeGroup()
    half_length, x = 0.5 * (field.x_max - field.x_min), 0.5 * (field.x_min + field.x_max)
    for y in (field.y_max, field.y_min):
        group.add_shape(pycrcc.RectOBB(half_length, 0.5 * BOUNDARY_THICKNESS, 0.0, x, y))
    return group


def check(states: dict[str, np.ndarray], box: Box, field: Box, footprint: Footprint) -> tuple[np.ndarray, np.ndarray]:
    """Per time step of ``states`` (:func:`~moose.commonroad.geometry.resample`): does the footprint touch the
    obstacle ``box``, does it touch the boundary of the road over ``field`` (the drivability checker's collision
    library, at the steps where the circle about the footprint reaches either)."""
    theta = states["theta"]
    cx, cy = footprint.centre(states["x"], states["y"], theta)
    reach = footprint.radius + REACH_MARGIN
    near_obstacle = box.clearance(cx, cy) <= reach
    edge = 0.5 * BOUNDARY_THICKNESS + reach
    near_edge = (((cy >= field.y_max - edge) | (cy <= field.y_min + edge))
                 & (cx >= field.x_min - reach) & (cx <= field.x_max + reach))
    obstacle = pycrcc.RectAABB(0.5 * (box.x_max - box.x_min), 0.5 * (box.y_max - box.y_min),
                               0.5 * (box.x_min + box.x_max), 0.5 * (box.y_min + box.y_max))
    boundary = road_boundary(field)
    hits, off = np.zeros(len(cx), dtype=bool), np.zeros(len(cx), dtype=bool)
    half_length, half_width = 0.5 * footprint.length, 0.5 * footprint.width
    for k in np.flatnonzero(near_obstacle | near_edge).tolist():
        car = pycrcc.RectOBB(half_length, half_width, float(theta[k]), float(cx[k]), float(cy[k]))
        hits[k] = near_obstacle[k] and car.collide(obstacle)
        off[k] = near_edge[k] and boundary.collide(car)
    return hits, off


def compare(trace: Any, scenario: Scenario, vehicle: VehicleParams, verdict: Verdict, dt: float = DT
            ) -> CommonRoadVerdict:
    """The drivability checker's verdict of the run (its ``trace`` of the true state in ``scenario``, the footprint
    of ``vehicle``) beside ``verdict`` (ours), with the reasons for every difference."""
    footprint = Footprint.of(vehicle)
    zone, field = scenario.danger_zone, scenario.field
    box, note = obstacle_of_zone(zone, footprint)
    states = resample(trace, dt)
    hits, off = check(states, box, field, footprint)
    t, x, y, theta = states["t"], states["x"], states["y"], states["theta"]
    k_hit, k_off = _first(hits), _first(off)
    differences: list[str] = []
    explained = True
    own_zone = zone_of_obstacle(box, footprint)
    if k_hit is not None and not verdict.collided:
        c = float(zone.clearance(x[k_hit], y[k_hit]))
        if float(own_zone.clearance(x[k_hit], y[k_hit])) > 0.0:
            why = (f"the footprint touches the obstacle at t = {t[k_hit]:.2f} s, yawed {theta[k_hit]:+.3f} rad, while "
                   f"the CoG stays {c:.2f} m outside the danger zone: the zone is the obstacle enlarged by the car "
                   "at heading 0, and a yawed car's corners reach further")
        elif note is not None:
            why = (f"the footprint touches the obstacle at t = {t[k_hit]:.2f} s with the CoG {c:.2f} m outside the "
                   f"run's danger zone but inside the obstacle's: {note}")
        else:
            why, explained = f"unexplained: the footprint touches the obstacle at t = {t[k_hit]:.2f} s", False
        differences.append(why)
    if verdict.collided and k_hit is None:
        inside = zone.clearance(x, y) <= 0.0
        k_in = _first(inside)
        if k_in is not None and float(own_zone.clearance(x[k_in], y[k_in])) > 0.0 and note is not None:
            why = (f"the CoG enters the run's danger zone at t = {t[k_in]:.2f} s but not the obstacle's, and the "
                   f"footprint never touches the obstacle: {note}")
        elif k_in is not None:
            why = (f"the CoG enters the danger zone at t = {t[k_in]:.2f} s yawed {theta[k_in]:+.3f} rad, and the "
                   "footprint never touches the obstacle: a yawed car no longer covers the enlarged zone's corner")
        elif any(segment_hits_box(x[i], y[i], x[i + 1], y[i + 1], zone) for i in range(len(x) - 1)):
            why = ("the CoG path crosses a corner of the danger zone between two samples, where the checker, which "
                   "checks the footprint at the samples, sees no contact")
        else:
            why, explained = "unexplained: our verdict finds the CoG in the danger zone, the checker no contact", False
        differences.append(why)
    if k_off is not None and not verdict.left_field:
        depth = float(-field.clearance(x[k_off], y[k_off]))
        differences.append(f"the footprint crosses the road's edge at t = {t[k_off]:.2f} s while the CoG stays "
                           f"{depth:.2f} m inside the field: the field bounds the CoG (the paper's), the road the "
                           "whole car")
    if verdict.left_field and k_off is None:
        differences.append("unexplained: the CoG leaves the field, the footprint never touches the road's edge")
        explained = False
    agrees = (k_hit is not None) == verdict.collided and (k_off is not None) == verdict.left_field
    return CommonRoadVerdict(
        collision=k_hit is not None, collision_t_s=None if k_hit is None else k_hit * dt,
        road_compliant=k_off is None, off_road_t_s=None if k_off is None else k_off * dt,
        agrees=agrees, explained=explained, differences=tuple(differences))
