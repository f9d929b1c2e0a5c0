"""Node parameters are typed and strict: unknown keys are errors in the graph as in ``moose simulate``."""
from __future__ import annotations

import io
import re
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Optional

import pytest

from moose.config import load_config
from moose.params import ParamError
from moose.scenario import load_scenario
from moose_ros.launch import launch, node_overrides
from moose_ros.parameters import SimulatorParams, check_parameter_file, node_parameters

MOOSE = [sys.executable, "-m", "moose.cli"]
MISSPELT_GROUP = "/**:\n  ros__parameters:\n    vehicel: {m: 900.0}\n"

PROCESS_EVENTS = ("subprocess.Popen", "os.posix_spawn", "os.spawn", "os.fork", "os.forkpty", "os.exec", "os.system")
"""The audit events (PEP 578) of Python's ways to start a process."""
_recording: Optional[list[str]] = None


def _audit(event: str, args: tuple[Any, ...]) -> None:
    if _recording is not None and event in PROCESS_EVENTS:
        _recording.append(f"{event} {args[:2]!r}")


sys.addaudithook(_audit)  # an audit hook stays for the life of the process: it records only inside the block below


@contextmanager
def processes_started() -> Iterator[list[str]]:
    """The processes this process starts in the block (in any thread), each as its audit event."""
    global _recording
    _recording = started = []
    try:
        yield started
    finally:
        _recording = None


def test_a_misspelt_group_is_an_error_for_every_node_as_for_simulate(tmp_path: Path) -> None:
    """The probe of the review: ``vehicel:`` used to be dropped silently by every node."""
    bad = tmp_path / "bad.yaml"
    bad.write_text(MISSPELT_GROUP)
    with pytest.raises(ParamError, match=r"vehicel = \{'m': 900.0\} is unknown"):
        load_config(bad)  # moose simulate
    for node in ("observer", "can_bridge", "vehicle_simulator"):
        with pytest.raises(ParamError, match=rf"{node}.vehicel = .* is unknown"):
            node_parameters(node, {"vehicel": {"m": 900.0}})
    result = subprocess.run(MOOSE + ["node", "observer", "--params", str(bad)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2 and "moose: error: observer.vehicel = {'m': 900.0} is unknown" in result.stderr


def test_unknown_values_and_wrong_types_of_node_parameters_are_errors() -> None:
    with pytest.raises(ParamError, match="observer.seed = 3 is unknown"):  # the simulator's, not the observer's
        node_parameters("observer", {"seed": 3})
    with pytest.raises(ParamError, match="vehicle_simulator.rate = 'fast' is invalid: expected a number"):
        node_parameters("vehicle_simulator", {"rate": "fast"})
    with pytest.raises(ParamError, match="vehicle_simulator.seed = -1 is invalid"):
        node_parameters("vehicle_simulator", {"seed": -1})
    with pytest.raises(ParamError, match="vehicle_bus = 'bus' is invalid: expected one of"):
        node_parameters("vehicle_simulator", {"vehicle_bus": "bus"})
    with pytest.raises(ParamError, match="can_bridge.can_port = 70000 is invalid"):
        node_parameters("can_bridge", {"can_port": 70000})
    with pytest.raises(ParamError, match="weight_fbl.vehicle.m = 'heavy' is invalid"):
        node_parameters("weight_fbl", {"vehicle": {"m": "heavy"}})
    config, params = node_parameters("vehicle_simulator", {"use_sim_time": False, "rate": 2, "wait_for": ["observer"],
                                                           "vehicle": {"mu": 0.4}})
    assert params == SimulatorParams(rate=2.0, wait_for=("observer",)) and config.vehicle.mu == 0.4
    scenario = node_parameters("observer", {"speed": 6.0, "tau": 2.5, "obstacle_half_width": 1.8, "mu": 0.3})[1]
    assert scenario.load_scenario().mu == 0.3  # the ad-hoc test takes mu as moose simulate does


def test_a_section_for_no_node_of_the_graph_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "typo.yaml"
    path.write_text("observr:\n  ros__parameters:\n    observer: {q_gamma: 1.0}\n")
    with pytest.raises(ParamError, match="section 'observr' names no node of the graph"):
        check_parameter_file(path)
    result = subprocess.run(MOOSE + ["node", "observer", "--params", str(path)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2 and "names no node of the graph" in result.stderr
    path.write_text("/observer:\n  ros__parameters:\n    observer: {}\n/**:\n  ros__parameters: {}\n")
    check_parameter_file(path)


@pytest.mark.parametrize(("section", "graph"), [("/*", "full"), ("can_bridge", "full"), ("vehicle_simulator", "car")])
def test_a_section_the_launched_graph_would_ignore_is_an_error(tmp_path: Path, section: str, graph: str) -> None:
    """A wildcard other than ``/**``, or a node that the launched graph does not run, names no node of it."""
    path = tmp_path / "sections.yaml"
    path.write_text(f'"{section}":\n  ros__parameters:\n    vehicle: {{m: -5.0}}\n')
    with pytest.raises(ParamError, match=f"section '{re.escape(section)}' names no node of the graph '{graph}'"):
        node_overrides(graph, "combined", {}, str(path))


def test_the_launcher_refuses_a_bad_configuration_before_any_node_starts(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text(MISSPELT_GROUP)
    with processes_started() as started, pytest.raises(ParamError, match="vehicel"):
        launch(load_scenario("paper_v5_tau3"), {}, params_file=str(bad), out=io.StringIO())
    assert started == []  # no node process was started
    with pytest.raises(ParamError, match="can_lgo = 'x.log' is taken by no node of the graph 'can'"):
        node_overrides("can", "combined", {"can_lgo": "x.log"})
    with pytest.raises(ParamError, match="can_interface = 'pcan' is invalid"):
        node_overrides("car", "combined", {"can_interface": "pcan"})
    result = subprocess.run(MOOSE + ["launch", "--config", str(bad), "--no-bag"], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 2 and "vehicel" in result.stderr and "[observer]" not in result.stdout


def test_each_node_gets_only_the_parameters_it_takes() -> None:
    overrides = node_overrides("can", "mpc", {"scenario": "paper_v5_tau3", "can_log": "bus.log", "can_port": 5000},
                               seed=4, rate=2.0)
    assert "msf_planner" not in overrides
    # every node: its own parameters, the planner mode, simulated time, and that the launcher's monitor reads it
    assert overrides["can_bridge"] == {"can_log": "bus.log", "can_port": 5000, "simulation.planner": "mpc",
                                       "use_sim_time": True, "monitored": True}
    assert overrides["observer"] == {"scenario": "paper_v5_tau3", "simulation.planner": "mpc", "use_sim_time": True,
                                     "monitored": True}
    assert overrides["vehicle_simulator"]["seed"] == 4 and overrides["vehicle_simulator"]["vehicle_bus"] == "can"
    assert overrides["vehicle_simulator"]["wait_for"] == [n for n in overrides if n != "vehicle_simulator"]


def test_every_node_of_an_adhoc_launch_assumes_the_launchers_field() -> None:
    """``moose launch --field-margin``: the nodes' scenario is the launcher's, field included (it was the
    launcher's verdict alone that widened)."""
    from moose.scenario import adhoc_scenario

    given = {"speed": 7.0, "tau": 2.0, "obstacle_half_width": 3.0, "field_margin": 4.0}
    launcher = adhoc_scenario(7.0, 2.0, 3.0, 2.0, field_margin=4.0)
    assert launcher.field != load_scenario("paper_v7_tau2").field  # the margin changes it
    overrides = node_overrides("full", "combined", given)
    takers = [n for n, o in overrides.items() if "speed" in o]
    assert {"vehicle_simulator", "observer", "mpc_planner", "msf_planner"} <= set(takers)
    for name in takers:
        _, params = node_parameters(name, {k: v for k, v in overrides[name].items() if "." not in k})
        assert params.load_scenario().field == launcher.field, name
