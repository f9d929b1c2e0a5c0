"""CPU time to write and read a message with the compiled CDR of the DDS message classes (moose_ros.cdr) against
cyclonedds-python's own interpreter of the type, in the same run: ``python bench/bench_cdr.py [--repeat N]``."""
from __future__ import annotations

import argparse
import time
from typing import Any, Callable

from cyclonedds.idl import IdlStruct

from moose_ros.interfaces import message_class

TYPES = ("nav_msgs/msg/Odometry", "sensor_msgs/msg/Imu", "moose_msgs/msg/Tick", "moose_msgs/msg/StateEstimate")


def per_call(fn: Callable[[], Any], repeat: int) -> float:
    """CPU microseconds per call of ``fn``."""
    start = time.process_time()
    for _ in range(repeat):
        fn()
    return (time.process_time() - start) / repeat * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeat", type=int, default=3000)
    args = parser.parse_args()
    print(f"{'type':32s} {'write µs':>9s} {'(cyclonedds)':>12s} {'read µs':>8s} {'(cyclonedds)':>12s}")
    for type_name in TYPES:
        cls = message_class(type_name)
        msg = cls()
        data = bytes(msg.serialize())
        write = per_call(msg.serialize, args.repeat)
        write_slow = per_call(lambda m=msg: IdlStruct.serialize(m), args.repeat)
        read = per_call(lambda c=cls, d=data: c.deserialize(d), args.repeat)
        read_slow = per_call(lambda c=cls, d=data: IdlStruct.deserialize.__func__(c, d), args.repeat)
        print(f"{type_name:32s} {write:9.1f} {write_slow:12.1f} {read:8.1f} {read_slow:12.1f}"
              f"   ×{write_slow / write:.0f} / ×{read_slow / read:.0f}")


if __name__ == "__main__":
    main()
