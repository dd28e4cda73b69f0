"""A :class:`~wand_calib_ros.core.after.rig_scene.RigScene` as visualization_msgs/MarkerArray for RViz (no maths here).

Namespaces: ``frustums`` (one LINE_LIST per camera, its pose the camera's in the parent frame, so a
marker's pose is the camera's), ``names`` (the cameras' names at their centres), ``wand`` (the newest
placements, first to last marker) and ``volume`` (the convex hull of every placement, translucent).
Marker ids are the cameras' indices; every array replaces the whole previous one.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from numpy.typing import NDArray
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from wand_calib_ros.core.after.rig_scene import RigScene
from wand_calib_ros.nodes.messages import camera_in_parent

#: A frustum's edges as index pairs into its five points (apex, then the image's four corners).
FRUSTUM_EDGES = ((0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1))
#: Each estimate's markers, per namespace.
NAMESPACES = ("frustums", "names", "wand", "volume")


def _points(points_mm: NDArray[np.float64]) -> list[Point]:
    return [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in np.asarray(points_mm).reshape(-1, 3) / 1000.0]


def _marker(namespace: str, index: int, kind: int, frame: str, stamp: Time, color: Iterable[float]) -> Marker:
    marker = Marker(ns=namespace, id=index, type=kind, action=Marker.ADD)
    marker.header.frame_id, marker.header.stamp = frame, stamp
    marker.pose.orientation.w = 1.0
    marker.color = ColorRGBA(**dict(zip("rgba", (float(v) for v in color), strict=True)))
    return marker


def markers_message(scene: RigScene, stamp: Time, frame: str, *, preliminary: bool = False) -> MarkerArray:
    """The scene in the tf frame ``frame`` (the poses' parent), metres; ``preliminary`` draws it grey
    (a running estimate, not the final calibration)."""
    camera_color = (0.6, 0.6, 0.6, 1.0) if preliminary else (0.1, 0.6, 1.0, 1.0)
    array = MarkerArray(markers=[Marker(action=Marker.DELETEALL)])
    for c, (name, pose) in enumerate(zip(scene.names, scene.poses, strict=True)):
        (px, py, pz), (qx, qy, qz, qw) = camera_in_parent(pose)
        for namespace, kind in (("frustums", Marker.LINE_LIST), ("names", Marker.TEXT_VIEW_FACING)):
            marker = _marker(namespace, c, kind, frame, stamp, camera_color)
            position, orientation = marker.pose.position, marker.pose.orientation
            position.x, position.y, position.z = px, py, pz
            orientation.x, orientation.y, orientation.z, orientation.w = qx, qy, qz, qw
            if kind == Marker.LINE_LIST:
                marker.scale.x = 0.005
                marker.points = _points(scene.frustums[c][np.array(FRUSTUM_EDGES).ravel()])
            else:
                marker.scale.z = 0.08
                marker.text = name + (" (preliminary)" if preliminary else "")
            array.markers.append(marker)
    wand = _marker("wand", 0, Marker.LINE_LIST, frame, stamp, (1.0, 0.5, 0.0, 0.8))
    wand.scale.x = 0.003
    wand.points = _points(scene.wands[:, [0, -1]])
    volume = _marker("volume", 0, Marker.TRIANGLE_LIST, frame, stamp, (0.2, 0.8, 0.2, 0.15))
    volume.scale.x = volume.scale.y = volume.scale.z = 1.0
    volume.points = _points(scene.hull)
    array.markers += [wand, volume]
    return array
