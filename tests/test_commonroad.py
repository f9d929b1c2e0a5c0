"""CommonRoad, tested against the packages themselves: a run written as a scenario and read back by commonroad-io,
a CommonRoad scenario run as a moose test (and what cannot be one refused by name), the drivability checker's
verdict beside ours on the paper's cases, the comparison cases and sweep cases with collisions, and
commonroad-crime's measures against their closed forms."""
from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from commonroad.common.file_reader import CommonRoadFileReader
from commonroad.common.file_writer import CommonRoadFileWriter, OverwriteExistingFile
from commonroad.geometry.shape import Rectangle
from commonroad.planning.planning_problem import PlanningProblemSet
from commonroad.prediction.prediction import TrajectoryPrediction
from commonroad.scenario.lanelet import Lanelet
from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType, StaticObstacle
from commonroad.scenario.state import InitialState, KSState
from commonroad.scenario.trajectory import Trajectory

from moose.commonroad import EGO_ID, OBSTACLE_ID, PLANNING_PROBLEM_ID, criticality
from moose.commonroad.assess import assess
from moose.commonroad.geometry import Footprint, obstacle_of_zone, resample, zone_of_obstacle
from moose.commonroad.judge import check, compare
from moose.commonroad.scenario import export_run, load, write, write_run
from moose.config import load_config
from moose.metrics import summarize
from moose.params import ParamError
from moose.scenario import adhoc_scenario, available_scenarios, load_scenario
from moose.signals import Obstacle as Box
from moose.simulation import SimulationResult, simulate
from moose.verdict import judge as our_verdict

CONFIG = load_config()
FOOTPRINT = Footprint.of(CONFIG.vehicle)
SWEEP_SAMPLE = (  # (speed, τ, half width, μ, planner): sweep cases of the paper region, collisions and a car that
    # leaves the road (the baseline max_steer) among them
    (7.0, 1.0, 3.0, 0.33, "msf"), (7.0, 1.0, 3.0, 0.33, "combined"), (8.0, 2.0, 2.5, 0.33, "combined"),
    (5.0, 1.0, 1.0, 0.8, "mpc"), (6.0, 2.5, 4.0, 0.33, "mpc"), (4.0, 1.0, 0.3, 0.8, "msf"),
    (8.0, 1.0, 2.0, 0.8, "combined"), (6.0, 1.5, 2.5, 0.33, "mpc"), (6.0, 2.5, 2.0, 0.33, "max_steer"),
    (7.0, 1.5, 1.0, 0.8, "aeb"),
)


@pytest.fixture(scope="module")
def runs() -> dict[str, SimulationResult]:
    """The paper's nine cases and the comparison cases (combined planner), and the sweep sample."""
    out = {name: simulate(CONFIG, load_scenario(name)) for name in available_scenarios()}
    for v, tau, w, mu, planner in SWEEP_SAMPLE:
        scenario = dataclasses.replace(adhoc_scenario(v, tau, w, field_margin=5.0), mu=mu)
        out[f"{scenario.name}_mu{mu}_{planner}"] = simulate(CONFIG, scenario, planner)
    return out


def test_a_run_is_written_as_a_scenario_commonroad_io_reads_back(runs: dict, tmp_path: Path) -> None:
    result = runs["paper_v5_tau3"]
    path = write_run(result, tmp_path / "run.xml")
    scenario, problems = CommonRoadFileReader(str(path)).open()
    assert scenario.dt == pytest.approx(0.01)
    field = result.scenario.field
    network = scenario.lanelet_network
    corners = np.vstack([lanelet.polygon.vertices for lanelet in network.lanelets])
    assert corners.min(axis=0) == pytest.approx([field.x_min, field.y_min])
    assert corners.max(axis=0) == pytest.approx([field.x_max, field.y_max])
    obstacle = scenario.obstacle_by_id(OBSTACLE_ID)
    assert isinstance(obstacle, StaticObstacle)
    box, note = obstacle_of_zone(result.scenario.danger_zone, FOOTPRINT)
    assert obstacle.obstacle_shape.width == pytest.approx(box.y_max - box.y_min)
    assert zone_of_obstacle(box, FOOTPRINT).y_max == pytest.approx(result.scenario.danger_zone.y_max)
    assert note is not None and "2.00 m long" in note  # the paper's zones are shorter than the car
    ego = scenario.obstacle_by_id(EGO_ID)
    assert isinstance(ego, DynamicObstacle) and ego.obstacle_type == ObstacleType.CAR
    assert (ego.obstacle_shape.length, ego.obstacle_shape.width) == (CONFIG.vehicle.length, CONFIG.vehicle.width)
    trace = result.trace
    assert ego.prediction.final_time_step == len(trace["t"]) - 1
    for k in (0, 250, len(trace["t"]) - 1):  # the footprint's centre, (l_f − l_r)/2 ahead of the CoG
        state = ego.state_at_time(k)
        heading = trace["theta"][k]
        centre = np.array([trace["x"][k], trace["y"][k]]) + FOOTPRINT.offset * np.array([np.cos(heading),
                                                                                       np.sin(heading)])
        assert state.position == pytest.approx(centre, abs=1e-5)
        assert state.velocity == pytest.approx(math.hypot(trace["vx"][k], trace["vy"][k]), abs=1e-5)
    problem = problems.planning_problem_dict[PLANNING_PROBLEM_ID]
    assert problem.initial_state.time_step * 0.01 == pytest.approx(result.first_threat.t)
    assert problem.initial_state.velocity == pytest.approx(result.scenario.v_init, abs=0.05)


def test_an_exported_run_imports_as_the_same_moose_test(tmp_path: Path) -> None:
    """A zone longer and wider than the car is exactly an obstacle's: the round trip keeps it (in the ego's frame at
    detection), the field and τ."""
    scenario = dataclasses.replace(adhoc_scenario(6.0, 2.0, 2.0, obstacle_length=4.0), duration=3.0)
    result = simulate(CONFIG, scenario, "msf")
    path = write_run(result, tmp_path / "run.xml")
    back = load(path, CONFIG.vehicle)
    k = int(round(result.first_threat.t / 0.01))
    x0, y0 = result.trace["x"][k], result.trace["y"][k]
    zone, field = scenario.danger_zone, scenario.field
    assert back.obstacle.x_min == pytest.approx(zone.x_min - x0, abs=0.02)
    assert back.obstacle.x_max == pytest.approx(zone.x_max - x0, abs=0.02)
    assert back.obstacle.y_min == pytest.approx(zone.y_min - y0, abs=0.02)
    assert back.field.y_max == pytest.approx(field.y_max - y0, abs=0.02)
    assert back.field.x_max == pytest.approx(field.x_max - x0, abs=0.02)
    assert back.tau == pytest.approx(result.first_threat.tau, abs=0.01)
    assert back.v_init == pytest.approx(scenario.v_init, abs=0.05)
    assert back.lead_time == 0.0 and back.duration == pytest.approx(scenario.duration, abs=0.02)
    assert summarize(simulate(CONFIG, dataclasses.replace(back, duration=1.0), "msf"))["tau_s"] == pytest.approx(
        back.tau, abs=0.02)


def _lanelet(lanelet_id: int, y_low: float, y_high: float, bend: float = 0.0) -> Lanelet:
    xs = np.linspace(-20.0, 120.0, 141)
    curve = bend * (xs / 140.0) ** 2
    return Lanelet(np.column_stack((xs, y_high + curve)), np.column_stack((xs, 0.5 * (y_low + y_high) + curve)),
                   np.column_stack((xs, y_low + curve)), lanelet_id)


def _obstacle(obstacle_id: int, x: float, y: float, length: float = 2.0, width: float = 1.0) -> StaticObstacle:
    return StaticObstacle(obstacle_id, ObstacleType.PARKED_VEHICLE, Rectangle(length, width),
                          InitialState(time_step=0, position=np.array([x, y]), orientation=0.0, velocity=0.0,
                                       acceleration=0.0, yaw_rate=0.0, slip_angle=0.0))


def _file(tmp_path: Path, lanelets: list, obstacles: list, speed: float = 6.0) -> Path:
    """A CommonRoad scenario built with commonroad-io: the ego at the origin heading along x at ``speed``."""
    from commonroad.common.util import Interval
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem
    from commonroad.scenario.scenario import Location, Scenario, ScenarioID
    from commonroad.scenario.state import CustomState

    scenario = Scenario(0.1, ScenarioID(map_name="test"))
    scenario.add_objects(lanelets)
    scenario.add_objects(obstacles)
    start = InitialState(time_step=0, position=np.array([0.0, 0.0]), orientation=0.0, velocity=speed,
                         acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
    goal = GoalRegion([CustomState(time_step=Interval(0, 50))])
    problems = PlanningProblemSet([PlanningProblem(1, start, goal)])
    path = tmp_path / "scenario.xml"
    CommonRoadFileWriter(scenario, problems, author="test", affiliation="", source="test", tags=set(),
                         location=Location()).write_to_file(str(path), OverwriteExistingFile.ALWAYS)
    return path


def test_a_commonroad_scenario_runs_as_a_moose_test(tmp_path: Path) -> None:
    path = _file(tmp_path, [_lanelet(1, -1.75, 1.75), _lanelet(2, 1.75, 5.25)], [_obstacle(7, 30.0, 0.0)])
    scenario = load(path, CONFIG.vehicle)
    centre_to_cog = FOOTPRINT.offset  # the ego's position is its footprint's centre
    assert scenario.obstacle == pytest.approx(Box(29.0 - FOOTPRINT.front + centre_to_cog,
                                                  31.0 + FOOTPRINT.rear + centre_to_cog,
                                                  -0.5 - CONFIG.vehicle.width / 2, 0.5 + CONFIG.vehicle.width / 2))
    assert scenario.field == pytest.approx(Box(-20.0 + centre_to_cog, 120.0 + centre_to_cog, -1.75, 5.25))
    assert scenario.tau == pytest.approx(scenario.obstacle.x_min / 6.0)
    assert scenario.duration == pytest.approx(5.0)
    summary = summarize(simulate(CONFIG, scenario, "msf"))
    assert summary["tau_s"] == pytest.approx(scenario.tau, abs=0.02)
    assert summary["commonroad_verdict"]["explained"]


@pytest.mark.parametrize("case, needle", [
    ("two", "several obstacles (ids [7, 8])"),
    ("dynamic", "dynamic obstacles (ids [9])"),
    ("curved", "lanelet 1 is curved"),
    ("beside", "obstacle 7 is not in the ego's path"),
    ("none", "no static obstacle"),
])
def test_what_a_moose_test_cannot_represent_is_refused_by_name(tmp_path: Path, case: str, needle: str,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """By the reader and by ``moose simulate`` (in this process; as a child for one case, the command's smoke
    test: the exit status and stderr of the process)."""
    lanes = [_lanelet(1, -1.75, 1.75, bend=5.0 if case == "curved" else 0.0)]
    obstacles = {"two": [_obstacle(7, 30.0, 0.0), _obstacle(8, 50.0, 0.0)], "beside": [_obstacle(7, 30.0, 4.0)],
                 "none": []}.get(case, [_obstacle(7, 30.0, 0.0)])
    if case == "dynamic":
        shape = Rectangle(4.0, 1.8)
        other = InitialState(time_step=0, position=np.array([60.0, 0.0]), orientation=math.pi, velocity=5.0,
                             acceleration=0.0, yaw_rate=0.0, slip_angle=0.0)
        states = [KSState(time_step=k, position=np.array([60.0 - 0.5 * k, 0.0]), orientation=math.pi, velocity=5.0,
                          steering_angle=0.0) for k in range(1, 20)]
        obstacles.append(DynamicObstacle(9, ObstacleType.CAR, shape, other,
                                         TrajectoryPrediction(Trajectory(1, states), shape)))
    path = _file(tmp_path, lanes, obstacles)
    with pytest.raises(ParamError, match=f"--commonroad '{path}'") as err:
        load(path, CONFIG.vehicle)
    assert needle in str(err.value)
    args = ["simulate", "--commonroad", str(path), "--no-bag"]
    if case == "two":
        out = subprocess.run([sys.executable, "-m", "moose.cli", *args], capture_output=True, text=True, timeout=120)
        code, stderr = out.returncode, out.stderr
    else:
        from moose.cli import main

        capsys.readouterr()
        code, stderr = main(args), capsys.readouterr().err
    assert code == 2 and "moose: error:" in stderr and needle in stderr and "Traceback" not in stderr, stderr[-800:]


def test_the_checker_agrees_with_our_verdict_or_the_difference_is_explained(runs: dict) -> None:
    """The paper's cases, the comparison cases and the sweep sample: every difference has a checked reason, and the
    checker's own findings are real (it finds the collisions of the sample)."""
    collisions = 0
    for name, result in runs.items():
        summary = summarize(result)
        independent = summary["commonroad_verdict"]
        assert independent["agrees"] or independent["explained"], (name, independent)
        if not independent["agrees"]:
            assert independent["differences"], name
        collisions += independent["collision"]
        if summary["outcome"] == "collision":
            assert independent["collision"] or independent["differences"], name
    assert collisions >= 2


def checker_from_export(result: SimulationResult) -> tuple[np.ndarray, np.ndarray]:
    """The checker's answers per time step from its own construction of the exported run's shapes: the ego's
    time-variant collision object, the obstacle's, and the road boundary of the lanelets."""
    from commonroad_dc.boundary.boundary import create_road_boundary_obstacle
    from commonroad_dc.collision.collision_detection.pycrcc_collision_dispatch import create_collision_object

    exported = export_run(result.trace, result.scenario, result.config.vehicle, None)
    ego, obstacle = create_collision_object(exported.ego), create_collision_object(exported.obstacle)
    _, boundary = create_road_boundary_obstacle(exported.scenario, method="obb_rectangles")
    at = [ego.obstacle_at_time(k) for k in range(ego.time_end_idx() + 1)]
    return (np.array([a.collide(obstacle) for a in at], dtype=bool),
            np.array([boundary.collide(a) for a in at], dtype=bool))


def test_the_judge_s_shapes_give_the_checker_s_answers_at_every_time_step(runs: dict) -> None:
    """The judge builds the checker's shapes from the run directly and asks it only where a contact is possible; at
    every time step of the paper's cases, the comparison cases and the sweep sample (collisions, cars off the road
    among them) its answers are those of the checker's own construction from the export."""
    contacts = offs = 0
    for name, result in runs.items():
        states = resample(result.trace)
        box, _ = obstacle_of_zone(result.scenario.danger_zone, FOOTPRINT)
        hits, off = check(states, box, result.scenario.field, FOOTPRINT)
        expected_hits, expected_off = checker_from_export(result)
        np.testing.assert_array_equal(hits, expected_hits, err_msg=name)
        np.testing.assert_array_equal(off, expected_off, err_msg=name)
        contacts, offs = contacts + int(hits.sum()), offs + int(off.sum())
    assert contacts > 0 and offs > 0


def test_a_yawed_footprint_touching_the_obstacle_is_a_difference_with_its_reason() -> None:
    """A car driving yawed along the zone's side, its CoG just outside the zone: only its corner reaches the
    obstacle.  Built by hand, so the geometry (not a planner) decides."""
    scenario = adhoc_scenario(5.0, 2.0, 2.0, obstacle_length=4.0, duration=4.0)
    zone = scenario.danger_zone
    t = np.arange(0.0, scenario.lead_time + scenario.duration + 1e-9, 0.01)
    theta = np.full_like(t, -0.25)
    x = zone.x_min - 2.0 + 5.0 * (t - t[0]) * 0.5
    y = np.full_like(t, zone.y_max + 0.05)
    trace = {"t": t, "x": x, "y": y, "theta": theta, "vx": np.full_like(t, 2.5), "vy": np.zeros_like(t)}
    ours = our_verdict(t, x, y, theta, trace["vx"], trace["vy"], zone, scenario.field, t[-1])
    assert not ours.collided
    independent = compare(trace, scenario, CONFIG.vehicle, ours)
    assert independent.collision and not independent.agrees and independent.explained
    assert "yawed -0.250 rad" in independent.differences[0] and "outside the danger zone" in independent.differences[0]


def test_criticality_measures_match_their_closed_forms(runs: dict) -> None:
    """TTC = headway / v; TTB = (headway − v² / 2a) / v with the motors' deceleration a; the extreme case cannot
    brake in time (−∞, null with a note), no kick-down passes a static obstacle (TTK −∞)."""
    vehicle = CONFIG.vehicle
    relaxed = runs["paper_v5_tau5"]
    m = criticality.measures(relaxed.scenario, relaxed.config.vehicle)
    v = relaxed.scenario.v_init
    assert m["ttc_s"] == pytest.approx(m["hw_m"] / v, abs=0.011)
    a = vehicle.longitudinal_accel_limit
    assert m["ttb_s"] == pytest.approx((m["hw_m"] - v * v / (2.0 * a)) / v, abs=criticality.DT + 0.01)
    assert m["ttk_s"] == -math.inf and m["ttr_s"] == max(m["ttb_s"], m["tts_s"])
    extreme = runs["paper_v7_tau1.4"]
    summary = summarize(extreme, criticality=True)
    assert summary["criticality"]["ttb_s"] is None and summary["notes"]["ttb_s"].startswith("-inf")
    assert 0.0 < summary["criticality"]["tts_s"] < summary["criticality"]["ttc_s"] <= summary["tau_scenario_s"]
    assert summarize(extreme)["criticality"] is None


def test_without_the_packages_the_core_runs_and_a_command_that_needs_them_says_so(tmp_path: Path) -> None:
    hide = ("import sys; sys.modules.update(commonroad=None, commonroad_dc=None, commonroad_crime=None); "
            "from moose.cli import main; sys.exit(main(sys.argv[1:]))")
    base = [sys.executable, "-c", hide, "simulate", "--duration", "0.5", "--no-bag"]
    out = subprocess.run(base + ["--json", str(tmp_path / "s.json")], capture_output=True, text=True, timeout=120)
    assert out.returncode in (0, 1, 3), out.stderr[-800:]
    assert "pip install 'moose-avoidance[commonroad]'" in (tmp_path / "s.json").read_text()
    out = subprocess.run(base + ["--commonroad-out", str(tmp_path / "r.xml")], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2 and "moose: error: --commonroad-out needs the CommonRoad packages" in out.stderr
    assert "pip install 'moose-avoidance[commonroad]'" in out.stderr and not (tmp_path / "r.xml").exists()


def test_the_graph_refuses_a_commonroad_scenario_its_nodes_could_not_build(tmp_path: Path) -> None:
    """The nodes build the scenario from a name or ad-hoc flags: with a CommonRoad file they would run another test."""
    path = _file(tmp_path, [_lanelet(1, -1.75, 1.75)], [_obstacle(7, 30.0, 0.0)])
    out = subprocess.run([sys.executable, "-m", "moose.cli", "launch", "--commonroad", str(path), "--no-bag"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "moose: error: --commonroad is not supported by moose launch" in out.stderr


def test_a_bag_exports_as_the_scenario_of_its_run(tmp_path: Path) -> None:
    bag = Path(__file__).resolve().parents[1] / "bags" / "paper_v7_tau1.4_combined"
    out = subprocess.run([sys.executable, "-m", "moose.cli", "bag", "export", "--format", "commonroad", str(bag),
                          "-o", str(tmp_path)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-800:]
    scenario, problems = CommonRoadFileReader(str(tmp_path / "commonroad.xml")).open()
    ego = scenario.obstacle_by_id(EGO_ID)
    assert ego.prediction.final_time_step >= 850  # 9 s of odometry at 100 Hz
    assert problems.planning_problem_dict[PLANNING_PROBLEM_ID].initial_state.velocity == pytest.approx(7.0, abs=0.1)
    assert scenario.obstacle_by_id(OBSTACLE_ID) is not None


def test_assess_reports_nothing_it_cannot_compute(runs: dict) -> None:
    result = runs["paper_v7_tau1.4"]
    trace = result.trace
    verdict = our_verdict(trace["t"], trace["x"], trace["y"], trace["theta"], trace["vx"], trace["vy"],
                          result.scenario.danger_zone, result.scenario.field, result.end_time)
    independent, measures, notes = assess(result, verdict, criticality=False)
    assert independent is not None and measures is None and "--criticality" in notes["criticality"]


def test_write_replaces_a_file_only_with_a_whole_one(runs: dict, tmp_path: Path) -> None:
    result = runs["paper_v5_tau4"]
    target = tmp_path / "run.xml"
    target.write_text("old")
    exported = export_run(result.trace, result.scenario, result.config.vehicle, result.first_threat.t)
    write(exported, target)
    assert CommonRoadFileReader(str(target)).open()[0].obstacle_by_id(EGO_ID) is not None
    assert [p.name for p in tmp_path.iterdir()] == ["run.xml"]


def test_a_sweep_with_criticality_rows_the_measures_of_each_situation_and_maps_nu_against_them(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``moose sweep --criticality``: every row carries its situation's measures (both planners of the situation
    those of :func:`criticality.measures`), and ``moose sweep plot`` draws ν and τ against them; a sweep without the
    flag has no measures and its rows say why."""
    from moose.cli import main
    from moose.sweep.case import case_scenario
    from moose.sweep.store import RunFolder

    out = tmp_path / "sweep"
    args = ["sweep", "--speed", "5", "--obstacle-half-width", "1.5", "--mu", "0.8", "--duration", "1", "--workers", "1",
            "--quiet"]
    assert main([*args, "--tau", "2,3", "--planner", "combined,aeb", "--criticality", "-o", str(out)]) == 0
    rows = RunFolder(out).rows()
    assert len(rows) == 4
    measures = {(r["input.tau_s"], r["input.planner"]): {k: v for k, v in r.items() if k.startswith("criticality.")}
                for r in rows}
    assert measures[2, "combined"] == measures[2, "aeb"] != measures[3, "combined"] == measures[3, "aeb"]
    expected = criticality.measures(case_scenario(_case_of(rows[0])), dataclasses.replace(CONFIG.vehicle, mu=0.8))
    for key, value in expected.items():
        assert rows[0][f"criticality.{key}"] == (value if math.isfinite(value) else None), key
    assert main(["sweep", "plot", str(out), "--plot-output", str(tmp_path / "maps")]) == 0
    assert (tmp_path / "maps" / "criticality.png").stat().st_size > 0
    assert "criticality.png" in (tmp_path / "maps" / "index.html").read_text(encoding="utf-8")
    assert main([*args, "--tau", "2", "-o", str(tmp_path / "plain")]) == 0
    (plain,) = RunFolder(tmp_path / "plain").rows()
    assert plain["criticality"] is None and "--criticality" in plain["notes"]
    capsys.readouterr()


def _case_of(row: dict):
    from moose.sweep.axes import Case

    return Case(speed=row["input.speed_mps"], tau=row["input.tau_s"], half_width=row["input.half_width_m"],
                nu=row["input.nu"], length=row["input.length_m"], duration=row["input.duration_s"],
                field_margin=row["input.field_margin_m"], mu=row["input.mu"], planner=row["input.planner"],
                seed=row["input.seed"])
