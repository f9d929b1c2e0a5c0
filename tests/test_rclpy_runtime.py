"""The runtime on real rclpy behaves as on Cyclone DDS; choosing the runtime; ``ros2 run``-style entry points.

The same script exercises a runtime (parameters, ``use_sim_time`` and ``/clock``, timers, QoS, the
order of callbacks across topics, shutdown) in a process of the ROS 2 prefix (``make ros``), once
with ``runtime="rclpy"`` and once with ``runtime="dds"``; both must give the same results, and the
results the ones ROS 2 specifies.  rclpy tests skip without the prefix and fail with
``MOOSE_REQUIRE_ROS=1`` (``tests/ros2_prefix.py``); loopback only, the test run's own domain.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import pytest

from moose.params import ParamError
from moose_ros import runtime
from moose_ros.graph import NODES, publishes, subscribes
from moose_ros.interfaces import typestore
from ros2_prefix import ros_prefix

pytestmark = [pytest.mark.graph]

CONFORMANCE = textwrap.dedent(r'''
    import json, sys, threading, time
    from pathlib import Path
    from moose.params import ParamError
    from moose_ros.runtime import QOS_LATCHED, Qos, create_node

    chosen, tmp = sys.argv[1], Path(sys.argv[2])
    WHEELS = "moose_msgs/msg/WheelSpeeds"
    out = {}

    def node(name, **kw):
        return create_node(name, runtime=chosen, **kw)

    def spin_until(n, condition, limit=10.0):
        deadline = time.monotonic() + limit
        while not condition() and time.monotonic() < deadline:
            n.spin_once(0.005)
        return bool(condition())

    def errors(*calls):
        found = []
        for call in calls:
            try:
                call()
                found.append(None)
            except ParamError as exc:
                found.append(str(exc))
        return found

    # parameters: file sections, overrides, declarations with type checks
    good = tmp / "params.yaml"
    good.write_text("/**:\n  ros__parameters:\n    rate: 2.0\n    vehicle: {mu: 0.4}\n"
                    "planner_node:\n  ros__parameters:\n    rate: 5\n    name: fast\n")
    n = node("planner_node", params_file=str(good), overrides={"vehicle.m": 900.0})
    out["type"] = type(n).__name__
    out["params"] = [n.param("rate"), n.param("vehicle.mu"), n.param("vehicle.m"), n.declare_parameter("rate", 1.0),
                     type(n.get_parameter("rate")).__name__, n.declare_parameter("horizon", 10),
                     n.get_parameter("horizon"), n.use_sim_time]
    out["param_errors"] = errors(lambda: n.declare_parameter("name", 1.0), lambda: n.get_parameter("missing"))
    n.shutdown()
    other = node("other_node", params_file=str(good))
    out["wildcard_only"] = other.param("rate")
    other.shutdown()
    bad = tmp / "sim.yaml"
    bad.write_text("/**:\n  ros__parameters:\n    use_sim_time: 'yes'\n")
    out["sim_time_error"] = errors(lambda: node("x", params_file=str(bad)))

    # simulated time: /clock drives now() and the timers
    sim, source = node("sim_follower", overrides={"use_sim_time": True}), node("clock_source")
    clock = source.publisher("rosgraph_msgs/msg/Clock", "/clock")
    ticks = []
    sim.timer(0.1, lambda: ticks.append(round(sim.now(), 6)))
    out["now_before_clock"] = sim.now()
    sim.spin_once(0.05)
    out["ticks_before_clock"] = list(ticks)

    def publish(t):
        msg = source.make("rosgraph_msgs/msg/Clock")
        msg.clock.sec, msg.clock.nanosec = int(t), int(round((t % 1.0) * 1e9)) % 1_000_000_000
        clock(msg)
        spin_until(sim, lambda: abs(sim.now() - t) < 1e-9)
        sim.spin_once(0.01)  # a timer that became due runs

    spin_until(sim, lambda: clock.subscription_count() > 0)
    for k in range(1, 101):
        publish(0.01 * k)
    out["ticks_first_second"] = list(ticks)
    for t in (5.05, 5.1, 5.15, 5.2):  # a jump forward fires once, then the grid goes on
        publish(t)
    out["ticks_after_jump"] = ticks[10:]
    sim.shutdown()
    source.shutdown()

    # callbacks in publication order across topics, keep-last depth, a late joiner of a latched topic
    talker, listener = node("order_talker"), node("order_listener")
    got = []
    for topic in ("/rt_test/x", "/rt_test/y"):  # y's messages need not wake the executor: in order all the same
        listener.subscription(WHEELS, topic, lambda m: got.append(m.omega_rl), Qos(reliable=True, depth=10),
                              wake=topic.endswith("x"))
    pubs = {t: talker.publisher(WHEELS, t, Qos(reliable=True, depth=10)) for t in ("/rt_test/x", "/rt_test/y")}
    spin_until(listener, lambda: all(p.subscription_count() > 0 for p in pubs.values()))
    for k, topic in enumerate("xxxyyyxxx"):
        pubs["/rt_test/" + topic](talker.make(WHEELS, omega_rl=float(k)))
    time.sleep(0.3)
    listener.spin_once(0.2)
    out["order"] = list(got)
    got.clear()  # spin_some: what has arrived, in publication order, without waiting for more
    for k, topic in enumerate("yyxxy"):
        pubs["/rt_test/" + topic](talker.make(WHEELS, omega_rl=float(10 + k)))
    time.sleep(0.3)
    listener.spin_some()
    out["some"] = list(got)
    listener.spin_some()
    out["some_again"] = list(got)
    got.clear()  # a message only on a subscription that does not wake the executor still arrives (WAKE_POLL)
    pubs["/rt_test/y"](talker.make(WHEELS, omega_rl=20.0))
    spin_until(listener, lambda: bool(got))
    out["asleep"] = list(got)
    burst = []
    listener.subscription(WHEELS, "/rt_test/burst", lambda m: burst.append(m.omega_rl), Qos(reliable=True, depth=5))
    pub = talker.publisher(WHEELS, "/rt_test/burst", Qos(reliable=True, depth=50))
    spin_until(listener, lambda: pub.subscription_count() > 0)
    for k in range(50):
        pub(talker.make(WHEELS, omega_rl=float(k)))
    time.sleep(0.3)
    listener.spin_once(0.2)
    out["keep_last_5"] = burst
    latched = talker.publisher(WHEELS, "/rt_test/latched", QOS_LATCHED)
    latched(talker.make(WHEELS, omega_rl=7.0))
    late, seen = node("late_listener"), []
    late.subscription(WHEELS, "/rt_test/latched", lambda m: seen.append(m.omega_rl), QOS_LATCHED)
    spin_until(late, lambda: bool(seen))
    out["latched"] = seen
    for n in (talker, listener, late):
        n.shutdown()

    # shutdown from another thread, and from a callback, ends spin
    stopper = node("stopper")
    start = time.monotonic()
    threading.Timer(0.2, stopper.shutdown).start()
    stopper.spin(until=lambda: time.monotonic() - start > 10)
    selfstop, calls = node("self_stopper"), []
    selfstop.timer(0.01, lambda: (calls.append(1), selfstop.shutdown()))
    selfstop.spin(until=lambda: time.monotonic() - start > 10)
    out["shutdown"] = [time.monotonic() - start < 5, calls]

    # a watched file descriptor (the CAN bus's socket): its callback runs in the executor when it is readable
    import socket
    watcher, (ours, theirs) = node("watcher"), socket.socketpair()
    ours.setblocking(False)
    seen, threads = [], []

    def on_readable(take=1):
        threads.append(threading.current_thread() is threading.main_thread())
        seen.append(ours.recv(take))

    handle = watcher.watch(ours.fileno, on_readable, 0.05)
    watcher.spin_once(0.2)
    quiet = list(seen)  # nothing to read: never called
    theirs.send(b"ab")  # one byte read per call: the second wakes it again
    spin_until(watcher, lambda: len(seen) >= 2)
    watcher.spin_once(0.2)
    polled = []
    watcher.watch(lambda: None, lambda: polled.append(1), 0.01)  # no descriptor: polled
    spin_until(watcher, lambda: len(polled) >= 3)
    handle.cancel()
    theirs.send(b"c")
    watcher.spin_once(0.3)
    out["watch"] = [quiet, [b.decode() for b in seen], all(threads), len(polled) >= 3]
    watcher.shutdown()

    # the graph as `ros2 node list` shows it, and the launcher's refusal of a domain where a moose graph's node runs
    from moose_ros.launch import check_domain
    probe = node("domain_probe")
    out["domain_free"] = errors(lambda: check_domain(probe, wait=0.5))
    left = node("observer")
    spin_until(probe, lambda: ("/", "observer") in probe.node_names())
    out["node_names"] = [list(n) for n in probe.node_names() if n[1] in ("observer", "domain_probe")]
    out["domain_taken"] = errors(lambda: check_domain(probe, wait=10.0))
    left.shutdown()
    probe.shutdown()
    print(json.dumps(out))
''')

STOCK_ORDER = textwrap.dedent(r'''
    import json, time
    import rclpy
    from rclpy.qos import QoSProfile
    from moose_msgs.msg import WheelSpeeds
    rclpy.init()
    node = rclpy.create_node("stock_listener")
    got = []
    for topic in ("/rt_test/x", "/rt_test/y"):
        node.create_subscription(WheelSpeeds, topic, lambda m: got.append(m.omega_rl), QoSProfile(depth=10))
    pubs = {t: node.create_publisher(WheelSpeeds, t, QoSProfile(depth=10)) for t in ("/rt_test/x", "/rt_test/y")}
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and not all(p.get_subscription_count() for p in pubs.values()):
        time.sleep(0.01)
    for k, topic in enumerate("xxxyyyxxx"):
        pubs["/rt_test/" + topic].publish(WheelSpeeds(omega_rl=float(k)))
    time.sleep(0.3)
    for _ in range(20):
        rclpy.spin_once(node, timeout_sec=0.01)
    print(json.dumps(got))
''')

BYTES_AND_ENDPOINTS = textwrap.dedent(r'''
    import json, sys
    import numpy as np
    from moose.signals import PlanResult
    from moose_ros import convert as cv
    from moose_ros.nodes import node_class
    from moose_ros.runtime import DdsNode, RclpyNode, create_node

    out = {"cdr": {}, "endpoints": {}}
    rclpy_node = create_node("cdr_check", runtime="rclpy")
    state = np.array([1.25, -0.5, 0.125, 7.0, 0.25, 0.0625])
    for name, make in (("odometry", lambda n: cv.odometry_to_msg(n, 1.5, state)),
                       ("diagnostics", lambda n: cv.diagnostic_to_msg(n, 2.0, "observer", 1, "late", {"dropped": 3}))):
        out["cdr"][name] = [RclpyNode.serialize(make(rclpy_node)).hex(), DdsNode.serialize(make(DdsNode)).hex()]
    rclpy_node.shutdown()
    for name in json.loads(sys.argv[1]):
        overrides = {"use_sim_time": name != "vehicle_simulator", "scenario": "paper_v5_tau3"}
        if name == "can_bridge":
            overrides = {"use_sim_time": True, "can_interface": "virtual", "can_channel": "contract-rclpy"}
        if name in ("obstacle_detector", "weight_fbl", "motion_controller"):
            overrides.pop("scenario")
        rt = create_node(name, overrides=overrides, runtime="rclpy")
        node = node_class(name)(rt)
        close = getattr(node, "close", None)  # a node's own release, where nodes have one (it frees the CAN bus)
        if close is not None:
            close()
        elif name == "can_bridge":
            node.bus.shutdown()
        out["endpoints"][name] = sorted([e.kind, e.topic, e.type, e.qos.reliable, e.qos.depth, e.qos.transient_local]
                                        for e in rt.endpoints())
        rt.shutdown()
    print(json.dumps(out))
''')


def run_child(python: str, code: str, args: list[str], env: dict[str, str], timeout: float = 180.0) -> Any:
    """Run ``code`` in a child of its own session; its last line of output as JSON (killed on timeout)."""
    proc = subprocess.Popen([python, "-c", code, *args], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        pytest.fail(f"child did not finish in {timeout} s: {err[-3000:]}")
    assert proc.returncode == 0, err[-3000:]
    return json.loads(out.strip().splitlines()[-1])


def test_runtimes_behave_the_same(ros_env: dict[str, str], tmp_path: Path) -> None:
    results = {}
    for chosen in ("rclpy", "dds"):
        folder = tmp_path / chosen
        folder.mkdir()
        results[chosen] = run_child(ros_env["MOOSE_ROS_PYTHON"], CONFORMANCE, [chosen, str(folder)], ros_env)
    rclpy, dds = results["rclpy"], results["dds"]
    assert (rclpy.pop("type"), dds.pop("type")) == ("RclpyNode", "DdsNode")
    assert rclpy == dds
    assert rclpy["params"] == [5, 0.4, 900.0, 5.0, "float", 10, 10, False]
    assert rclpy["param_errors"] == ["planner_node.name = 'fast' is invalid: expected float like the default 1.0",
                                     "planner_node.missing is not set: declare it or give it in the parameter file"]
    assert rclpy["wildcard_only"] == 2.0
    assert rclpy["sim_time_error"] == ["use_sim_time = 'yes' is invalid: expected true or false"]
    assert rclpy["now_before_clock"] == 0.0 and rclpy["ticks_before_clock"] == []
    assert rclpy["ticks_first_second"] == pytest.approx([0.1 * k for k in range(1, 11)], abs=1e-9)
    assert rclpy["ticks_after_jump"] == pytest.approx([5.05, 5.1, 5.2], abs=1e-9)
    assert rclpy["order"] == [float(k) for k in range(9)]  # publication order across the two topics
    assert rclpy["some"] == rclpy["some_again"] == [float(k) for k in range(10, 15)]
    assert rclpy["asleep"] == [20.0]
    assert rclpy["keep_last_5"] == [45.0, 46.0, 47.0, 48.0, 49.0]
    assert rclpy["latched"] == [7.0]
    assert rclpy["shutdown"] == [True, [1]]
    assert rclpy["watch"] == [[], ["a", "b"], True, True]  # in the executor's thread; nothing after cancel
    assert rclpy["domain_free"] == [None] and rclpy["node_names"] == [["/", "observer"]]  # not itself
    domain = ros_env.get("ROS_DOMAIN_ID", "0") or "0"
    assert rclpy["domain_taken"] == [f"DDS domain {domain} (ROS_DOMAIN_ID) already has nodes of a moose graph: "
                                     "/observer; a graph left from an earlier run, or another launch: stop it (moose "
                                     "launch stops its nodes when it ends or is killed) or use another ROS_DOMAIN_ID"]


def test_stock_rclpy_executor_does_not_keep_publication_order(ros_env: dict[str, str]) -> None:
    """Why the rclpy runtime has its own turn: rclpy's executor takes one message per subscription and
    wait, subscriptions in creation order, so the order check above fails on it."""
    got = run_child(ros_env["MOOSE_ROS_PYTHON"], STOCK_ORDER, [], ros_env)
    assert sorted(got) == [float(k) for k in range(9)] and got != sorted(got)


def test_both_runtimes_serialise_alike_and_every_node_makes_the_contracts_endpoints_on_rclpy(
        ros_env: dict[str, str]) -> None:
    """Bags recorded on either runtime hold the same CDR, but for padding: rmw_fastrtps leaves the
    alignment bytes of a fresh buffer as they were (not zero), so the bytes are compared after rosbags
    has read and rewritten rclpy's.  On rclpy every node creates exactly the endpoints of the graph
    contract (with the time source's /clock reader), as on Cyclone DDS."""
    report = run_child(ros_env["MOOSE_ROS_PYTHON"], BYTES_AND_ENDPOINTS, [json.dumps(list(NODES))], ros_env)
    store = typestore()
    for name, kind in (("odometry", "nav_msgs/msg/Odometry"), ("diagnostics", "diagnostic_msgs/msg/DiagnosticArray")):
        from_rclpy, from_dds = (bytes.fromhex(h) for h in report["cdr"][name])
        assert len(from_rclpy) == len(from_dds), name
        assert bytes(store.serialize_cdr(store.deserialize_cdr(from_rclpy, kind), kind)) == from_dds, name
    for name in NODES:
        expected = {("publisher", t.name, t.type, t.qos) for t in publishes(name)}
        expected |= {("subscription", t.name, t.type, t.subscription_qos) for t in subscribes(name)}
        assert sorted(report["endpoints"][name]) == sorted(
            [k, topic, kind, q.reliable, q.depth, q.transient_local] for k, topic, kind, q in expected), name


# -- choosing the runtime ------------------------------------------------------------------

def test_runtime_choice_in_an_interpreter_without_rclpy(monkeypatch: pytest.MonkeyPatch) -> None:
    """This interpreter (.venv) has no rclpy: the default is Cyclone DDS; asking for rclpy says why not."""
    pytest.importorskip("cyclonedds")
    if not runtime.rclpy_missing():
        pytest.skip("this interpreter can import rclpy and moose_msgs")
    monkeypatch.delenv("MOOSE_RUNTIME")
    assert runtime.backend() == "dds"
    with pytest.raises(ParamError, match=r"runtime 'rclpy' is not available in .*: rclpy cannot be imported"):
        runtime.backend("rclpy")
    monkeypatch.setenv("MOOSE_RUNTIME", "fastdds")
    with pytest.raises(ParamError, match=r"MOOSE_RUNTIME = 'fastdds' is invalid: expected one of 'rclpy', 'dds'"):
        runtime.backend()
    with pytest.raises(ParamError, match=r"runtime = 'ros1' is invalid"):
        runtime.create_node("x", runtime="ros1")
    assert runtime.process("dds") == (sys.executable, {**os.environ, "MOOSE_RUNTIME": "dds"})
    monkeypatch.setenv("MOOSE_ROS_PREFIX", "/nonexistent-prefix")
    with pytest.raises(ParamError, match=r"no ROS 2 prefix .* has ros-env.json: run `make ros`"):
        runtime.process("rclpy")


def test_a_child_on_rclpy_gets_the_prefix_interpreter_and_environment(ros_env: dict[str, str]) -> None:
    """From an interpreter without rclpy, process('rclpy') is the prefix's interpreter with the environment
    ros_prefix.environment() gives (the reader in moose_ros and the writer's own reader agree)."""
    if not runtime.rclpy_missing():
        pytest.skip("this interpreter can import rclpy and moose_msgs")
    base = {"PATH": "/usr/bin", "PYTHONPATH": "/somewhere", "ROS_DOMAIN_ID": "7"}
    python, env = runtime.process("rclpy", base)
    assert python == ros_env["MOOSE_ROS_PYTHON"]
    assert env == {**ros_prefix.environment(ros_prefix.default_prefix(), base), "MOOSE_RUNTIME": "rclpy"}


BACKEND_IN_PREFIX = textwrap.dedent(r'''
    import json
    from moose.params import ParamError
    from moose_ros.runtime import backend
    try:
        explicit = backend("rclpy")
    except ParamError as exc:
        explicit = str(exc)
    print(json.dumps([backend(), explicit]))
''')


def test_default_runtime_in_the_prefix_is_rclpy_unless_moose_msgs_is_missing(ros_env: dict[str, str]) -> None:
    env = {k: v for k, v in ros_env.items() if k != "MOOSE_RUNTIME"}
    assert run_child(env["MOOSE_ROS_PYTHON"], BACKEND_IN_PREFIX, [], env) == ["rclpy", "rclpy"]
    # rclpy without our messages (a ROS 2 shell where moose_msgs is not built): Cyclone, or a clear error
    without = {**env, "PYTHONPATH": ""}
    default, explicit = run_child(env["MOOSE_ROS_PYTHON"], BACKEND_IN_PREFIX, [], without)
    assert default == "dds"
    assert "runtime 'rclpy' is not available" in explicit and "moose_msgs cannot be imported" in explicit


# -- ros2 run-style entry points ---------------------------------------------------------------

PARAM_PROBE = textwrap.dedent(r'''
    import json, sys, time
    import rclpy
    from rcl_interfaces.srv import GetParameters
    rclpy.init()
    node = rclpy.create_node("entry_point_probe")
    target, names = sys.argv[1], json.loads(sys.argv[2])
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and target not in [f"{ns.rstrip('/')}/{n}"
                                                         for n, ns in node.get_node_names_and_namespaces()]:
        rclpy.spin_once(node, timeout_sec=0.1)
    client = node.create_client(GetParameters, f"{target}/get_parameters")
    client.wait_for_service(timeout_sec=20)
    future = client.call_async(GetParameters.Request(names=names))
    while time.monotonic() < deadline and not future.done():
        rclpy.spin_once(node, timeout_sec=0.1)
    publishers = sorted({i.node_name for i in node.get_publishers_info_by_topic("/perception/state")})
    print(json.dumps({"values": [v.string_value or v.bool_value for v in future.result().values],
                      "publishers": publishers}))
''')


def test_console_script_starts_one_node_on_rclpy_with_ros_args(ros_env: dict[str, str], tmp_path: Path) -> None:
    """``observer`` of .venv-ros (what ``ros2 run moose_ros observer`` starts) with ``--ros-args`` as
    ``ros2 run``/``ros2 launch`` pass them: a ROS 2 node in the namespace given, with the parameters
    given, seen by another rclpy process; Ctrl-C ends it with status 0."""
    script = Path(ros_env["MOOSE_ROS_PYTHON"]).parent / "observer"
    log = tmp_path / "observer.log"
    env = {k: v for k, v in ros_env.items() if k != "MOOSE_RUNTIME"}  # as a user's shell: the default runtime
    with open(log, "w") as out:
        proc = subprocess.Popen([str(script), "--ros-args", "-r", "__ns:=/car1", "-p", "scenario:=paper_v5_tau3",
                                 "-p", "use_sim_time:=true"], env=env, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
    try:
        seen = run_child(ros_env["MOOSE_ROS_PYTHON"], PARAM_PROBE,
                         ["/car1/observer", json.dumps(["scenario", "use_sim_time"])], ros_env, timeout=90)
        proc.send_signal(signal.SIGINT)
        status = proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert seen == {"values": ["paper_v5_tau3", True], "publishers": ["observer"]}
    assert status == 0, log.read_text()[-2000:]
    assert "observer started" in log.read_text()


SHUTDOWN_UNDER_THE_WAIT = textwrap.dedent(r'''
    import json
    import rclpy
    from moose_ros.runtime import create_node
    node = create_node("shutdown_probe", runtime="rclpy")
    node.timer(0.01, lambda: None)
    rclpy.try_shutdown()  # what rclpy's SIGINT handler does, here between a check of ok() and the next wait
    node._turn(0.05)
    print(json.dumps({"ok": rclpy.ok()}))
''')


def test_a_context_shut_down_under_the_executors_wait_ends_the_turn(ros_env: dict[str, str]) -> None:
    """CI (load 18): SIGINT to an rclpy node landed between spin()'s check of ``ok()`` and the executor's wait, which
    then raised RCLError ("the given context is not valid") and the node exited with a traceback, status 1."""
    assert run_child(ros_env["MOOSE_ROS_PYTHON"], SHUTDOWN_UNDER_THE_WAIT, [], ros_env, timeout=90) == {"ok": False}


INCOMPATIBLE_QOS = textwrap.dedent(r'''
    import json, os, sys, time
    from moose_ros.runtime import QOS_DEFAULT, QOS_SENSOR, create_node
    WHEELS = "moose_msgs/msg/WheelSpeeds"
    read, write = os.pipe()  # the log (rcutils writes to file descriptor 2), read here
    os.set_blocking(read, False)
    stderr = os.dup(2)
    os.dup2(write, 2)
    log = b""
    try:
        offer, request = create_node("qos_offer", runtime="rclpy"), create_node("qos_request", runtime="rclpy")
        offer.publisher(WHEELS, "/rt_test/qos", QOS_SENSOR)  # best effort
        request.publisher(WHEELS, "/rt_test/other")
        for n in (offer, request):  # a first wait with their event handlers: the next is a second later
            n.spin_once(0.05)
        request.subscription(WHEELS, "/rt_test/qos", print, QOS_DEFAULT)  # reliable: both sides' event is now
        deadline = time.monotonic() + float(sys.argv[1])
        while time.monotonic() < deadline and log.count(b"incompatible QoS") < 2:
            for n in (offer, request):
                n.spin_once(0.02)
            try:
                log += os.read(read, 65536)
            except BlockingIOError:
                pass
        for n in (offer, request):
            n.shutdown()
    finally:
        os.dup2(stderr, 2)
        sys.stderr.write(log.decode())
    print(json.dumps(sorted(line.split("]: ", 1)[-1] for line in log.decode().splitlines() if "incompatible" in line)))
''')


def test_an_incompatible_qos_is_logged_on_both_sides(ros_env: dict[str, str]) -> None:
    """rclpy's warnings for a remote endpoint with an incompatible QoS (its default event handlers, which the
    runtime gathers into one waitable that joins a wait once a second) reach the log of both nodes, also when the
    endpoints meet between two waits with the handlers."""
    assert run_child(ros_env["MOOSE_ROS_PYTHON"], INCOMPATIBLE_QOS, ["60"], ros_env, timeout=90) == [
        "New publisher discovered on topic '/rt_test/qos', offering incompatible QoS. No messages will be received "
        "from it. Last incompatible policy: RELIABILITY",
        "New subscription discovered on topic '/rt_test/qos', requesting incompatible QoS. No messages will be sent "
        "to it. Last incompatible policy: RELIABILITY"]


def test_console_script_refuses_bad_arguments_with_a_clear_error(ros_env: dict[str, str]) -> None:
    """A bad value given as ROS 2 does it, a misspelt option, and --ros-args on Cyclone (which would ignore
    them): each is ``observer: error: …`` with status 2 before the node runs."""
    script = str(Path(ros_env["MOOSE_ROS_PYTHON"]).parent / "observer")
    env = {k: v for k, v in ros_env.items() if k != "MOOSE_RUNTIME"}
    for args, extra, message in (
            (["--ros-args", "-p", "vehicle.m:=heavy"], {}, "observer: error: observer.vehicle.m = 'heavy' is invalid"),
            (["--parm", "seed=1"], {}, "error: unrecognized arguments: --parm seed=1"),
            (["--ros-args", "-p", "vehicle.m:=900.0"], {"MOOSE_RUNTIME": "dds"},
             "observer: error: --ros-args -p vehicle.m:=900.0: --ros-args are read by rclpy only")):
        result = subprocess.run([script, *args], env={**env, **extra}, capture_output=True, text=True, timeout=60)
        assert result.returncode == 2 and message in result.stderr, (args, result.stderr[-2000:])
        assert "Traceback" not in result.stderr
