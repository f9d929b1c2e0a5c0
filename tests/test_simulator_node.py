"""The ``vehicle_simulator`` node on its actuator topic: a command older than ``command_timeout`` stops driving.

The real node class on a real Cyclone DDS participant (this run's domain); its simulated time is advanced
step by step by the test (its wall-clock timer is set 10 s apart, so it never fires), and the command comes
from another participant over DDS.  The reference is the plant driven with the input the timeout allows.
"""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

from moose.canbus.bridge import BridgeCore
from moose.canbus.bus import open_bus
from moose.canbus.safety import Command, GuardParams
from moose.vehicle import DELTA, OMEGA_RL, VX, VY, VehiclePlant
from moose_ros.graph import ACTUATOR_COMMAND
from moose_ros.nodes.simulator import VehicleSimulator
from moose_ros.runtime import DdsNode

pytestmark = [pytest.mark.graph]

TORQUE = 200.0


def wait_until(condition, seconds: float, spin) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if condition():
            return True
        spin()
    return condition()


def test_a_command_older_than_the_timeout_stops_driving_the_plant() -> None:
    rt = DdsNode("vehicle_simulator", overrides={"scenario": "paper_v7_tau1.4", "wait_for": [], "rate": 1e-3,
                                                  "use_sim_time": False})
    commander = DdsNode("test_commander", overrides={"use_sim_time": False})
    try:
        sim = VehicleSimulator(rt)
        timeout, dt = sim.params.command_timeout, sim.dt
        publish = ACTUATOR_COMMAND.publisher(commander)
        assert wait_until(lambda: commander.count_subscribers(ACTUATOR_COMMAND.name) >= 1
                          and rt.count_publishers(ACTUATOR_COMMAND.name) >= 1, 20.0, lambda: rt.spin_once(0.05))
        for _ in range(20):  # 0.2 s of coasting: no command yet
            sim.tick()
        before = sim.plant.state
        msg = commander.make(ACTUATOR_COMMAND.type, steering_angle=0.0, steering_rate=0.0, torque_rl=TORQUE,
                             torque_rr=TORQUE)
        publish(msg)
        end = time.monotonic() + 1.0  # delivery on loopback takes milliseconds; the node's timer never fires
        while time.monotonic() < end:
            rt.spin_once(0.02)
        states = []
        for _ in range(100):  # 1 s of simulated time after the single command
            sim.tick()
            states.append(sim.plant.state)
        states = np.array(states)
    finally:
        commander.shutdown()
        rt.shutdown()
    # the reference: the plant under the command for as long as the timeout allows (the steps at t1 … t1 + timeout),
    # then without drive torque
    steps = int(np.floor(timeout / dt + 1e-9)) + 1
    reference = VehiclePlant(sim.plant.params, dt=sim.plant.dt)
    reference.reset(before)
    driven = [reference.step(np.array([0.0, TORQUE, TORQUE]), sim.steps) for _ in range(steps)]
    coasted = [reference.step(np.zeros(3), sim.steps) for _ in range(100 - steps)]
    expected = np.array(driven + coasted)
    # the command arrived and acted: the car sped up (the whole command, or a rate-limited part of it)
    assert np.max(states[:, VX]) > before[VX] + 0.01 and np.max(states[:, OMEGA_RL]) > before[OMEGA_RL] + 0.1
    # and it stopped acting after the timeout: never more drive than the command held for the timeout gives
    # (the simulator may limit the torque's rate, or brake once the command is stale)
    assert np.all(states[steps:, VX] <= expected[steps:, VX] + 1e-6)
    held = VehiclePlant(sim.plant.params, dt=sim.plant.dt)  # what ignoring the timeout would have done
    held.reset(before)
    assert held.step(np.array([0.0, TORQUE, TORQUE]), 100 * sim.steps)[VX] > expected[-1, VX] + 1.0


@pytest.mark.can
@pytest.mark.parametrize("level_two", [True, False], ids=["ecu_minimum_risk", "no_ecu_minimum_risk"])
def test_on_the_can_bus_the_emulated_ecus_stop_the_car_when_the_commands_stop(level_two: bool) -> None:
    """The simulator as the vehicle-side ECU emulator (``vehicle_bus: can``) on a virtual bus: commands as frames
    from the bridge's core for 0.5 s, then none (a dead bridge).  ``ecu_minimum_risk`` decides what the car does."""
    channel = f"moose-test-ecu-{os.getpid()}-{level_two}"
    rt = DdsNode("vehicle_simulator", overrides={"scenario": "paper_v7_tau1.4", "wait_for": [], "rate": 1e-3,
                                                  "use_sim_time": False, "vehicle_bus": "can",
                                                  "can_interface": "virtual", "can_channel": channel,
                                                  "ecu_minimum_risk": level_two})
    bridge_side = open_bus("virtual", channel)
    try:
        sim = VehicleSimulator(rt)
        bridge = BridgeCore(GuardParams.from_vehicle(sim.config.vehicle))
        for k in range(50):  # steer left gently, light drive torque
            bridge.on_command(Command(0.05, 0.5, 20.0, 20.0), 0.01 * k)
            for frame in bridge.tick(0.01 * k):
                bridge_side.send(frame)
            sim.tick()
        for _ in range(1000):  # 10 s without a bridge
            sim.tick()
        state = sim.plant.state
    finally:
        bridge_side.shutdown()
        rt.shutdown()
    speed = float(np.hypot(state[VX], state[VY]))
    if level_two:
        assert speed < 0.1 and abs(state[DELTA]) < 0.01
    else:
        assert speed > 2.0 and abs(state[DELTA]) > 0.02, (speed, state[DELTA])  # coasting, the steering held


def test_a_lockstep_graph_that_stops_reporting_ends_with_lockstep_stuck() -> None:
    """In lockstep the simulator waits for every node's tick; an observer that connects and then never reports one
    must not hang the run: after ``lockstep_timeout`` of wall-clock time the simulator names it and ends."""
    from moose_ros.graph import GPS, IMU, STEERING, WHEEL_SPEEDS
    from moose_ros.lockstep import QOS_DATA, QOS_MARKER, TICK_TYPE, marker_topic

    nodes = ["vehicle_simulator", "observer"]
    rt = DdsNode("vehicle_simulator", overrides={"scenario": "paper_v7_tau1.4", "wait_for": [], "use_sim_time": False,
                                                  "lockstep_nodes": nodes, "lockstep_timeout": 0.5})
    silent = DdsNode("observer", overrides={"use_sim_time": False})  # reads what the simulator sends, never reports
    ticks: list[float] = []
    try:
        sim = VehicleSimulator(rt)
        for topic in (IMU, GPS, WHEEL_SPEEDS, STEERING):
            silent.subscription(topic.type, topic.name, lambda _msg: None, QOS_DATA)
        silent.subscription(TICK_TYPE, marker_topic("vehicle_simulator"), lambda msg: ticks.append(msg.stamp.sec),
                            QOS_MARKER)
        assert wait_until(lambda: sim.finished, 30.0, lambda: (rt.spin_once(0.02), silent.spin_once(0.02)))
    finally:
        silent.shutdown()
        rt.shutdown()
    assert ticks == [0]  # tick 0 went out; tick 1 never came
    assert sim.message == "stuck" and sim.t == 0.0
    level, text = sim.problems["lockstep_stuck"]
    assert level == 2 and "lockstep stuck at t = 0.00 s: no tick from observer" in text, text


@pytest.mark.parametrize("observer_reports", [False, True], ids=["observer-silent", "detector-silent"])
def test_a_stuck_graph_names_the_nodes_whose_markers_the_simulator_does_not_read(observer_reports: bool) -> None:
    """The simulator reads only the markers that imply all others (here the detector's, which waits for the
    observer's tick); when the graph is stuck it listens to the rest before it names every node that did not report."""
    from moose_ros.graph import GPS, IMU, OBSTACLES, STEERING, WHEEL_SPEEDS
    from moose_ros.lockstep import QOS_DATA, QOS_MARKER, TICK_TYPE, marker_message, marker_topic

    nodes = ["vehicle_simulator", "observer", "obstacle_detector"]
    rt = DdsNode("vehicle_simulator", overrides={"scenario": "paper_v7_tau1.4", "wait_for": [], "use_sim_time": False,
                                                  "lockstep_nodes": nodes, "lockstep_timeout": 0.5})
    observer = DdsNode("observer", overrides={"use_sim_time": False})
    detector = DdsNode("obstacle_detector", overrides={"use_sim_time": False})
    marker = observer.publisher(TICK_TYPE, marker_topic("observer"), QOS_MARKER)

    def on_root(msg: object) -> None:
        if observer_reports:  # it reports every tick the root opens, and publishes nothing
            marker(marker_message(observer.make, "observer", msg.stamp.sec + 1e-9 * msg.stamp.nanosec, []))

    try:
        sim = VehicleSimulator(rt)
        assert sim.join is not None and list(sim.join.waits) == ["obstacle_detector"]
        for topic in (IMU, GPS, WHEEL_SPEEDS, STEERING):
            observer.subscription(topic.type, topic.name, lambda _msg: None, QOS_DATA)
        detector.subscription(OBSTACLES.type, OBSTACLES.name, lambda _msg: None, QOS_DATA)
        observer.subscription(TICK_TYPE, marker_topic("vehicle_simulator"), on_root, QOS_MARKER)
        detector.subscription(TICK_TYPE, marker_topic("vehicle_simulator"), lambda _msg: None, QOS_MARKER)
        assert wait_until(lambda: sim.finished, 30.0,
                          lambda: (rt.spin_once(0.02), observer.spin_once(0.01), detector.spin_once(0.01)))
    finally:
        observer.shutdown()
        detector.shutdown()
        rt.shutdown()
    assert sim.message == "stuck" and sim.t == 0.0
    late = "obstacle_detector" if observer_reports else "observer, obstacle_detector"
    assert f"lockstep stuck at t = 0.00 s: no tick from {late} for " in sim.problems["lockstep_stuck"][1]


def test_the_stuck_probe_waits_only_for_the_nodes_the_tick_expects() -> None:
    """A probed node the fault plan killed never reports again: the probe does not wait for it (and does not name
    it); it waits for the expected probed nodes it has not heard report the tick, whom :meth:`missing` names."""
    nodes = ["vehicle_simulator", "observer", "obstacle_detector", "weight_fbl"]
    rt = DdsNode("vehicle_simulator", overrides={"scenario": "paper_v7_tau1.4", "wait_for": [], "use_sim_time": False,
                                                  "lockstep_nodes": nodes, "faults": ["observer:kill@0"]})
    try:
        sim = VehicleSimulator(rt)
        assert sim.join is not None and "observer" not in sim.join.waits
        sim.probe(0.0)
        assert sim.heard is not None and sim.heard.get("observer") == -1
        probed = set(sim.heard) - {"observer"}
        assert probed, sim.heard  # another probed node, expected at the tick
        assert sim.unheard() == probed and set(sim.missing()) >= probed
        for node in probed:
            sim.heard[node] = sim.join.next
        assert sim.unheard() == set() and "observer" not in sim.missing()
    finally:
        rt.shutdown()


def test_a_lockstep_graph_that_never_connects_ends_with_lockstep_stuck() -> None:
    rt = DdsNode("vehicle_simulator", overrides={"scenario": "paper_v7_tau1.4", "wait_for": [], "use_sim_time": False,
                                                  "lockstep_nodes": ["vehicle_simulator", "observer"],
                                                  "lockstep_timeout": 0.5})
    try:
        sim = VehicleSimulator(rt)
        assert wait_until(lambda: sim.finished, 30.0, lambda: rt.spin_once(0.02))
    finally:
        rt.shutdown()
    assert "the graph did not connect" in sim.problems["lockstep_stuck"][1]
