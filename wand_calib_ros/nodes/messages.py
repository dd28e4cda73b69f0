"""Translation between ROS messages and the core's arrays and records (no maths here).

Conventions: pixel coordinates are OpenCV's (origin at the centre of the top-left
pixel); wand points travel as geometry_msgs/PolygonStamped with the points A, B, C
in that order (x = u, y = v, z = 0, float32) and an empty polygon when the image
showed no usable wand.
"""

from __future__ import annotations

from collections.abc import Mapping

import cv2
import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point32, PolygonStamped, TransformStamped
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header

from wand_calib_ros.collection.coverage import CoverageStatus
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.io.result_yaml import camera_info_dict


def stamp_ns(header: Header) -> int:
    """A header's stamp in nanoseconds."""
    return int(header.stamp.sec) * 10**9 + int(header.stamp.nanosec)


def time_message(nanoseconds: int) -> Time:
    """builtin_interfaces/Time of a stamp in nanoseconds."""
    sec, nanosec = divmod(int(nanoseconds), 10**9)
    return Time(sec=sec, nanosec=nanosec)


def array_to_image(pixels: NDArray[np.uint8], stamp: int, frame_id: str, encoding: str = "mono8") -> Image:
    """sensor_msgs/Image of an 8-bit (H, W) or (H, W, channels) array (filled from bytes: fast)."""
    message = Image()
    message.header.stamp = time_message(stamp)
    message.header.frame_id = frame_id
    message.height, message.width = pixels.shape[:2]
    message.encoding = encoding
    message.step = pixels.shape[1] * (pixels.shape[2] if pixels.ndim == 3 else 1) * pixels.dtype.itemsize
    message.data = np.ascontiguousarray(pixels).tobytes()
    return message


def points_message(points: NDArray[np.float64] | None, header: Header) -> PolygonStamped:
    """PolygonStamped of A, B, C ((3, 2) pixels), or an empty polygon for "no wand"."""
    message = PolygonStamped(header=header)
    if points is not None:
        message.polygon.points = [Point32(x=float(u), y=float(v), z=0.0) for u, v in points]
    return message


def message_points(message: PolygonStamped, n_points: int = 3) -> NDArray[np.float64] | None:
    """The wand's markers ((K, 2) pixels: A, B, C of the paper's wand) of a PolygonStamped, None for an
    empty polygon.

    Raises:
        ValueError: neither 0 nor ``n_points`` points, or coordinates that are not finite.
    """
    if not message.polygon.points:
        return None
    points = np.array([[p.x, p.y] for p in message.polygon.points], dtype=np.float64)
    if points.shape != (n_points, 2) or not np.all(np.isfinite(points)):
        raise ValueError(f"expected the {n_points} finite points of the wand, got {points.tolist()}")
    return points


def camera_info_message(result: CalibrationResult, name: str, stamp: Time, frame_id: str | None = None) -> CameraInfo:
    """sensor_msgs/CameraInfo exactly equivalent to a calibrated camera (in its own model: ``equidistant``,
    ``plumb_bob`` or ``rational_polynomial``), in its tf frame
    ``frame_id`` (default its name)."""
    document = camera_info_dict(name, result.camera(name).model)
    info = CameraInfo()
    info.header.stamp = stamp
    info.header.frame_id = frame_id or name
    info.width, info.height = document["image_width"], document["image_height"]
    info.distortion_model = document["distortion_model"]
    info.d = [float(v) for v in document["distortion_coefficients"]["data"]]
    info.k = [float(v) for v in document["camera_matrix"]["data"]]
    info.r = [float(v) for v in document["rectification_matrix"]["data"]]
    info.p = [float(v) for v in document["projection_matrix"]["data"]]
    return info


def extrinsics_message(
    result: CalibrationResult,
    name: str,
    stamp: Time,
    world_frame: str = "world",
    frame_ids: Mapping[str, str] | None = None,
) -> TransformStamped:
    """geometry_msgs/TransformStamped of a camera in the world (a floor was given: parent ``world_frame``)
    or else in the reference camera's frame (parent = the reference camera); metres.

    The transform maps the camera's frame into the parent's (ROS convention: child = this camera),
    i.e. the inverse of X_cam = R X_parent + T. Frames are named by ``frame_ids`` (camera -> tf
    frame; default the camera names).
    """
    frame_of = dict(frame_ids or {})
    pose = result.camera(name).pose
    if result.world is not None:
        pose = result.world.camera_in_world(pose)
    message = TransformStamped()
    message.header.stamp = stamp
    message.header.frame_id = parent_frame(result, world_frame, frame_of)
    message.child_frame_id = frame_of.get(name, name)
    t = message.transform.translation
    r = message.transform.rotation
    (t.x, t.y, t.z), (r.x, r.y, r.z, r.w) = camera_in_parent(pose)
    return message


def parent_frame(result: CalibrationResult, world_frame: str, frame_ids: Mapping[str, str]) -> str:
    """The tf frame the result's poses are in: ``world_frame`` once a floor was set, else the reference
    camera's frame."""
    if result.world is not None:
        return world_frame
    return frame_ids.get(result.reference_camera, result.reference_camera)


def camera_in_parent(pose: Pose) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    """A camera's pose X_cam = R X_parent + T (mm) as ROS gives a child frame in its parent: position of
    its centre (m) and orientation (x, y, z, w) of R transposed."""
    x, y, z, w = Rotation.from_matrix(pose.rotation.T).as_quat()
    cx, cy, cz = (float(v) for v in pose.center / 1000.0)
    return (cx, cy, cz), (float(x), float(y), float(z), float(w))


def static_transforms(
    result: CalibrationResult, stamp: Time, world_frame: str = "world", frame_ids: Mapping[str, str] | None = None
) -> list[TransformStamped]:
    """Every camera's :func:`extrinsics_message` for ``/tf_static``, except a frame that would be its own
    parent (the reference camera when no floor was given): tf refuses such a transform."""
    names = [camera.name for camera in result.cameras]
    transforms = [extrinsics_message(result, name, stamp, world_frame, frame_ids) for name in names]
    return [t for t in transforms if t.header.frame_id != t.child_frame_id]


def diagnostics_message(
    status: CoverageStatus,
    counts: dict[str, dict[str, int | str]],
    rig_values: dict[str, int | str],
    stamp: Time,
    source: str = "wand_calib_collector",
    moved: Mapping[str, str] | None = None,
    notes: Mapping[str, list[str]] | None = None,
    faults: Mapping[str, list[str]] | None = None,
) -> DiagnosticArray:
    """/diagnostics: one OK/WARN entry per camera (what is missing) and one for the rig, named
    ``<source>: <camera>`` and ``<source>: rig`` (``source`` the collector's namespaced name, so an
    aggregator tells two rigs apart).

    Args:
        status: coverage of what the buffer holds.
        counts: per camera counters (images, wands, rejections) shown as key/values.
        rig_values: rig-wide counters (frames stored, late or out-of-order messages, ...).
        stamp: the array's stamp.
        moved: cameras judged to have moved since the calibration, with their message (ERROR entries).
        notes: per camera warnings of what its detector sees (LEDs saturating, too dim): added to its message
            (WARN).
        faults: per camera what is wrong with its stream now (silent, unusable images): first in its message
            (WARN), and named in the rig's (WARN, even when the coverage is ready).
    """
    array = DiagnosticArray()
    array.header.stamp = stamp
    for camera in status.cameras:
        entry = DiagnosticStatus(name=f"{source}: {camera.name}", hardware_id=camera.name)
        entry.level = DiagnosticStatus.OK if camera.ok else DiagnosticStatus.WARN
        entry.message = "ready" if camera.ok else "; ".join(camera.missing)
        said = [*(faults or {}).get(camera.name, []), *(notes or {}).get(camera.name, [])]
        if said:
            entry.level = DiagnosticStatus.WARN
            entry.message = "; ".join([*([] if camera.ok else camera.missing), *said])
        if moved and camera.name in moved:
            entry.level, entry.message = DiagnosticStatus.ERROR, moved[camera.name]
        values = {
            "placements": camera.placements,
            "image_coverage_percent": f"{100 * camera.image_fraction:.0f}",
            "max_theta_deg": f"{camera.max_theta_deg:.1f}",
            "reachable_theta_deg": f"{camera.reach_theta_deg:.1f}",
            **counts.get(camera.name, {}),
        }
        entry.values = [KeyValue(key=key, value=str(value)) for key, value in values.items()]
        array.status.append(entry)
    rig = DiagnosticStatus(name=f"{source}: rig", hardware_id="rig")
    rig.level = DiagnosticStatus.OK if status.ready else DiagnosticStatus.WARN
    rig.message = "ready to calibrate" if status.ready else " | ".join(status.messages())
    faulty = [f"{name}: {'; '.join(lines)}" for name, lines in (faults or {}).items() if lines]
    if faulty:
        rig.level, rig.message = DiagnosticStatus.WARN, " | ".join([*faulty, rig.message])
    rig.values = [KeyValue(key=key, value=str(value)) for key, value in rig_values.items()]
    array.status.append(rig)
    return array


def heat_map_message(counts: NDArray[np.int64], image_size: tuple[int, int], stamp: Time, frame_id: str) -> Image:
    """bgr8 picture (about 320 px wide, the camera's aspect) of where a camera saw the wand.

    Args:
        counts: (rows, cols) wand points per image cell.
        image_size: the camera's (width, height), for the aspect ratio.
        stamp: the message stamp.
        frame_id: the camera's frame.
    """
    width, height = image_size
    size = (320, max(1, round(320 * height / width)))
    level = np.sqrt(counts / max(float(counts.max()), 1.0)) * 255
    picture = cv2.applyColorMap(level.astype(np.uint8), cv2.COLORMAP_INFERNO)
    picture[counts == 0] = (96, 0, 0)  # never seen: dark blue, apart from "seen a little"
    resized = np.asarray(cv2.resize(picture, size, interpolation=cv2.INTER_NEAREST), dtype=np.uint8)
    message = array_to_image(resized, 0, frame_id, "bgr8")
    message.header.stamp = stamp
    return message
