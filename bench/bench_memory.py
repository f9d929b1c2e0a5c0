"""Resident memory of each node of the graph and of the whole graph (issue target: graph total ≤ 350 MB).

Runs the ``can`` graph — all eight nodes, the simulator as the vehicle-ECU emulator behind the CAN
bridge over ``udp_multicast`` on loopback — through ``moose_ros.launch.launch`` on a short moose test
at real-time pace, and samples every node process every 0.1 s: its resident set size (RSS, ``VmRSS``
of ``/proc/PID/status``) and its proportional set size (PSS, ``/proc/PID/smaps_rollup``: pages shared
with other processes — libpython, NumPy, Cyclone DDS, CasADi — counted as a share).  RSS counts each
shared library once per process, so the sum of RSS overstates what the graph takes; the sum of PSS is
what it takes.  Prints, per node, the RSS once it announced itself, its peak RSS and PSS, and whether
CasADi was ever mapped into it; then both totals (the largest sum of simultaneous samples), the launcher's
own RSS (the monitor and recorder; not a node) and the load average (the figures are taken on a shared
machine).  The DDS domain is claimed with ``tests/isolation.py``.
Run: ``python bench/bench_memory.py``.
"""
from __future__ import annotations

import io
import os
import socket
import sys
import tempfile
import threading
import time
from pathlib import Path

from moose.scenario import load_scenario
from moose_ros.graph import GRAPHS
from moose_ros.launch import launch

TARGET_MB = 350.0
REPO = Path(__file__).resolve().parents[1]


def rss_mb(pid: int) -> float:
    """Resident set size (MB) of ``pid``; 0 when it is gone."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0.0
    for line in text.splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


def pss_mb(pid: int) -> float:
    """Proportional set size (MB) of ``pid``; 0 when it is gone."""
    try:
        text = Path(f"/proc/{pid}/smaps_rollup").read_text()
    except OSError:
        return 0.0
    for line in text.splitlines():
        if line.startswith("Pss:"):
            return int(line.split()[1]) / 1024
    return 0.0


def maps(pid: int, *needles: str) -> dict[str, bool]:
    """Which of ``needles`` appear in the memory map of ``pid`` (a loaded extension module or shared library)."""
    try:
        text = Path(f"/proc/{pid}/maps").read_text()
    except OSError:
        return {n: False for n in needles}
    return {n: n in text for n in needles}


def node_children() -> dict[str, int]:
    """Node name → pid of the processes below this one that run a node (``python -m moose_ros.nodes NAME``: exec'd,
    or forked by the run's fork server, which shows its children so)."""
    from moose_ros.process import descendants

    found: dict[str, int] = {}
    for pid in descendants(os.getpid()):
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"moose_ros.nodes" in argv:
            found[argv[argv.index(b"moose_ros.nodes") + 1].decode()] = pid
    return found


def main() -> None:
    sys.path.insert(0, str(REPO / "tests"))
    from isolation import claim_domain

    load = os.getloadavg()
    os.environ.setdefault("ROS_DOMAIN_ID", str(claim_domain()))
    if "CYCLONEDDS_URI" not in os.environ:
        config = Path(tempfile.mkdtemp()) / "cyclonedds.xml"
        config.write_text('<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface name="lo"/>'
                          "</Interfaces><AllowMulticast>spdp</AllowMulticast></General></Domain></CycloneDDS>")
        os.environ["CYCLONEDDS_URI"] = config.as_uri()
    os.environ.setdefault("MOOSE_RUNTIME", "dds")
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    group = f"239.74.{os.getpid() % 250}.{1 + os.getpid() % 199}"
    params = {"scenario": "paper_v5_tau3", "duration": 3.0, "can_interface": "udp_multicast", "can_channel": group,
              "can_port": port}
    result: dict = {}
    out = io.StringIO()
    runner = threading.Thread(target=lambda: result.update(
        launch(load_scenario("paper_v5_tau3"), params, graph="can", out=out)))
    runner.start()
    started: dict[str, float] = {}
    peak_rss: dict[str, float] = {}
    peak_pss: dict[str, float] = {}
    casadi: dict[str, bool] = {}
    total_rss = total_pss = 0.0
    while runner.is_alive():
        pids = node_children()
        log = out.getvalue()
        rss = {name: rss_mb(pid) for name, pid in pids.items()}
        pss = {name: pss_mb(pid) for name, pid in pids.items()}
        for name, pid in pids.items():
            peak_rss[name] = max(peak_rss.get(name, 0.0), rss[name])
            peak_pss[name] = max(peak_pss.get(name, 0.0), pss[name])
            if name not in started and f"{name} started" in log:
                started[name] = rss[name]
            # ever mapped: a process on its way out reads as mapping nothing
            casadi[name] = casadi.get(name, False) or maps(pid, "casadi")["casadi"]
        if len(pids) == len(GRAPHS["can"]) and all(rss.values()):
            total_rss, total_pss = max(total_rss, sum(rss.values())), max(total_pss, sum(pss.values()))
        time.sleep(0.1)
    print(f"graph 'can' (8 nodes), outcome collided={result.get('collided')}, node exits {result.get('node_exits')}")
    print(f"{'node':>18} {'started RSS':>12} {'peak RSS':>9} {'peak PSS':>9}  CasADi   (MB)")
    for name in GRAPHS["can"]:
        print(f"{name:>18} {started.get(name, float('nan')):12.1f} {peak_rss.get(name, float('nan')):9.1f} "
              f"{peak_pss.get(name, float('nan')):9.1f}  {'yes' if casadi.get(name) else 'no':>6}")
    for label, total in (("graph total RSS", total_rss), ("graph total PSS", total_pss)):
        verdict = "meets" if total <= TARGET_MB else "misses"
        print(f"{label:>18} {total:22.1f}  ({verdict} the {TARGET_MB:.0f} MB target)")
    print(f"{'launcher RSS':>18} {rss_mb(os.getpid()):22.1f}  (monitor + recorder, this process; not a node)")
    end = os.getloadavg()
    print(f"load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} at the start, {end[0]:.1f} at the end, "
          f"{os.cpu_count()} cores")


if __name__ == "__main__":
    main()
