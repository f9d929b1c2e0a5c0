"""Bags: round trip through DDS, crash safety, recovery errors, replay into the observer, re-planning."""
from __future__ import annotations

import dataclasses
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import Reader

from moose.config import load_config
from moose.scenario import load_scenario
from moose.verdict import EXIT_INCOMPLETE
from moose_ros import convert as cv
from moose_ros.bag import BagError, ReadReport, Recorder, bag_info, export, play, read_bag, replan
from moose_ros.interfaces import from_rosbags
from moose_ros.lockstep import QOS_DATA
from moose_ros.runtime import DdsNode

ROOT = Path(__file__).resolve().parents[1]
EXTREME = ROOT / "bags" / "paper_v7_tau1.4_combined"
RELAXED = ROOT / "bags" / "paper_v5_tau3_combined"

PUBLISHER = textwrap.dedent("""
    import sys, time
    import numpy as np
    from moose_ros.runtime import create_node, QOS_DEFAULT
    from moose_ros import convert as cv
    node = create_node("bag_source")
    odom = node.publisher("nav_msgs/msg/Odometry", "/vehicle/odom", QOS_DEFAULT)
    state = node.publisher("moose_msgs/msg/StateEstimate", "/perception/state", QOS_DEFAULT)
    deadline = time.monotonic() + 20.0
    while odom.subscription_count() == 0 and time.monotonic() < deadline:  # the recorder has matched
        time.sleep(0.05)
    time.sleep(0.3)
    from moose.signals import StateEstimate
    for k in range(int(sys.argv[1])):
        odom(cv.odometry_to_msg(node, 0.02 * k, np.array([0.1 * k, 0.0, 0.0, 5.0, 0.0, 0.0])))
        if k % 2 == 0:
            state(cv.estimate_to_msg(node, StateEstimate(0.02 * k, 0.1 * k, 0.0, 0.0, 5.0, 0.0, 0.0, 0.0)))
        time.sleep(0.02)
    time.sleep(0.5)
""")


@pytest.mark.graph
@pytest.mark.slow
@pytest.mark.realtime  # the rate of a sleep-paced publisher, stamped on reception: judged against the wall clock
def test_record_round_trip_read_back_independently(tmp_path: Path) -> None:
    node = DdsNode("bag_test_recorder")
    recorder = Recorder(node, tmp_path / "bag", ["/vehicle/odom", "/perception/state"])
    proc = subprocess.Popen([sys.executable, "-c", PUBLISHER, "100"])
    try:
        deadline = time.monotonic() + 30.0
        while proc.poll() is None and time.monotonic() < deadline:
            node.spin_once(0.05)
        node.spin_once(0.2)
    finally:
        proc.kill()
        proc.wait()
        recorder.close()
    with Reader(tmp_path / "bag") as reader:  # rosbags' own reader, not ours
        counts = {c.topic: c.msgcount for c in reader.connections}
        stamps = [t for c, t, _ in reader.messages() if c.topic == "/vehicle/odom"]
        assert {c.msgtype for c in reader.connections} == {"nav_msgs/msg/Odometry", "moose_msgs/msg/StateEstimate"}
    assert counts["/vehicle/odom"] == 100 and counts["/perception/state"] == 50
    rate = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) * 1e-9)
    assert 30.0 < rate < 55.0  # published at 50 Hz (sleep-paced), stamped on reception
    assert (tmp_path / "bag" / "metadata.yaml").is_file()


RECORDER = [sys.executable, "-m", "moose.cli", "bag", "record", "--topics", "/vehicle/odom", "-o"]


@pytest.mark.graph
@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killed_recorder_leaves_a_readable_bag(tmp_path: Path, sig: int) -> None:
    """Killed 0.5 s after the last message was published, the recorder has lost nothing it received: its timer
    closed the last chunk within 0.3 s.  SIGKILL leaves the bag as its last checkpoint wrote it: a valid MCAP file
    and metadata.yaml that mcap's own reader and rosbags open (on main: RecordLengthLimitExceeded, and no
    metadata.yaml for rosbags), said to be unfinished."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    out = tmp_path / "bag"
    recorder = subprocess.Popen(RECORDER + [str(out)], stdout=subprocess.PIPE, text=True)
    publisher = None
    try:
        assert recorder.stdout is not None and "recording into" in recorder.stdout.readline()
        publisher = subprocess.Popen([sys.executable, "-c", PUBLISHER, "200"])
        publisher.wait(timeout=40)
        time.sleep(0.5)
        recorder.send_signal(sig)
        recorder.wait(timeout=20)
    finally:
        if publisher is not None:
            publisher.kill()
            publisher.wait()
        recorder.kill()
        recorder.wait()
    report = ReadReport(str(out))
    messages = list(read_bag(out, report=report))
    xs = [from_rosbags(m.msg, m.type_name).pose.pose.position.x for m in messages]
    assert len(messages) == 200 and np.allclose(xs, 0.1 * np.arange(200))  # all of them, in order
    assert (report.unfinished != []) == (sig == signal.SIGKILL) and report.missing == {} and not report.lost_bytes
    with open(next(out.glob("*.mcap")), "rb") as stream:
        decoded = [m.decoded_message.pose.pose.position.x
                   for m in make_reader(stream, decoder_factories=[DecoderFactory()]).iter_decoded_messages()]
    assert np.allclose(decoded, 0.1 * np.arange(200))
    with Reader(out) as reader:
        assert sum(1 for _ in reader.messages()) == 200


def test_corrupt_and_truncated_bags_give_clear_errors(tmp_path: Path) -> None:
    garbage = tmp_path / "garbage"
    garbage.mkdir()
    (garbage / "garbage.mcap").write_bytes(b"not an mcap file at all" * 10)
    with pytest.raises(BagError, match="not a readable MCAP file|no complete chunk"):
        list(read_bag(garbage))
    with pytest.raises(BagError, match="does not exist"):
        list(read_bag(tmp_path / "missing"))
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(BagError, match="neither metadata.yaml nor an .mcap"):
        list(read_bag(empty))
    truncated = tmp_path / "truncated"
    shutil.copytree(EXTREME, truncated)
    mcap = next(truncated.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[: int(mcap.stat().st_size * 0.9)])  # past the first (1 MiB) chunk
    (truncated / "metadata.yaml").unlink()
    recovered = list(read_bag(truncated))
    assert 0 < len(recovered) < bag_info(EXTREME)["messages"]


def test_info_and_export(tmp_path: Path) -> None:
    info = bag_info(RELAXED)
    assert info["duration_s"] == pytest.approx(9.0)
    assert info["topics"]["/perception/state"]["rate_hz"] == pytest.approx(100.0)
    assert info["topics"]["/planning/mpc"]["rate_hz"] == pytest.approx(5.0, rel=0.05)
    files = export(RELAXED, tmp_path, ["/perception/state"])
    lines = files[0].read_text().splitlines()
    assert lines[0].startswith("timestamp_ns,header.stamp.sec") and len(lines) == 902
    import pyarrow.parquet as pq

    (parquet,) = export(RELAXED, tmp_path / "pq", ["/planning/mpc"], fmt="parquet")
    table = pq.read_table(parquet)
    assert table.num_rows == 46 and "accel_y[0]" in table.column_names and "status" in table.column_names


SENSORS = ["/vehicle/imu", "/vehicle/gps", "/vehicle/wheel_speeds", "/vehicle/steering"]


def _estimate(m: object) -> tuple[float, ...]:
    """A /perception/state message as its time and every field."""
    return (cv.time_of(m),) + tuple(float(getattr(m, f)) for f in ("x", "y", "theta", "vx", "vy", "gamma", "beta",
                                                                    "delta"))


def _observer(*params: str) -> subprocess.Popen:
    """An observer node process for the relaxed case's bag (paper_v5_tau3)."""
    return subprocess.Popen([sys.executable, "-m", "moose_ros.nodes", "observer", "--param", "scenario=paper_v5_tau3",
                             *[a for p in params for a in ("--param", p)]], env=dict(os.environ),
                            stdout=subprocess.DEVNULL)


@pytest.mark.graph
@pytest.mark.slow
def test_replay_in_lockstep_drives_the_observer_to_every_recorded_estimate() -> None:
    """The example bag's sensor topics replayed in lockstep (``bag play --lockstep observer``) into a real observer
    node process drive it to every estimate the recording holds after the first sensor sample, field for field: the
    nodes pace the replay, so the machine's load changes how long it takes, never what is computed.  (Replayed in
    real time, at twice its speed, at load average 21 only 701 of the 900 estimates were reproduced.)"""
    node = DdsNode("replay_test")
    live: list[tuple[float, ...]] = []
    # subscribed before play() subscribes to the observer's marker: the observer learns of this reader first (one
    # participant's endpoints are announced in order), and it starts tick 0 only once its marker has its reader
    node.subscription("moose_msgs/msg/StateEstimate", "/perception/state", lambda m: live.append(_estimate(m)),
                      QOS_DATA)
    observer = _observer("lockstep_nodes=[vehicle_simulator,observer]")
    recorded = [(m.timestamp_ns, _estimate(from_rosbags(m.msg, m.type_name)))
                for m in read_bag(RELAXED, ["/perception/state"])]
    first = min(m.timestamp_ns for m in read_bag(RELAXED, SENSORS))
    expected = [e for stamp, e in recorded if stamp >= first]
    try:
        sent = play(RELAXED, node, topics=SENSORS, lockstep=["observer"], timeout=60.0)
        deadline = time.monotonic() + 30.0  # the last tick's estimate, published before the marker play() waited for
        while len(live) < len(expected) and time.monotonic() < deadline:
            assert observer.poll() is None, f"the observer ended (exit {observer.returncode})"
            node.spin_once(0.05)
    finally:
        observer.kill()
        observer.wait()
        node.shutdown()
    assert sent == 2709 and len(expected) == 900
    assert len(live) == len(expected)
    np.testing.assert_allclose(np.array(live), np.array(expected), rtol=0.0, atol=1e-9)


@pytest.mark.graph
@pytest.mark.slow
def test_lockstep_replay_into_a_node_not_in_lockstep_stops_and_says_so() -> None:
    """A node started without ``lockstep_nodes`` reads the replay but never reports a tick: ``bag play --lockstep``
    gives up after ``--lockstep-timeout``, names the node and the tick, and exits with status 3 (incomplete).  (The
    timeout also bounds the player's connection to the observer's readers, discovered on loopback in well under a
    second: 5 s leave room for a loaded machine.)"""
    observer = _observer("use_sim_time=true")
    node = DdsNode("replay_probe")
    try:
        deadline = time.monotonic() + 60.0
        while not all(node.count_subscribers(topic) >= 1 for topic in SENSORS):
            assert observer.poll() is None, f"the observer ended (exit {observer.returncode})"
            assert time.monotonic() < deadline, "the observer's subscriptions were not discovered in 60 s"
            node.spin_once(0.05)
        out = subprocess.run([sys.executable, "-m", "moose.cli", "bag", "play", str(RELAXED), "--topics", *SENSORS,
                              "--lockstep", "observer", "--lockstep-timeout", "5"], capture_output=True, text=True,
                             timeout=120)
    finally:
        observer.kill()
        observer.wait()
        node.shutdown()
    assert out.returncode == EXIT_INCOMPLETE, (out.returncode, out.stderr[-2000:])
    assert "moose: error: lockstep replay stuck at tick 0 (t = 0.00 s after the first message): no tick from " \
           "observer for 5 s" in out.stderr and "Traceback" not in out.stderr
    assert "lockstep_nodes = [vehicle_simulator, observer]" in out.stderr and "played 3 messages" in out.stdout


def test_replan_reproduces_the_recording_and_sees_a_parameter_change(tmp_path: Path) -> None:
    config = load_scenario("paper_v7_tau1.4").configure(load_config())  # the run's parameters: its road's μ
    same = replan(EXTREME, config, v_des=7.0)["summary"]
    assert same["steps"] == 46 and same["mpc_status_agreement"] == 1.0
    assert same["rms_ay"] < 1e-6 and same["rms_weight"] < 1e-6
    changed = dataclasses.replace(config, msf=dataclasses.replace(config.msf, omega_track=1.5))
    other = replan(EXTREME, changed, v_des=7.0)["summary"]
    assert other["rms_ay"] > 0.1
    odom_only = tmp_path / "odom_only"
    shutil.copytree(RELAXED, tmp_path / "relaxed")
    from moose_ros.bag import BagWriter

    writer = BagWriter(odom_only)
    for m in read_bag(tmp_path / "relaxed", ["/vehicle/odom"]):
        writer.write(m.topic, m.type_name, m.timestamp_ns, bytes(from_rosbags(m.msg, m.type_name).serialize()))
    writer.close()
    with pytest.raises(BagError, match="topic '/perception/state' is not in bag .*; its topics: /vehicle/odom"):
        replan(odom_only, config)


def test_existing_or_unwritable_output_is_a_clear_error(tmp_path: Path) -> None:
    from moose_ros.bag import BagWriter

    (tmp_path / "taken").mkdir()
    with pytest.raises(BagError, match="exists already"):
        BagWriter(tmp_path / "taken")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        if os.access(locked, os.W_OK):  # root ignores permissions: use a path under a file instead
            blocker = tmp_path / "file"
            blocker.write_text("x")
            with pytest.raises(BagError, match="cannot be written"):
                BagWriter(blocker / "bag")
        else:
            with pytest.raises(BagError, match="not writable"):
                BagWriter(locked / "bag")
    finally:
        locked.chmod(0o700)


def test_written_bag_reads_with_mcap_and_rosbags_and_refuses_disorder(tmp_path: Path) -> None:
    from mcap.reader import make_reader

    from moose_ros.bag import BagWriter
    from moose_ros.interfaces import make, typestore

    writer = BagWriter(tmp_path / "bag")
    for k in range(5):
        writer.write("/vehicle/wheel_speeds", "moose_msgs/msg/WheelSpeeds", 1000 * k,
                     bytes(make("moose_msgs/msg/WheelSpeeds", omega_rl=float(k)).serialize()))
    with pytest.raises(BagError, match="earlier than the previous message"):
        writer.write("/vehicle/wheel_speeds", "moose_msgs/msg/WheelSpeeds", 10, b"")
    with pytest.raises(BagError, match="carries 'moose_msgs/msg/WheelSpeeds'"):
        writer.write("/vehicle/wheel_speeds", "moose_msgs/msg/SteeringReport", 5000, b"")
    writer.close()
    (file,) = (tmp_path / "bag").glob("*.mcap")
    with open(file, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == 5
        (schema,) = summary.schemas.values()
        assert schema.encoding == "ros2msg" and schema.data.decode() == typestore().generate_msgdef(
            "moose_msgs/msg/WheelSpeeds", ros_version=2)[0]
        stamps = [(message.log_time, channel.topic) for _schema, channel, message in reader.iter_messages()]
    assert stamps == [(1000 * k, "/vehicle/wheel_speeds") for k in range(5)]
    with Reader(tmp_path / "bag") as bag:
        (connection,) = bag.connections
        assert connection.digest == typestore().hash_rihs01("moose_msgs/msg/WheelSpeeds")
        assert [typestore().deserialize_cdr(raw, connection.msgtype).omega_rl for _c, _t, raw in bag.messages()] == [
            0.0, 1.0, 2.0, 3.0, 4.0]
