"""The rig description ``cameras.yaml``.

```yaml
wand: {L1: 400.0, L2: 200.0}        # mm, |AB| = L1, |BC| = L2, A-B-C collinear
cameras:
  - {name: cam0, image_size: [640, 480], pixel_size_um: [5.6, 5.6],
     nominal_focal_mm: 1.8, max_view_angle_deg: 92.5, lens: fisheye,   # lens optional
     camera_model: equidistant,                                        # optional: or plumb_bob, rational_polynomial
     readout_ms: 0.0,                                                  # optional: fixed rolling-shutter readout
     intrinsics: {K: [fx, 0, cx, 0, fy, cy, 0, 0, 1], D: [d1, d2, d3, d4],   # optional: known intrinsics
                  distortion_model: equidistant, fixed: true}}       # (or {camera_info: file.yaml}, or file.yaml)
```
The ROS nodes read three optional keys per camera with :func:`load_camera_endpoints`:
``image_topic`` (default ``/<name>/image_raw``), ``points_topic`` (default ``wand_points`` next to
the image topic) and ``set_camera_info`` (the driver's service, default next to the image topic).
The detector reads an optional ``mask`` per camera with :func:`load_camera_masks`: the pixels it
ignores, a PNG (named relative to the rig file, white where ignored) or
``{circles: [[u, v, r], ...], rectangles: [[u0, v0, u1, v1], ...], file: mask.png}``.
The core never sees them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.initialise.intrinsics_init import FISHEYE_PROJECTIONS, PROJECTIONS
from wand_calib_ros.core.model.camera_model import CAMERA_MODELS, EQUIDISTANT, CameraModel, to_opencv
from wand_calib_ros.core.model.known_intrinsics import known_model
from wand_calib_ros.core.model.rig import LENS_CLASSES, CameraSpec, RigSpec, WandSpec
from wand_calib_ros.io.errors import FormatError
from wand_calib_ros.io.outputs import write_text
from wand_calib_ros.io.text import read_yaml

_REQUIRED = ("name", "image_size", "pixel_size_um", "nominal_focal_mm", "max_view_angle_deg")


def _number(path: Path, where: str, value: Any, *, positive: bool = True) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise FormatError(path, f"{where} must be a number, got {value!r}") from None
    if not math.isfinite(number) or (positive and number <= 0):
        kind = "a positive number" if positive else "a finite number"
        raise FormatError(path, f"{where} must be {kind}, got {value!r}")
    return number


def _pair(path: Path, where: str, value: Any) -> tuple[float, float]:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise FormatError(path, f"{where} must be a list of two numbers, got {value!r}")
    return _number(path, where, value[0]), _number(path, where, value[1])


def _matrix(path: Path, where: str, value: Any, size: int) -> list[float]:
    """``size`` numbers from a flat or nested list (a 3x3 K may be written either way)."""
    flat = [v for row in value for v in (row if isinstance(row, list) else [row])] if isinstance(value, list) else None
    if flat is None or len(flat) != size:
        raise FormatError(path, f"{where} must be a list of {size} numbers, got {value!r}")
    return [_number(path, where, v, positive=False) for v in flat]


def _beside(path: Path, name: str) -> Path:
    """A file the rig file names: absolute (``~`` expanded) or relative to the rig file's folder."""
    file = Path(name).expanduser()
    return file if file.is_absolute() else path.parent / file


def _camera_info_intrinsics(path: Path, label: str, file: Any) -> dict[str, Any]:
    """K, D, distortion model and image size of a ROS camera_info YAML named relative to ``path``."""
    if not isinstance(file, str) or not file:
        raise FormatError(path, f"{label} intrinsics camera_info must be a file name, got {file!r}")
    info_path = _beside(path, file)
    if not info_path.is_file():
        raise FormatError(path, f"{label} intrinsics: no such camera_info file {info_path}")
    info = read_yaml(info_path)
    try:
        given = {
            "K": info["camera_matrix"]["data"],
            "D": info["distortion_coefficients"]["data"],
            "distortion_model": info.get("distortion_model", "plumb_bob"),
            "image_size": [info["image_width"], info["image_height"]],
        }
    except (KeyError, TypeError):
        raise FormatError(
            info_path, "not a ROS camera_info YAML: needs image_width, image_height, camera_matrix.data, "
            "distortion_coefficients.data"
        ) from None  # fmt: skip
    _matrix(info_path, "camera_matrix data", given["K"], 9)  # its own faults named in its own file
    if not isinstance(given["D"], list):
        raise FormatError(info_path, f"distortion_coefficients data must be a list of numbers, got {given['D']!r}")
    for value in given["D"]:
        _number(info_path, "distortion_coefficients data", value, positive=False)
    _pair(info_path, "image_width, image_height", given["image_size"])
    return given


def _intrinsics(
    path: Path, label: str, value: Any, m: Any, image_size: tuple[int, int], camera_model: str | None
) -> tuple[CameraModel | None, bool]:
    """A camera's known intrinsics (``intrinsics`` key, in ``camera_model`` if the camera names one) and
    whether they are held fixed."""
    if value is None:
        return None, True
    if isinstance(value, str):
        value = {"camera_info": value}
    if not isinstance(value, dict):
        raise FormatError(path, f"{label} intrinsics must be a mapping ({{K: ..., D: ...}}) or a camera_info file")
    fixed = value.get("fixed", True)
    if not isinstance(fixed, bool):
        raise FormatError(path, f"{label} intrinsics fixed must be true or false, got {fixed!r}")
    given = dict(value)
    if "camera_info" in value:
        given |= _camera_info_intrinsics(path, label, value["camera_info"])
        if tuple(int(v) for v in given["image_size"]) != image_size:
            raise FormatError(
                path, f"{label} intrinsics: {value['camera_info']} is for {given['image_size'][0]}x"
                f"{given['image_size'][1]} images, the camera's image_size is {image_size[0]}x{image_size[1]}"
            )  # fmt: skip
    for key in ("K", "D"):
        if key not in given:
            raise FormatError(path, f"{label} intrinsics lacks {key} (or give camera_info: file.yaml)")
    model_name = str(given.get("distortion_model", "equidistant"))
    K = np.array(_matrix(path, f"{label} intrinsics K", given["K"], 9)).reshape(3, 3)
    D = given["D"] if isinstance(given["D"], list) else None
    if D is None:
        raise FormatError(path, f"{label} intrinsics D must be a list of numbers, got {given['D']!r}")
    D_values = np.array([_number(path, f"{label} intrinsics D", v, positive=False) for v in D])
    inside = (K[:2, 2] >= -0.5) & (K[:2, 2] <= np.asarray(image_size) - 0.5)
    if not inside.all():
        raise FormatError(
            path, f"{label} intrinsics: the principal point ({K[0, 2]:g}, {K[1, 2]:g}) is outside its "
            f"{image_size[0]} x {image_size[1]} image: is K this camera's, for this image size?"
        )  # fmt: skip
    try:
        model = known_model(model_name, K, D_values, np.asarray(m), image_size, name=label, camera_model=camera_model)
    except ModelError as error:
        raise FormatError(path, f"intrinsics: {error}") from None
    return model, fixed


def _camera_model(path: Path, label: str, value: Any, lens: str | None, angle: float) -> str | None:
    """The ``camera_model`` key: one of CAMERA_MODELS; a pinhole model only for a lens that can be one."""
    if value is None:
        return None
    if value not in CAMERA_MODELS:
        raise FormatError(path, f"{label} camera_model must be one of {list(CAMERA_MODELS)}, got {value!r}")
    if value != EQUIDISTANT and (lens == "fisheye" or lens in FISHEYE_PROJECTIONS or angle >= 90):
        raise FormatError(
            path, f"{label} camera_model {value} is a pinhole model, which images no ray at 90 deg or more: "
            f"not for a fisheye lens (lens {lens}, max_view_angle_deg {angle:g}); use equidistant"
        )  # fmt: skip
    return str(value)


def _wand(path: Path, wand_data: Any) -> WandSpec:
    """The ``wand`` entry: {L1, L2} (the three-LED wand) or {points_mm: [0, ...]} (any 2 to 8 markers)."""
    usage = "'wand' must be a mapping with L1 and L2 in mm, e.g. {L1: 400.0, L2: 200.0}, or points_mm: [0, 400, 600]"
    if not isinstance(wand_data, dict):
        raise FormatError(path, usage)
    if "points_mm" in wand_data and ("L1" in wand_data or "L2" in wand_data):
        raise FormatError(path, "wand: give L1 and L2 or points_mm, not both (they may disagree)")
    try:
        if "points_mm" in wand_data:
            points = wand_data["points_mm"]
            if not isinstance(points, list):
                raise FormatError(path, f"wand points_mm must be a list of positions in mm, got {points!r}")
            return WandSpec(tuple(_number(path, "wand points_mm", p, positive=False) for p in points))
        if "L1" not in wand_data or "L2" not in wand_data:
            raise FormatError(path, usage)
        l1 = _number(path, "wand L1", wand_data["L1"], positive=False)
        l2 = _number(path, "wand L2", wand_data["L2"], positive=False)
        return WandSpec.from_lengths(l1, l2)
    except ModelError as error:
        raise FormatError(path, str(error)) from None


def wand_dict(wand: WandSpec) -> dict[str, Any]:
    """The ``wand`` entry of a rig or result file: L1 and L2 for the three-LED wand, else points_mm."""
    if wand.n_points == 3:
        return {"L1": float(wand.L1), "L2": float(wand.L2)}
    return {"points_mm": [float(p) for p in wand.positions_mm]}


def parse_rig(data: Any, path: str | Path = "<rig>") -> RigSpec:
    """Validate a parsed ``cameras.yaml`` document.

    Raises:
        FormatError: naming the file and the offending key or camera.
    """
    path = Path(path)
    if not isinstance(data, dict):
        raise FormatError(path, "expected a mapping with keys 'wand' and 'cameras'")
    wand = _wand(path, data.get("wand"))
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
        pixel_size = _pair(path, f"{label} pixel_size_um", item["pixel_size_um"])
        size = (int(width), int(height))
        m = 1000.0 / np.asarray(pixel_size)
        camera_model = _camera_model(path, label, item.get("camera_model"), lens, angle)
        intrinsics, fixed = _intrinsics(path, label, item.get("intrinsics"), m, size, camera_model)
        cameras.append(
            CameraSpec(
                name=str(item["name"]),
                image_size=size,
                pixel_size_um=pixel_size,
                nominal_focal_mm=_number(path, f"{label} nominal_focal_mm", item["nominal_focal_mm"]),
                max_view_angle_deg=angle,
                lens=lens,
                readout_ms=readout,
                intrinsics=intrinsics,
                intrinsics_fixed=fixed,
                camera_model=camera_model,
            )
        )
    names = [c.name for c in cameras]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise FormatError(path, f"camera names must be unique; repeated: {', '.join(duplicates)}")
    return RigSpec(wand, tuple(cameras), _floor_tool(path, data.get("floor"), wand))


def _floor_tool(path: Path, data: Any, wand: WandSpec) -> tuple[tuple[float, float, float], ...] | None:
    """``floor: {points_mm: [[x, y, z], ...]}``: a floor tool's markers in the world frame it defines."""
    if data is None:
        return None
    if not isinstance(data, dict) or set(data) != {"points_mm"}:
        raise FormatError(
            path, "'floor' must be a mapping with one key, points_mm: [[0, 0, 0], [500, 0, 0], [0, 300, 0]]"
        )
    try:
        points = np.array(data["points_mm"], dtype=float)
    except (TypeError, ValueError):
        raise FormatError(
            path, f"floor points_mm must be a list of [x, y, z] in mm, got {data['points_mm']!r}"
        ) from None
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise FormatError(path, f"floor points_mm must be a list of [x, y, z] in mm, got {data['points_mm']!r}")
    if not 3 <= len(points) <= wand.n_points:
        raise FormatError(
            path, f"floor points_mm has {len(points)} markers: a floor tool needs 3 or more, and at most the wand's "
            f"{wand.n_points} (its markers are the floor frames' points A, B, C, ...)"
        )  # fmt: skip
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    if spread[1] < 10.0:
        raise FormatError(path, "floor points_mm lie on one line: a floor tool's markers must span the floor (an L)")
    return tuple((float(x), float(y), float(z)) for x, y, z in points)


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
        if spec.camera_model is not None:
            item["camera_model"] = spec.camera_model
        if spec.intrinsics is not None:
            opencv = to_opencv(spec.intrinsics)
            item["intrinsics"] = {
                "K": [float(v) for v in opencv.camera_matrix.ravel()],
                "D": [float(v) for v in opencv.distortion],
                "distortion_model": opencv.distortion_model,
                "fixed": bool(spec.intrinsics_fixed),
            }
        cameras.append(item)
    document: dict[str, Any] = {"wand": wand_dict(rig.wand), "cameras": cameras}
    if rig.floor_tool is not None:
        document["floor"] = {"points_mm": [[float(v) for v in point] for point in rig.floor_tool]}
    return document


def save_rig(rig: RigSpec, path: str | Path) -> None:
    """Write ``cameras.yaml``."""
    write_text(path, yaml.safe_dump(rig_to_dict(rig), sort_keys=False, default_flow_style=None))


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
    """A topic or service name: absolute (``/cam0/image_raw``) or relative to the node's namespace
    (``cam0/image_raw``)."""
    bad = not isinstance(value, str) or not value or value.endswith("/") or "//" in value
    if bad or any(c.isspace() for c in value) or value.startswith("~"):
        raise FormatError(
            path, f"{where} must be a ROS name such as cam0/image_raw (in the node's namespace) or /cam0/image_raw, "
            f"got {value!r}"
        )  # fmt: skip
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
        # (relative defaults: a node started in a namespace, __ns:=/rigA, listens to /rigA/cam0/image_raw)
        image = _ros_name(path, f"camera '{name}' image_topic", item.get("image_topic", f"{name}/image_raw"))
        beside = image.rsplit("/", 1)[0] + "/" if "/" in image.lstrip("/") else ("/" if image.startswith("/") else "")
        endpoints[name] = CameraEndpoints(
            image,
            _ros_name(path, f"camera '{name}' points_topic", item.get("points_topic", f"{beside}wand_points")),
            _ros_name(
                path, f"camera '{name}' set_camera_info", item.get("set_camera_info", f"{beside}set_camera_info")
            ),
            _frame_id(path, name, item.get("frame_id", name)),
        )
    return endpoints


@dataclass(frozen=True)
class MaskSpec:
    """A camera's ``mask`` in the rig file: the pixels its detector ignores (lamps, a window).

    Attributes:
        circles: (u, v, radius) in px.
        rectangles: (u0, v0, u1, v1) in px, inclusive corners.
        file: a PNG, white where ignored (the camera's image size), or None.
    """

    circles: tuple[tuple[float, float, float], ...] = ()
    rectangles: tuple[tuple[float, float, float, float], ...] = ()
    file: Path | None = None


def _shapes(path: Path, where: str, value: Any, size: int) -> list[tuple[float, ...]]:
    if not isinstance(value, list):
        raise FormatError(path, f"{where} must be a list of [{', '.join(['n'] * size)}] lists, got {value!r}")
    shapes = []
    for item in value:
        if not isinstance(item, list) or len(item) != size:
            raise FormatError(path, f"{where}: each entry has {size} numbers, got {item!r}")
        shapes.append(tuple(_number(path, where, v, positive=False) for v in item))
    return shapes


def _mask(path: Path, name: str, value: Any) -> MaskSpec:
    where = f"camera '{name}' mask"
    if isinstance(value, str):
        value = {"file": value}
    if not isinstance(value, dict) or not value or not set(value) <= {"circles", "rectangles", "file"}:
        raise FormatError(
            path, f"{where} must be a PNG file name or a mapping of circles: [[u, v, r], ...], "
            f"rectangles: [[u0, v0, u1, v1], ...] and file: mask.png; got {value!r}"
        )  # fmt: skip
    circles = _shapes(path, f"{where} circles", value.get("circles", []), 3)
    if any(r <= 0 for _, _, r in circles):
        raise FormatError(path, f"{where} circles: a radius must be positive, got {value['circles']!r}")
    rectangles = _shapes(path, f"{where} rectangles", value.get("rectangles", []), 4)
    if any(u1 < u0 or v1 < v0 for u0, v0, u1, v1 in rectangles):
        raise FormatError(path, f"{where} rectangles are [u0, v0, u1, v1] with u0 <= u1 and v0 <= v1")
    file = value.get("file")
    if file is not None:
        if not isinstance(file, str) or not file:
            raise FormatError(path, f"{where} file must be a PNG file name, got {file!r}")
        file = _beside(path, file)
        if not file.is_file():
            raise FormatError(path, f"{where}: no such file {file}")
    return MaskSpec(tuple(circles), tuple(rectangles), file)  # type: ignore[arg-type]


def load_camera_masks(path: str | Path) -> dict[str, MaskSpec]:
    """Per camera the ``mask`` of ``cameras.yaml`` (cameras without one are left out)."""
    path = Path(path)
    rig = load_rig(path)
    items = {str(item["name"]): item for item in read_yaml(path)["cameras"]}
    return {name: _mask(path, name, items[name]["mask"]) for name in rig.camera_names if "mask" in items[name]}
