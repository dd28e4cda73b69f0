"""ament_python / setuptools build of wand_calib_ros (colcon and plain pip)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "wand_calib_ros"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "benchmarks"]),
    package_data={"wand_calib_ros.nodes": ["*.xml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
    ],
    install_requires=["setuptools", "numpy", "scipy", "opencv-python-headless", "networkx", "PyYAML"],
    zip_safe=True,
    maintainer="wand_calib_ros developers",
    maintainer_email="dev@wand-calib.local",
    description="Multi-camera fisheye/conventional calibration with a three-LED wand (ROS 2).",
    license="Apache-2.0",
    python_requires=">=3.10",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            "wand-calib = wand_calib_ros.cli:main",
            "collector = wand_calib_ros.nodes.collector:main",
            "calibrator = wand_calib_ros.nodes.calibrator:main",
            "detector = wand_calib_ros.nodes.detector:main",
            "wand-calib-replay = wand_calib_ros.nodes.replay:main",
            "wand-calib-trigger = wand_calib_ros.nodes.trigger:main",
        ],
    },
)
