"""Bags never lose data silently: the probes of the review (section 2), each as a regression test.

Bags are made with independent writers (rosbags' Writer, the mcap library's Writer) from the example bag,
then damaged: a message of a type this installation does not know (with and without its definition), a
corrupt message, a file cut short (unchunked, and inside the first 1 MiB chunk, plain and zstd), a topic
with another type.  Reading must deliver every message that is there, and say what it could not deliver.
"""
from __future__ import annotations

import os
import random
import re
import shutil
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any, Callable

import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from moose.config import load_config
from moose.schema import PLANNER_MODES
from moose_ros.bag import BagError, BagReader, BagWriter, ReadReport, bag_info, export, read_bag, replan
from moose_ros.graph import ACTUATOR_COMMAND
from moose_ros.interfaces import typestore
from moose_ros.runtime import DdsNode
from test_cli_errors import here

ROOT = Path(__file__).resolve().parents[1]
EXTREME = ROOT / "bags" / "paper_v7_tau1.4_combined"
with Reader(EXTREME) as _example:
    TOTAL = _example.message_count
"""Messages of the example bag (its metadata.yaml)."""
PROBE_DEF = "float64 value\nstring note\nstd_msgs/Header header"
MOOSE = [sys.executable, "-m", "moose.cli"]


def lab_store():
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(dict(typestore().fielddefs))
    store.register(get_types_from_msg(PROBE_DEF, "lab_msgs/msg/Probe"))
    return store


def with_extra(dst: Path, at: int, definition: bool = True, corrupt: bool = False) -> Path:
    """The example bag rewritten by rosbags' Writer with, before message ``at``, one ``lab_msgs/msg/Probe`` on
    /lab/probe (its definition embedded, or not) — or, with ``corrupt``, one undecodable /vehicle/imu message."""
    store = lab_store()
    with Reader(EXTREME) as reader, Writer(dst, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
        imu = next(conns[c.id] for c in reader.connections if c.topic == "/vehicle/imu")
        probe = writer.add_connection("/lab/probe", "lab_msgs/msg/Probe", typestore=store) if definition else \
            writer.add_connection("/lab/probe", "lab_msgs/msg/Probe", msgdef="", rihs01="RIHS01_" + "0" * 64)
        Time, Header, Probe = (store.types[n] for n in ("builtin_interfaces/msg/Time", "std_msgs/msg/Header",
                                                        "lab_msgs/msg/Probe"))
        for i, (c, t, raw) in enumerate(reader.messages()):
            if i == at:
                if corrupt:
                    writer.write(imu, t, b"\x00\x01\x00\x00\x07")  # a CDR header and 1 byte of a 60-byte message
                else:
                    writer.write(probe, t, store.serialize_cdr(Probe(1.5, "hi", Header(Time(0, 0), "x")),
                                                                "lab_msgs/msg/Probe"))
            writer.write(conns[c.id], t, raw)
    return dst


def chunked(dst: Path, compression: CompressionType = CompressionType.NONE) -> Path:
    """The example bag as a chunked MCAP (1 MiB chunks, as ros2 bag record writes), with its metadata.yaml."""
    dst.mkdir()
    shutil.copy(EXTREME / "metadata.yaml", dst / "metadata.yaml")
    source = next(EXTREME.glob("*.mcap"))
    with open(source, "rb") as i, open(dst / source.name, "wb") as o:
        writer = McapWriter(o, chunk_size=1024 * 1024, compression=compression)
        writer.start(profile="ros2", library="test")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in make_reader(i).iter_messages(log_time_order=False):
            if schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas[schema.id], channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time,
                               message.sequence)
        writer.finish()
    return dst


def cut(bag: Path, size: int, metadata: bool = True) -> Path:
    mcap = next(bag.glob("*.mcap"))
    with open(mcap, "r+b") as handle:
        handle.truncate(size)
    if not metadata:
        (bag / "metadata.yaml").unlink()
    return bag


Derive = Callable[..., Path]
Capture = pytest.CaptureFixture[str]


@pytest.fixture(scope="session")
def derived(tmp_path_factory: pytest.TempPathFactory) -> Derive:
    """``derived(dst, make, **kwargs)``: the bag ``make(path, **kwargs)`` writes from the example bag, copied to
    ``dst`` (the test's own, to damage).  Each is written once per test session: the example bag is rewritten
    message by message, seconds each, and several tests start from the same one."""
    store = tmp_path_factory.mktemp("derived-bags")
    made: dict[tuple[str, tuple[tuple[str, Any], ...]], Path] = {}

    def copy(dst: Path, make: Callable[..., Any], **kwargs: Any) -> Path:
        key = (make.__name__, tuple(sorted(kwargs.items())))
        if key not in made:
            path = store / str(len(made))
            make(path, **kwargs)
            made[key] = path
        shutil.copytree(made[key], dst)
        return dst

    return copy


def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    """``moose ARGS`` as a child process: for ``bag play``, whose publishers join the DDS graph (the other bag
    commands run in this process, :func:`test_cli_errors.here`)."""
    return subprocess.run(MOOSE + list(args), capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize("metadata", [True, False])
def test_a_type_unknown_here_is_decoded_from_the_bags_own_definition(tmp_path: Path, metadata: bool,
                                                                   derived: Derive,
                                                                   capsys: Capture) -> None:
    """The review: one such message cut info, export and play off at it (200 of 5555 messages, exit 0)."""
    bag = derived(tmp_path / "bag", with_extra, at=200)
    if not metadata:
        (bag / "metadata.yaml").unlink()
    report = ReadReport(str(bag))
    messages = list(read_bag(bag, report=report))
    assert len(messages) == TOTAL + 1 and report.complete
    assert report.registered == ["lab_msgs/msg/Probe"]
    probe = next(m for m in messages if m.topic == "/lab/probe")
    assert (probe.msg.value, probe.msg.note) == (1.5, "hi")
    out = here(capsys, "bag", "info", str(bag))
    assert out.returncode == 0 and f"messages  {TOTAL + 1}" in out.stdout and out.stderr == ""
    assert "decoded with the bag's own definition: lab_msgs/msg/Probe" in out.stdout
    played = run("bag", "play", str(bag), "--rate", "100")  # every message it can send; the probe is reported
    assert played.returncode == 1 and f"played {TOTAL} messages" in played.stdout, played.stderr
    assert "1 message(s) on /lab/probe (lab_msgs/msg/Probe) skipped: not published" in played.stderr
    files = export(bag, tmp_path / "csv")
    assert len(files) == len(BagReader(EXTREME).topics) + 1
    assert (tmp_path / "csv" / "lab__probe.csv").read_text().count("\n") == 2


@pytest.mark.parametrize("kind", ["no definition", "corrupt"])
def test_an_undecodable_message_is_skipped_counted_and_reported_and_reading_goes_on(tmp_path: Path, kind: str,
                                                                                   derived: Derive,
                                                                                   capsys: Capture) -> None:
    bag = derived(tmp_path / "bag", with_extra, at=200, definition=kind != "no definition", corrupt=kind == "corrupt")
    report = ReadReport(str(bag))
    messages = list(read_bag(bag, report=report))
    assert len(messages) == TOTAL and messages[-1].timestamp_ns == 9_000_000_000  # to the end of the bag
    topic = "/lab/probe" if kind == "no definition" else "/vehicle/imu"
    assert report.skipped[topic]["count"] == 1 and not report.complete
    reason = "holds no definition" if kind == "no definition" else "undecodable CDR"
    assert reason in report.skipped[topic]["reason"]
    out = here(capsys, "bag", "info", str(bag))
    assert out.returncode == 1 and f"messages  {TOTAL}" in out.stdout
    assert f"moose: warning: bag '{bag}': 1 message(s) on {topic}" in out.stderr and reason in out.stderr


def test_a_truncated_bag_reads_what_is_there_and_says_what_was_lost(tmp_path: Path,
                                                                    capsys: Capture) -> None:
    """The review: a truncated bag with metadata.yaml read partially without a warning."""
    bag = tmp_path / "bag"
    shutil.copytree(EXTREME, bag)
    size = next(bag.glob("*.mcap")).stat().st_size
    cut(bag, int(size * 0.9))
    report = ReadReport(str(bag))
    delivered = len(list(read_bag(bag, report=report)))
    assert 0 < delivered < TOTAL and sum(report.missing.values()) == TOTAL - delivered
    assert 0 < report.lost_bytes < 1000  # the last, partial record
    out = here(capsys, "bag", "export", str(bag), "-o", str(tmp_path / "csv"))
    assert out.returncode == 1 and f"{TOTAL - delivered} message(s) that metadata.yaml lists are missing" in out.stderr
    assert len(list((tmp_path / "csv").glob("*.csv"))) == len(BagReader(EXTREME).topics)  # what is there, exported


@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.ZSTD])
@pytest.mark.parametrize("metadata", [True, False])
def test_a_bag_cut_inside_its_first_chunk_still_gives_the_complete_messages(tmp_path: Path, metadata: bool,
                                                                           compression: CompressionType,
                                                                           derived: Derive) -> None:
    """The review: cut at 700 KB, a chunked bag (first chunk 1 MiB) gave an empty error and nothing."""
    bag = derived(tmp_path / "bag", chunked, compression=compression)
    with open(next(bag.glob("*.mcap")), "rb") as handle:
        first = make_reader(handle).get_summary().chunk_indexes[0]
    assert first.uncompressed_size > 1_000_000  # a 1 MiB chunk
    cut(bag, first.chunk_start_offset + int(0.6 * first.chunk_length), metadata)
    report = ReadReport(str(bag))
    messages = list(read_bag(bag, report=report))
    original = list(read_bag(EXTREME))
    assert len(messages) > 1000 and not report.complete
    assert ([(m.topic, m.timestamp_ns) for m in messages]
            == [(m.topic, m.timestamp_ns) for m in original[:len(messages)]])
    if metadata:
        assert sum(report.missing.values()) == TOTAL - len(messages)
    assert report.lost_bytes > 0


def corrupt_first_chunk(bag: Path, record: int = 100) -> int:
    """Give the ``record``-th record inside the first chunk a length far beyond the chunk (its checksum then fails);
    returns the chunk's offset in the file."""
    import struct

    mcap = next(bag.glob("*.mcap"))
    with open(mcap, "rb") as handle:
        first = make_reader(handle).get_summary().chunk_indexes[0]
    data = bytearray(mcap.read_bytes())
    head = first.chunk_start_offset + 1 + 8 + 8 + 8 + 8 + 4
    (name_length,) = struct.unpack_from("<I", data, head)
    position = head + 4 + name_length + 8
    for _ in range(record):
        position += 9 + struct.unpack_from("<Q", data, position + 1)[0]
    struct.pack_into("<Q", data, position + 1, 2**40)
    mcap.write_bytes(bytes(data))
    return first.chunk_start_offset


def first_chunk_messages(bag: Path) -> int:
    """How many messages the first chunk of the bag's (intact) file holds."""
    from mcap.records import Chunk, Message
    from mcap.stream_reader import StreamReader, breakup_chunk

    with open(next(bag.glob("*.mcap")), "rb") as handle:
        chunk = next(r for r in StreamReader(handle, emit_chunks=True).records if isinstance(r, Chunk))
    return sum(isinstance(r, Message) for r in breakup_chunk(chunk))


def file_order(bag: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time, CDR) of every message, in the order of the file (mcap's own reader)."""
    with open(next(bag.glob("*.mcap")), "rb") as handle:
        return [(c.topic, m.log_time, m.data) for _s, c, m in make_reader(handle).iter_messages(log_time_order=False)]


@pytest.mark.parametrize("metadata", [True, False])
def test_a_chunk_failing_its_checksum_is_skipped_and_reading_goes_on_after_it(tmp_path: Path, metadata: bool,
                                                                             derived: Derive,
                                                                             capsys: Capture) -> None:
    """Its data are corrupt: none of its messages is delivered (on main they were, "may be corrupt"), every other
    one is, and the report names the chunk."""
    bag = derived(tmp_path / "bag", chunked, compression=CompressionType.NONE)
    lost = first_chunk_messages(bag)
    expected = Counter((topic, t) for topic, t, _raw in file_order(bag)[lost:])
    offset = corrupt_first_chunk(bag)
    if not metadata:
        (bag / "metadata.yaml").unlink()
    report = ReadReport(str(bag))
    got = Counter((m.topic, m.timestamp_ns) for m in read_bag(bag, report=report))
    assert got == expected and lost > 1000
    (damaged,) = report.damaged
    assert f"the chunk at byte {offset} of " in damaged and f"count {lost} message(s)" in damaged
    assert report.lost_bytes > 1_000_000  # the whole 1 MiB chunk
    assert sum(report.missing.values()) == (lost if metadata else 0)
    out = here(capsys, "bag", "info", str(bag))
    assert out.returncode == 1 and "fails its checksum (its data are corrupt): skipped" in out.stderr


def test_damaged_files_give_errors_that_say_why(tmp_path: Path, derived: Derive) -> None:
    bag = derived(tmp_path / "bag", chunked, compression=CompressionType.NONE)
    cut(bag, 200, metadata=False)  # inside the first chunk's header
    with pytest.raises(BagError, match=r"truncated before its first complete chunk or channel: \d+ of 200 bytes"):
        list(read_bag(bag))
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "x.mcap").write_bytes(b"")
    with pytest.raises(BagError, match=r"not a readable MCAP file \(0 bytes"):
        list(read_bag(empty))


def test_a_topic_filter_naming_a_missing_topic_is_an_error_listing_the_bags_topics(tmp_path: Path,
                                                                                   capsys: Capture) -> None:
    """The review: ``export --topics /nope`` exported every topic; ``play --topics /vehicle/imuu`` published every
    topic (recorded actuator commands included) into the live graph."""
    out = here(capsys, "bag", "export", str(EXTREME), "-o", str(tmp_path / "csv"), "--topics", "/nope")
    assert out.returncode == 2 and "moose: error: topic '/nope' is not in bag" in out.stderr
    assert "/vehicle/imu, /vehicle/odom" in out.stderr and not list(tmp_path.glob("csv/*"))
    listener = DdsNode("play_victim")
    received: list = []
    ACTUATOR_COMMAND.subscription(listener, received.append)
    received_imu: list = []
    listener.subscription("sensor_msgs/msg/Imu", "/vehicle/imu", received_imu.append)
    try:
        play = subprocess.Popen(MOOSE + ["bag", "play", str(EXTREME), "--topics", "/vehicle/imuu", "--rate", "10"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while play.poll() is None and time.monotonic() < deadline:
            listener.spin_once(0.05)
        listener.spin_once(0.5)
        _, err = play.communicate(timeout=10)
    finally:
        listener.shutdown()
    assert play.returncode == 2 and "moose: error: topic '/vehicle/imuu' is not in bag" in err
    assert received == [] and received_imu == []
    with pytest.raises(BagError, match="is not in bag"):
        list(read_bag(EXTREME, ["/perception/state", "/nope"]))
    assert BagReader(EXTREME).topics["/vehicle/imu"] == "sensor_msgs/msg/Imu"


def wrong_state_type(path: Path) -> Path:
    """A bag whose /perception/state carries nav_msgs/msg/Odometry."""
    writer = BagWriter(path)
    odom = typestore().types["nav_msgs/msg/Odometry"]
    for msg in read_bag(EXTREME, ["/vehicle/odom", "/planning/blend"]):
        topic = "/perception/state" if msg.topic == "/vehicle/odom" else msg.topic
        assert msg.topic != "/vehicle/odom" or isinstance(msg.msg, odom)
        writer.write(topic, msg.type_name, msg.timestamp_ns, typestore().serialize_cdr(msg.msg, msg.type_name))
    writer.close()
    return path


def test_replan_on_a_bag_whose_state_topic_has_another_type_is_a_clear_error(tmp_path: Path,
                                                                             capsys: Capture) -> None:
    bag = wrong_state_type(tmp_path / "bag")
    with pytest.raises(BagError, match=r"topic '/perception/state' of bag .* carries 'nav_msgs/msg/Odometry', "
                                       r"not 'moose_msgs/msg/StateEstimate'"):
        replan(bag, load_config(None))
    out = here(capsys, "bag", "replan", str(bag))
    assert out.returncode == 2 and "moose: error: topic '/perception/state'" in out.stderr
    assert "Traceback" not in out.stderr
    out = run("bag", "play", str(bag), "--rate", "100")  # nor is it published into the graph under that name
    assert out.returncode == 2 and "carries 'nav_msgs/msg/Odometry'" in out.stderr


@pytest.mark.parametrize(("args", "message"), [
    (["export", str(EXTREME), "-o", "{file}"], "is not a directory"),
    (["replan", str(EXTREME), "--plot", "{file}/x.png"], "--plot '{file}/x.png' cannot be written"),
    (["replan", str(EXTREME), "--plot", "{tmp}/figure.xyz"], "expected a file ending in one of"),
])
def test_bad_output_paths_of_the_bag_tools_are_errors_before_any_work(tmp_path: Path, args: list[str],
                                                                     message: str,
                                                                     capsys: Capture) -> None:
    file = tmp_path / "a_file"
    file.write_text("x")
    fill = {"file": str(file), "tmp": str(tmp_path)}
    start = time.monotonic()
    out = here(capsys, "bag", *[a.format(**fill) for a in args])
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "moose: error: " in out.stderr and message.format(**fill) in out.stderr
    assert time.monotonic() - start < 30  # refused before the re-planning (tens of seconds) ran


def test_the_example_bags_read_completely() -> None:
    for bag in (EXTREME, ROOT / "bags" / "paper_v5_tau3_combined"):
        report = ReadReport(str(bag))
        info = bag_info(bag, report)
        assert report.complete and info["losses"] == [] and info["messages"] == report.delivered
        assert report.recovered == ""


def test_run_parameters_naming_an_unknown_planner_are_refused(tmp_path: Path,
                                                              capsys: Capture) -> None:
    """A bag whose recorded planner mode is not moose's is refused by name, not re-planned as another mode."""
    bag = tmp_path / "bag"
    shutil.copytree(EXTREME, bag)
    metadata = bag / "metadata.yaml"
    text = metadata.read_text(encoding="utf-8")
    assert "moose.planner: combined\n" in text
    metadata.write_text(text.replace("moose.planner: combined\n", "moose.planner: bogus\n"), encoding="utf-8")
    with pytest.raises(BagError, match=re.escape(f"moose.planner = 'bogus' is invalid: expected one of "
                                                 f"{list(PLANNER_MODES)}")):
        replan(bag, load_config(None))
    out = here(capsys, "bag", "replan", str(bag))
    assert out.returncode == 2 and "moose: error:" in out.stderr and "moose.planner = 'bogus'" in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("section", ["/*", "observer"])
def test_replan_refuses_a_parameter_file_section_it_would_ignore(tmp_path: Path, section: str,
                                                                 capsys: Capture) -> None:
    """The probe's ``moose bag replan --params`` with a file whose only section is ``/*``: the file's name was
    printed and the defaults used."""
    params = tmp_path / "params.yaml"
    params.write_text(f'"{section}":\n  ros__parameters:\n    vehicle: {{m: -5.0}}\n')
    out = here(capsys, "bag", "replan", str(EXTREME), "--params", str(params))
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert f"moose: error: parameter file {str(params)!r}: section {section!r} is not applied by moose bag replan" \
        in out.stderr


def ours(dst: Path, until: int | None = None) -> BagWriter:
    """The example bag written again by our writer (the recorder's), message for message; with ``until``, only
    its first ``until`` messages and the writer left open (as a killed recorder leaves it)."""
    import yaml

    info = yaml.safe_load((EXTREME / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    writer = BagWriter(dst, custom_data=info["custom_data"])
    with open(next(EXTREME.glob("*.mcap")), "rb") as handle:
        for k, (schema, channel, message) in enumerate(make_reader(handle).iter_messages(log_time_order=False)):
            if k == until:
                return writer
            writer.write(channel.topic, schema.name, message.log_time, message.data)
    writer.close()
    return writer


def decoded(bag: Path, report: ReadReport | None = None) -> Counter:
    """Every message of the bag as (topic, time, its fields): what a reader hands out."""
    from moose_ros.bag import flatten

    return Counter((m.topic, m.timestamp_ns, repr(flatten(m.msg))) for m in read_bag(bag, report=report))


def test_random_damage_costs_the_damaged_chunk_only_and_the_tools_deliver_the_rest(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], derived: Derive) -> None:
    """The probe: 1,000 random bytes in the middle of a bag made ``bag info`` stop ("unreadable after 4541
    messages", rc 2, 5,575 later messages lost) and ``bag export`` write nothing.  Now the damaged chunk is
    skipped (its checksum fails), no corrupt message is delivered, everything else is, and the tools say so."""
    from moose.cli import main

    bag = derived(tmp_path / "bag", ours)
    original = decoded(bag)
    mcap = next(bag.glob("*.mcap"))
    with open(mcap, "rb") as handle:
        chunks = make_reader(handle).get_summary().chunk_indexes
    data = bytearray(mcap.read_bytes())
    at = int(0.4 * len(data))
    data[at:at + 1000] = random.Random(23).randbytes(1000)
    mcap.write_bytes(bytes(data))
    report = ReadReport(str(bag))
    got = decoded(bag, report)
    lost = sorted(t for _topic, t, _f in original - got)
    assert got <= original and lost
    first = max(k for k, c in enumerate(chunks) if c.message_start_time <= lost[0])
    assert lost[-1] <= chunks[first + 1].message_end_time  # one chunk or two (0.25 s each) at the damage
    assert sum(report.missing.values()) == TOTAL - got.total() and report.damaged
    capsys.readouterr()
    assert main(["bag", "info", str(bag)]) == 1
    out, err = capsys.readouterr()
    assert f"messages  {got.total()}" in out and "fails its checksum (its data are corrupt): skipped" in err
    assert main(["bag", "export", str(bag), "-o", str(tmp_path / "csv")]) == 1
    topics = Counter(topic for topic, _t, _f in got)
    files = {f.stem: f.read_text().count("\n") - 1 for f in (tmp_path / "csv").glob("*.csv")}
    assert files == {t.strip("/").replace("/", "__"): n for t, n in topics.items()}  # every readable message


def test_a_chunk_whose_length_is_damaged_is_found_again_at_the_next_chunk(tmp_path: Path, derived: Derive) -> None:
    """The record's own length is wrong: reading resynchronises on the next record that verifies (a chunk whose
    checksum holds) instead of losing the rest of the file."""
    import struct

    bag = derived(tmp_path / "bag", ours)
    original = decoded(bag)
    mcap = next(bag.glob("*.mcap"))
    with open(mcap, "rb") as handle:
        chunks = make_reader(handle).get_summary().chunk_indexes
    third, fourth = chunks[2], chunks[3]
    data = bytearray(mcap.read_bytes())
    struct.pack_into("<Q", data, third.chunk_start_offset + 1, third.chunk_length - 9 + 1000)  # still in the file
    mcap.write_bytes(bytes(data))
    (bag / "metadata.yaml").unlink()  # else rosbags reads the chunk through the summary's index, which is intact
    report = ReadReport(str(bag))
    got = decoded(bag, report)
    lost = original - got
    assert got <= original and lost.total() < 1000
    assert all(third.message_start_time <= t <= third.message_end_time for _topic, t, _f in lost)
    assert any(t >= fourth.message_start_time for _topic, t, _f in got)  # on past the damage
    assert report.lost_bytes >= third.chunk_length


def test_a_recording_cut_between_checkpoints_is_a_bag_for_every_reader(tmp_path: Path,
                                                                        capsys: Capture) -> None:
    """What a SIGKILL leaves (the files as the writer left them, not closed): mcap's own reader (with Foxglove's
    decoder) and rosbags read every message up to the last checkpoint; on main mcap's reader raised
    RecordLengthLimitExceeded and rosbags found no metadata.yaml.  Our reader says the recording was not closed."""
    from mcap_ros2.decoder import DecoderFactory

    from moose.cli import main

    writer = ours(tmp_path / "live", until=TOTAL // 2)
    killed = tmp_path / "killed"
    shutil.copytree(tmp_path / "live", killed)
    saved = writer.saved
    writer.close()
    assert TOTAL // 2 - 500 < saved < TOTAL // 2  # the open chunk (at most 0.25 s) is what a kill takes
    with open(next(killed.glob("*.mcap")), "rb") as handle:
        by_mcap = sum(1 for m in make_reader(handle, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
                      if m.decoded_message is not None)
    with Reader(killed) as reader:
        by_rosbags = sum(1 for _ in reader.messages())
    report = ReadReport(str(killed))
    assert by_mcap == by_rosbags == len(list(read_bag(killed, report=report))) == saved
    assert report.missing == {} and report.lost_bytes == 0 and len(report.unfinished) == 1
    capsys.readouterr()
    assert main(["bag", "info", str(killed)]) == 1
    assert "was not closed" in capsys.readouterr().err


def every_reader(bag: Path) -> dict[str, Counter | str]:
    """What each reader delivers from ``bag``: mcap's (with Foxglove's decoder), rosbags' and ours, as the
    (topic, time) of every message, or the name of the exception with which it refuses the bag."""
    from mcap_ros2.decoder import DecoderFactory

    def mcap() -> Counter:
        with open(next(bag.glob("*.mcap")), "rb") as handle:
            return Counter((m.channel.topic, m.message.log_time) for m in
                           make_reader(handle, decoder_factories=[DecoderFactory()]).iter_decoded_messages()
                           if m.decoded_message is not None)

    def rosbags() -> Counter:
        with Reader(bag) as reader:
            return Counter((c.topic, t) for c, t, _raw in reader.messages())

    def ours() -> Counter:
        return Counter((m.topic, m.timestamp_ns) for m in read_bag(bag, report=ReadReport(str(bag))))

    found: dict[str, Counter | str] = {}
    for read in (mcap, rosbags, ours):
        try:
            found[read.__name__] = read()
        except Exception as exc:  # noqa: BLE001 - each reader refuses a bag in its own way
            found[read.__name__] = type(exc).__name__
    return found


def test_a_kill_between_any_two_writes_leaves_one_bag_for_every_reader(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """Issue 25's flake: the bag of a SIGKILLed ``moose launch`` held one message more for mcap's reader than for
    rosbags and ours.  The checkpoint that put a topic's first message on the file wrote ``metadata.yaml`` only
    after it, and rosbags reads only the topics that names; and the space reserved for a checkpoint extended the
    file with zeros after its footer (mcap's and rosbags' readers refused it, ours read it).  A SIGKILL lands
    between two system calls: every state the bag passes through, before and after each of the writer's writes,
    truncations and renames, is read by the three readers, which deliver the same messages or all refuse the bag
    (its file still empty); and every state of a checkpoint delivers every message before it."""
    store = typestore()
    text = store.types["std_msgs/msg/String"]
    bag = tmp_path / "bag"
    states: dict[bytes, Path] = {}  # contents → a copy of the bag, each state once
    copying = False

    def snapshot() -> None:
        nonlocal copying
        if copying or not bag.exists():
            return
        copying = True
        try:
            files = sorted(f for f in bag.iterdir() if f.suffix != ".tmp")  # a rename makes metadata.yaml
            key = b"".join(f.name.encode() + b"\0" + f.read_bytes() + b"\0" for f in files)
            if key not in states:
                states[key] = tmp_path / f"state{len(states)}"
                states[key].mkdir()
                for f in files:
                    shutil.copy(f, states[key] / f.name)
        finally:
            copying = False

    def around(call: Callable[..., Any]) -> Callable[..., Any]:
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            snapshot()
            try:
                return call(*args, **kwargs)
            finally:
                snapshot()
        return wrapped

    for name in ("open", "pwrite", "ftruncate", "replace"):
        monkeypatch.setattr(os, name, around(getattr(os, name)))
    writer = BagWriter(bag, fsync_period=3600.0)
    for t, topic in [(0.0, "/a"), (0.1, "/a"), (0.3, "/b"), (0.35, "/a"), (0.6, "/c"), (0.9, "/d")]:
        # chunks of 0.25 s: the checkpoints before /b, /c and /d put a new topic's first message on the file, and
        # closing puts /d's
        writer.write(topic, "std_msgs/msg/String", int(t * 1e9), store.serialize_cdr(text(topic), text.__msgtype__))
    writer.close()
    monkeypatch.undo()
    read = [every_reader(state) for state in states.values()]
    disagree = [found for found in read if not (found["mcap"] == found["rosbags"] == found["ours"] or
                                                all(isinstance(f, str) for f in found.values()))]
    assert [{name: f if isinstance(f, str) else sum(f.values()) for name, f in found.items()}
            for found in disagree] == []  # messages delivered, or the exception
    delivered = {sum(found["ours"].values()) for found in read if isinstance(found["ours"], Counter)}
    assert sorted(delivered) == [0, 2, 4, 5, 6]  # each checkpoint's messages, none lost


def test_view_of_a_truncated_bag_warns_and_exits_1(tmp_path: Path, capsys: Capture) -> None:
    """The probe: ``bag view`` drew half of a truncated bag with rc 0 and no warning."""
    from moose.cli import main

    bag = tmp_path / "bag"
    shutil.copytree(EXTREME, bag)
    cut(bag, int(next(bag.glob("*.mcap")).stat().st_size * 0.6))
    assert main(["bag", "view", str(bag), "-o", str(tmp_path / "view.png")]) == 1
    err = capsys.readouterr().err
    assert "moose: warning:" in err and "that metadata.yaml lists are missing" in err and "without a footer" in err
    assert (tmp_path / "view.png").stat().st_size > 0  # what is there, drawn
