"""ament_python package of the moose node graph; also pip-installable without ROS 2.

Without ROS 2 (Cyclone DDS backend), from anywhere, after the core (the repository's root)::

    pip install path/to/repository path/to/repository/ros2_ws/src/moose_ros

The ``.msg`` files of moose_msgs ship inside the package (``moose_ros/msg`` links to
``../moose_msgs/msg``, the single definition; wheels carry copies), so an installed wheel needs no
source tree.  With ROS 2, ``colcon build`` installs it like any ament_python package (colcon does not
install Python dependencies: the Docker image pip-installs both packages first).
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
    # the core (distribution "moose-avoidance", this repository's root: not on PyPI, install it with this one),
    # the DDS backend, the bag formats, the CAN bus (can_bridge), the replan figure and the Foxglove live view
    install_requires=["moose-avoidance", "cyclonedds>=0.10.5", "rosbags>=0.10", "mcap>=1.5", "numpy>=1.24",
                      "pyyaml>=6.0", "python-can>=4.3", "matplotlib>=3.7", "foxglove-sdk>=0.14"],
    extras_require={"parquet": ["pyarrow>=12"]},  # moose bag export --format parquet
    package_data={PACKAGE: ["msg/*.msg", "runtime/*.xml"]},  # the .msg files; the Fast DDS profile
    zip_safe=False,  # the .msg files are read from the installed package folder
    maintainer="moose-avoidance maintainers",
    maintainer_email="maintainers@moose-avoidance.invalid",
    description="Node graph of the moose-test collision avoidance",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [f"{node} = {PACKAGE}.nodes:{node}_main" for node in NODES],
        # plugins of the `moose` command (moose.cli.plugins)
        "moose.commands": [f"{command} = {PACKAGE}.cli.{command}:add_subparser"
                           for command in ("node", "launch", "bag")],
        "moose.recorders": [f"bag = {PACKAGE}.bag.record:record_simulation"],
    },
)
