"""The lockstep protocol's bookkeeping (moose_ros.lockstep): who waits for whom, and which tick a node may handle
with which messages — without middleware."""
from __future__ import annotations

from moose_ros.faults import Fault
from moose_ros.graph import GRAPHS
from moose_ros.lockstep import ROOT, TickJoin, listeners, root_reads, waits

FULL = GRAPHS["full"]


def test_each_node_waits_for_the_root_its_upstream_and_the_feedback_one_tick_late() -> None:
    assert waits("observer", FULL) == {ROOT: 0}
    assert waits("motion_controller", FULL) == {ROOT: 0, "observer": 0, "weight_fbl": 0}
    # the planners and weight_fbl read nothing of the simulator: its marker's list of the nodes waited for comes
    # from the fault plan (expected_at), one datagram less per tick each
    assert waits("mpc_planner", FULL) == {"weight_fbl": 1, "observer": 0, "obstacle_detector": 0}
    assert waits("msf_planner", FULL) == waits("mpc_planner", FULL)  # both hear the blends in flight
    assert waits("weight_fbl", FULL) == {"observer": 0, "obstacle_detector": 0, "mpc_planner": 0, "msf_planner": 0}
    assert waits("mpc_planner", (ROOT, "mpc_planner")) == {ROOT: 0}  # the bag player announces what it plays
    assert waits(ROOT, FULL) == {n: 0 for n in FULL if n != ROOT}  # the bag player: every node it drives
    assert waits(ROOT, FULL, ()) == {"motion_controller": 0}  # the simulator without faults: the commands' marker
    can = GRAPHS["can"]  # the bridge makes the sensor topics and forwards the commands: it handles a tick last
    assert waits("observer", can) == {"can_bridge": 1, ROOT: 0}  # its samples one tick later: the bus hop
    assert waits("motion_controller", can) == {"can_bridge": 1, ROOT: 0, "observer": 0, "weight_fbl": 0}
    assert waits("can_bridge", can) == {ROOT: 0, "motion_controller": 0}  # the tick's commands go out in the tick
    assert waits(ROOT, can, ()) == {"can_bridge": 0}  # the simulator steps with the command frames of the tick
    assert listeners("weight_fbl", FULL) == 3  # the planners (its blend), the motion controller
    assert listeners("motion_controller", FULL) == 1  # the simulator (its commands)
    assert listeners(ROOT, FULL) == 3  # the observer, the detector, the motion controller: they read its messages
    assert listeners(ROOT, GRAPHS["can"]) == 4  # and the bridge, its frames


def test_the_simulator_reads_the_markers_that_imply_every_other_one() -> None:
    """The simulator steps past tick k once the nodes of ``root_reads`` have reported k.  Checked against the
    waits themselves: for every set of nodes a fault plan can leave out, every expected node has a chain of
    same-tick waits (its marker k is needed before another expected node handles k) to a node the simulator reads."""
    import itertools

    for graph in ("full", "can"):
        nodes = GRAPHS[graph]
        others = [n for n in nodes if n != ROOT]
        for size in range(len(others) + 1):
            for faulted in itertools.combinations(others, size):
                read = root_reads(nodes, faulted)
                assert read <= set(others)
                for left in itertools.chain.from_iterable(itertools.combinations(faulted, r)
                                                          for r in range(len(faulted) + 1)):
                    expected = set(others) - set(left)
                    done = {n for n in read if n in expected}  # reported k: so has everything they wait for at k
                    frontier = list(done)
                    while frontier:
                        node = frontier.pop()
                        for upstream, lag in waits(node, nodes).items():
                            if lag == 0 and upstream in expected and upstream not in done:
                                done.add(upstream)
                                frontier.append(upstream)
                    assert done == expected, (graph, faulted, left, sorted(expected - done))
    assert root_reads(FULL, ["weight_fbl"]) == {"mpc_planner", "msf_planner", "motion_controller"}  # blend gone
    assert root_reads(FULL, ["motion_controller"]) == {"weight_fbl", "motion_controller"}
    assert root_reads(GRAPHS["can"], ["can_bridge"]) == {"motion_controller", "can_bridge"}


def join(node: str, faults: tuple[Fault, ...] = ()) -> TickJoin:
    from moose_ros.lockstep import data_topics

    return TickJoin(node, FULL, [t.name for t in data_topics(node)], faults=faults, period=0.01)


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
    j = join("mpc_planner", (Fault("weight_fbl", "kill", 0.01),))  # weight_fbl killed at tick 1
    for k in (0, 1):
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
    # from tick 1 on weight_fbl is out of the plan (a fault): it ran no tick 1, so tick 2 needs no marker of it
    j.marker("observer", 2, (), None)
    j.marker("obstacle_detector", 2, (), None)
    assert j.take() == (2, [])


def stalled_planner(ticks: int) -> TickJoin:
    """The MPC planner's join, left out of ticks 1 … ``ticks`` (a stall), with one estimate and one threat announced
    and sent per tick 0 … ``ticks`` + 1 and the blend of tick 0."""
    j = join("mpc_planner", (Fault("mpc_planner", "stall", 0.01, 0.01 * ticks),))
    for k in range(ticks + 2):
        for node, topic in (("observer", "/perception/state"), ("obstacle_detector", "/perception/threat")):
            j.marker(node, k, (topic,), None)
            j.message(topic, f"{topic.rsplit('/', 1)[1]}{k}")
        j.marker("weight_fbl", k, ("/planning/blend",) if k == 0 else (), None)
    j.message("/planning/blend", "blend0")
    return j


def test_a_stalled_node_runs_no_tick_and_then_gets_what_its_queues_kept() -> None:
    """A node the root leaves out of a tick (a stall) does not run it; at the tick the graph expects it again it gets
    the backlog first, the newest of each topic up to its subscription's depth on the car (10 for the estimate and the
    threat), then the tick's own messages — what the process would find in its reader queues after SIGCONT."""
    j = stalled_planner(15)
    assert j.take() == (0, [("/perception/state", "state0"), ("/perception/threat", "threat0")])
    k, items = j.take()  # ticks 1 … 15 passed by, stopped
    assert k == 16
    assert items == ([("/planning/blend", "blend0")] + [("/perception/state", f"state{i}") for i in range(6, 16)]
                     + [("/perception/threat", f"threat{i}") for i in range(6, 16)]
                     + [("/perception/state", "state16"), ("/perception/threat", "threat16")])
    assert j.take() is None and j.next == 17 and not j.backlog


def test_a_stalled_node_waits_for_its_whole_backlog_before_it_runs_again() -> None:
    j = stalled_planner(3)
    j.queues["/perception/threat"].pop()  # tick 4's threat still on its way
    assert j.take() is not None and j.take() is None and j.next == 4  # ticks 1 … 3 passed by; 4 waits
    j.message("/perception/threat", "threat4")
    k, items = j.take()
    assert k == 4 and items[-1] == ("/perception/threat", "threat4") and len(items) == 1 + 2 * 3 + 2


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


def test_a_stall_longer_than_the_queues_keep_is_refused_in_lockstep() -> None:
    """While a stalled node is stopped, what the graph sends it waits in keep-last histories of DEPTH ticks: a longer
    stall would lose what it must be handed, so the launcher refuses it before anything starts."""
    import pytest

    from moose.params import ParamError
    from moose_ros.faults import Fault
    from moose_ros.launch import node_overrides
    from moose_ros.lockstep import STALL_TICKS_MAX

    def launch(fault: str, lockstep: bool = True) -> None:
        node_overrides("full", "combined", {"scenario": "paper_v6_w2.0"}, lockstep=lockstep,
                       faults=[Fault.parse(fault)])

    longest = STALL_TICKS_MAX * 0.01
    launch(f"observer:stall@2.5:{longest:g}")
    with pytest.raises(ParamError, match=rf"observer:stall@2.5:{longest + 0.01:g}' is invalid in lockstep: a stall "
                                         rf"lasts at most {longest:g} s"):
        launch(f"observer:stall@2.5:{longest + 0.01:g}")
    launch("observer:stall@2.5:5", lockstep=False)  # at real time the queues drop what they must
    launch("vehicle_simulator:stall@2.5:5")  # simulated time stands still with it: no backlog


def test_in_lockstep_the_fault_signals_wait_until_the_graph_has_taken_what_the_node_sent() -> None:
    """The faulted node runs no tick from its fault's on, whenever the signal lands; the signal waits one tick, until
    every reader has taken what the node sent before (a killed writer cannot resend a message lost on the way, and its
    reader would wait for it for good).  A stall ends at its simulated end, where the graph waits for the node, not D
    after the signal; a killed simulator steps no further than its fault's tick, so it is killed at that tick.  Real
    processes (``sleep``), their state read from /proc."""
    import subprocess
    import time

    from moose_ros.faults import FaultInjector
    from moose_ros.incidents import IncidentLog
    from moose_ros.process import state as process_state

    def now(proc: subprocess.Popen) -> str:
        if proc.poll() is not None:
            return f"exit {proc.returncode}"
        return "stopped" if process_state(proc.pid) in "Tt" else "running"

    def state(proc: subprocess.Popen, settle: float = 0.2) -> str:
        """Its state once a signal sent to it has taken effect (/proc shows it within milliseconds)."""
        time.sleep(settle)
        return now(proc)

    names = ("observer", "mpc_planner", "vehicle_simulator")
    procs = {name: subprocess.Popen(["sleep", "60"]) for name in names}
    try:
        plan = ("observer:kill@2.5", "mpc_planner:stall@2.5:0.6", "vehicle_simulator:kill@3.2")
        faults = [Fault.parse(f) for f in plan]
        injector = FaultInjector(faults, procs, 1.0, IncidentLog(), lambda _text: None, tick=0.01)
        injector.poll(2.5)
        assert [state(procs[n]) for n in names] == ["running"] * 3  # the graph may still read what they sent
        injector.poll(2.51)
        assert [state(procs[n]) for n in names] == ["exit -9", "stopped", "running"]
        injector.poll(3.09)
        assert state(procs["mpc_planner"]) == "stopped"  # 0.6 s after the signal, but not yet the stall's end
        injector.poll(3.1)
        assert state(procs["mpc_planner"]) == "running"  # continued: the graph waits for it at 3.1
        injector.poll(3.19)
        assert state(procs["vehicle_simulator"]) == "running"
        injector.poll(3.2)
        assert state(procs["vehicle_simulator"]) == "exit -9"
    finally:
        for proc in procs.values():
            proc.kill()
            proc.wait()
