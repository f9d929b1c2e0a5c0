"""moose.exiting.end_process: the exit handlers run and the streams are flushed, the interpreter's teardown does
not run, and the status is the one given."""
from __future__ import annotations

import subprocess
import sys

PROGRAM = """
import atexit, os, sys
from moose.exiting import end_process

class Held:
    def __del__(self):
        print("teardown ran", flush=True)

held = Held()  # a module global: deleted at the interpreter's teardown
atexit.register(lambda: os.write(2, b"exit handler ran\\n"))  # beside the streams' buffers
sys.stdout.write("unflushed output")
end_process(7)
print("after end_process")
"""


def test_end_process_runs_the_exit_handlers_flushes_and_skips_the_teardown() -> None:
    done = subprocess.run([sys.executable, "-c", PROGRAM], capture_output=True, text=True, timeout=60)
    assert done.returncode == 7, done.stderr
    assert done.stdout == "unflushed output", done.stdout  # no "teardown ran", nothing after end_process
    assert "exit handler ran\n" in done.stderr, done.stderr
