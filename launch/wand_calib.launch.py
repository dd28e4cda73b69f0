"""Launch a wand calibration session: the collector (and its calibrator), optionally a detector per camera.

    ros2 launch wand_calib_ros wand_calib.launch.py params_file:=my_rig.params.yaml
    ros2 launch wand_calib_ros wand_calib.launch.py cameras_file:=cameras.yaml detectors:=all

Then wave the wand and call /calibrate. Which nodes start is decided by
``wand_calib_ros.nodes.launch_plan.plan`` (arguments listed there); this file only turns its
records into launch_ros Node actions.
"""

from __future__ import annotations

from pathlib import Path

from ament_index_python.packages import get_package_share_directory
from launch import LaunchContext, LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import Parameter

from wand_calib_ros.nodes.launch_plan import ARGUMENTS, plan

SHARE = Path(get_package_share_directory("wand_calib_ros"))
DEFAULTS = {
    "params_file": str(SHARE / "config" / "collector.params.yaml"),
    "detector_params_file": str(SHARE / "config" / "detector.params.yaml"),
}


def _nodes(context: LaunchContext) -> list[Node]:
    value = {name: LaunchConfiguration(name).perform(context) for name in ARGUMENTS}
    records = plan(
        value["params_file"],
        value["detector_params_file"],
        cameras_file=value["cameras_file"],
        output_dir=value["output_dir"],
        detectors=value["detectors"],
        namespace=value["namespace"],
        resolve=(SHARE,),
    )
    return [
        Node(
            package="wand_calib_ros",
            executable=record.executable,
            name=record.name,
            namespace=record.namespace,
            # After the files, the overrides twice: as a dictionary (launch_ros writes it for this node by
            # its full name, which beats the files' /**/<node> sections) and as "-p name:=value" (beats
            # their /** sections and reaches every node of the process: the collector's calibrator too).
            parameters=[
                *record.params_files,
                *([dict(record.overrides)] if record.overrides else []),
                *(Parameter(name, value) for name, value in record.overrides.items()),
            ],
            output="screen",
        )
        for record in records
    ]


def generate_launch_description() -> LaunchDescription:
    arguments = [
        DeclareLaunchArgument(name, default_value=DEFAULTS.get(name, ""), description=text)
        for name, text in ARGUMENTS.items()
    ]
    return LaunchDescription([*arguments, OpaqueFunction(function=_nodes)])
