"""Parameters cannot change under a running node: on rclpy every one is read-only and a change is refused with a
reason; the Cyclone DDS runtime serves no parameter services at all.

The probe (eafd7a4, ``moose launch --scenario paper_v6_w2.0 --rate 0.5`` on rclpy): ``SetParameters`` on
``/observer`` with ``use_sim_time=False`` was accepted, the observer's clock jumped to wall time and the motion
controller stopped the car in the road; ``simulation.planner=mpc`` on ``/weight_fbl`` was accepted and reported back
by ``get_parameters`` while the node kept blending.  Here the same requests go, through ``rcl_interfaces``' services
as ``ros2 param set`` sends them, to ``moose node observer`` and ``moose node weight_fbl`` on rclpy, and to the
observer on Cyclone DDS.  Each node is a process of its own, bounded in time and killed at the end; loopback only,
the test run's own domain (tests/ros2_prefix.py).
"""
from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import textwrap
from pathlib import Path
from typing import Iterator

import pytest

from isolation import claim_domain
from moose_ros.runtime.rclpy_node import READ_ONLY_REASON
from test_rclpy_runtime import run_child

pytestmark = [pytest.mark.graph]

START_TIMEOUT = 60.0

CLIENT = textwrap.dedent(r'''
    import json, sys, time
    import rclpy
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters

    requests, limit = json.loads(sys.argv[1]), float(sys.argv[2])
    rclpy.init()
    node = rclpy.create_node("ros2_param_probe")
    deadline = time.monotonic() + limit

    def call(kind, name, request):
        client = node.create_client(kind, name)
        if not client.wait_for_service(timeout_sec=max(0.1, deadline - time.monotonic())):
            return None
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=10.0)
        return future.result()

    def value(v):
        out = ParameterValue()
        if isinstance(v, bool):
            out.type, out.bool_value = ParameterType.PARAMETER_BOOL, v
        elif isinstance(v, float):
            out.type, out.double_value = ParameterType.PARAMETER_DOUBLE, v
        else:
            out.type, out.string_value = ParameterType.PARAMETER_STRING, v
        return out

    def plain(v):
        return {ParameterType.PARAMETER_BOOL: v.bool_value, ParameterType.PARAMETER_DOUBLE: v.double_value,
                ParameterType.PARAMETER_STRING: v.string_value}.get(v.type)

    report = {}
    for target, changes in requests.items():
        names = list(changes)
        done = call(SetParameters, f"{target}/set_parameters", SetParameters.Request(
            parameters=[Parameter(name=n, value=value(v)) for n, v in changes.items()]))
        if done is None:
            report[target] = None
            continue
        after = call(GetParameters, f"{target}/get_parameters", GetParameters.Request(names=names))
        listed = call(ListParameters, f"{target}/list_parameters", ListParameters.Request())
        described = call(DescribeParameters, f"{target}/describe_parameters",
                         DescribeParameters.Request(names=list(listed.result.names)))
        report[target] = {
            "set": [[r.successful, r.reason] for r in done.results],
            "after": dict(zip(names, [plain(v) for v in after.values])),
            "read_only": {d.name: [d.read_only, d.additional_constraints] for d in described.descriptors},
        }
    report["nodes"] = sorted(name for name, _ns in node.get_node_names_and_namespaces())
    node.destroy_node()
    rclpy.try_shutdown()
    print(json.dumps(report))
''')

IN_PROCESS = textwrap.dedent(r'''
    import json
    from rclpy.parameter import Parameter
    from moose_ros.runtime import create_node

    rt = create_node("probe", overrides={"use_sim_time": True, "simulation.planner": "combined"}, runtime="rclpy")
    mine = rt.declare_parameter("mpc_timeout", 0.05)  # a node's own declaration passes the callback
    try:  # declared past the runtime (a library a node uses), not read-only: the callback refuses it
        rt.node.declare_parameter("raw", 1)
        raw = "declared"
    except Exception as exc:
        raw = str(exc)
    results = [rt.node.set_parameters([Parameter(name, value=v)])[0] for name, v in
               (("use_sim_time", False), ("simulation.planner", "mpc"), ("mpc_timeout", 1.0))]
    print(json.dumps({"declared": mine, "raw": raw, "results": [[r.successful, r.reason] for r in results],
                      "values": [rt.node.get_parameter(n).value for n in
                                 ("use_sim_time", "simulation.planner", "mpc_timeout")],
                      "sim_time_active": rt.node.get_clock().ros_time_is_active}))
    rt.shutdown()
''')


def _start(args: list[str], env: dict[str, str], log: Path) -> subprocess.Popen:
    with open(log, "w") as out:
        return subprocess.Popen(args, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=10)


def _wait_started(log: Path, name: str, proc: subprocess.Popen) -> None:
    import time

    deadline = time.monotonic() + START_TIMEOUT
    while time.monotonic() < deadline and proc.poll() is None:
        if f"{name} started" in log.read_text():
            return
        time.sleep(0.1)
    pytest.fail(f"{name} did not start: {log.read_text()[-2000:]}")


@contextlib.contextmanager
def running(specs: dict[str, tuple[list[str], dict[str, str]]], folder: Path) -> Iterator[None]:
    """The nodes of ``specs`` (name → command and environment), each logging to ``folder/NAME.log``, until they
    started; all killed at the end."""
    procs = {}
    try:
        for key, (args, env) in specs.items():
            procs[key] = _start(args, env, folder / f"{key}.log")
        for key, proc in procs.items():
            _wait_started(folder / f"{key}.log", key, proc)
        yield
    finally:
        for proc in procs.values():
            _stop(proc)


def _node(python: str, name: str) -> list[str]:
    given = ["scenario=paper_v6_w2.0"] if name == "observer" else ["mpc_timeout=0.05", "minimum_risk.stop_speed=0.1",
                                                                     "vehicle.T_max=200.0"]
    extra = [arg for value in given for arg in ("--param", value)]
    return [python, "-m", "moose.cli", "node", name, "--param", "use_sim_time=true", "--param",
            "simulation.planner=combined", *extra]


def test_a_running_node_refuses_every_parameter_change(ros_env: dict[str, str], tmp_path: Path) -> None:
    """``moose node observer`` and ``weight_fbl`` on rclpy, with simulated time as in a graph: the clock, the planner
    mode, a node parameter, a minimum-risk value and a vehicle limit are all refused and stay what the node uses."""
    env = {**ros_env, "MOOSE_RUNTIME": "rclpy"}
    requests = {"/observer": {"use_sim_time": False},
                "/weight_fbl": {"simulation.planner": "mpc", "mpc_timeout": 1.0, "minimum_risk.stop_speed": 1000.0,
                                "vehicle.T_max": 1e6}}
    with running({name: (_node(env["MOOSE_ROS_PYTHON"], name), env) for name in ("observer", "weight_fbl")},
                 tmp_path):
        report = run_child(env["MOOSE_ROS_PYTHON"], CLIENT, [json.dumps(requests), "30"], ros_env)
    observer, weight_fbl = report["/observer"], report["/weight_fbl"]
    assert observer["set"] == [[False, "Trying to set a read-only parameter: use_sim_time."]]
    assert observer["after"] == {"use_sim_time": True}  # what the node runs on, still
    assert [ok for ok, _reason in weight_fbl["set"]] == [False] * 4
    assert weight_fbl["after"] == {"simulation.planner": "combined", "mpc_timeout": 0.05,  # what the node uses
                                   "minimum_risk.stop_speed": 0.1, "vehicle.T_max": 200.0}
    for described in (observer["read_only"], weight_fbl["read_only"]):
        assert {"use_sim_time", "simulation.planner"} <= set(described)
        for name, (read_only, why) in described.items():
            assert read_only, name  # ros2 param describe says so, with the reason
            if name not in ("start_type_description_service",) and not name.startswith("qos_overrides"):
                assert why == READ_ONLY_REASON, name


def test_the_runtime_refuses_changes_also_to_parameters_declared_past_it(ros_env: dict[str, str]) -> None:
    """The node's own declarations are read-only; the set-parameters callback refuses, with the reason, what would
    get past the descriptors (a parameter some library declares on the running node); simulated time stays on."""
    report = run_child(ros_env["MOOSE_ROS_PYTHON"], IN_PROCESS, [], {**ros_env, "MOOSE_RUNTIME": "rclpy"})
    assert report["declared"] == 0.05
    assert report["raw"].endswith(f"Reason: raw: {READ_ONLY_REASON}: raw"), report["raw"]
    assert report["results"] == [[False, f"Trying to set a read-only parameter: {name}."]
                                 for name in ("use_sim_time", "simulation.planner", "mpc_timeout")]
    assert report["values"] == [True, "combined", 0.05] and report["sim_time_active"] is True


def test_the_cyclone_runtime_serves_no_parameter_services(ros_env: dict[str, str], dds_env: dict[str, str],
                                                          tmp_path: Path) -> None:
    """What an rclpy client (``ros2 param``) sees of a node on our Cyclone DDS runtime: the node, but no
    ``set_parameters`` or ``get_parameters`` service to call (its parameters are in the launcher's summary and the
    bag's run parameters)."""
    domain = str(claim_domain())  # a domain of its own: no rclpy observer of another test answers for it
    with running({"observer": (_node(ros_env["MOOSE_ROS_PYTHON"], "observer"), {**dds_env, "ROS_DOMAIN_ID": domain})},
                 tmp_path):
        report = run_child(ros_env["MOOSE_ROS_PYTHON"], CLIENT, [json.dumps({"/observer": {"use_sim_time": False}}),
                                                                  "5"], {**ros_env, "ROS_DOMAIN_ID": domain})
    assert report["/observer"] is None  # no service answered within 5 s
    assert "observer" in report["nodes"]  # while the client sees the node itself (ros_discovery_info)
