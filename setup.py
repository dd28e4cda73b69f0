"""ament_python / setuptools build of wand_calib_ros (colcon and plain pip)."""

import sys
from glob import glob

from setuptools import find_packages, setup

PACKAGE = "wand_calib_ros"

#: The nodes' entry points by their ``ros2 run wand_calib_ros <name>`` names.
NODES = {
    "collector": "wand_calib_ros.nodes.collector:main",
    "calibrator": "wand_calib_ros.nodes.calibrator:main",
    "detector": "wand_calib_ros.nodes.detector:main",
    "replay": "wand_calib_ros.nodes.replay:main",
    "trigger": "wand_calib_ros.nodes.trigger:main",
}


def console_scripts() -> list[str]:
    """The node executables: plain names in colcon's ``lib/wand_calib_ros`` (what ``ros2 run`` looks for;
    setup.cfg sends ``install``/``develop`` scripts there), ``wand-calib-<name>`` when pip puts them on a
    user's PATH (a wheel), so no generic ``collector`` lands in ``bin/``."""
    ros_layout = any(command in sys.argv[1:] for command in ("install", "develop"))
    prefix = "" if ros_layout else "wand-calib-"
    return ["wand-calib = wand_calib_ros.cli:main", *(f"{prefix}{name} = {target}" for name, target in NODES.items())]


setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks"]),
    package_data={"wand_calib_ros.nodes": ["*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools", "numpy", "scipy", "opencv-python-headless", "networkx", "PyYAML"],
    zip_safe=True,
    maintainer="wand_calib_ros developers",
    maintainer_email="dev@wand-calib.local",
    description="Multi-camera fisheye/conventional calibration with a three-LED wand (ROS 2).",
    license="Apache-2.0",
    python_requires=">=3.10",
    tests_require=["pytest"],
    entry_points={"console_scripts": console_scripts()},
)
