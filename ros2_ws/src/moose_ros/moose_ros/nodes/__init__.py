"""The node graph (paper Fig. 3): one node per ECU function, thin shells around the core's blocks.

One module per node (``simulator``, ``observer``, ``detector``, ``planner``, ``weight_fbl``,
``motion``, ``can_bridge``; :mod:`.base` holds what they share).  A node's module is imported only
when that node starts (:data:`moose_ros.graph.NODES` names it), so each process loads only what its
job needs: the CAN bridge and the motion controller never load CasADi or the planners (under ``moose launch``
the nodes are forked from a server that loaded what the whole graph needs once: :mod:`moose_ros.forkserver`).

Run one with ``moose node NAME [--params FILE] [--param key=value ...]``, ``python -m
moose_ros.nodes NAME …`` or, on ROS 2, ``ros2 run moose_ros NAME`` (the console script
``NAME`` is ``moose_ros.nodes:NAME_main``).  Topics, rates and QoS: :mod:`moose_ros.graph`.
"""
from __future__ import annotations

import argparse
import faulthandler
import gc
import importlib
import os
import signal
import sys
import threading
from typing import Any, Callable, NoReturn, Sequence

from moose.exiting import end_process
from moose.params import ParamError

from ..graph import NODES
from ..process import exit_later, watch_parent


def node_class(name: str) -> Callable[[Any], Any]:
    """The class of node ``name`` (imports its module)."""
    if name not in NODES:
        raise ParamError(f"node {name!r} is unknown; nodes: {', '.join(sorted(NODES))}")
    module, cls = NODES[name].implementation.split(":")
    return getattr(importlib.import_module(f"{__name__}.{module}"), cls)


def parse_overrides(items: Sequence[str]) -> dict[str, Any]:
    """``key=value`` pairs (values parsed as YAML) → parameter overrides."""
    import yaml

    out: dict[str, Any] = {}
    for item in items:
        if "=" not in item:
            raise ParamError(f"--param {item!r} is invalid: expected key=value")
        key, value = item.split("=", 1)
        out[key.strip()] = yaml.safe_load(value)
    return out


STACK_DUMP = signal.SIGUSR1
"""The signal on which a node writes the Python stack of every thread to its output (:mod:`faulthandler`) and
runs on: the launcher sends it to a node that did not end within its grace after SIGTERM, before SIGKILL, so
that the run's log shows where it hung."""


def run(name: str, argv: Sequence[str] = ()) -> int:
    """Start node ``name`` and spin it until shutdown; returns the exit status."""
    from ..parameters import check_parameter_file
    from ..runtime import backend, create_node
    from ..runtime.dds import DdsNode

    parser = argparse.ArgumentParser(prog=f"moose node {name}", epilog="On rclpy, --ros-args and what follows are "
                                     "ROS 2's (ros2 run and ros2 launch pass remappings and parameters so).")
    parser.add_argument("--params", help="ROS 2 parameter file")
    parser.add_argument("--param", action="append", default=[], help="parameter override key=value")
    argv = list(argv)
    ros_args = argv[argv.index("--ros-args"):] if "--ros-args" in argv else []
    args = parser.parse_args(argv[:len(argv) - len(ros_args)])  # a misspelt option is an error, not ignored
    if ros_args and backend() != "rclpy":  # rcl reads them (rclpy.init); on Cyclone they would be ignored
        raise ParamError(f"{' '.join(ros_args)}: --ros-args are read by rclpy only, and this node would run on "
                         "Cyclone DDS (MOOSE_RUNTIME=dds, or no rclpy here); use --params FILE and --param key=value")
    cls = node_class(name)
    if args.params:
        check_parameter_file(args.params)
    rt = create_node(name, args.params, parse_overrides(args.param))
    if isinstance(rt, DdsNode):
        rt.release_limit = RELEASE_LIMIT
    node = None

    def terminate(*_: Any) -> None:  # SIGTERM: the end of a run, or the launcher is gone — a normal end, status 0
        if node is None:
            raise SystemExit(0)
        node.message = "stopped"
        try:
            node.publish_diagnostics()  # the final counters reach the launcher
        except Exception:  # noqa: BLE001 - the node is going anyway
            pass
        _teardown_watchdog(name)
        rt.shutdown()

    signal.signal(signal.SIGTERM, terminate)
    faulthandler.register(STACK_DUMP, all_threads=True)  # the launcher's last look at a node that hangs
    watch_parent(_parent_gone)
    try:
        node = cls(rt)
    except BaseException:  # refused to start (ParamError: the CAN bridge without its bus): leave the domain
        rt.shutdown()
        raise
    # what the node built to start (modules, message classes, compiled functions, the core's tables) lives as long as
    # the process: out of the collector's sight, a full collection scans only what the ticks allocate (the lockstep
    # full graph took about 11 % less CPU, docs/testing.md)
    gc.freeze()
    node.publish_diagnostics()  # announce: the simulator starts the clock when every node has
    rt.log_info(f"{name} started (DDS discovery {rt.describe_discovery()})")
    try:
        rt.spin()
    except KeyboardInterrupt:
        pass
    finally:
        node.message = "stopped"
        node.close()
        _teardown_watchdog(name)
        rt.shutdown()
    return 0


TEARDOWN_GRACE = 10.0
"""Seconds a node may take to end once it is stopping (SIGTERM after its last status, or its spin over): rclpy's
``destroy_node`` hung in Fast DDS's participant deletion in about one launch of twenty (ros2/rclpy#456 and
ros2/build_cop#248 are of its kind), so a node that ended normally was killed at the launcher's grace
(``moose_ros.launch.STOP_GRACE``, longer) and the run counted as degraded."""
RELEASE_LIMIT = 2.0
"""Seconds a node on Cyclone DDS gives its participant's deletion, the last step of its teardown
(:attr:`moose_ros.runtime.dds.DdsNode.release_limit`: Cyclone DDS 11 can wait for it for ever), before it ends with
status 0 and a line saying so; it takes 0.1-0.3 s here, and the teardown's watchdog (:data:`TEARDOWN_GRACE`) bounds
the rest."""
TEARDOWN_DUMP = 0.5
"""Seconds between the stacks of a hung teardown and the end of the process (time to write them)."""
_stopping: list[threading.Timer] = []


def _teardown_watchdog(name: str) -> None:
    """Exit with status 0 if the process has not ended within :data:`TEARDOWN_GRACE` seconds (armed once, at the
    first call): the node's work is done and its last status sent; the run's log gets every thread's stack, so a
    hang in the teardown is visible, not hidden.

    rclpy's ``destroy_node`` holds the interpreter's lock while it waits in the middleware (no Python thread runs
    then), so the stacks come from :mod:`faulthandler`'s own thread and the exit from a POSIX timer
    (:func:`moose_ros.process.exit_later`), neither of which needs the lock; a Python timer adds a line saying what
    happened, when the lock is free to write it."""
    if _stopping:
        return

    def explain() -> None:
        print(f"{name}: the middleware's teardown did not end within {TEARDOWN_GRACE:g} s (stacks follow): exiting",
              file=sys.stderr, flush=True)

    timer = threading.Timer(TEARDOWN_GRACE, explain)
    timer.daemon = True
    timer.start()
    _stopping.append(timer)
    faulthandler.dump_traceback_later(TEARDOWN_GRACE + TEARDOWN_DUMP / 5, exit=False, file=sys.stderr)
    exit_later(TEARDOWN_GRACE + TEARDOWN_DUMP, 0)


PARENT_GRACE = 3.0
"""Seconds a node whose launcher is gone has to shut down before it exits hard."""


def _parent_gone() -> None:
    """The process that started this node is gone (:func:`moose_ros.process.watch_parent`): stop as on SIGTERM,
    and exit hard if that does not end the process within :data:`PARENT_GRACE`."""
    print("the process that started this node is gone: shutting down", file=sys.stderr, flush=True)
    exit_later(PARENT_GRACE, 1)
    os.kill(os.getpid(), signal.SIGTERM)


def main(name: str, argv: Sequence[str]) -> NoReturn:
    """Run node ``name`` as a program: exit status 0, or 2 with ``NAME: error: …`` for bad input.  The process ends
    without the interpreter's teardown (:func:`moose.exiting.end_process`: the exit handlers run, coverage.py's
    among them): the node has deleted its DDS participant (announced itself gone) and sent its last status, and what
    the teardown would add is Cyclone DDS's deletion of the process's domain, which hung in about one launch of ten
    until :data:`TEARDOWN_GRACE` ended the process (docs/testing.md)."""
    try:
        status = run(name, argv)
    except ParamError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        status = 2
    end_process(status)


def __getattr__(attr: str) -> Callable[[], None]:
    """``NAME_main``: the console script of node ``NAME`` (``setup.py``'s entry points)."""
    name = attr[:-len("_main")] if attr.endswith("_main") else ""
    if name in NODES:
        return lambda: main(name, sys.argv[1:])
    raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")
