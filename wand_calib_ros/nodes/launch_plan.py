"""Which nodes ``launch/wand_calib.launch.py`` starts, as plain records (no launch or rclpy import).

The launch file only turns these records into ``launch_ros`` Node actions, so what a launch
starts is decided (and tested) here: the collector (with its in-process calibrator) and,
optionally, one detector node per camera in that camera's namespace, in which case the
collector subscribes to their points (``input: points``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from wand_calib_ros.io.rig_yaml import load_rig
from wand_calib_ros.io.text import read_yaml
from wand_calib_ros.nodes.params import SettingsError

#: Launch arguments and their meaning (defaults are filled in by the launch file).
ARGUMENTS = {
    "params_file": "parameters of the collector and its calibrator (default: the shipped collector.params.yaml)",
    "detector_params_file": "parameters of the detector nodes (default: the shipped detector.params.yaml)",
    "cameras_file": "rig description; overrides the params file's cameras_file when given",
    "output_dir": "where the buffer and the results go; overrides the params file's output_dir when given",
    "detectors": "cameras to start a detector node for: comma-separated names, 'all', or empty (none)",
    "namespace": "namespace of every node (two rigs side by side)",
}


@dataclass(frozen=True)
class NodeLaunch:
    """One node process of a launch.

    Attributes:
        executable: its ``ros2 run wand_calib_ros`` name.
        name: the node's name.
        namespace: the node's namespace ("" for the root).
        params_files: params files, in the order they apply.
        overrides: parameters that win over the files, for every node of the process (the
            collector's calibrator too); the launch file passes them both ways rcl needs.
    """

    executable: str
    name: str
    namespace: str = ""
    params_files: tuple[str, ...] = ()
    overrides: dict[str, str] = field(default_factory=dict)


def _rig_file(params_file: str, cameras_file: str) -> str:
    """The rig file the collector will read: the override, else the params file's ``cameras_file``."""
    if cameras_file:
        return cameras_file
    document = read_yaml(Path(params_file)) if params_file else {}
    for section in (document or {}).values():
        value = (section or {}).get("ros__parameters", {}).get("cameras_file") if isinstance(section, dict) else None
        if value:
            return str(value)
    raise SettingsError(f"launch argument detectors: no cameras_file in {params_file}; give cameras_file:=FILE")


def _cameras(detectors: str, rig_file: Path) -> list[str]:
    """The cameras named by the ``detectors`` argument, checked against the rig."""
    names = list(load_rig(rig_file).camera_names)
    if detectors.strip() == "all":
        return names
    wanted = [name.strip() for name in detectors.split(",") if name.strip()]
    unknown = [name for name in wanted if name not in names]
    if unknown:
        raise SettingsError(
            f"launch argument detectors: {', '.join(unknown)} not in {rig_file} (cameras: {', '.join(names)})"
        )
    return wanted


def plan(
    params_file: str,
    detector_params_file: str = "",
    *,
    cameras_file: str = "",
    output_dir: str = "",
    detectors: str = "",
    namespace: str = "",
    resolve: Sequence[Path] = (),
) -> list[NodeLaunch]:
    """The nodes of one launch of wand_calib_ros.

    Args:
        params_file: the collector's params file (sections ``/**`` and ``/**/<node>``).
        detector_params_file: the detectors' params file ("" for none).
        cameras_file: rig file overriding the params file's.
        output_dir: output folder overriding the params file's.
        detectors: "", "all" or comma-separated camera names (see :data:`ARGUMENTS`).
        namespace: namespace of all nodes.
        resolve: folders a relative rig path is also looked up in (the package's share), as the
            nodes do.

    Raises:
        SettingsError: a detector camera the rig does not have, or no rig file to check them against.
    """
    overrides: dict[str, str] = {}
    if cameras_file:
        overrides["cameras_file"] = cameras_file
    if output_dir:
        overrides["output_dir"] = output_dir
    cameras: list[str] = []
    rig_file = ""
    if detectors.strip():
        rig_file = _rig_file(params_file, cameras_file)  # the detectors read the collector's rig
        rig = Path(rig_file).expanduser()
        found = next((folder / rig for folder in resolve if not rig.is_file() and (folder / rig).is_file()), rig)
        cameras = _cameras(detectors, found)
    nodes = [
        NodeLaunch(
            "collector",
            "wand_calib_collector",
            namespace,
            (params_file,),
            {**overrides, **({"input": "points"} if cameras else {})},
        )
    ]
    for camera in cameras:
        nodes.append(
            NodeLaunch(
                "detector",
                "wand_calib_detector",
                f"{namespace.rstrip('/')}/{camera}" if namespace else camera,
                (detector_params_file,) if detector_params_file else (),
                {"cameras_file": rig_file, "camera": camera},
            )
        )
    return nodes
