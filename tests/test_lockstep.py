"""The lockstep protocol's bookkeeping (moose_ros.lockstep): who waits for whom, and which tick a node may handle
with which messages — without middleware."""
from __future__ import annotations

from moose_ros.graph import GRAPHS
from moose_ros.lockstep import ROOT, TickJoin, listeners, waits

FULL = GRAPHS["full"]


def test_each_node_waits_for_the_root_its_upstream_and_the_feedback_one_tick_late() -> None:
    assert waits("observer", FULL) == {ROOT: 0}
    assert waits("motion_controller", FULL) == {ROOT: 0, "observer": 0, "weight_fbl": 0}
    assert waits("mpc_planner", FULL) == {"weight_fbl": 1, ROOT: 0, "observer": 0, "obstacle_detector": 0}
    assert waits("msf_planner", FULL) == waits("mpc_planner", FULL)  # both hear the blends in flight
    assert waits(ROOT, FULL) == {n: 0 for n in FULL if n != ROOT}
    can = GRAPHS["can"]  # the bridge makes the sensor topics and forwards the commands: it handles a tick last
    assert waits("observer", can) == {"can_bridge": 1, ROOT: 0}  # its samples one tick later: the bus hop
    assert waits("motion_controller", can) == {"can_bridge": 1, ROOT: 0, "observer": 0, "weight_fbl": 0}
    assert waits("can_bridge", can) == {ROOT: 0, "motion_controller": 0}  # the tick's commands go out in the tick
    assert waits(ROOT, can)["can_bridge"] == 0  # the simulator steps with the command frames of the tick
    assert listeners("weight_fbl", FULL) == 4  # the planners (its blend), the motion controller, the simulator
    assert listeners(ROOT, FULL) == len(FULL) - 1


def join(node: str) -> TickJoin:
    from moose_ros.lockstep import data_topics

    return TickJoin(node, FULL, [t.name for t in data_topics(node)])


def test_a_tick_is_handed_over_only_complete_and_in_publication_order() -> None:
    j = join("motion_controller")
    everyone = tuple(FULL)
    j.marker(ROOT, 0, ("/vehicle/imu", "/vehicle/wheel_speeds", "/vehicle/steering"), everyone)
    assert j.take() is None  # nothing from the observer and weight_fbl yet
    j.message("/control/reference", "ref0")
    j.marker("weight_fbl", 0, ("/planning/blend", "/control/reference"), None)
    j.marker("observer", 0, ("/perception/state", "/tf"), None)
    assert j.take() is None  # the root announced wheel speeds and steering, not here yet
    j.message("/vehicle/steering", "eps0")
    j.message("/vehicle/wheel_speeds", "wheels0")
    assert j.take() is None  # the estimate the observer announced is missing
    j.message("/perception/state", "state0")
    assert j.take() == (0, [("/vehicle/wheel_speeds", "wheels0"), ("/vehicle/steering", "eps0"),
                            ("/perception/state", "state0"), ("/control/reference", "ref0")])
    assert j.take() is None and j.next == 1


def test_feedback_of_the_previous_tick_comes_first_and_a_faulted_node_is_not_waited_for() -> None:
    j = join("mpc_planner")
    everyone = tuple(FULL)
    for k in (0, 1):
        j.marker(ROOT, k, (), everyone if k == 0 else tuple(n for n in everyone if n != "weight_fbl"))
        j.marker("observer", k, ("/perception/state",), None)
        j.message("/perception/state", f"state{k}")
        j.marker("obstacle_detector", k, ("/perception/threat",), None)
        j.message("/perception/threat", f"threat{k}")
    assert j.take() == (0, [("/perception/state", "state0"), ("/perception/threat", "threat0")])
    assert j.take() is None  # tick 1 needs weight_fbl's tick 0: the blend the MPC warm-starts from
    j.message("/planning/blend", "blend0")
    j.marker("weight_fbl", 0, ("/planning/blend", "/control/reference"), None)
    assert j.take() == (1, [("/planning/blend", "blend0"), ("/perception/state", "state1"),
                            ("/perception/threat", "threat1")])
    # from tick 2 on weight_fbl is out of the plan (a fault): its messages are taken as they come, no marker needed
    j.marker(ROOT, 2, (), tuple(n for n in everyone if n != "weight_fbl"))
    j.marker("observer", 2, (), None)
    j.marker("obstacle_detector", 2, (), None)
    j.message("/planning/blend", "late blend")
    assert j.take() == (2, [("/planning/blend", "late blend")])


def test_a_node_left_out_runs_on_whatever_arrived() -> None:
    j = join("obstacle_detector")
    j.marker(ROOT, 0, (), tuple(n for n in FULL if n != "obstacle_detector"))
    j.message("/perception/state", "state0")
    assert j.take() == (0, [("/perception/state", "state0")])


def test_the_bus_counts_frames_between_the_ecus_and_the_bridge() -> None:
    """The CAN graph: each frame on the bus is an entry ``can`` of its sender's marker; the other side hands a tick
    over only with all of them."""
    from moose_ros.lockstep import BUS

    can = GRAPHS["can"]
    bridge = TickJoin("can_bridge", can)
    bridge.add(BUS)
    bridge.add("/control/actuator_command")
    assert bridge.publishes == {ROOT: [BUS], "motion_controller": ["/control/actuator_command"]}
    bridge.marker(ROOT, 0, (BUS, BUS, BUS), tuple(can))
    bridge.marker("motion_controller", 0, ("/control/actuator_command",), None)
    bridge.message(BUS, "IMU")
    bridge.message("/control/actuator_command", "u0")
    bridge.message(BUS, "WHEEL_SPEEDS")
    assert bridge.take() is None  # the EPS frame is still on its way
    bridge.message(BUS, "EPS_STATUS")
    assert bridge.take() == (0, [(BUS, "IMU"), (BUS, "WHEEL_SPEEDS"), (BUS, "EPS_STATUS"),
                                 ("/control/actuator_command", "u0")])
