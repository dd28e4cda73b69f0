"""Which marker of a floor tool is which in each view, from the calibrated cameras.

A floor tool (an L-frame, a square of markers) is not collinear like the wand. A detector finds its
markers as blobs, in no particular order. The calibration tells them apart. For each frame:

1. Two cameras that see every marker are paired in every correspondence. Each pairing is triangulated,
   and the triangulated points are matched to the tool's known positions in every order. The pairing
   and order whose rigid fit is closest wins, with the tool's z towards the cameras: an L turned over is
   its mirror image.
2. Every camera's points are then matched to the tool's projection, nearest first. A view is kept only
   when each of its points lies within :data:`MAX_LABEL_ERROR_PX` of its marker's projection.
"""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.model.camera_model import CameraModel, project
from wand_calib_ros.core.model.geometry import Pose

FloatArray = NDArray[np.float64]

#: A view's points must each lie this close (px) to the projection of the marker they are given.
MAX_LABEL_ERROR_PX = 15.0
#: Tools with more markers than this are too many orders to try; their views must come labelled.
MAX_UNLABELLED_MARKERS = 5


def rigid_fit(model: FloatArray, measured: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(R, t) minimising |R model + t - measured|^2 over (K, 3) point sets (Kabsch, a proper rotation)."""
    a, b = model - model.mean(axis=0), measured - measured.mean(axis=0)
    u, _, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    rotation = u @ np.diag([1.0, 1.0, d]) @ vt
    return rotation, measured.mean(axis=0) - rotation @ model.mean(axis=0)


def _tool_pose(
    models: tuple[CameraModel, ...], poses: tuple[Pose, ...], views: FloatArray, full: list[int], tool_mm: FloatArray
) -> Pose | None:
    """The tool's pose (X_ref = R X_tool + t) in one frame from two cameras that see all its markers."""
    a, b = full[0], full[int(np.argmax([np.linalg.norm(poses[c].center - poses[full[0]].center) for c in full]))]
    centres = np.array([pose.center for pose in poses])
    n = len(tool_mm)
    best: tuple[float, Pose] | None = None
    for order_b in itertools.permutations(range(n)):
        pair = np.stack([views[a], views[b][list(order_b)]])[None]  # (1, 2, K, 2)
        points = triangulate_placements((models[a], models[b]), (poses[a], poses[b]), pair)[0]
        if not np.all(np.isfinite(points)):
            continue
        for labels in itertools.permutations(range(n)):
            rotation, translation = rigid_fit(tool_mm[list(labels)], points)
            if float(np.median((centres - translation) @ rotation[:, 2])) <= 0:
                continue  # the tool upside down: the mirror image of the right order
            error = float(np.sum((tool_mm[list(labels)] @ rotation.T + translation - points) ** 2))
            if best is None or error < best[0]:
                best = (error, Pose(rotation, translation))
    return None if best is None else best[1]


def label_tool_views(
    models: tuple[CameraModel, ...], poses: tuple[Pose, ...], uv: FloatArray, tool_mm: FloatArray
) -> FloatArray:
    """The floor frames' views of a tool with each point given its marker's label.

    Args:
        models, poses: the calibrated cameras (poses relative to the reference camera).
        uv: (F, C, K, 2) the frames' views: the tool's K markers in any order per view, NaN where not seen.
        tool_mm: (K, 3) the tool's markers in its own (the world's) frame, mm.

    Returns:
        (F, C, K, 2) the views with point k the tool's marker k; NaN for views that could not be labelled
        (fewer than two cameras saw every marker in the frame, or a point far from every marker).
    """
    from scipy.optimize import linear_sum_assignment  # (scipy.optimize takes 0.3 s to import: only with a tool)

    n_frames, n_cameras, n = uv.shape[:3]
    out = np.full_like(uv, np.nan)
    if n > MAX_UNLABELLED_MARKERS:
        return uv.copy()
    for f in range(n_frames):
        seen = np.isfinite(uv[f]).all(axis=-1)  # (C, K)
        full = [c for c in range(n_cameras) if seen[c].all()]
        if len(full) < 2:
            continue
        pose = _tool_pose(models, poses, uv[f], full, tool_mm)
        if pose is None:
            continue
        markers = pose.apply(tool_mm)
        for c in range(n_cameras):
            points = uv[f, c][seen[c]]
            if not len(points):
                continue
            projected = project(models[c], poses[c].apply(markers))
            distance = np.linalg.norm(points[:, None, :] - projected[None, :, :], axis=-1)
            if not np.all(np.isfinite(projected)):
                continue
            rows, labels = linear_sum_assignment(distance)
            if np.all(distance[rows, labels] < MAX_LABEL_ERROR_PX):
                out[f, c, labels] = points[rows]
    return out
