"""A node of our Cyclone DDS runtime ends promptly although a process that read its topics was killed
(``moose_ros.runtime.dds.WRITER_LINGER``).

A reader in a killed process never acknowledges and stays matched until its lease expires; Cyclone DDS's default
makes deleting each reliable writer with unacknowledged data wait a whole second for it.  With the simulator killed
(the fault matrix), every other node of the lockstep graph lingered that second per writer it had sent to the
simulator and took 4–5.3 s to end after SIGTERM, past the launcher's 5 s grace: they were SIGKILLed.  Judged by the
wall clock, so in the serial ``realtime`` phase."""
from __future__ import annotations

import subprocess
import sys
import time

import pytest

from moose_ros.lockstep import QOS_DATA
from moose_ros.process import spawn
from moose_ros.runtime import create_node

pytestmark = [pytest.mark.graph, pytest.mark.realtime]

WRITERS = 10
"""Reliable writers whose reader is killed: at Cyclone's default they linger 10 s at shutdown."""
PROMPT = 5.0
"""Seconds within which the node must end: the launcher's grace when the fault was found (it is more generous now,
moose_ros.launch.STOP_GRACE, for starved machines; how promptly a node ends is this test's claim)."""
TYPE = "moose_msgs/msg/Tick"
READER = f"""
from moose_ros.lockstep import QOS_DATA
from moose_ros.runtime import create_node
node = create_node("linger_reader")
for k in range({WRITERS}):
    node.subscription("{TYPE}", f"/linger/t{{k}}", lambda msg: None, QOS_DATA)
print("ready", flush=True)
while True:
    node.spin_once(0.1)
"""


def test_a_node_whose_reader_was_killed_ends_promptly() -> None:
    node = create_node("linger_writer")
    pubs = [node.publisher(TYPE, f"/linger/t{k}", QOS_DATA) for k in range(WRITERS)]
    reader = spawn([sys.executable, "-c", READER], stdout=subprocess.PIPE, text=True)
    try:
        assert reader.stdout is not None and reader.stdout.readline().strip() == "ready"
        deadline = time.monotonic() + 60.0
        while any(pub.subscription_count() < 1 for pub in pubs) and time.monotonic() < deadline:
            node.spin_once(0.05)
        assert all(pub.subscription_count() >= 1 for pub in pubs)
    finally:
        reader.kill()
        reader.wait()
    for pub in pubs:  # sent to a reader that will never acknowledge them
        pub(node.make(TYPE, node="linger_writer", topics=[], expected=[]))
    started = time.monotonic()
    node.shutdown()
    took = time.monotonic() - started
    assert took < PROMPT, f"shutdown took {took:.1f} s with {WRITERS} writers to a killed reader"
