"""``python -m moose_ros.runtime``: print this environment's DDS discovery settings as shell ``export`` lines.

For ROS 2 tools (``ros2 topic echo``, ``ros2 bag record``) that should see a graph confined to this host:
``eval "$(python -m moose_ros.runtime)"`` gives them the range and, for rmw_cyclonedds, the loopback
binding of :mod:`moose_ros.runtime.discovery`.
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
