"""``python -m moose_ros.runtime``: print this environment's DDS discovery settings as shell ``export`` lines.

For ROS 2 tools (``ros2 topic echo``, ``ros2 bag record``) and plain Cyclone DDS tools (``cyclonedds ls``,
cyclonedds-python) that should see a graph confined to this host: ``eval "$(python -m moose_ros.runtime)"`` gives
them the range and the Cyclone DDS settings of :mod:`moose_ros.runtime.discovery` (loopback, multicast off,
127.0.0.1 as a peer), which rmw_cyclonedds would add for the range but a plain Cyclone DDS participant would not.
"""
import shlex
import sys

from moose.params import ParamError

from .discovery import Discovery

try:
    ENV = Discovery.from_environ().ros_environment()
except ParamError as exc:
    print(f"moose: error: {exc}", file=sys.stderr)
    sys.exit(2)
for key, value in ENV.items():
    print(f"export {key}={shlex.quote(value)}")
