"""A normal install works: both packages built as wheels, installed into a fresh virtual environment (pip's cache
reused), run from a directory outside the source tree.  The Dockerfile installs the same way."""
from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from node_output import read_until_started

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
GIT_IGNORED = [line.strip().strip("/") for line in (ROOT / ".gitignore").read_text(encoding="utf-8").splitlines()
               if line.strip() and not line.startswith("#")]
"""What .gitignore keeps out of the repository, by name: the virtual environments (``.venv-ros`` is 1 GB), caches,
and the coverage data the suite's other processes write and delete while the copy is made (ci42 failed copying a
data file that was gone by then)."""
SKIP = shutil.ignore_patterns(*GIT_IGNORED, ".git", "bags", "dist", "tests", "bench", "docs")


def run(cmd: list, cwd: Path, timeout: float = 600.0) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)


def test_wheels_install_into_a_fresh_environment_and_run_from_anywhere(tmp_path: Path) -> None:
    source = tmp_path / "source"  # a copy: the build must not depend on anything outside the two packages
    shutil.copytree(ROOT, source, symlinks=True, ignore=SKIP)
    assert not [name for name in (".venv-ros", ".coverage-data") if (source / name).exists()]
    wheels, venv, elsewhere = tmp_path / "wheels", tmp_path / "venv", tmp_path / "elsewhere"
    elsewhere.mkdir()
    built = run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", wheels, source,
                 source / "ros2_ws" / "src" / "moose_ros"], cwd=tmp_path)
    assert built.returncode == 0, built.stderr[-2000:]
    core = next(wheels.glob("moose_avoidance-*.whl"))
    ros = next(wheels.glob("moose_ros-*.whl"))
    # the environment gets no pip of its own (ensurepip took 6 CPU-s): this pip installs into it (`pip --python`)
    assert run([sys.executable, "-m", "venv", "--without-pip", venv], cwd=tmp_path).returncode == 0
    python, moose = venv / "bin" / "python", venv / "bin" / "moose"
    pip = [sys.executable, "-m", "pip", "--python", python, "install", "--no-compile"]  # bytecode: not the claim

    # the core alone: a scenario runs, and the missing bag recorder is named, not a traceback
    installed = run([*pip, core], cwd=tmp_path)
    assert installed.returncode == 0, installed.stderr[-2000:]
    alone = run([moose, "simulate", "--scenario", "paper_v7_tau1.4", "--duration", "2"], cwd=elsewhere)
    assert alone.returncode == 0, alone.stderr[-2000:]
    assert "outcome         CLEAR" in alone.stdout
    assert "no bag recorded: the bag recorder comes with the moose_ros" in alone.stderr
    refused = run([moose, "simulate", "--duration", "0.5", "--bag", "b"], cwd=elsewhere)
    assert refused.returncode == 2 and "moose: error: --bag 'b': the bag recorder comes with" in refused.stderr
    assert run([python, "-c", "import cyclonedds"], cwd=elsewhere).returncode != 0  # the core does not pull it in

    installed = run([*pip, ros], cwd=tmp_path)
    assert installed.returncode == 0, installed.stderr[-2000:]
    where = run([python, "-c", "import moose, moose_ros; from moose_ros.interfaces import msg_dir; "
                 "from moose_ros.runtime.discovery import FASTDDS_PROFILE as f; assert f.is_file(), f; "
                 "print(moose.__file__, moose_ros.__file__, msg_dir(), f, sep='\\n')"], cwd=elsewhere)
    assert [Path(p).is_relative_to(venv) for p in where.stdout.split()] == [True] * 4, where.stdout
    simulated = run([moose, "simulate", "--scenario", "paper_v7_tau1.4", "--no-bag", "--duration", "2"], cwd=elsewhere)
    assert simulated.returncode == 0 and "outcome         CLEAR" in simulated.stdout, simulated.stderr[-2000:]
    recorded = run([moose, "simulate", "--scenario", "paper_v5_tau3", "--duration", "0.5"], cwd=elsewhere)
    bag = re.search(r"^bag\s+(\S+)$", recorded.stdout, re.M)
    # 0.5 s after the obstacle appeared the car has not passed it: stopped_short, exit status 1, bag recorded
    assert recorded.returncode == 1 and "STOPPED_SHORT" in recorded.stdout and bag is not None, recorded.stderr[-2000:]
    info = run([moose, "bag", "info", bag.group(1)], cwd=elsewhere)
    assert info.returncode == 0 and "/perception/state" in info.stdout and "moose_msgs/msg/StateEstimate" in info.stdout

    # one node, started by its console script (as `ros2 run` would), announces itself and stops on SIGTERM
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    node = subprocess.Popen([str(venv / "bin" / "observer"), "--param", "scenario=paper_v5_tau3"], cwd=elsewhere,
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        read_until_started(node, "observer")
        node.send_signal(signal.SIGTERM)
        node.wait(timeout=20)
    finally:
        node.kill()
        node.wait()
