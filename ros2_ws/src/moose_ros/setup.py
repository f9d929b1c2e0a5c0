"""ament_python package of the moose node graph; also pip-installable without ROS 2."""
from glob import glob

from setuptools import setup

PACKAGE = "moose_ros"
NODES = [
    "observer", "obstacle_detector", "mpc_planner", "msf_planner",
    "weight_fbl", "motion_controller", "vehicle_simulator", "can_bridge",
]

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=[PACKAGE],
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="moose-avoidance maintainers",
    maintainer_email="maintainers@moose-avoidance.invalid",
    description="Node graph of the moose-test collision avoidance",
    license="Apache-2.0",
    entry_points={"console_scripts": [f"{node} = {PACKAGE}.nodes:{node}_main" for node in NODES]},
)
