"""A run as a CommonRoad scenario (commonroad-io), and a CommonRoad scenario as a moose test.

**Export** (:func:`export_run`, :func:`write_run`; ``moose simulate --commonroad-out``, ``moose bag export
--format commonroad``).  The scenario's time step is the trace's, 10 ms (the motion-control rate: nothing
recorded is dropped); time step k is the run's time k·dt.

* The road: straight lanelets along x covering the field, split at the danger zone's lateral edges, so the
  ego's lanelet is the strip the zone blocks (commonroad-crime's steering maneuver changes lanes by its width).
* The obstacle (:data:`~moose.commonroad.OBSTACLE_ID`): a static obstacle with its real size, the danger zone
  shrunk by the footprint (:func:`moose.commonroad.geometry.obstacle_of_zone`).
* The ego's driven path (:data:`~moose.commonroad.EGO_ID`): a dynamic obstacle of type ``car`` with the
  footprint (``vehicle.length`` × ``vehicle.width``) and a single-track state at every time step.  As CommonRoad's
  readers assume, a state's position is the centre of the footprint, ``vehicle.footprint_offset`` ahead of the
  CoG along the heading; velocity (|v|), slip angle, yaw rate and steering angle are the CoG's.
* The planning problem (:data:`~moose.commonroad.PLANNING_PROBLEM_ID`): the ego's state at the detection
  instant (when the obstacle appears; the start of the run if it never does), and the goal of the moose test:
  the CoG past the zone's far edge (the footprint's centre ``footprint_offset`` further), inside the field,
  before the run ends.

**Import** (:func:`load`; ``moose simulate --commonroad FILE``).  One planning problem, one static rectangular
obstacle in the ego's path, a straight road along the ego's heading: the moose test in the ego's frame (CoG at
the origin, x along its heading), τ = (near edge of the danger zone) / v, the zone the obstacle grown by the
footprint, the field the lanelets' extent, no lead time (the obstacle is there from the first instant).  A
dynamic obstacle with the id :data:`~moose.commonroad.EGO_ID` is a recorded ego path and is ignored; anything
else the moose test cannot represent is a :class:`~moose.params.ParamError` that names it.
"""
from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any, Mapping, Optional

import numpy as np
from commonroad.common.file_reader import CommonRoadFileReader
from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
from commonroad.common.util import AngleInterval, Interval
from commonroad.geometry.shape import Rectangle
from commonroad.planning.goal import GoalRegion
from commonroad.planning.planning_problem import PlanningProblem, PlanningProblemSet
from commonroad.prediction.prediction import TrajectoryPrediction
from commonroad.scenario.lanelet import Lanelet, LaneletNetwork, LaneletType
from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType, StaticObstacle
from commonroad.scenario.scenario import Location, ScenarioID
from commonroad.scenario.scenario import Scenario as CrScenario
from commonroad.scenario.state import CustomState, InitialState, STState
from commonroad.scenario.trajectory import Trajectory

from ..params import ParamError, VehicleParams
from ..scenario import V_MAX_FIELD, Scenario
from ..signals import Obstacle as Box
from . import EGO_ID, OBSTACLE_ID, PLANNING_PROBLEM_ID
from .geometry import DT, Footprint, obstacle_of_zone, resample, zone_of_obstacle

VERTEX_SPACING = 1.0
"""Distance between a lanelet's vertices (m): commonroad-crime smooths and projects onto them."""
STRAIGHT_TOLERANCE = 0.01
"""How far a lanelet's vertex may lie off the straight line through its ends, and how far the lanelets' union may
fall short of its bounding box (m, m²/m), for the road to count as straight and rectangular."""
ANGLE_TOLERANCE = 0.01
"""How far the ego's heading, a lanelet's and the obstacle's direction may differ from the road's (rad), and how
large the ego's initial yaw rate (rad/s) and slip angle (rad) may be: what the moose test, which starts straight
along a straight road, takes as zero."""
DURATION_DEFAULT = 8.0
"""Simulated time of an imported scenario whose goal sets no time (s): a scenario file's default."""


@dataclasses.dataclass(frozen=True)
class Exported:
    """A run as CommonRoad objects."""

    scenario: CrScenario
    problems: PlanningProblemSet
    ego: DynamicObstacle
    obstacle: StaticObstacle
    footprint: Footprint
    box: Box
    """The obstacle's rectangle."""
    zone: Box
    """The run's danger zone."""
    field: Box
    """The run's field."""
    detection_step: int
    """Time step of the planning problem's initial state."""
    note: Optional[str]
    """Why the obstacle's danger zone is not the run's (a zone shorter or narrower than the car), or None."""


def lanelets(field: Box, zone: Box) -> LaneletNetwork:
    """Straight lanelets along x over the field, split at the zone's lateral edges, numbered 1, 2, … from the
    right, each the left neighbour (same direction) of the one before."""
    edges = sorted({field.y_min, field.y_max, *(y for y in (zone.y_min, zone.y_max) if field.y_min < y < field.y_max)})
    n = max(2, int(math.ceil((field.x_max - field.x_min) / VERTEX_SPACING)) + 1)
    xs = np.linspace(field.x_min, field.x_max, n)
    network = LaneletNetwork()
    count = len(edges) - 1
    def line(y: float) -> np.ndarray:
        return np.column_stack((xs, np.full(n, y)))

    for i, (low, high) in enumerate(zip(edges[:-1], edges[1:])):
        left = i + 1 < count
        network.add_lanelet(Lanelet(
            left_vertices=line(high), center_vertices=line(0.5 * (low + high)), right_vertices=line(low),
            lanelet_id=i + 1, lanelet_type={LaneletType.UNKNOWN},
            adjacent_left=i + 2 if left else None, adjacent_left_same_direction=True if left else None,
            adjacent_right=i if i > 0 else None, adjacent_right_same_direction=True if i > 0 else None))
    return network


def static_obstacle(box: Box) -> StaticObstacle:
    """The obstacle (:data:`~moose.commonroad.OBSTACLE_ID`, type ``unknown``): the rectangle ``box``."""
    return StaticObstacle(
        OBSTACLE_ID, ObstacleType.UNKNOWN, Rectangle(box.x_max - box.x_min, box.y_max - box.y_min),
        InitialState(time_step=0, position=np.array([0.5 * (box.x_min + box.x_max), 0.5 * (box.y_min + box.y_max)]),
                     orientation=0.0, velocity=0.0, acceleration=0.0, yaw_rate=0.0, slip_angle=0.0))


def export_run(trace: Mapping[str, np.ndarray], scenario: Scenario, vehicle: VehicleParams,
               detection_t: Optional[float], dt: float = DT) -> Exported:
    """The run (its trace of the true state: t, x, y, θ, v_x, v_y, δ) as a CommonRoad scenario and planning
    problem; ``detection_t`` is when the obstacle was detected (None: never)."""
    footprint = Footprint.of(vehicle)
    states = resample(trace, dt)
    zone = scenario.danger_zone
    box, note = obstacle_of_zone(zone, footprint)
    cr = CrScenario(dt, ScenarioID(map_name="moose", obstacle_behavior="T", configuration_id=1),
                    author="moose", source=f"moose test {scenario.name}")
    cr.add_objects(lanelets(scenario.field, zone))
    obstacle = static_obstacle(box)
    cx, cy = footprint.centre(states["x"], states["y"], states["theta"])
    speed = np.hypot(states["vx"], states["vy"])
    slip = np.arctan2(states["vy"], states["vx"])
    steps = len(states["t"])
    gamma = states["gamma"] if "gamma" in states else (
        np.gradient(states["theta"], dt) if steps > 1 else np.zeros(1))
    delta = states.get("delta", np.zeros(steps))

    def state(k: int) -> STState:
        return STState(time_step=k, position=np.array([cx[k], cy[k]]), orientation=float(states["theta"][k]),
                       velocity=float(speed[k]), slip_angle=float(slip[k]), yaw_rate=float(gamma[k]),
                       steering_angle=float(delta[k]))

    shape = Rectangle(footprint.length, footprint.width)
    first = state(0)
    initial = InitialState(time_step=0, position=first.position, orientation=first.orientation,
                           velocity=first.velocity, acceleration=0.0, yaw_rate=first.yaw_rate,
                           slip_angle=first.slip_angle)
    prediction = (TrajectoryPrediction(Trajectory(1, [state(k) for k in range(1, steps)]), shape)
                  if steps > 1 else None)
    ego = DynamicObstacle(EGO_ID, ObstacleType.CAR, shape, initial, prediction)
    cr.add_objects([obstacle, ego])
    k0 = 0 if detection_t is None else int(min(max(round(detection_t / dt), 0), steps - 1))
    at = state(k0)
    problem_initial = InitialState(time_step=k0, position=at.position, orientation=at.orientation,
                                   velocity=at.velocity, acceleration=0.0, yaw_rate=at.yaw_rate,
                                   slip_angle=at.slip_angle)
    field = scenario.field
    end = int(round(scenario.end_time / dt))
    past = Rectangle(field.x_max - zone.x_max, field.y_max - field.y_min,
                     center=np.array([0.5 * (zone.x_max + field.x_max) + footprint.offset,
                                      0.5 * (field.y_min + field.y_max)]))
    goal = GoalRegion([CustomState(time_step=Interval(k0, max(end, k0)), position=past,
                                   orientation=AngleInterval(-0.5 * math.pi, 0.5 * math.pi))])
    problems = PlanningProblemSet([PlanningProblem(PLANNING_PROBLEM_ID, problem_initial, goal)])
    return Exported(cr, problems, ego, obstacle, footprint, box, zone, field, k0, note)


def write(exported: Exported, path: str | Path) -> Path:
    """Write ``exported`` as a CommonRoad XML file: into a temporary file beside ``path``, renamed over it when
    complete (an existing file is replaced only by a whole one)."""
    path = Path(path)
    partial = path.with_name(f".{path.name}.partial")
    writer = CommonRoadFileWriter(exported.scenario, exported.problems, author="moose", affiliation="",
                                  source=exported.scenario.source or "moose", tags=set(), location=Location(),
                                  decimal_precision=6)
    try:
        writer.write_to_file(str(partial), OverwriteExistingFile.ALWAYS)
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)
    return path


def write_run(result: Any, path: str | Path) -> Path:
    """Write a run (:class:`moose.simulation.SimulationResult`) as a CommonRoad XML file."""
    first = result.first_threat
    exported = export_run(result.trace, result.scenario, result.config.vehicle,
                          first.t if first is not None else None)
    return write(exported, path)


# --------------------------------------------------------------------------------------------------- import


def read(path: str | Path) -> tuple[CrScenario, PlanningProblemSet]:
    """The scenario and planning problems of a CommonRoad file; an unreadable file is a ParamError."""
    path = Path(path)
    if not path.is_file():
        raise ParamError(f"--commonroad {str(path)!r}: no such file")
    try:
        return CommonRoadFileReader(str(path)).open()
    except Exception as exc:  # noqa: BLE001 - commonroad-io raises whatever its XML and schema code raise
        raise ParamError(f"--commonroad {str(path)!r} is not a readable CommonRoad file: "
                         f"{type(exc).__name__}: {exc}") from None


def _frame(origin: np.ndarray, direction: float) -> Any:
    """The map of points (…, 2) of the scenario into the frame with its origin at ``origin`` and x along
    ``direction``."""
    c, s = math.cos(direction), math.sin(direction)

    def to_frame(points: Any) -> np.ndarray:
        d = np.asarray(points, dtype=float) - origin
        return np.stack((c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]), axis=-1)

    return to_frame


def _angle_off(angle: float) -> float:
    """How far a direction lies from the x axis, either way along it: |angle| folded onto [0, π/2] (rad)."""
    return abs(math.remainder(angle, math.pi))


def load(path: str | Path, vehicle: VehicleParams, mu: Optional[float] = None) -> Scenario:
    """The moose test of a CommonRoad file (see the module's docstring); what it cannot represent is a
    :class:`~moose.params.ParamError` that names it."""
    where = f"--commonroad {str(path)!r}"
    cr, problems = read(path)
    pps = list(problems.planning_problem_dict.values())
    if len(pps) != 1:
        raise ParamError(f"{where}: {len(pps)} planning problems, a moose test has one ego")
    initial = pps[0].initial_state
    for name in ("yaw_rate", "slip_angle"):
        value = float(getattr(initial, name, 0.0) or 0.0)
        if abs(value) > ANGLE_TOLERANCE:
            raise ParamError(f"{where}: the ego's initial {name} = {value:g} cannot be represented: a moose test "
                             f"starts driving straight (|{name}| ≤ {ANGLE_TOLERANCE:g})")
    dynamic = [o.obstacle_id for o in cr.dynamic_obstacles if o.obstacle_id != EGO_ID]
    if dynamic:
        raise ParamError(f"{where}: dynamic obstacles (ids {dynamic}) cannot be represented: the moose test has one "
                         "static obstacle")
    statics = list(cr.static_obstacles)
    if len(statics) != 1:
        ids = [o.obstacle_id for o in statics]
        raise ParamError(f"{where}: {'no static obstacle' if not statics else f'several obstacles (ids {ids})'} "
                         "cannot be represented: the moose test has exactly one")
    lanelets = list(cr.lanelet_network.lanelets)
    if not lanelets:
        raise ParamError(f"{where}: no lanelets: the field comes from the road")
    footprint = Footprint.of(vehicle)
    heading = float(initial.orientation)
    centre = np.asarray(initial.position, dtype=float)
    if centre.shape != (2,):
        raise ParamError(f"{where}: the ego's initial position is not a point ({initial.position!r})")
    axis = lanelets[0].center_vertices[-1] - lanelets[0].center_vertices[0]
    road = math.atan2(axis[1], axis[0])
    if math.cos(road - heading) < 0.0:
        road += math.pi  # the lanelet runs against the ego: the frame's x axis is the ego's way along it
    cog = centre - footprint.offset * np.array([math.cos(heading), math.sin(heading)])
    to_road = _frame(cog, road)
    field = _field(lanelets, to_road, where)
    if abs(math.remainder(heading - road, 2.0 * math.pi)) > ANGLE_TOLERANCE:
        raise ParamError(f"{where}: the ego heads {math.remainder(heading - road, 2.0 * math.pi):.3f} rad off the "
                         f"road, which cannot be represented: a moose test starts along the road "
                         f"(within {ANGLE_TOLERANCE:g} rad)")
    obstacle = statics[0]
    zone = zone_of_obstacle(_obstacle_box(obstacle, road, to_road, where), footprint)
    if not zone.y_min <= 0.0 <= zone.y_max:
        raise ParamError(f"{where}: obstacle {obstacle.obstacle_id} is not in the ego's path (its danger zone spans "
                         f"y = {zone.y_min:.2f} .. {zone.y_max:.2f} m beside the ego's path)")
    if not zone.x_min > 0.0:
        raise ParamError(f"{where}: obstacle {obstacle.obstacle_id} is not ahead of the ego (its danger zone starts "
                         f"{zone.x_min:.2f} m ahead of the CoG)")
    v = float(initial.velocity)
    if not 0.0 < v <= V_MAX_FIELD:
        raise ParamError(f"{where}: the ego's initial velocity = {v:g} m/s is invalid: expected a speed in "
                         f"(0, {V_MAX_FIELD:g}] m/s")
    duration = DURATION_DEFAULT
    ends = [s.time_step.end for s in pps[0].goal.state_list if isinstance(getattr(s, "time_step", None), Interval)]
    if ends:
        duration = min(120.0, max(cr.dt, (max(ends) - initial.time_step) * cr.dt))
    name = str(cr.scenario_id) or Path(path).stem
    return Scenario(name=name, v_init=v, v_des=v, tau=zone.x_min / v, obstacle=zone, field=field,
                    duration=duration, lead_time=0.0, mu=mu,
                    description=f"CommonRoad scenario {name} ({Path(path).name}), obstacle {obstacle.obstacle_id}")


def _obstacle_box(obstacle: StaticObstacle, road: float, to_road: Any, where: str) -> Box:
    """The obstacle's rectangle in the road's frame, after checking it is one and aligned with the road."""
    shape = obstacle.obstacle_shape
    if not isinstance(shape, Rectangle):
        raise ParamError(f"{where}: obstacle {obstacle.obstacle_id} is a {type(shape).__name__}, which cannot be "
                         "represented: the moose test's obstacle is a rectangle")
    orientation = float(shape.orientation) + float(getattr(obstacle.initial_state, "orientation", 0.0) or 0.0)
    turned = _angle_off(orientation - road)
    if ANGLE_TOLERANCE < turned < 0.5 * math.pi - ANGLE_TOLERANCE:
        raise ParamError(f"{where}: obstacle {obstacle.obstacle_id} is turned {turned:.3f} rad against the ego's "
                         "heading, which cannot be represented: the moose test's obstacle is aligned with the road")
    corners = to_road(obstacle.occupancy_at_time(obstacle.initial_state.time_step).shape.vertices)
    return Box(float(corners[:, 0].min()), float(corners[:, 0].max()), float(corners[:, 1].min()),
               float(corners[:, 1].max()))


def _field(lanelets: list[Lanelet], to_road: Any, where: str) -> Box:
    """The lanelets' extent in the road's frame, after checking each is straight and along the road and that
    together they cover a rectangle."""
    from shapely.geometry import Polygon as ShapelyPolygon
    from shapely.ops import unary_union

    parts = []
    for lanelet in lanelets:
        for side in (lanelet.left_vertices, lanelet.right_vertices):
            points = to_road(side)
            start, end = points[0], points[-1]
            direction = end - start
            length = float(np.hypot(*direction))
            if length == 0.0:
                raise ParamError(f"{where}: lanelet {lanelet.lanelet_id} has a boundary of zero length")
            normal = np.array([-direction[1], direction[0]]) / length
            off_line = float(np.max(np.abs((points - start) @ normal)))
            if off_line > STRAIGHT_TOLERANCE:
                raise ParamError(f"{where}: lanelet {lanelet.lanelet_id} is curved ({off_line:.2f} m off a straight "
                                 "line), which cannot be represented: the moose test's road is straight")
            angle = _angle_off(math.atan2(direction[1], direction[0]))
            if angle > ANGLE_TOLERANCE:
                raise ParamError(f"{where}: lanelet {lanelet.lanelet_id} runs {angle:.3f} rad off lanelet "
                                 f"{lanelets[0].lanelet_id}, which cannot be represented: the moose test's road is "
                                 "one straight road")
        parts.append(ShapelyPolygon(to_road(lanelet.polygon.vertices)).buffer(0))
    union = unary_union(parts)
    x_min, y_min, x_max, y_max = union.bounds
    gap = (x_max - x_min) * (y_max - y_min) - union.area
    if gap > STRAIGHT_TOLERANCE * max(x_max - x_min, y_max - y_min):
        raise ParamError(f"{where}: the lanelets do not cover a rectangle ({gap:.1f} m² of their extent is no road), "
                         "which cannot be represented: the moose test's field is a rectangle")
    return Box(float(x_min), float(x_max), float(y_min), float(y_max))
