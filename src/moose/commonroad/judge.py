"""An independent verdict of a run: commonroad-drivability-checker's collision check of the car's footprint against
the obstacle and its road-compliance check against the road, beside our verdict (:func:`moose.verdict.judge`: the
CoG path in the danger zone, a CoG sample outside the field).

Both are computed from the export (:func:`moose.commonroad.scenario.export_run`): the footprint at every 10 ms time
step as the checker's time-variant collision object of the ego, the obstacle with its real size, and the road
boundary of the lanelets (``create_road_boundary_obstacle``, oriented rectangles along the road's outline): the car
left the road when its footprint touches the boundary.

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

import numpy as np
from commonroad_dc.boundary.boundary import create_road_boundary_obstacle
from commonroad_dc.collision.collision_detection.pycrcc_collision_dispatch import create_collision_object

from ..verdict import Verdict, segment_hits_box
from .geometry import zone_of_obstacle
from .scenario import Exported, resample


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


def check(exported: Exported) -> tuple[np.ndarray, np.ndarray]:
    """Per time step 0, 1, … of the ego's trajectory: does the footprint touch the obstacle, does it touch the
    road's boundary (drivability checker)."""
    ego = create_collision_object(exported.ego)
    obstacle = create_collision_object(exported.obstacle)
    _, boundary = create_road_boundary_obstacle(exported.scenario, method="obb_rectangles")
    if ego.time_start_idx() != 0:
        raise ValueError(f"the ego's collision object starts at time step {ego.time_start_idx()}, not 0")
    at = [ego.obstacle_at_time(k) for k in range(ego.time_end_idx() + 1)]
    hits = np.array([a.collide(obstacle) for a in at], dtype=bool)
    off = np.array([boundary.collide(a) for a in at], dtype=bool)
    return hits, off


def compare(exported: Exported, trace: Any, verdict: Verdict) -> CommonRoadVerdict:
    """The drivability checker's verdict of the exported run (of ``trace``) beside ``verdict`` (ours), with the
    reasons for every difference."""
    hits, off = check(exported)
    states = resample(trace, exported.scenario.dt)
    t, x, y, theta = states["t"], states["x"], states["y"], states["theta"]
    dt, zone, field = exported.scenario.dt, exported.zone, exported.field
    k_hit, k_off = _first(hits), _first(off)
    differences: list[str] = []
    explained = True
    own_zone = zone_of_obstacle(exported.box, exported.footprint)
    if k_hit is not None and not verdict.collided:
        c = float(zone.clearance(x[k_hit], y[k_hit]))
        if float(own_zone.clearance(x[k_hit], y[k_hit])) > 0.0:
            why = (f"the footprint touches the obstacle at t = {t[k_hit]:.2f} s, yawed {theta[k_hit]:+.3f} rad, while "
                   f"the CoG stays {c:.2f} m outside the danger zone: the zone is the obstacle enlarged by the car "
                   "at heading 0, and a yawed car's corners reach further")
        elif exported.note is not None:
            why = (f"the footprint touches the obstacle at t = {t[k_hit]:.2f} s with the CoG {c:.2f} m outside the "
                   f"run's danger zone but inside the obstacle's: {exported.note}")
        else:
            why, explained = f"unexplained: the footprint touches the obstacle at t = {t[k_hit]:.2f} s", False
        differences.append(why)
    if verdict.collided and k_hit is None:
        inside = zone.clearance(x, y) <= 0.0
        k_in = _first(inside)
        if k_in is not None and float(own_zone.clearance(x[k_in], y[k_in])) > 0.0 and exported.note is not None:
            why = (f"the CoG enters the run's danger zone at t = {t[k_in]:.2f} s but not the obstacle's, and the "
                   f"footprint never touches the obstacle: {exported.note}")
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
