"""BridgeRunner: the sender thread's schedule, the bounded receive, diagnostics, re-open, simulated time, the log."""
from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

import can
import pytest

from moose.canbus.bus import BusParams, open_bus
from moose.canbus.codec import Codec
from moose.canbus.runner import ERROR, WARN, BridgeParams, BridgeRunner, frames_per_period
from moose.canbus.safety import Command, GuardState
from moose.params import ParamError

CHANNEL = f"moose-test-runner-{os.getpid()}"


def drain(bus: can.BusABC) -> list[can.Message]:
    frames = []
    while (frame := bus.recv(timeout=0.0)) is not None:
        frames.append(frame)
    return frames


def decoded(frames: list[can.Message]) -> list[tuple[float, str, dict]]:
    rx = Codec()
    out = []
    for frame in frames:
        d = rx.decode(frame)
        assert d is not None
        out.append((frame.timestamp, d[0], d[1]))
    return out


@pytest.fixture()
def peer():
    bus = open_bus("virtual", CHANNEL)
    yield bus
    bus.shutdown()


def test_the_receive_bound_is_a_saturated_bus_per_command_period() -> None:
    assert frames_per_period(0.01) == 100  # 500 kbit/s over 10 ms / 50 bits (shortest frame + interframe space)
    assert BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL))).max_frames == 100
    with pytest.raises(ParamError, match="max_frames_per_cycle = 0 is invalid"):
        BridgeParams(max_frames_per_cycle=0)


def test_start_runs_the_bridge_threads_real_time_and_close_restores_the_scheduler() -> None:
    before = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    with BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL))) as runner:
        runner.start()
        time.sleep(0.02)
        assert runner.realtime_error is None, runner.realtime_error  # root here; elsewhere it needs CAP_SYS_NICE
        policy = os.sched_getscheduler(0)
        assert policy & ~os.SCHED_RESET_ON_FORK == os.SCHED_FIFO and os.sched_getparam(0).sched_priority == 10
        assert runner._thread is not None
        sender = runner._thread.native_id
        assert os.sched_getscheduler(sender) & ~os.SCHED_RESET_ON_FORK == os.SCHED_FIFO
        child = subprocess.run([sys.executable, "-c", "import os; print(os.sched_getscheduler(0))"],
                               capture_output=True, text=True, check=True)
        assert int(child.stdout) == os.SCHED_OTHER  # children do not inherit it
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before
    with pytest.raises(ParamError, match="realtime_priority = 100 is invalid"):
        BridgeParams(realtime_priority=100)


def test_the_sender_keeps_its_schedule_and_a_flood_is_cut_counted_and_reported(peer: can.BusABC) -> None:
    runner = BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)))
    junk = can.Message(arbitration_id=0x555, data=b"\x00" * 8, is_extended_id=False)
    with runner:
        runner.start()
        for _ in range(30):
            runner.command(Command(0.05, 0.0, 20.0, 20.0))
            runner.receive()
            time.sleep(0.01)
        assert "receive flood" not in runner.diagnostics().message
        for _ in range(1000):
            peer.send(junk)
        before = runner.rx_frames
        assert runner.receive() == [] and runner.rx_frames - before == 100  # one call reads at most 100 frames
        for _ in range(12):  # the virtual bus keeps the rest: 100 per cycle until it is read
            runner.command(Command(0.05, 0.0, 20.0, 20.0))
            runner.receive()
            time.sleep(0.01)
        assert runner.core.rx_overflows == 10 and runner.rx_frames - before == 1000
        diagnostics = runner.diagnostics()
        assert diagnostics.level == WARN and "receive flood: 10 cycles hit the 100-frame bound" in diagnostics.message
        assert diagnostics.values["rx_overflow_cycles"] == "10"
        for _ in range(25):
            runner.command(Command(0.05, 0.0, 20.0, 20.0))
            runner.receive()
            time.sleep(0.01)
        assert "receive flood" not in runner.diagnostics().message  # reported once, since the previous call
    frames = [f for f in drain(peer) if f.arbitration_id != 0x555]
    status = [v for _, name, v in decoded(frames) if name == "BRIDGE_STATUS"]
    assert any(s["RxOverflow"] == 1 for s in status)
    assert sum(f.arbitration_id == 0x100 for f in frames) > 40  # the sender ran throughout (gaps: test_can_flood.py)


def test_the_heartbeat_stops_saying_commanding_when_the_sender_stalls(peer: can.BusABC) -> None:
    runner = BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)))
    with runner:
        runner.start()
        stop = threading.Event()

        def controller() -> None:
            while not stop.is_set():
                runner.command(Command(0.0, 0.0, 10.0, 10.0))
                time.sleep(0.005)

        feeder = threading.Thread(target=controller)
        feeder.start()
        try:
            time.sleep(0.3)
            with runner._lock:  # the sender cannot build frames for 200 ms (a stalled process, a long GC pause)
                time.sleep(0.2)
            time.sleep(0.3)
        finally:
            stop.set()
            feeder.join()
        diagnostics = runner.diagnostics()
    beats = [(t, v["State"]) for t, name, v in decoded(drain(peer)) if name == "BRIDGE_HEARTBEAT"]
    assert diagnostics.level == WARN and "command frames late" in diagnostics.message
    assert runner.core.late_commands >= 1 and runner.core.max_command_gap >= 0.19
    states = [state for _, state in beats]
    assert 2 in states and states[-1] == 0  # "fault" after the stall, then commanding again
    first_fault = states.index(2)
    assert all(s == 0 for s in states[1:first_fault])


def test_a_driver_that_blocks_a_send_is_reported_by_the_next_heartbeat(peer: can.BusABC) -> None:
    class SlowOnce(can.interfaces.virtual.VirtualBus):
        """A real virtual bus whose driver blocks once for 60 ms (a full transmit queue)."""

        stalled = False

        def send(self, msg: can.Message, timeout: float | None = None) -> None:
            if msg.arbitration_id == 0x100 and not SlowOnce.stalled and time.monotonic() > start + 0.3:
                SlowOnce.stalled = True
                time.sleep(0.06)
            super().send(msg, timeout)

    start, wall = time.monotonic(), time.time()  # the virtual bus stamps frames with the wall clock
    runner = BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)), opener=lambda: SlowOnce(channel=CHANNEL))
    with runner:
        runner.start()
        for _ in range(70):
            runner.command(Command(0.0, 0.0, 10.0, 10.0))
            time.sleep(0.01)
    assert SlowOnce.stalled and runner.core.late_commands >= 1
    beats = [(t, v["State"]) for t, name, v in decoded(drain(peer)) if name == "BRIDGE_HEARTBEAT"]
    first_fault = next(t for t, state in beats if state == 2)
    assert wall + 0.3 < first_fault < wall + 0.3 + 0.06 + 0.2  # the heartbeat after the late send


def test_a_failing_bus_is_an_error_and_is_reopened_after_the_backoff(peer: can.BusABC) -> None:
    runner = BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)))
    with runner:
        runner.start()
        runner.command(Command(0.0, 0.0, 0.0, 0.0))
        time.sleep(0.05)
        assert drain(peer)
        runner.link.bus.shutdown()  # the interface goes away under the bridge
        time.sleep(0.03)
        diagnostics = runner.diagnostics()
        assert diagnostics.level == ERROR and "bus error: send failed" in diagnostics.message
        time.sleep(0.3)  # the first back-off is 0.1 s
        drain(peer)
        time.sleep(0.05)
        assert drain(peer) and runner.core.health.reopens == 1
        assert runner.diagnostics().level != ERROR


def test_a_dead_sender_is_reported(peer: can.BusABC) -> None:
    class BrokenBus(can.interfaces.virtual.VirtualBus):
        def send(self, msg: can.Message, timeout: float | None = None) -> None:
            raise RuntimeError("driver bug")

    runner = BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)),
                          opener=lambda: BrokenBus(channel=CHANNEL))
    with runner:
        runner.start()
        time.sleep(0.05)
        diagnostics = runner.diagnostics()
    assert diagnostics.level == ERROR and diagnostics.message == "command sender stopped: RuntimeError: driver bug"
    assert drain(peer) == []


def test_with_simulated_time_the_caller_drives_the_sender(peer: can.BusABC) -> None:
    now = [100.0]
    runner = BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)), clock=lambda: now[0])
    car = Codec()
    with runner:
        for k in range(40):
            now[0] = 100.0 + 0.01 * k
            peer.send(car.encode("EPS_STATUS", {"SteerAngle": 0.02}, now[0]))
            samples = runner.receive(stamp=now[0] - 100.0)  # ROS time of the sample
            assert len(samples) == 1 and samples[0].t == pytest.approx(0.01 * k)
            runner.command(Command(0.1, 0.5, 50.0, 50.0))
            runner.send_due()
        assert runner.core.guard.state == GuardState.COMMANDING
    steer = [v for _, name, v in decoded(drain(peer)) if name == "CMD_STEER"]
    assert len(steer) == 40 and steer[-1]["SteerAngleCmd"] == pytest.approx(0.1)  # 0.01 rad per frame


def test_the_log_records_both_directions_and_a_bad_log_path_is_a_param_error(tmp_path, peer: can.BusABC) -> None:
    path = tmp_path / "traffic.log"
    with BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)), log=str(path)) as runner:
        runner.start()
        peer.send(Codec().encode("EPS_STATUS", {"SteerAngle": 0.0}))
        time.sleep(0.05)
        runner.receive()
    ids = [frame.arbitration_id for frame in can.LogReader(str(path))]
    assert 0x100 in ids and 0x200 in ids
    with pytest.raises(ParamError, match=r"can_log = '.*traffic\.nope' is invalid"):
        BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)), log=str(tmp_path / "traffic.nope"))
    with pytest.raises(ParamError, match=r"can_log = '/proc/nope/traffic\.log' cannot be written"):
        BridgeRunner(BridgeParams(bus=BusParams("virtual", CHANNEL)), log="/proc/nope/traffic.log")
