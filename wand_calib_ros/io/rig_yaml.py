"""The rig description ``cameras.yaml``.

```yaml
wand: {L1: 400.0, L2: 200.0}        # mm, |AB| = L1, |BC| = L2, A-B-C collinear
cameras:
  - {name: cam0, image_size: [640, 480], pixel_size_um: [5.6, 5.6],
     nominal_focal_mm: 1.8, max_view_angle_deg: 92.5, lens: fisheye,   # lens optional
     readout_ms: 0.0}                                                  # optional: fixed rolling-shutter readout
```
The ROS nodes read three optional keys per camera with :func:`load_camera_endpoints`:
``image_topic`` (default ``/<name>/image_raw``), ``points_topic`` (default ``wand_points`` next to
the image topic) and ``set_camera_info`` (the driver's service, default next to the image topic).
The core never sees them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.intrinsics_init import PROJECTIONS
from wand_calib_ros.core.rig import LENS_CLASSES, CameraSpec, RigSpec, WandSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.text import read_yaml

_REQUIRED = ("name", "image_size", "pixel_size_um", "nominal_focal_mm", "max_view_angle_deg")


def _number(path: Path, where: str, value: Any, *, positive: bool = True) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise FormatError(path, f"{where} must be a number, got {value!r}") from None
    if not math.isfinite(number) or (positive and number <= 0):
        raise FormatError(path, f"{where} must be a positive number, got {value!r}")
    return number


def _pair(path: Path, where: str, value: Any) -> tuple[float, float]:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise FormatError(path, f"{where} must be a list of two numbers, got {value!r}")
    return _number(path, where, value[0]), _number(path, where, value[1])


def parse_rig(data: Any, path: str | Path = "<rig>") -> RigSpec:
    """Validate a parsed ``cameras.yaml`` document.

    Raises:
        FormatError: naming the file and the offending key or camera.
    """
    path = Path(path)
    if not isinstance(data, dict):
        raise FormatError(path, "expected a mapping with keys 'wand' and 'cameras'")
    wand_data = data.get("wand")
    if not isinstance(wand_data, dict) or "L1" not in wand_data or "L2" not in wand_data:
        raise FormatError(path, "'wand' must be a mapping with L1 and L2 in mm, e.g. {L1: 400.0, L2: 200.0}")
    l1 = _number(path, "wand L1", wand_data["L1"], positive=False)
    l2 = _number(path, "wand L2", wand_data["L2"], positive=False)
    try:
        wand = WandSpec(l1, l2)
    except ModelError as error:
        raise FormatError(path, str(error)) from None
    cameras_data = data.get("cameras")
    if not isinstance(cameras_data, list) or not cameras_data:
        raise FormatError(path, "'cameras' must be a non-empty list")
    cameras = []
    for index, item in enumerate(cameras_data):
        if not isinstance(item, dict):
            raise FormatError(path, f"camera #{index + 1} must be a mapping")
        missing = [key for key in _REQUIRED if key not in item]
        label = f"camera '{item.get('name', f'#{index + 1}')}'"
        if missing:
            raise FormatError(path, f"{label} lacks {', '.join(missing)}")
        width, height = _pair(path, f"{label} image_size", item["image_size"])
        if width != int(width) or height != int(height):
            raise FormatError(path, f"{label} image_size must be whole pixels, got {item['image_size']!r}")
        angle = _number(path, f"{label} max_view_angle_deg", item["max_view_angle_deg"])
        if angle >= 180:
            raise FormatError(path, f"{label} max_view_angle_deg is half the field of view and must be < 180")
        lens = item.get("lens")
        if lens is not None and lens not in (*LENS_CLASSES, *PROJECTIONS):
            raise FormatError(path, f"{label} lens must be one of {[*LENS_CLASSES, *PROJECTIONS]}, got {lens!r}")
        readout = item.get("readout_ms")
        if readout is not None:
            readout = _number(path, f"{label} readout_ms", readout, positive=False)
            if readout < 0 or readout > 1000:
                raise FormatError(
                    path, f"{label} readout_ms is the rolling-shutter readout time of one image, 0 to 1000 ms; "
                    f"got {item['readout_ms']!r}"
                )  # fmt: skip
        cameras.append(
            CameraSpec(
                name=str(item["name"]),
                image_size=(int(width), int(height)),
                pixel_size_um=_pair(path, f"{label} pixel_size_um", item["pixel_size_um"]),
                nominal_focal_mm=_number(path, f"{label} nominal_focal_mm", item["nominal_focal_mm"]),
                max_view_angle_deg=angle,
                lens=lens,
                readout_ms=readout,
            )
        )
    names = [c.name for c in cameras]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise FormatError(path, f"camera names must be unique; repeated: {', '.join(duplicates)}")
    return RigSpec(wand, tuple(cameras))


def load_rig(path: str | Path) -> RigSpec:
    """Read and validate ``cameras.yaml``."""
    path = Path(path)
    return parse_rig(read_yaml(path), path)


def rig_to_dict(rig: RigSpec) -> dict[str, Any]:
    """The ``cameras.yaml`` document of a rig."""
    cameras = []
    for spec in rig.cameras:
        item: dict[str, Any] = {
            "name": spec.name,
            "image_size": list(spec.image_size),
            "pixel_size_um": [float(p) for p in spec.pixel_size_um],
            "nominal_focal_mm": float(spec.nominal_focal_mm),
            "max_view_angle_deg": float(spec.max_view_angle_deg),
        }
        if spec.lens is not None:
            item["lens"] = spec.lens
        if spec.readout_ms is not None:
            item["readout_ms"] = float(spec.readout_ms)
        cameras.append(item)
    return {"wand": {"L1": float(rig.wand.L1), "L2": float(rig.wand.L2)}, "cameras": cameras}


def save_rig(rig: RigSpec, path: str | Path) -> None:
    """Write ``cameras.yaml``."""
    Path(path).write_text(yaml.safe_dump(rig_to_dict(rig), sort_keys=False, default_flow_style=None))


@dataclass(frozen=True)
class CameraEndpoints:
    """Where a camera lives on ROS (absolute names).

    Attributes:
        image_topic: its images (sensor_msgs/Image).
        points_topic: its wand points from a detector node (geometry_msgs/PolygonStamped).
        set_camera_info: its driver's sensor_msgs/srv/SetCameraInfo service.
        frame_id: its tf frame (the drivers' ``header.frame_id``; default the camera's name).
    """

    image_topic: str
    points_topic: str
    set_camera_info: str
    frame_id: str


def _ros_name(path: Path, where: str, value: Any) -> str:
    if not isinstance(value, str) or not value.startswith("/") or value.endswith("/") or " " in value:
        raise FormatError(path, f"{where} must be an absolute ROS name such as /cam0/image_raw, got {value!r}")
    return value


def _frame_id(path: Path, name: str, value: Any) -> str:
    """A tf frame id: a non-empty name without spaces or a leading slash (tf2 refuses those)."""
    if not isinstance(value, str) or not value or value.startswith("/") or any(c.isspace() for c in value):
        raise FormatError(path, f"camera '{name}' frame_id must be a tf frame name such as cam0_optical, got {value!r}")
    return value


def load_camera_endpoints(path: str | Path) -> dict[str, CameraEndpoints]:
    """Per camera ROS topics and services of ``cameras.yaml`` (defaults where not given)."""
    path = Path(path)
    rig = load_rig(path)
    items = {str(item["name"]): item for item in read_yaml(path)["cameras"]}
    endpoints = {}
    for name in rig.camera_names:
        item = items[name]
        image = _ros_name(path, f"camera '{name}' image_topic", item.get("image_topic", f"/{name}/image_raw"))
        namespace = image.rsplit("/", 1)[0]
        endpoints[name] = CameraEndpoints(
            image,
            _ros_name(path, f"camera '{name}' points_topic", item.get("points_topic", f"{namespace}/wand_points")),
            _ros_name(
                path, f"camera '{name}' set_camera_info", item.get("set_camera_info", f"{namespace}/set_camera_info")
            ),
            _frame_id(path, name, item.get("frame_id", name)),
        )
    return endpoints
