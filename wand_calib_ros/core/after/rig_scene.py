"""What a viewer (RViz) shows of a calibrated rig: camera frustums, recent wand placements, the covered volume.

Everything is in one parent frame: the world once a floor was fitted, else the reference camera's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import ConvexHull, QhullError

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.model.camera_model import CameraModel, unproject
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.result import CalibrationResult

FloatArray = NDArray[np.float64]

#: Wand placements shown (the newest).
RECENT = 200
#: A frustum's length as a fraction of the median distance from the cameras to the wand.
FRUSTUM_FRACTION = 0.25


@dataclass(frozen=True, eq=False)
class RigScene:
    """A calibrated rig as drawn.

    Attributes:
        names: the cameras.
        poses: (C,) each camera's pose in the parent frame, X_cam = R X_parent + T (mm).
        frustums: (C, 5, 3) each camera's apex (its centre) and the rays to its image's four corners
            (top-left, top-right, bottom-right, bottom-left) at the frustum's length, in the camera's
            frame, mm (a fisheye's corners may lie behind it).
        wands: (N, K, 3) the newest placements' markers in the parent frame, mm.
        hull: (T, 3, 3) triangles of the convex hull of every placement's markers in the parent frame,
            mm (none when the placements span no volume).
    """

    names: tuple[str, ...]
    poses: tuple[Pose, ...]
    frustums: FloatArray
    wands: FloatArray
    hull: FloatArray


def corner_rays(model: CameraModel) -> FloatArray:
    """(4, 3) unit bearings of the image's corners (top-left, top-right, bottom-right, bottom-left), each
    pulled toward the principal point until the model reaches it."""
    width, height = model.image_size
    corners = np.array([[0.0, 0.0], [width, 0.0], [width, height], [0.0, height]])
    rays = unproject(model, corners)
    for _ in range(20):  # beyond the radius where r(theta) stops increasing: halve toward the centre
        unreached = ~np.all(np.isfinite(rays), axis=1)
        if not unreached.any():
            break
        corners[unreached] = 0.5 * (corners[unreached] + model.principal_point)
        rays[unreached] = unproject(model, corners[unreached])
    return rays


def rig_scene(result: CalibrationResult, names: tuple[str, ...], uv: FloatArray, recent: int = RECENT) -> RigScene:
    """The scene of ``result`` with the placements ``uv`` (F, C, K, 2; cameras in ``names`` order, NaN
    where unseen) triangulated with it."""
    models = tuple(result.camera(n).model for n in names)
    in_reference = tuple(result.camera(n).pose for n in names)
    points = triangulate_placements(models, in_reference, uv)
    points = points[np.all(np.isfinite(points), axis=(1, 2))]
    poses = in_reference
    if result.world is not None:
        poses = tuple(result.world.camera_in_world(p) for p in in_reference)
        points = result.world.world_from_reference.apply(points.reshape(-1, 3)).reshape(points.shape)
    centres = np.array([p.center for p in poses])
    if points.size:
        distance = float(np.median(np.linalg.norm(points[:, None, 0] - centres[None], axis=-1)))
    else:  # nothing triangulated: the rig's size
        distance = float(np.max(np.linalg.norm(centres - centres.mean(axis=0), axis=1), initial=1000.0))
    length = FRUSTUM_FRACTION * distance
    frustums = np.stack([np.vstack([np.zeros(3), length * corner_rays(m)]) for m in models])
    return RigScene(names, poses, frustums, points[-recent:], hull_triangles(points.reshape(-1, 3)))


def hull_triangles(points: FloatArray) -> FloatArray:
    """(T, 3, 3) the triangles of the convex hull of (N, 3) points ((0, 3, 3) when they span no volume)."""
    if points.shape[0] < 4:
        return np.zeros((0, 3, 3))
    try:
        hull = ConvexHull(points)
    except QhullError:  # all on a plane or a line
        return np.zeros((0, 3, 3))
    return np.asarray(points[hull.simplices], dtype=np.float64)
