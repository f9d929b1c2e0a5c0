"""``moose sweep``: axes and sampling, bad input refused before any case, a case equal to ``moose simulate``,
Ctrl-C and ``--resume``, failing cases recorded, the Dask backend against the local one, the maps.

Sweeps run as the user runs them (the ``moose`` command in a subprocess) wherever a process boundary
matters: signals, worker processes, a cluster of separate processes.
"""
from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, Optional

import pytest

pytest.importorskip("pyarrow")

from moose.cli import main
from moose.config import load_config
from moose.maneuver import MaxSteeringTable
from moose.paper import PAPER_FRICTION
from moose.params import ParamError, replace
from moose.sweep.axes import parse_axis, unit_samples
from moose.sweep.case import MACHINE_COLUMNS
from moose.sweep.spec import SweepSpec
from moose.sweep.store import read_results

MOOSE = [sys.executable, "-m", "moose.cli"]


def rows_of(folder: Path) -> list[dict[str, Any]]:
    return read_results(folder).to_pylist()


def journal(folder: Path) -> list[dict[str, Any]]:
    path = folder / "cases.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


# -- axes and sampling ------------------------------------------------------------------------------

def test_axes_lists_and_ranges() -> None:
    assert parse_axis("speed", "4,5,6").values == (4, 5, 6)
    assert parse_axis("tau", "1:2:0.25").values == (1.0, 1.25, 1.5, 1.75, 2.0)
    assert parse_axis("nu", "0.1:1.0:0.1").values[-1] == 1.0 and len(parse_axis("nu", "0.1:1.0:0.1").values) == 10
    assert parse_axis("set.planning.N_p", "10:20:5").values == (10, 15, 20)  # integers stay integers
    assert parse_axis("mu", "paper,0.8").values == ("paper", 0.8)
    sampled = parse_axis("speed", "4:8")
    assert sampled.sampled and (sampled.low, sampled.high) == (4.0, 8.0)


@pytest.mark.parametrize("text, words", [
    ("", "no values"), ("5:1:1", "LO = 5 is above HI = 1"), ("1:5:0", "STEP = 0 must be positive"),
    ("1:5:-1", "must be positive"), ("a:5", "expected a number"), ("1:2:3:4", "LO:HI"), ("4,,5", "number or a name"),
    ("4,4", "listed twice"), ("1:.nan:1", "finite"), ("1:nan:1", "expected a number"),
])
def test_axes_refuse_bad_text(text: str, words: str) -> None:
    with pytest.raises(ParamError, match="speed") as info:
        parse_axis("speed", text)
    assert words in str(info.value)


def test_latin_hypercube_has_one_point_per_stratum_and_is_seeded() -> None:
    import numpy as np

    a = unit_samples(50, 3, "lhs", np.random.default_rng(7))
    b = unit_samples(50, 3, "lhs", np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)
    for dim in range(3):
        assert sorted(np.floor(a[:, dim] * 50).astype(int)) == list(range(50))


def test_sampled_sweep_is_reproducible_from_its_recorded_seed() -> None:
    config = load_config()
    axes = (parse_axis("speed", "4:8"), parse_axis("tau", "1:5"), parse_axis("half_width", "1,2"),
            parse_axis("planner", "combined,msf"), parse_axis("seed", "0"))
    spec = SweepSpec(axes, config, samples=20, sampling_seed=3)
    cases = spec.cases()
    assert len(cases) == 20 * 2 * 2
    assert [c.id for c in cases] == [c.id for c in SweepSpec(axes, config, samples=20, sampling_seed=3).cases()]
    assert [c.id for c in cases] != [c.id for c in SweepSpec(axes, config, samples=20, sampling_seed=4).cases()]
    # every sampled threat is met by both planners
    by_threat: dict[tuple[float, float, float], set[str]] = {}
    for c in cases:
        by_threat.setdefault((c.speed, c.tau, c.half_width), set()).add(c.planner)
    assert all(p == {"combined", "msf"} for p in by_threat.values())


def test_target_nu_gives_the_width_of_the_simulated_car() -> None:
    config = load_config()
    spec = SweepSpec((parse_axis("speed", "7"), parse_axis("tau", "1.4"), parse_axis("nu", "0.5"),
                      parse_axis("mu", "paper,0.8"), parse_axis("seed", "0")), config)
    for case in spec.cases():
        table = MaxSteeringTable.build(replace(config.vehicle, mu=case.mu), config.maneuver)
        assert case.half_width == pytest.approx(0.5 * table.reach(1.4, 7.0), rel=1e-12)
    low, high = spec.cases()
    assert low.mu == PAPER_FRICTION and low.half_width < high.half_width  # grippier road: wider for the same nu


# -- bad input: a clear error before any case runs ----------------------------------------------------

BASE = ["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--duration", "2", "--quiet"]


@pytest.mark.parametrize("args, words", [
    (["sweep", "--speed", "", "--tau", "2", "--nu", "0.5"], "--speed"),
    (["sweep", "--speed", "5", "--tau", "3:1:0.5", "--nu", "0.5"], "--tau = '3:1:0.5' is an invalid range"),
    (["sweep", "--speed", "5:8", "--tau", "2", "--nu", "0.5"], "needs --samples"),
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--set", "mpc.N_p=10,20"], "did you mean planning.N_p"),
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--set", "mpcc.x=1"], "'mpcc' is not a parameter group"),
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--set", "planning.N_p=0,10"], "N_p = 0 is invalid"),
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--set", "vehicle.mu=0.5"], "the --mu axis"),
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--obstacle-half-width", "1"], "exactly one"),
    (["sweep", "--speed", "5,30", "--tau", "2", "--obstacle-half-width", "1"], "speed = 30"),
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--mu", "3"], "--mu 3"),
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--planner", "combined,lqr"], "--planner 'lqr'"),
    (["sweep", "--speed", "5", "--tau", "2", "--nu", "0.5", "--seeds", "0"], "--seeds 0"),
    (["sweep", "--speed", "5", "--tau", "2"], "exactly one of --obstacle-half-width and --nu"),
])
def test_bad_input_is_refused_before_any_case(tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
                                             words: str) -> None:
    out = tmp_path / "sweep"
    assert main(args + ["-o", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("moose: error: ") and words in err and "Traceback" not in err
    assert not out.exists()  # nothing ran, nothing was written


def test_an_unreachable_cluster_is_refused_before_any_case(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with socket.socket() as held:  # a port that is ours and listens to nobody: connections are refused
        held.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{held.getsockname()[1]}"
        code = main(BASE + ["-o", str(tmp_path / "s"), "--address", address,
                            "--connect-timeout", "2"])
    err = capsys.readouterr().err
    assert code == 2 and "moose: error: --address" in err and "no Dask scheduler answers" in err
    assert "(ConnectionRefusedError: Connection refused)" in err  # the port's refusal, not a wait for a timeout
    assert not (tmp_path / "s").exists()


def test_a_folder_of_another_sweep_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s"
    assert main(BASE + ["-o", str(out), "--workers", "1"]) == 0
    before = (out / "cases.jsonl").read_bytes()
    assert main(["sweep", "--speed", "6", "--tau", "2", "--nu", "0.5", "--duration", "2", "-o", str(out),
                 "--quiet"]) == 2
    assert "holds a different sweep" in capsys.readouterr().err
    assert main(BASE + ["-o", str(out)]) == 2  # the same sweep again: only with --resume
    assert "--resume continues it" in capsys.readouterr().err
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    assert main(BASE + ["-o", str(tmp_path / "other")]) == 2
    assert "holds no sweep" in capsys.readouterr().err
    assert (out / "cases.jsonl").read_bytes() == before


# -- a case is moose simulate --------------------------------------------------------------------------

@pytest.mark.slow
def test_a_sweep_case_equals_moose_simulate(tmp_path: Path) -> None:
    out = tmp_path / "s"
    assert main(["sweep", "--speed", "6.5", "--tau", "2.2", "--nu", "0.45", "--mu", "paper", "--duration", "4",
                 "--planner", "combined", "--seeds", "2", "--set", "planning.N_p=12", "--set", "sensors.gps_lag_s=0.3",
                 "--field-margin", "4", "--timing", "car", "-o", str(out), "--workers", "2", "--quiet"]) == 0
    rows = rows_of(out)
    assert len(rows) == 2 and {r["input.seed"] for r in rows} == {0, 1}
    for row in rows:
        summary_path = tmp_path / f"simulate_{row['input.seed']}.json"
        assert main(["simulate", "--speed", repr(row["input.speed_mps"]), "--tau", repr(row["input.tau_s"]),
                     "--obstacle-half-width", repr(row["input.half_width_m"]),
                     "--obstacle-length", repr(row["input.length_m"]), "--duration", repr(row["input.duration_s"]),
                     "--field-margin", repr(row["input.field_margin_m"]), "--mu", repr(row["input.mu"]),
                     "--planner", row["input.planner"], "--seed", str(row["input.seed"]),
                     "--set", "planning.N_p=12", "--set", "sensors.gps_lag_s=0.3", "--timing", "car",
                     "--json", str(summary_path), "--no-bag"]) == 0
        summary = json.loads(summary_path.read_text())
        compared = 0
        for key, value in summary.items():
            if key == "mpc_solve_ms":
                assert row["mpc_solve_ms.count"] == value["count"]
                continue
            if key == "timing":  # the profile and every value, in columns of their own
                assert {k: row[f"timing.{k}"] for k in value} == value and value["profile"] == "car"
                continue
            recorded = row[key]
            if isinstance(value, (dict, list)):
                recorded = json.loads(recorded)
            assert recorded == value, key
            compared += 1
        assert compared >= 30 and row["status"] == "done"
        assert row["mu"] == PAPER_FRICTION and row["nu"] == pytest.approx(0.45, abs=0.05)


# -- interruption, resume, failing cases ---------------------------------------------------------------

def _children(pid: int) -> list[int]:
    import psutil

    try:
        return [p.pid for p in psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


def _signal_all(pids: list[int], sig: int) -> None:
    for pid in pids:
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass


def _wait_for(predicate: Any, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


@pytest.mark.slow
def test_ctrl_c_keeps_finished_cases_and_resume_runs_the_rest(tmp_path: Path) -> None:
    import psutil

    out = tmp_path / "s"
    # 24 cases at a 10 kHz plant step: 12 of 3 s (a few tenths of a second of work each) and 12 of 20 s (a couple
    # of seconds each), so that when the third row is seen the sweep still has seconds of work for both cores left
    # and Ctrl-C arrives while it runs, even when this test process waits seconds for a core (with only the short
    # cases, a loaded machine once let the sweep finish before the test saw its third row)
    args = MOOSE + ["sweep", "--speed", "5,6", "--tau", "1.5,2,2.5", "--nu", "0.3", "--planner", "msf,combined",
                    "--duration", "3,20", "--set", "simulation.plant_dt=0.0001", "-o", str(out), "--workers", "2",
                    "--quiet"]
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    workers: list[int] = []
    try:
        # the workers are held (SIGSTOP) while the journal is read, so that no case ends between the third row and
        # Ctrl-C however long this process waits for a core: the sweep surely has cases left when it arrives
        deadline = time.monotonic() + 120
        while True:
            assert time.monotonic() < deadline and process.poll() is None, "no three finished cases"
            workers = _children(process.pid)
            _signal_all(workers, signal.SIGSTOP)
            if len(journal(out)) >= 3:
                break
            _signal_all(workers, signal.SIGCONT)
            time.sleep(0.05)
        assert len(journal(out)) < 24
        os.killpg(process.pid, signal.SIGINT)  # Ctrl-C reaches the whole foreground group (the held workers too)
        _signal_all(workers, signal.SIGCONT)
        _, err = process.communicate(timeout=60)
    finally:
        _signal_all(workers, signal.SIGCONT)
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == 130, err
    assert "--resume" in err and "Traceback" not in err
    _wait_for(lambda: not any(psutil.pid_exists(p) and psutil.Process(p).status() != psutil.STATUS_ZOMBIE
                              for p in workers), 10, "the workers to end")
    kept = rows_of(out)
    assert 3 <= len(kept) < 24 and kept == [dict(r) for r in rows_of(out)]
    assert {r["case_id"] for r in kept} == {r["case_id"] for r in journal(out)}
    assert json.loads((out / "manifest.json").read_text())["state"] == "interrupted"
    # --resume runs only the rest, and leaves the kept rows as they were
    done = subprocess.run(args + ["--resume"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert f"{len(kept)} recorded before" in done.stdout
    rows = rows_of(out)
    assert len(rows) == 24 and len({r["case_id"] for r in rows}) == 24
    by_id = {r["case_id"]: r for r in rows}
    for row in kept:
        assert by_id[row["case_id"]]["wall_s"] == row["wall_s"]  # not run again
    assert json.loads((out / "manifest.json").read_text())["state"] == "complete"


@pytest.mark.slow
@pytest.mark.realtime  # a time limit is wall-clock time: at load average 15-20 (ci1) the 0.6 s case took over 4 s
def test_failing_cases_are_recorded_and_the_sweep_goes_on(tmp_path: Path) -> None:
    """A case that raises (a plant step the RK4 cannot integrate stably), one that outlives its time limit
    (121 simulated seconds at a 100 kHz plant step, about 9 s of work here, against 4 s) and one whose worker
    is killed (SIGKILL from outside) are each recorded with why; the others run.  The case that must finish is
    about 0.6 s of work, a sixth of the limit: with two test runs at once under coverage (load average 9 on two
    cores) a 0.7 s case once took more than the 2 s limit this test had before."""
    import psutil

    out = tmp_path / "s"
    # 1 m/s: the car is still inside the field after 121 s (at 6 m/s it leaves it after ~25 s, and the run ends
    # there: a few seconds of work, no timeout)
    args = MOOSE + ["sweep", "--speed", "1", "--tau", "2", "--nu", "0.5", "--planner", "msf",
                    "--duration", "0.1,120", "--set", "simulation.plant_dt=0.00001,0.01", "--timeout", "4",
                    "--workers", "2", "-o", str(out), "--quiet"]
    assert subprocess.run(args, capture_output=True, text=True, timeout=300).returncode == 3
    rows = {(r["input.duration_s"], r["set.simulation.plant_dt"]): r for r in rows_of(out)}
    assert len(rows) == 4
    done = rows[(0.1, 0.00001)]
    assert done["status"] == "done" and done["outcome"] is not None, done
    for duration in (0.1, 120.0):
        error = rows[(duration, 0.01)]
        assert error["status"] == "error" and "RK4 needs dt" in error["error"] and error["outcome"] is None
    slow = rows[(120.0, 0.00001)]  # 121 simulated seconds at a 100 kHz plant step: about 9 s of work
    assert slow["status"] == "timeout" and "4 s" in slow["error"] and slow["wall_s"] >= 4.0

    # a worker killed under its case (SIGKILL from outside): recorded as crashed, the sweep runs the rest.  Both
    # workers are held (SIGSTOP) as soon as they exist, and the journal is then empty: each holds its first case
    # (given at its start), none finished, whatever this machine's speed (ci17: on a fast host the 60-s cases this
    # test had took under a second, the kill 1 s after the start found a worker between cases, nothing crashed).
    # The cases are long (40 s at 1 m/s, inside the field, at a 100 kHz plant step: about 3 s of work here).
    out2 = tmp_path / "s2"
    args2 = MOOSE + ["sweep", "--speed", "1", "--tau", "2", "--nu", "0.5", "--planner", "msf", "--duration", "40",
                     "--set", "simulation.plant_dt=0.00001", "--seeds", "3", "--workers", "2", "-o", str(out2),
                     "--quiet"]
    process = subprocess.Popen(args2, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)

    def workers() -> list[int]:
        return [p for p in _children(process.pid) if "spawn_main" in " ".join(psutil.Process(p).cmdline())]

    held: list[int] = []
    try:
        _wait_for(lambda: len(workers()) == 2, 60, "two workers")
        held = workers()
        _signal_all(held, signal.SIGSTOP)
        assert journal(out2) == [], "a case finished before the workers were held"
        os.kill(held[0], signal.SIGKILL)
        _signal_all(held[1:], signal.SIGCONT)
        process.communicate(timeout=300)
    finally:
        _signal_all(held, signal.SIGCONT)
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    assert process.returncode == 3
    rows2 = rows_of(out2)
    assert len(rows2) == 3
    crashed = [r for r in rows2 if r["status"] == "crashed"]
    assert len(crashed) == 1 and "SIGKILL" in crashed[0]["error"]
    assert sum(r["status"] == "done" for r in rows2) == 2


# -- Dask ------------------------------------------------------------------------------------------------

def _scheduler_address(path: Path) -> Optional[str]:
    """The address in a Dask scheduler file, or None while the file is missing or not yet whole."""
    try:
        return str(json.loads(path.read_text())["address"])
    except (OSError, ValueError, KeyError):
        return None


@pytest.mark.slow
def test_dask_cluster_gives_the_rows_of_the_local_backend(tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    dask = Path(sys.executable).with_name("dask")
    scheduler_file = tmp_path / "scheduler.json"
    scheduler = subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                                  "--scheduler-file", str(scheduler_file)], stdout=subprocess.DEVNULL,
                                 stderr=subprocess.DEVNULL, start_new_session=True)
    worker = None
    try:
        # the scheduler writes its file in place: it can exist, empty or cut short, before it holds the address
        # (ci22: JSONDecodeError on an empty file)
        _wait_for(lambda: _scheduler_address(scheduler_file) is not None, 60, "the Dask scheduler")
        address = _scheduler_address(scheduler_file)
        assert address is not None
        worker = subprocess.Popen([str(dask), "worker", address, "--nworkers", "2", "--nthreads", "1",
                                   "--no-dashboard", "--host", "127.0.0.1"], stdout=subprocess.DEVNULL,
                                  stderr=subprocess.DEVNULL, start_new_session=True)
        from distributed import Client

        with Client(address, timeout="60s") as client:  # both workers up before the sweep starts
            client.wait_for_workers(2, timeout=120)
        axes = ["sweep", "--speed", "5,7", "--tau", "1.4,2.5", "--nu", "0.4", "--mu", "paper",
                "--planner", "combined,mpc", "--duration", "3", "--quiet"]
        local, remote = tmp_path / "local", tmp_path / "dask"
        assert subprocess.run(MOOSE + axes + ["-o", str(local), "--workers", "2"], capture_output=True,
                              timeout=300).returncode == 0
        run = subprocess.run(MOOSE + axes + ["-o", str(remote), "--address", address,
                                             "--connect-timeout", "60"], capture_output=True, text=True, timeout=300)
        assert run.returncode == 0, run.stderr
        assert "backend dask" in run.stderr
        a = {r["case_id"]: r for r in rows_of(local)}
        b = {r["case_id"]: r for r in rows_of(remote)}
        assert len(a) == 8 and a.keys() == b.keys()
        workers = {r["worker"] for r in b.values()}
        assert len(workers) == 2  # both Dask workers ran cases, none ran in this process
        for key, row in a.items():
            for column, value in row.items():
                if column not in MACHINE_COLUMNS:
                    assert b[key][column] == value, (key, column)
        assert json.loads((remote / "manifest.json").read_text())["backend"] == "dask"
    finally:
        for process in (worker, scheduler):
            if process is not None and process.poll() is None:
                os.killpg(process.pid, signal.SIGTERM)
                try:
                    process.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait()


# -- results and maps ---------------------------------------------------------------------------------------

@pytest.mark.slow
def test_results_and_maps_agree_with_the_journal(tmp_path: Path) -> None:
    out = tmp_path / "s"
    assert main(["sweep", "--speed", "7", "--tau", "1:2:0.5", "--nu", "0.3,0.9", "--mu", "paper",
                 "--planner", "combined,mpc,msf", "--duration", "3", "-o", str(out), "--workers", "2", "--quiet"]) == 0
    rows = rows_of(out)
    assert len(rows) == 18
    lines = (out / "cases.jsonl").read_text().splitlines()
    assert [json.loads(line)["case_id"] for line in lines] == [r["case_id"] for r in rows]
    for line in lines:
        assert "NaN" not in line and "Infinity" not in line
    for row in rows:  # every verdict column is consistent with the outcome
        assert row["outcome"] in ("clear", "collision", "left_field", "lost_control", "stopped_short", "incomplete")
        assert (row["outcome"] == "clear") == (not row["collided"] and not row["lost_control"]
                                               and not row["left_field"] and row["complete"] and row["passed_obstacle"])
        assert not math.isnan(row["wall_s"])
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["state"] == "complete" and manifest["cases"] == 18 and manifest["spec"]["sampling"] == "grid"
    assert (out / "config.yaml").read_text().startswith("/**:")
    maps = tmp_path / "maps"
    assert main(["sweep", "plot", str(out), "--plot-output", str(maps)]) == 0
    page = (maps / "index.html").read_text()
    for name in ("envelope.png", "advantage.png", "outcome.png", "clearance.png"):
        assert (maps / name).stat().st_size > 10_000 and f"src='{name}'" in page
    assert "The paper's nine experiments" in page  # τ-ν axes at the paper calibration
    assert main(["sweep", "plot", str(out), "--x", "speed"]) == 2  # speed does not vary here


def test_rows_record_their_verdict_limits_and_maps_show_only_the_default_verdict(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A sweep with a looser ``sideslip_max`` could call lost control a pass without a trace: each row records
    the limits it was judged with, and ``sweep plot`` refuses rows judged with others."""
    out = tmp_path / "s"
    assert main(["sweep", "--speed", "7", "--tau", "1.4", "--nu", "0.9", "--mu", "paper", "--planner", "mpc",
                 "--duration", "2", "--set", "verdict.sideslip_max=10", "-o", str(out), "--workers", "1",
                 "--quiet"]) == 0
    (row,) = rows_of(out)
    assert row["verdict_limits_default"] is False and json.loads(row["verdict_limits"])["sideslip_max"] == 10.0
    capsys.readouterr()
    assert main(["sweep", "plot", str(out), "--plot-output", str(tmp_path / "maps")]) == 2
    error = capsys.readouterr().err
    assert "1 cases were judged with other verdict limits (sideslip_max = 10 instead of 0.35)" in error
    assert not (tmp_path / "maps" / "index.html").exists()


def test_the_core_stays_light_and_a_missing_extra_is_named(tmp_path: Path) -> None:
    """``moose`` loads no sweep dependency until a sweep runs; without pyarrow the sweep says what to install."""
    code = ("import sys; from moose.cli import build_parser; build_parser(); "
            "print(sorted(m for m in ('pyarrow', 'rich', 'dask', 'distributed') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert loaded.returncode == 0 and loaded.stdout.strip() == "[]", loaded.stdout + loaded.stderr
    blocked = ("import sys, importlib.abc\n"
               "class Block(importlib.abc.MetaPathFinder):\n"
               "    def find_spec(self, name, path=None, target=None):\n"
               "        if name.split('.')[0] == 'pyarrow': raise ImportError('no pyarrow here')\n"
               "sys.meta_path.insert(0, Block())\n"
               "from moose.cli import main; sys.exit(main(sys.argv[1:]))\n")
    out = tmp_path / "s"
    run = subprocess.run([sys.executable, "-c", blocked, "sweep", "--speed", "5", "--tau", "2", "--nu", "0.5",
                          "-o", str(out)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and "pip install 'moose-avoidance[sweep]'" in run.stderr, run.stderr
    assert not out.exists()


def test_a_journal_line_cut_by_a_kill_costs_only_that_case(tmp_path: Path) -> None:
    out = tmp_path / "s"
    args = ["sweep", "--speed", "5,6", "--tau", "2", "--nu", "0.5", "--planner", "msf", "--duration", "2.5",
            "-o", str(out), "--workers", "1", "--quiet"]
    assert main(args) == 0
    lines = (out / "cases.jsonl").read_text().splitlines()
    # as a SIGKILL mid-write leaves it
    (out / "cases.jsonl").write_text(lines[0] + "\n" + lines[1][: len(lines[1]) // 2])
    assert main(args + ["--resume"]) == 0  # reruns the cut case only
    rows = rows_of(out)
    assert len(rows) == 2 and {r["case_id"] for r in rows} == {json.loads(line)["case_id"] for line in lines}
    assert json.loads((out / "cases.jsonl").read_text().splitlines()[0]) == json.loads(lines[0])


def test_a_rows_mpc_statuses_count_the_plans_through_the_barrier() -> None:
    """The paper's hand-over trigger is in every row: ``mpc_status_counts`` counts ``barrier_violated`` (7 m/s,
    τ = 1.4 s: the MPC's plans cannot lift the car over y_safe)."""
    from moose.config import load_config
    from moose.paper import PAPER_FRICTION
    from moose.sweep.axes import Case
    from moose.sweep.case import run_case

    case = Case(speed=7.0, tau=1.4, half_width=2.0, nu=None, length=2.0, duration=2.0, field_margin=None,
                mu=PAPER_FRICTION, planner="mpc", seed=0)
    row = run_case(case, load_config())
    assert row["status"] == "done", row["error"]
    counts = json.loads(row["mpc_status_counts"])
    assert counts["barrier_violated"] > 0 and sum(counts.values()) == row["mpc_solve_ms.count"]
