"""Node parameters declared with type, range and description, validated once at start-up.

A node lists its parameters as :class:`Param` records; :func:`declare` declares them
all (so ``ros2 param describe`` shows the ranges and choices) and turns a wrong type,
a value out of range or a missing required value into one :class:`SettingsError` that
names the parameter and what to write instead.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.node import Node
from rclpy.parameter import Parameter as RclpyParameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from wand_calib_ros.collection.coverage import CoverageThresholds
from wand_calib_ros.errors import WandCalibError

_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
}


class SettingsError(WandCalibError):
    """A node parameter that cannot be used; the message names it and the node (its params-file section).

    Attributes:
        node: the node's name (its log lines are its own).
    """

    def __init__(self, message: str, node: str = "") -> None:
        super().__init__(message)
        self.node = node


#: A parameter's type as a sentence says it.
_KINDS = {bool: "true or false", int: "an integer", float: "a number with a decimal point", str: "a string"}


@dataclass(frozen=True)
class Param:
    """One node parameter.

    Attributes:
        name: parameter name.
        default: default value; its Python type is the parameter's type.
        description: what it does, with units.
        low: smallest allowed value (numbers).
        high: largest allowed value (numbers).
        choices: allowed values (strings).
        required: an empty string is not accepted.
    """

    name: str
    default: bool | int | float | str
    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    required: bool = False

    def descriptor(self) -> ParameterDescriptor:
        descriptor = ParameterDescriptor(
            description=self.description,
            type=_TYPES[type(self.default)],
        )
        if isinstance(self.default, float) and self.low is not None and self.high is not None:
            descriptor.floating_point_range = [FloatingPointRange(from_value=self.low, to_value=self.high, step=0.0)]
        elif type(self.default) is int and self.low is not None and self.high is not None:
            descriptor.integer_range = [IntegerRange(from_value=int(self.low), to_value=int(self.high), step=1)]
        if self.choices:
            descriptor.additional_constraints = "one of: " + ", ".join(self.choices)
        elif self.required:
            descriptor.additional_constraints = "required"
        return descriptor


def declare(node: Node, params: Iterable[Param], fallback: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Declare ``params`` on ``node`` and return their validated values by name. They are read once, at
    start-up: a later ``ros2 param set`` is refused with the reason (a restart applies a new value).

    Args:
        node: the node.
        params: its parameters.
        fallback: values for the parameters its own settings leave at their defaults (an in-process
            calibrator takes the collector's ``cameras_file``, ``output_dir``, ...).

    Raises:
        SettingsError: naming the node, the first unusable parameter and what it accepts.
    """
    values: dict[str, Any] = {}
    where = f"{node.get_name()}'s parameter"
    declared = list(params)
    for param in declared:
        try:
            value = node.declare_parameter(param.name, param.default, param.descriptor()).value
        except InvalidParameterTypeException:
            hint = " (write 5.0, not 5)" if isinstance(param.default, float) else ""
            kind = _KINDS[type(param.default)]
            raise SettingsError(
                f"{where} {param.name} must be {kind}{hint}: {param.description}", node.get_name()
            ) from None
        except InvalidParameterValueException:
            raise SettingsError(
                f"{where} {param.name} must lie in [{param.low}, {param.high}]: {param.description}", node.get_name()
            ) from None
        if fallback is not None and param.name in fallback and value == param.default:
            value = fallback[param.name]
        if param.choices and value not in param.choices:
            raise SettingsError(
                f"{where} {param.name} must be one of {', '.join(param.choices)}, got {value!r}", node.get_name()
            )
        if param.required and value == "":
            raise SettingsError(
                f"{where} {param.name} is required (in its section {node.get_name()}: of the params file, or "
                f"-p {param.name}:=...): {param.description}",
                node.get_name(),
            )
        values[param.name] = value
    names = {param.name for param in declared}
    node.add_on_set_parameters_callback(functools.partial(_read_at_start, names))
    return values


def _read_at_start(names: set[str], parameters: list[RclpyParameter]) -> SetParametersResult:
    """Refuse a change of a start-up parameter, saying what applies one."""
    changed = [p.name for p in parameters if p.name in names]
    if not changed:
        return SetParametersResult(successful=True)
    return SetParametersResult(
        successful=False,
        reason=f"{', '.join(changed)} is read-only: read at start-up; restart the node with the new value "
        "(-p NAME:=VALUE or its params file) to apply it",
    )


def package_share() -> Path | None:
    """This package's installed share directory (colcon or pip install), None when not installed."""
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    except ImportError:  # pragma: no cover - rclpy's wheels bring ament_index_python
        return None
    try:
        return Path(get_package_share_directory("wand_calib_ros"))
    except (PackageNotFoundError, ValueError):  # ValueError: AMENT_PREFIX_PATH unset
        return None


def existing_file(values: dict[str, Any], name: str) -> Path:
    """The file a parameter names (SettingsError when it does not exist).

    A relative path is read from the working directory or, failing that, from the package's share
    directory, so the shipped params files (``cameras_file: config/...``) work from any directory
    once the package is installed.
    """
    path = Path(values[name]).expanduser()
    if path.is_file():
        return path
    share = package_share() if not path.is_absolute() else None
    if share is not None and (share / path).is_file():
        return share / path
    where = f" (nor in {share})" if share is not None and not path.is_absolute() else ""
    raise SettingsError(f"parameter {name}: no such file {path}{where}")


def usage(executable: str, summary: str | None, *groups: tuple[str, Sequence[Param]]) -> str:
    """The ``--help`` text of a node executable: what it does and every parameter it reads.

    Args:
        executable: the ``ros2 run wand_calib_ros`` name.
        summary: the node module's docstring (its first paragraph is used).
        groups: (node name, its parameters) for each node the executable starts.
    """
    first = (summary or "").strip().split("\n\n")[0]
    lines = [
        f"usage: ros2 run wand_calib_ros {executable} --ros-args [-p NAME:=VALUE ...] [--params-file FILE]",
        "",
        " ".join(first.split()),
    ]
    shown: set[str] = set()
    for node, params in groups:
        shared = [param.name for param in params if param.name in shown]
        lines += ["", f"parameters of {node}" + (f" (also {', '.join(shared)}, above):" if shared else ":")]
        for param in params:
            if param.name in shown:
                continue
            shown.add(param.name)
            kind = type(param.default).__name__
            number = int if kind == "int" else float
            limits = (
                f", one of {'|'.join(param.choices)}"
                if param.choices
                else f", {number(param.low)}..{number(param.high)}"
                if param.low is not None and param.high is not None
                else ""
            )
            default = "required" if param.required else f"default {param.default!r}"
            lines.append(f"  {param.name} ({kind}, {default}{limits})")
            lines.append(f"      {param.description}")
    return "\n".join(lines)


#: Parameters every wand_calib node reads.
RIG = (
    Param("cameras_file", "", "rig description: wand lengths and cameras (cameras.yaml contract)", required=True),
    Param("output_dir", "wand_calib_output", "observations.csv, result.yaml, camera_info/ and report/ go here"),
)

#: What "ready to calibrate" means (the collector reports it, /calibrate requires it).
COVERAGE = (
    Param("min_placements", 100, "complete wand views each camera needs", 1, 10**7),
    Param("min_pair_placements", 15, "placements two cameras must share to link them", 1, 10**7),
    Param("min_image_fraction", 0.25, "share of each image (8 x 8 grid) the wand must reach", 0.0, 1.0),
    Param("min_theta_fraction", 0.4, "widest off-axis angle reached over what the image offers", 0.0, 1.0),
    Param("min_directions", 4, "of 6 30-degree sectors, how many the wand's image direction must reach", 0, 6),
    Param("min_depth_ratio", 1.2, "90th/10th percentile of the wand's image length (near and far)", 1.0, 100.0),
)

#: How a node subscribes to images.
IMAGE_QOS = Param(
    "image_qos",
    "sensor_data",
    "image subscription QoS (reliable: every image is queued until processed, for bag replay)",
    choices=("sensor_data", "reliable"),
)


#: Results (final and preliminary) stay available to late subscribers, as tf2's static broadcaster does.
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


def image_qos(choice: str) -> QoSProfile:
    """The QoS an ``image_qos`` choice names.

    ``reliable`` keeps all: a subscriber that falls behind a burst (a bag replayed faster
    than detection runs) queues the images instead of overwriting the oldest, as a
    keep-last history does once it is full.
    """
    if choice == "sensor_data":
        return qos_profile_sensor_data
    return QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE)


#: How long the labeller may hold an A/C-ambiguous view back.
LABEL_HOLD = Param(
    "label_hold_ms", 1000.0, "how long an A/C-ambiguous view may wait for a later one to settle it (ms)", 0.0, 60000.0
)


def coverage_thresholds(values: dict[str, Any]) -> CoverageThresholds:
    """:class:`CoverageThresholds` from the :data:`COVERAGE` parameters."""
    return CoverageThresholds(
        min_placements=values["min_placements"],
        min_image_fraction=values["min_image_fraction"],
        min_theta_fraction=values["min_theta_fraction"],
        min_pair_placements=values["min_pair_placements"],
        min_directions=values["min_directions"],
        min_depth_ratio=values["min_depth_ratio"],
    )
