"""The literature's criticality measures at the detection instant, computed by commonroad-crime.

A criticality measure rates a situation, not what a planner then did: CriMe's time-to-X measures assume the
ego's own predicted trajectory and ask how late a maneuver could still leave it.  Ours is the trajectory of a car
that does nothing: from its true state at detection it drives on at constant velocity along its heading (to
past the obstacle).  The road and the obstacle are those of the export (:func:`moose.commonroad.scenario.export_run`:
the obstacle with its real size, the ego's lanelet the strip the danger zone blocks) at a time step of
:data:`DT`, and the vehicle is ours, not one of CriMe's three passenger cars:

* braking (TTB) and kick-down (TTK): ``a_max`` = the most the rear motors can give (the grid's longitudinal
  bound, :attr:`moose.params.VehicleParams.longitudinal_accel_limit`: 1.40 m/s² at any μ ≥ 0.2);
* steering (TTS): ``a_max`` = the lateral bound μ g (the lateral acceleration of CriMe's bang-bang lane change
  by the width of the ego's lanelet, ``time.steer_width = 2``);
* no speed above which the acceleration falls (``v_switch`` above the field's top speed), and the friction
  circle μ g as the point-mass model's Cartesian bounds.

Measures (SI keys): ``ttc_s`` (time to collision, constant acceleration), ``ttb_s`` (time to brake: the latest
start of full braking that avoids the collision), ``tts_s`` (time to steer), ``ttk_s`` (time to kick-down),
``ttr_s`` (time to react: the latest of the three, CriMe's definition), ``thw_s`` (time headway), ``hw_m``
(headway: bumper to obstacle along the lane).  CriMe's required longitudinal deceleration (``ALongReq``) is left
out: version 0.4.5 takes a lane orientation of 0 (a road along x, as every moose road) for "outside the lanelet"
and returns 0 m/s², a silently wrong value.
CriMe reports +∞ for "never needed" and −∞ for "no such maneuver avoids it" (a kick-down never passes a static
obstacle in the path); the summary keeps them as ``null`` with a note, as every non-finite quantity.
"""
from __future__ import annotations

import copy
import functools
import logging
import math
from typing import Any

import numpy as np
from commonroad.geometry.shape import Rectangle
from commonroad.prediction.prediction import TrajectoryPrediction
from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType
from commonroad.scenario.scenario import Scenario as CrScenario
from commonroad.scenario.scenario import ScenarioID
from commonroad.scenario.state import InitialState, KSState
from commonroad.scenario.trajectory import Trajectory

from ..params import VehicleParams
from ..scenario import V_MAX_FIELD, Scenario
from ..signals import Obstacle as Box
from . import EGO_ID, OBSTACLE_ID
from .geometry import Footprint, obstacle_of_zone
from .scenario import lanelets, static_obstacle

DT = 0.05
"""Time step of the criticality scenario (s): the resolution of TTB, TTS, TTK and TTR."""
MARGIN_S = 1.0
"""How long the do-nothing trajectory runs on after its rear bumper has passed the obstacle (s)."""
ROAD_BEYOND_M = 10.0
"""How much road the criticality scenario keeps behind the car and beyond the end of its do-nothing trajectory (m):
CriMe smooths and projects onto the lanelets at every step it simulates, so it gets the part of the field the
measures look at, not the whole field."""
KEYS = ("ttc_s", "ttb_s", "tts_s", "ttk_s", "ttr_s", "thw_s", "hw_m")
"""The keys of :func:`measures`, in order."""


def _scenario(state: dict[str, float], scenario: Scenario, vehicle: VehicleParams) -> CrScenario:
    """Road, obstacle and the do-nothing ego from ``state`` (CoG x, y, θ, speed) at time step 0."""
    footprint = Footprint.of(vehicle)
    box, _ = obstacle_of_zone(scenario.danger_zone, footprint)
    cr = CrScenario(DT, ScenarioID(map_name="moose", obstacle_behavior="T", configuration_id=2))
    cr.add_objects(static_obstacle(box))
    x, y, theta, v = state["x"], state["y"], state["theta"], state["v"]
    c, s = math.cos(theta), math.sin(theta)
    span = max(0.0, box.x_max + footprint.rear - x)
    steps = int(math.ceil((span / max(v * c, 1e-3) + MARGIN_S) / DT)) if v * c > 0.0 else int(MARGIN_S / DT)
    steps = min(steps, int(60.0 / DT))

    end = min(scenario.field.x_max, x + v * c * steps * DT + ROAD_BEYOND_M)
    road = Box(max(scenario.field.x_min, x - ROAD_BEYOND_M), max(end, x + ROAD_BEYOND_M), scenario.field.y_min,
               scenario.field.y_max)
    cr.add_objects(lanelets(road, scenario.danger_zone))

    def centre(k: int) -> np.ndarray:
        return np.array([x + footprint.offset * c + v * c * k * DT, y + footprint.offset * s + v * s * k * DT])

    shape = Rectangle(footprint.length, footprint.width)
    initial = InitialState(time_step=0, position=centre(0), orientation=theta, velocity=v, acceleration=0.0,
                           yaw_rate=0.0, slip_angle=0.0)
    states = [KSState(time_step=k, position=centre(k), orientation=theta, velocity=v, steering_angle=0.0)
              for k in range(1, steps + 1)]
    ego = DynamicObstacle(EGO_ID, ObstacleType.CAR, shape, initial,
                          TrajectoryPrediction(Trajectory(1, states), shape))
    cr.add_objects(ego)
    cr.assign_obstacles_to_lanelets()
    return cr


def _configuration(cr: CrScenario, vehicle: VehicleParams, a_max: float) -> Any:
    from commonroad_crime.data_structure.configuration import CriMeConfiguration

    config = CriMeConfiguration()
    config.update(ego_id=EGO_ID, sce=cr)
    config.time.steer_width = 2
    config.debug.save_plots = False
    config.vehicle.width, config.vehicle.length = vehicle.width, vehicle.length
    params = copy.deepcopy(config.vehicle.params)
    params.longitudinal.a_max = a_max
    params.longitudinal.v_switch = 2.0 * V_MAX_FIELD
    params.longitudinal.v_max = 2.0 * V_MAX_FIELD
    config.vehicle.params = params
    grip = vehicle.lateral_accel_limit
    cartesian = config.vehicle.cartesian
    cartesian.a_x_min, cartesian.a_x_max, cartesian.a_y_min, cartesian.a_y_max = -grip, grip, -grip, grip
    return config


def situation(scenario: Scenario) -> dict[str, float]:
    """The car's state at the detection instant as the scenario places it: on its path (y = 0, heading 0) at
    x_min − v τ, at ``v_init`` (:attr:`moose.scenario.Scenario.x_appear`)."""
    return {"x": scenario.x_appear, "y": 0.0, "theta": 0.0, "v": scenario.v_init}


@functools.lru_cache(maxsize=256)
def measures(scenario: Scenario, vehicle: VehicleParams) -> dict[str, float]:
    """The criticality measures (:data:`KEYS`) of ``scenario``'s situation (:func:`situation`) for ``vehicle``
    (its footprint and limits, at its μ), computed once per situation in a process."""
    from commonroad_crime.measure.distance.hw import HW
    from commonroad_crime.measure.time.thw import THW
    from commonroad_crime.measure.time.ttb import TTB
    from commonroad_crime.measure.time.ttc import TTC
    from commonroad_crime.measure.time.ttk import TTK
    from commonroad_crime.measure.time.tts import TTS

    cr = _scenario(situation(scenario), scenario, vehicle)
    longitudinal = _configuration(cr, vehicle, vehicle.longitudinal_accel_limit)
    lateral = _configuration(cr, vehicle, vehicle.lateral_accel_limit)
    quiet = logging.getLogger("commonroad_crime")
    level = quiet.level
    quiet.setLevel(logging.ERROR)
    try:
        out = {
            "ttc_s": TTC(longitudinal).compute(OBSTACLE_ID, 0, verbose=False),
            "ttb_s": TTB(longitudinal).compute(0, OBSTACLE_ID, verbose=False),
            "tts_s": TTS(lateral).compute(0, OBSTACLE_ID, verbose=False),
            "ttk_s": TTK(longitudinal).compute(0, OBSTACLE_ID, verbose=False),
            "thw_s": THW(longitudinal).compute(OBSTACLE_ID, 0, verbose=False),
            "hw_m": HW(longitudinal).compute(OBSTACLE_ID, 0, verbose=False),
        }
    finally:
        quiet.setLevel(level)
    out["ttr_s"] = max(out["ttb_s"], out["tts_s"], out["ttk_s"])  # CriMe's TTR: the latest of the three
    return {key: float(out[key]) for key in KEYS}
