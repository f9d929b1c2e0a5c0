"""ament_python package of the moose node graph; also pip-installable without ROS 2.

Without ROS 2 (Cyclone DDS backend), from the repository root::

    pip install -e . && pip install -e ros2_ws/src/moose_ros

The DDS message types are generated at import from ``ros2_ws/src/moose_msgs/msg`` (found next to
this package in the source tree, through the ament index, or at ``$MOOSE_MSG_DIR``), so the install
must be editable or ``MOOSE_MSG_DIR`` set.  With ROS 2, ``colcon build`` installs it like any
ament_python package (colcon does not install Python dependencies: the Docker image pip-installs
the core first).
"""
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "moose_ros"
NODES = [
    "vehicle_simulator", "observer", "obstacle_detector", "mpc_planner", "msf_planner", "weight_fbl",
    "motion_controller", "can_bridge",
]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(include=[PACKAGE, f"{PACKAGE}.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    python_requires=">=3.10",
    # the core (distribution "moose-avoidance", this repository's root: not on PyPI, install it first),
    # the DDS backend and the message definitions' parser
    install_requires=["setuptools", "moose-avoidance", "cyclonedds>=0.10.5", "rosbags>=0.10", "numpy", "pyyaml"],
    zip_safe=True,
    maintainer="moose-avoidance maintainers",
    maintainer_email="maintainers@moose-avoidance.invalid",
    description="Node graph of the moose-test collision avoidance",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [f"{node} = {PACKAGE}.nodes:{node}_main" for node in NODES],
        # plugins of the `moose` command (moose.cli.plugins)
        "moose.commands": [f"{command} = {PACKAGE}.cli.{command}:add_subparser" for command in ("node", "launch", "bag")],
        "moose.recorders": [f"bag = {PACKAGE}.bag.record:record_simulation"],
    },
)
