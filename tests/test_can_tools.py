"""`moose can` tools on hostile input: corrupt and unknown logs, bad ports and interfaces give a ParamError, never a
traceback."""
from __future__ import annotations

import gzip
import io
import os
import re

import can
import pytest

from moose.canbus.bus import BusParams, open_bus
from moose.canbus.codec import Codec
from moose.canbus.tools import dump, open_tool_bus, read_log, replay
from moose.params import ParamError

CHANNEL = f"moose-test-tools-{os.getpid()}"


@pytest.fixture()
def bus():
    sender = open_bus("virtual", CHANNEL)
    yield sender
    sender.shutdown()


def good_log(path, frames: int = 5) -> None:
    codec = Codec()
    with can.Logger(str(path)) as logger:
        for k in range(frames):
            logger(codec.encode("IMU", {"YawRate": 0.01 * k, "AccelX": 0.0, "AccelY": 0.0}, 1.0 + 0.001 * k))


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".log", ".csv", ".trc", ".asc.gz"])
def test_replay_of_a_corrupt_log_is_a_param_error_naming_the_file_and_sends_nothing(tmp_path, bus, suffix: str) -> None:
    path = tmp_path / f"random{suffix}"
    path.write_bytes(os.urandom(4096))
    receiver = open_bus("virtual", CHANNEL)
    try:
        with pytest.raises(ParamError, match=rf"log '.*random{re.escape(suffix)}' is not a valid"):
            replay(path, bus, rate=100.0)
        assert receiver.recv(timeout=0.05) is None
    finally:
        receiver.shutdown()


def test_a_log_corrupt_after_good_frames_sends_nothing(tmp_path, bus) -> None:
    path = tmp_path / "cut.log"
    good_log(path)
    path.write_text(path.read_text() + "(2.000000) vcan0 123#ZZ\n")
    receiver = open_bus("virtual", CHANNEL)
    try:
        with pytest.raises(ParamError, match=r"cut\.log' is not a valid \.log file \(after 5 frames\): ValueError"):
            replay(path, bus, rate=100.0)
        assert receiver.recv(timeout=0.05) is None
    finally:
        receiver.shutdown()
    truncated = tmp_path / "short.blf"
    good_log(truncated, 200)
    truncated.write_bytes(truncated.read_bytes()[:300])
    with pytest.raises(ParamError, match=r"short\.blf' is truncated: its header says \d+ bytes, the file has 300"):
        replay(truncated, bus)


def test_frames_can_cannot_carry_are_refused(tmp_path) -> None:
    path = tmp_path / "long.log"
    path.write_text("(1.000000) vcan0 123#0011223344556677889900\n")
    with pytest.raises(ParamError, match=r"long\.log' is corrupt: frame 1: 11 data bytes \(DLC 11\), at most 8"):
        list(read_log(path))


def test_unknown_suffixes_and_missing_files_are_param_errors(tmp_path, bus) -> None:
    for name in ("traffic.txt", "traffic", "traffic.txt.gz"):
        path = tmp_path / name
        path.write_text("(1.0) vcan0 123#00\n")
        with pytest.raises(ParamError, match=rf"log '.*{name}' has an unknown format"):
            replay(path, bus)
    with pytest.raises(ParamError, match="missing.asc' does not exist"):
        replay(tmp_path / "missing.asc", bus)
    with pytest.raises(ParamError, match="does not exist or is not a file"):
        replay(tmp_path, bus)
    good = tmp_path / "good.log"
    good_log(good)
    for rate in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(ParamError, match=r"rate = "):
            replay(good, bus, rate=rate)


@pytest.mark.parametrize("suffix", [".asc", ".log", ".csv", ".trc", ".asc.gz"])
def test_a_log_without_frames_is_a_param_error_naming_it(tmp_path, bus, suffix: str) -> None:
    empty = tmp_path / f"empty{suffix}"
    empty.write_bytes(gzip.compress(b"") if suffix.endswith(".gz") else b"")
    with pytest.raises(ParamError, match=rf"log '.*empty{re.escape(suffix)}' holds no CAN frames to replay"):
        replay(empty, bus)
    errors_only = tmp_path / "errors.log"  # error frames are skipped: nothing is left to send
    errors_only.write_text("(1.000000) vcan0 20000080#0000000000000000\n")
    with pytest.raises(ParamError, match=r"errors\.log' holds no CAN frames"):
        replay(errors_only, bus)


def test_moose_can_replay_of_a_log_without_frames_exits_2_naming_it(tmp_path) -> None:
    import subprocess
    import sys

    empty = tmp_path / "quiet.asc"
    empty.write_text("")
    done = subprocess.run([sys.executable, "-m", "moose.cli", "can", "replay", str(empty), "--interface", "virtual",
                           "--channel", CHANNEL], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and done.stdout == "", (done.stdout, done.stderr)
    assert done.stderr.startswith("moose: error: log ") and "quiet.asc' holds no CAN frames" in done.stderr


def test_a_gzip_log_replays(tmp_path, bus) -> None:
    plain = tmp_path / "traffic.log"
    good_log(plain)
    packed = tmp_path / "traffic.log.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    assert replay(packed, bus, rate=100.0) == 5


@pytest.mark.parametrize("port, shown", [(70000, "70000"), (0, "0"), (-1, "-1"), ("43113", "'43113'"), (True, "True")])
def test_a_bad_port_is_a_param_error_naming_it(port: object, shown: str) -> None:
    with pytest.raises(ParamError, match=rf"port = {shown} is invalid: expected a UDP port number in 1..65535"):
        open_tool_bus("udp_multicast", "239.74.163.2", port)
    with pytest.raises(ParamError, match=rf"port = {shown}"):
        BusParams(port=port)  # type: ignore[arg-type]


def test_bad_interfaces_channels_and_unavailable_buses_are_param_errors() -> None:
    with pytest.raises(ParamError, match="interface = 'serial' is invalid"):
        open_tool_bus("serial", "x")
    with pytest.raises(ParamError, match=r"channel = '10.0.0.1' is invalid: expected an IPv4 multicast group"):
        open_tool_bus("udp_multicast", "10.0.0.1")
    with pytest.raises(ParamError, match=r"channel = 'moose-no-such-can' on interface = 'socketcan' cannot be opened"):
        open_tool_bus("socketcan", "moose-no-such-can")  # no such device here


def test_dump_checks_its_count_and_duration(bus) -> None:
    for kwargs, field in (({"count": 0}, "count"), ({"count": 2.5}, "count"), ({"duration": float("inf")}, "duration")):
        with pytest.raises(ParamError, match=rf"{field} = "):
            dump(bus, io.StringIO(), **kwargs)


def listening(group: str, port: int) -> bool:
    """A socket of this machine is bound to UDP ``port`` (/proc/net/udp) and one has joined the multicast ``group``
    (/proc/net/igmp, addresses in host byte order): a receiver of that bus is ready."""
    import socket

    with open("/proc/net/udp", encoding="ascii") as f:
        bound = any(line.split()[1].endswith(f":{port:04X}") for line in f.read().splitlines()[1:])
    with open("/proc/net/igmp", encoding="ascii") as f:
        joined = socket.inet_aton(group)[::-1].hex().upper() in f.read()
    return bound and joined


@pytest.mark.can
def test_moose_can_replay_and_dump_over_udp_multicast_from_the_command_line(tmp_path) -> None:
    """Two processes, as a user runs them: ``moose can dump`` decodes what ``moose can replay`` sends."""
    import subprocess
    import sys
    import time

    from isolation import claim_udp_port

    log = tmp_path / "drive.log"
    good_log(log, frames=5)
    pid = os.getpid()
    group, port = f"239.74.{pid % 250}.{1 + pid % 199}", claim_udp_port()
    bus = ["--interface", "udp_multicast", "--channel", group, "--port", str(port)]
    moose = [sys.executable, "-m", "moose.cli", "can"]
    dumper = subprocess.Popen(moose + ["dump", "--count", "5", "--duration", "60", *bus], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60.0
        while not listening(group, port):  # the dump has bound the port and joined the group
            assert dumper.poll() is None, dumper.communicate()[1]
            assert time.monotonic() < deadline, f"no socket on UDP port {port} joined {group} in 60 s"
            time.sleep(0.05)
        sent = subprocess.run(moose + ["replay", str(log), "--rate", "10", *bus], capture_output=True, text=True,
                              timeout=60)
        assert sent.returncode == 0 and sent.stdout.strip() == "sent 5 frames", sent.stderr
        out, err = dumper.communicate(timeout=60)
    finally:
        if dumper.poll() is None:
            dumper.kill()
            dumper.wait()
    assert dumper.returncode == 0, err
    lines = [line for line in out.splitlines() if " IMU " in line]
    assert len(lines) == 5
    assert [float(re.search(r"YawRate=(\S+)", line).group(1)) for line in lines] == pytest.approx(
        [0.0, 0.01, 0.02, 0.03, 0.04], abs=1e-3)
    missing = subprocess.run(moose + ["replay", str(tmp_path / "none.log"), *bus], capture_output=True, text=True,
                             timeout=60)
    assert missing.returncode == 2 and missing.stderr.startswith("moose: error:") and "none.log" in missing.stderr
