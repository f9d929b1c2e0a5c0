"""Bad input gets ``moose: error:`` and exit status 2, never a traceback, a hang or a memory blow-up; outputs are
checked before a run, and one that fails after it (a full disk) is exit status 5 after the result; the exit status
of ``moose simulate`` is its verdict.  The probes of the reviews (CLI input, scenario and parameter files, output
paths, non-finite values, devices, services, full disks), each as a regression test.  Most run the command in this
process (``moose.cli.main``, :func:`here`); those whose process boundary matters (signals, a closed pipe, the
verdict as a user sees it) run the ``moose`` command as a child process (:func:`moose`).
"""
from __future__ import annotations

import json
import os
import re
import resource
import signal
import socket
import struct
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path
from typing import Callable, Iterator

import pytest

from moose.resources import SCENARIO_DIR
from moose.sweep.store import read_results
from moose.verdict import EXIT_BAD_INPUT, EXIT_CLEAR, EXIT_FAILED, EXIT_INCOMPLETE, OUTCOME_EXIT, OUTCOMES, exit_status

MOOSE = [sys.executable, "-m", "moose.cli"]
SHORT = ["--duration", "0.5", "--no-bag"]


def moose(*args: str, cwd: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(MOOSE + list(args), capture_output=True, text=True, timeout=timeout, cwd=cwd)


def here(capsys: pytest.CaptureFixture[str], *args: str) -> subprocess.CompletedProcess:
    """``moose ARGS`` run in this process (``moose.cli.main``), as :func:`moose` reports it: a second of imports
    cheaper than a child process.  A command whose process boundary matters (signals, pipes) runs as a child."""
    from moose.cli import main

    capsys.readouterr()
    try:
        code = main(list(args))
    except SystemExit as exc:  # argparse's own errors
        code = int(exc.code or 0)
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(["moose", *args], code, out, err)


def refused(out: subprocess.CompletedProcess, *needles: str) -> None:
    """Exit status 2, ``moose: error:`` or argparse's error naming the problem, no traceback, nothing run."""
    assert out.returncode == EXIT_BAD_INPUT, (out.returncode, out.stdout[-500:], out.stderr[-2000:])
    assert "Traceback" not in out.stderr and "error:" in out.stderr
    assert "scenario        " not in out.stdout  # the summary: printed only after a run
    for needle in needles:
        assert needle in out.stderr, out.stderr


def strict_json(path: Path) -> dict:
    """JSON as the standard defines it: NaN and Infinity are not JSON."""
    def refuse(constant: str) -> None:
        raise ValueError(f"{constant} is not JSON")

    return json.loads(path.read_text(), parse_constant=refuse)


def test_a_negative_seed_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    refused(here(capsys, "simulate", "--seed", "-1", *SHORT), "--seed", "'-1' must be a non-negative integer")


@pytest.mark.parametrize("field", ["name", "v_init", "v_des", "tau", "obstacle"])
def test_a_scenario_file_missing_a_required_field_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                             field: str) -> None:
    text = (SCENARIO_DIR / "paper_v7_tau1.4.yaml").read_text()
    kept = [line for line in text.splitlines() if not line.startswith(f"{field}:")]
    assert len(kept) == len(text.splitlines()) - 1
    scenario = tmp_path / "partial.yaml"
    scenario.write_text("\n".join(kept) + "\n")
    refused(here(capsys, "simulate", "--scenario", str(scenario), *SHORT),
            f"partial.{field} is missing: a required field")


@pytest.mark.parametrize("value", ["inf", "-inf", "nan", "1e400"])
@pytest.mark.parametrize("flag", ["--obstacle-half-width", "--tau", "--speed", "--duration", "--mu"])
def test_non_finite_numbers_are_refused_at_the_command_line(capsys: pytest.CaptureFixture[str], flag: str,
                                                           value: str) -> None:
    args = {"--speed": "7", "--tau": "1.4", "--obstacle-half-width": "1"}
    args[flag] = value
    out = here(capsys, "simulate", *[f"{k}={v}" for k, v in args.items()], "--no-bag")
    refused(out, flag, f"'{value}' must be a finite positive number")


@pytest.mark.parametrize("adhoc", [["--speed", "7", "--tau", "0.001", "--obstacle-half-width", "1"],
                                   ["--speed", "1e-6", "--tau", "1", "--obstacle-half-width", "1"]])
def test_degenerate_tests_write_valid_json(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          adhoc: list[str]) -> None:
    """The review: ``--tau 0.001`` and ``--speed 1e-6`` wrote Infinity into the JSON."""
    out = here(capsys, "simulate", *adhoc, "--no-bag", "--json", str(tmp_path / "s.json"))
    summary = strict_json(tmp_path / "s.json")
    assert out.returncode == exit_status(summary["outcome"])
    assert summary["notes"]  # what is not a number says why


def bad_paths(tmp: Path) -> list[tuple[str, str, str]]:
    """(flag, path, what the error says) — unwritable or invalid outputs."""
    a_file = tmp / "a_file"
    a_file.write_text("x")
    a_dir = tmp / "a_dir"
    a_dir.mkdir(exist_ok=True)
    long = str(tmp / ("x" * 300 + ".json"))
    return [
        ("--json", str(a_dir), "is a directory"),
        ("--json", str(a_file / "s.json"), "cannot be written"),
        ("--json", "/proc/moose-summary.json", "cannot be written"),
        ("--json", "", "expected a file path"),
        ("--json", long, "cannot be written"),
        ("--plot", str(a_dir / "fig.xyz"), "expected a file ending in one of"),
        ("--plot", str(a_file / "fig.png"), "cannot be written"),
        ("--plot", "/proc/moose-figure.png", "cannot be written"),
        ("--bag", str(a_dir), "exists already"),
        ("--bag", str(a_file / "bag"), "cannot be created"),
        ("--bag", "/proc/moose-bag", "cannot be created"),
    ]


@pytest.mark.parametrize("case", range(11))
def test_unusable_output_paths_are_refused_before_the_run(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                         case: int) -> None:
    """The review: every unwritable --json/--plot/--bag path was a traceback after the run, and the bag and the
    other outputs were lost with it."""
    flag, path, what = bad_paths(tmp_path)[case]
    args = ["simulate", "--duration", "0.5", flag, path] + (["--no-bag"] if flag != "--bag" else [])
    refused(here(capsys, *args), f"moose: error: {flag} {path!r}", what)


@pytest.mark.graph
def test_launch_checks_its_outputs_before_any_node_starts(tmp_path: Path) -> None:
    for flag, path, what in [bad_paths(tmp_path)[i] for i in (0, 2, 8)]:
        start = time.monotonic()
        out = moose("launch", flag, path, *(["--no-bag"] if flag != "--bag" else []))
        refused(out, f"moose: error: {flag} {path!r}", what)
        assert "[observer]" not in out.stdout and time.monotonic() - start < 30


def test_every_outcome_has_an_exit_status() -> None:
    assert set(OUTCOME_EXIT) == set(OUTCOMES)
    assert exit_status("clear") == EXIT_CLEAR and exit_status("incomplete") == EXIT_INCOMPLETE
    assert {exit_status(o) for o in OUTCOMES if o not in ("clear", "incomplete")} == {EXIT_FAILED}
    assert len({EXIT_CLEAR, EXIT_FAILED, EXIT_BAD_INPUT, EXIT_INCOMPLETE}) == 4


@pytest.mark.slow
def test_simulate_prints_its_verdict_and_exits_with_it(tmp_path: Path) -> None:
    """The main job (``make run``) is clear: 0, and every output written; a collision: 1.  What is printed and the
    exit status agree with the JSON (the verdict's own record)."""
    main = moose("simulate", "--scenario", "paper_v7_tau1.4", "--json", str(tmp_path / "main" / "summary.json"),
                 "--plot", str(tmp_path / "main" / "figure.png"), "--bag", str(tmp_path / "main" / "bag"))
    summary = strict_json(tmp_path / "main" / "summary.json")
    assert main.returncode == 0 and summary["outcome"] == "clear", main.stderr
    assert f"outcome         CLEAR: {summary['reason']}" in main.stdout and "collision-free" not in main.stdout
    assert (tmp_path / "main" / "figure.png").stat().st_size > 0
    assert (tmp_path / "main" / "bag" / "metadata.yaml").is_file()
    hit = moose("simulate", "--speed", "7", "--tau", "0.3", "--obstacle-half-width", "2", "--no-bag",
                "--json", str(tmp_path / "hit.json"))
    summary = strict_json(tmp_path / "hit.json")
    assert summary["outcome"] == "collision" and hit.returncode == EXIT_FAILED
    assert f"outcome         COLLISION: {summary['reason']}" in hit.stdout


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a running process (/proc/PID/stat), 0 once it has gone."""
    from moose_ros.process import stat_fields

    fields = stat_fields(pid)
    return 0.0 if fields is None else (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_ctrl_c_ends_simulate_with_130(tmp_path: Path) -> None:
    # as from a terminal: SIGINT at its default (a parent started in the background may pass it on ignored)
    # a slow ad-hoc case: the whole 121 s are simulated (the paper's cases leave the field after ~25 s), and
    # most of the CPU time is its maneuver table, built in CasADi, where a Ctrl-C used to be swallowed (exit 0
    # with a verdict) or surface as a SystemError traceback
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    assert subprocess.run(MOOSE + ["simulate", "--help"], capture_output=True).returncode == 0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    start_up = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    proc = subprocess.Popen(MOOSE + ["simulate", "--speed", "1", "--tau", "3", "--obstacle-half-width", "0.5",
                                     "--duration", "120", "--no-bag", "--json", str(tmp_path / "s.json")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        # mid-run, judged by the child's CPU time, not the wall clock (a loaded machine stretches the wall
        # time, a fast one ends the run early): 0.3 s past what `moose simulate --help` takes here, its imports
        # (0.25–1.2 s: with or without bytecode, under coverage or not), of a run of ~1.6 s or more
        while cpu_seconds(proc.pid) < start_up + 0.3 and proc.poll() is None:
            time.sleep(0.01)
        assert proc.poll() is None, "the run ended before the Ctrl-C: no test of it"
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130 and "Traceback" not in err
    assert not (tmp_path / "s.json").exists()  # nothing claims to be the summary of an interrupted run


def test_a_closed_pipe_is_not_a_traceback() -> None:
    """``moose … | head``: the reader goes away before the output comes; the command ends quietly (128 + SIGPIPE)."""
    bag = Path(__file__).resolve().parents[1] / "bags" / "paper_v7_tau1.4_combined"
    proc = subprocess.Popen(MOOSE + ["bag", "info", str(bag)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None
    proc.stdout.close()
    _, err = proc.communicate(timeout=120)
    assert b"Traceback" not in err and b"Exception ignored" not in err and proc.returncode == 128 + signal.SIGPIPE


@pytest.mark.parametrize("section", ["/*", "observer", "/observer"])
@pytest.mark.parametrize("command", [["simulate", *SHORT], ["reproduce"],
                                     ["sweep", "--speed", "5", "-o", "{tmp}/sweep"]])
def test_a_parameter_file_section_that_the_command_would_ignore_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], section: str, command: list[str]) -> None:
    """The probe ran ``moose simulate --config`` with a file whose only section is ``/*`` (or ``observer:``)
    holding ``vehicle: {m: -5}``: CLEAR, rc 0, the file ignored.  The core applies only ``/**``."""
    path = tmp_path / "sections.yaml"
    path.write_text(f'"{section}":\n  ros__parameters:\n    vehicle: {{m: -5.0}}\n')
    args = [a.format(tmp=tmp_path) for a in command[1:]]
    refused(here(capsys, command[0], "--config", str(path), *args), f"section {section!r} is not applied by "
            f"moose {command[0]}, which reads only '/**'")


# -- in-process: moose.cli.main, as the command runs it (a subprocess each costs a second of imports) -------------

@pytest.fixture
def tiny_disk(tmp_path: Path) -> Iterator[Callable[[int], Path]]:
    """A tmpfs of a few KiB (mount needs root: skipped without it), unmounted at the end whatever happened."""
    mounted: list[Path] = []

    def mount(kib: int) -> Path:
        point = tmp_path / f"disk{len(mounted)}"
        point.mkdir()
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={kib}k,mode=0700", "tmpfs", str(point)],
                              capture_output=True, text=True, timeout=30)
        if done.returncode != 0:
            pytest.skip(f"a tmpfs of {kib} KiB cannot be mounted here: {done.stderr.strip()}")
        mounted.append(point)
        return point

    yield mount
    for point in mounted:
        if subprocess.run(["umount", str(point)], capture_output=True, timeout=30).returncode != 0:
            subprocess.run(["umount", "-l", str(point)], capture_output=True, timeout=30)


def grow(point: Path, kib: int) -> None:
    """Make room on a tiny disk."""
    subprocess.run(["mount", "-o", f"remount,size={kib}k", str(point)], check=True, capture_output=True, timeout=30)


def test_a_full_disk_under_the_bag_reports_the_verdict_then_the_output_error(
        tmp_path: Path, tiny_disk: Callable[[int], Path], capsys: pytest.CaptureFixture[str]) -> None:
    """The probe: ``simulate --bag`` on a full tmpfs printed CLEAR and exited 2 ("bad input, nothing was run").
    Now the verdict comes first, then ``moose: error:`` for the bag, exit status 5; the JSON (elsewhere) is
    written, and the bag holds what its last checkpoint wrote."""
    from moose.verdict import EXIT_OUTPUT
    from moose_ros.bag import ReadReport, read_bag

    bag = tiny_disk(64) / "bag"
    done = here(capsys, "simulate", "--speed", "5", "--tau", "3", "--obstacle-half-width", "1", "--duration", "1",
                "--bag", str(bag), "--json", str(tmp_path / "s.json"))
    code, out, err = done.returncode, done.stdout, done.stderr
    summary = strict_json(tmp_path / "s.json")
    assert code == EXIT_OUTPUT == 5 and f"outcome         {summary['outcome'].upper()}" in out
    assert err.startswith(f"moose: error: bag {str(bag)!r}: writing failed (No space left on device)")
    assert "Traceback" not in err and "bag             " not in out
    report = ReadReport(str(bag))
    held = len(list(read_bag(bag, report=report)))
    assert f"the bag holds {held} messages" in err and held > 0 and report.unfinished and not report.lost_bytes


def test_a_sweep_on_a_full_disk_keeps_its_rows_and_a_corrupt_row_is_run_again(
        tiny_disk: Callable[[int], Path], capsys: pytest.CaptureFixture[str]) -> None:
    """The probe: ``sweep -o`` on a full disk ended in a traceback, and a corrupt middle line of cases.jsonl was
    skipped on --resume without a word.  Now: exit 5 naming the case that could not be recorded, the rows before
    it kept; --resume, once there is room, runs the rest; a corrupt row is reported and its case run again."""
    from moose.verdict import EXIT_OUTPUT

    disk = tiny_disk(16)  # the manifest and config.yaml take a page each, the journal one: two rows or so
    out_dir = disk / "sweep"
    sweep = ["sweep", "--speed", "5", "--tau", "2", "--nu", "0.2,0.4,0.6,0.8", "--duration", "2", "--workers", "1",
             "--quiet", "-o", str(out_dir)]
    done = here(capsys, *sweep)
    code, err = done.returncode, done.stderr
    assert code == EXIT_OUTPUT and "Traceback" not in err
    assert f"moose: error: -o {str(out_dir)!r}: case " in err and "No space left on device" in err
    kept = [json.loads(line) for line in (out_dir / "cases.jsonl").read_text().split("\n")[:-1]]
    assert 0 < len(kept) < 4
    grow(disk, 1024)
    done = here(capsys, *sweep, "--resume")
    code, err = done.returncode, done.stderr
    assert code == 0 and "Traceback" not in err
    lines = (out_dir / "cases.jsonl").read_text().splitlines()
    rows = [json.loads(line) for line in lines if line.startswith("{") and line.endswith("}")]
    assert {r["case_id"] for r in rows} >= {r["case_id"] for r in kept} and len({r["case_id"] for r in rows}) == 4
    middle = next(i for i, line in enumerate(lines) if line == json.dumps(rows[1], allow_nan=False))
    lines[middle] = lines[middle][:40] + "\x00garbage" + lines[middle][48:]
    (out_dir / "cases.jsonl").write_text("\n".join(lines) + "\n")
    done = here(capsys, *sweep, "--resume")
    code, out, err = done.returncode, done.stdout, done.stderr
    listed = re.search(r"line\(s\) ([\d, ]+) are not rows of a case", err)
    assert code == 0 and listed and str(middle + 1) in listed.group(1).split(", ")  # and a line the disk cut, if any
    assert "ran             1 cases" in out  # that case, again
    assert len(read_results(out_dir)) == 4


class _Service:
    """A TCP service on loopback that is not a Dask scheduler: it greets with ``banner`` (or says nothing)."""

    def __init__(self, banner: bytes) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.address = f"tcp://127.0.0.1:{self.server.getsockname()[1]}"
        self.banner, self.clients = banner, []
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                client, _ = self.server.accept()
            except OSError:
                return
            self.clients.append(client)
            if self.banner:
                client.sendall(self.banner)

    def close(self) -> None:
        self.server.close()
        for client in self.clients:
            client.close()


@pytest.mark.parametrize("banner, words", [(b"SSH-2.0-OpenSSH_9.6\r\n", "is not a Dask scheduler (it opened with"),
                                           (b"", "no Dask scheduler answers"),
                                           # a small length, then garbage (the probe's rerun: a correct error, then
                                           # a traceback from the half-made Client and a 20 s wait)
                                           (struct.pack("Q", 16) + bytes(range(7, 23)),
                                            "is not a Dask scheduler (its first message, 16 of 16 bytes")])
def test_a_service_that_is_not_dask_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], banner: bytes,
                                               words: str) -> None:
    """The probe: an SSH server on --address made distributed allocate 3 EiB (ArrayMemoryError) and print two
    tracebacks."""
    service = _Service(banner)
    try:
        start = time.monotonic()
        result = here(capsys, "sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--quiet",
                          "-o", str(tmp_path / "s"), "--address", service.address, "--connect-timeout", "2")
        assert time.monotonic() - start < 30
    finally:
        service.close()
    refused(result, f"--address {service.address!r}", words)
    assert not (tmp_path / "s").exists()


@pytest.mark.parametrize("args, words", [
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "-o", "/proc/moose-sweep"],
     "-o '/proc/moose-sweep' cannot be written"),
    (["bag", "view", str(Path(__file__).resolve().parents[1] / "bags" / "paper_v5_tau3_combined"),
      "-o", "/proc/moose-view.png"], "-o '/proc/moose-view.png' cannot be written"),
    (["can", "dump", "--interface", "socketcan", "--channel", "moose-nonexist0"],
     "--interface socketcan --channel 'moose-nonexist0': the bus cannot be opened"),
])
def test_unusable_outputs_and_devices_are_errors_not_tracebacks(capsys: pytest.CaptureFixture[str], args: list[str],
                                                                 words: str) -> None:
    refused(here(capsys, *args), "moose: error: ", words)


RELAXED_BAG = str(Path(__file__).resolve().parents[1] / "bags" / "paper_v5_tau3_combined")


@pytest.mark.parametrize("args, words", [
    (["--lockstep", "nope"], "--lockstep 'nope' is invalid: expected nodes of the lockstep graph other than the "
                             "simulator"),
    (["--lockstep", "vehicle_simulator"], "--lockstep 'vehicle_simulator' is invalid"),
    (["--lockstep", "observer", "observer"], "--lockstep observer observer is invalid: a node is named twice"),
    (["--lockstep", "observer", "--rate", "2"], "--rate 2 does not apply with --lockstep"),
    (["--lockstep", "observer", "--loop"], "--loop does not apply with --lockstep"),
    (["--lockstep", "observer", "--lockstep-timeout", "0"], "--lockstep-timeout 0.0 is invalid"),
    (["--lockstep", "observer", "--lockstep-timeout", "inf"], "--lockstep-timeout inf is invalid"),
    (["--lockstep-timeout", "5"], "--lockstep-timeout 5 applies only with --lockstep"),
])
def test_bad_lockstep_replays_are_refused_before_joining_the_graph(capsys: pytest.CaptureFixture[str],
                                                                   args: list[str], words: str) -> None:
    out = here(capsys, "bag", "play", RELAXED_BAG, "--topics", "/vehicle/imu", *args)
    refused(out, "moose: error: ", words)
    assert "played" not in out.stdout


def _fifo_unblocker(path: Path, after: float) -> threading.Thread:
    """Open the FIFO for writing after ``after`` s and close it: a reader blocked on it (main) gets end of file."""
    def unblock() -> None:
        time.sleep(after)
        try:
            fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)  # ENXIO when no reader waits: nothing to unblock
        except OSError:
            return
        os.close(fd)

    thread = threading.Thread(target=unblock, daemon=True)
    thread.start()
    return thread


@pytest.mark.parametrize("kind, words", [
    ("non-UTF-8", "is not UTF-8 text: byte 0xff at offset 7"),
    ("/dev/zero", "it is a character device, not a regular file"),
    ("FIFO", "it is a FIFO, not a regular file"),
    ("directory", "it is a directory, not a regular file"),
    ("oversize", "is larger than 262144 bytes"),
])
def test_a_config_that_is_no_text_file_is_refused_before_it_is_read(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                     kind: str, words: str) -> None:
    """The probe: 0xff bytes gave a UnicodeDecodeError traceback, /dev/zero ate memory until SIGKILL, a FIFO hung."""
    path = tmp_path / "config.yaml"
    if kind == "non-UTF-8":
        path.write_bytes(b"/**:\n  \xff\xfe\n")
    elif kind == "/dev/zero":
        path = Path("/dev/zero")
    elif kind == "FIFO":
        os.mkfifo(path)
        _fifo_unblocker(path, 5.0)  # on main the read blocked until a writer came: this one, 5 s later
    elif kind == "directory":
        path = tmp_path
    else:
        path.write_text("/**:\n  ros__parameters:\n" + "    # padding\n" * 30_000)
    start = time.monotonic()
    result = here(capsys, "simulate", "--config", str(path), "--no-bag", "--duration", "0.5")
    assert time.monotonic() - start < 4.0  # refused at once, not after reading
    refused(result, f"parameter file {str(path)!r}", words)


@pytest.mark.can
def test_the_can_bridge_refuses_to_start_without_its_bus() -> None:
    """The probe: ``moose node can_bridge`` on a socketcan channel that does not exist printed "started" and
    nothing else (re-opening every 2 s, the graph none the wiser)."""
    from moose.params import ParamError
    from moose_ros.nodes.can_bridge import CanBridge
    from moose_ros.runtime import DdsNode

    node = DdsNode("can_bridge", overrides={"can_interface": "socketcan", "can_channel": "moose-nonexist0"})
    try:
        with pytest.raises(ParamError, match=r"can_interface 'socketcan', can_channel 'moose-nonexist0': the bus "
                                             r"cannot be opened \(open failed: .+\); the bridge does not start"):
            CanBridge(node)
    finally:
        node.shutdown()


def test_figures_and_maps_on_a_full_or_read_only_disk_are_errors(
        tmp_path: Path, tiny_disk: Callable[[int], Path], capsys: pytest.CaptureFixture[str]) -> None:
    """The probe's rerun: ``bag view -o`` on a full disk, ``sweep plot`` on a read-only folder and on a truncated
    results file each ended in a traceback.  Now: exit 5 naming the figure (nothing half written), and exit 2
    naming the folder or the file."""
    from moose.verdict import EXIT_BAD_INPUT, EXIT_OUTPUT

    full = tiny_disk(16)
    (full / "filler").write_bytes(bytes(15 * 1024))
    figure = full / "view.png"
    done = here(capsys, "bag", "view", str(Path(__file__).resolve().parents[1] / "bags" / "paper_v5_tau3_combined"),
                "-o", str(figure))
    assert done.returncode == EXIT_OUTPUT and "Traceback" not in done.stderr
    assert f"moose: error: -o {str(figure)!r}: writing failed (No space left on device)" in done.stderr
    assert sorted(p.name for p in full.iterdir()) == ["filler"]  # no half-written PNG, no temporary file
    sweep = tmp_path / "sweep"
    assert here(capsys, "sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--duration", "1", "--workers", "1",
                "--quiet", "-o", str(sweep)).returncode == 0
    blocked = tmp_path / "blocked"  # a folder that cannot be made (root writes read-only modes: a file is in the way)
    blocked.write_text("a file where the folder would go")
    done = here(capsys, "sweep", "plot", str(sweep), "--plot-output", str(blocked / "maps"))
    assert done.returncode == EXIT_BAD_INPUT and "Traceback" not in done.stderr
    assert f"moose: error: --plot-output {str(blocked / 'maps')!r} cannot be created" in done.stderr
    results = sweep / "results.parquet"
    results.write_bytes(results.read_bytes()[:100])
    done = here(capsys, "sweep", "plot", str(sweep))
    assert done.returncode == EXIT_BAD_INPUT and "Traceback" not in done.stderr
    assert f"moose: error: sweep results {str(results)!r} are unreadable" in done.stderr
    assert "--resume" in done.stderr  # and how to rebuild them


def test_a_ctrl_c_that_a_c_extension_turned_into_a_system_error_ends_with_130(monkeypatch: pytest.MonkeyPatch) -> None:
    """CasADi lets a KeyboardInterrupt out of a callback as a SystemError ("returned a result with an exception
    set") whose cause is the interrupt: 130, as any Ctrl-C.  A SystemError of another cause is a bug, not hidden."""
    import moose.cli.reproduce
    from moose.cli import _interrupted, main

    def casadi_interrupted(args: object) -> int:
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise SystemError("<built-in function ...> returned a result with an exception set") from exc

    def broken(args: object) -> int:
        raise SystemError("a real one")

    def class_body_interrupted(args: object) -> int:  # a Ctrl-C while matplotlib's classes are made (seen)
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise RuntimeError("Error calling __set_name__ on '_axis_method_wrapper' instance") from exc

    monkeypatch.setattr(moose.cli.reproduce, "cmd_reproduce", casadi_interrupted)
    assert main(["reproduce"]) == 130
    monkeypatch.setattr(moose.cli.reproduce, "cmd_reproduce", class_body_interrupted)
    assert main(["reproduce"]) == 130
    monkeypatch.setattr(moose.cli.reproduce, "cmd_reproduce", broken)
    with pytest.raises(SystemError, match="a real one"):
        main(["reproduce"])
    looped = SystemError("a chain that refers to itself")
    looped.__context__ = ValueError()
    looped.__context__.__context__ = looped
    assert not _interrupted(looped)
    deep = SystemError()
    deep.__context__ = ValueError()
    deep.__context__.__cause__ = KeyboardInterrupt()
    assert _interrupted(deep)


INTERRUPTED_PROGRAM = textwrap.dedent("""
    import atexit, sys
    import moose.cli.reproduce
    from moose.cli import main

    def interrupted(args):
        raise KeyboardInterrupt

    class Finalized:  # a module global's finaliser runs in the interpreter's teardown
        def __del__(self):
            print("the interpreter was torn down", flush=True)

    kept = Finalized()
    moose.cli.reproduce.cmd_reproduce = interrupted
    atexit.register(lambda: print("the exit handlers ran", flush=True))
    sys.argv = ["moose", "reproduce"]
    print("partial output", end="")  # still in the buffer when the process ends
    sys.exit(main())
""")


def test_an_interrupted_program_runs_its_exit_handlers_and_ends_with_130() -> None:
    """Run as the program, an interrupted command ends its process without Python's finalization (where a C
    extension interrupted mid-call aborted it, exit -6), after the exit handlers and with its output flushed."""
    run = subprocess.run([sys.executable, "-c", INTERRUPTED_PROGRAM], capture_output=True, text=True, timeout=60)
    assert run.returncode == 130, run.stderr
    assert run.stdout == "partial outputthe exit handlers ran\n" and "Traceback" not in run.stderr
