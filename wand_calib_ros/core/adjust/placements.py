"""The wand's placements with the cameras known: linear triangulation and a fit of each placement.

Both work on dense (P, C, K, 2) pixels (NaN where a camera did not see a point) and
return the wand in the reference frame (mm).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS, BundleProblem, BundleState, PlacementTiming
from wand_calib_ros.core.model.camera_model import CameraModel, unproject
from wand_calib_ros.core.model.geometry import Pose, triangulate_rays, wand_directions
from wand_calib_ros.core.model.rig import WandSpec
from wand_calib_ros.core.model.views import enough_views, seen_points
from wand_calib_ros.core.parallel import both

FloatArray = NDArray[np.float64]

#: Triangulations of more rays than this unproject them in two threads, half of the cameras each
#: (:func:`~wand_calib_ros.core.parallel.both`).
SPLIT_RAYS = 50_000


def triangulate_placements(
    models: tuple[CameraModel, ...], poses: tuple[Pose, ...], uv: FloatArray, rows: NDArray[np.int64] | None = None
) -> FloatArray:
    """Linear n-view triangulation of every wand point.

    Args:
        models, poses: per camera intrinsics and pose (reference frame).
        uv: (P, C, K, 2) pixels of the K markers, NaN where not seen.
        rows: (R,) the placements to triangulate (no copy of their views); None: all.

    Returns:
        (P, K, 3) the markers in the reference frame, or (R, K, 3) those of ``rows`` (NaN where fewer than two views).
    """
    _, n_cameras, n_markers = uv.shape[:3]
    seen = seen_points(uv) if rows is None else seen_points(uv)[rows]  # (P or R, C, K)
    n_placements = seen.shape[0]
    # only the pixels seen (a camera sees a fraction of the placements), camera by camera: one run each
    camera, placement, marker = np.nonzero(seen.transpose(1, 0, 2))
    bounds = np.searchsorted(camera, np.arange(n_cameras + 1))
    rays = np.empty((camera.size, 3))

    def unproject_cameras(cameras: NDArray[np.int64]) -> None:
        for c in cameras:
            run = slice(bounds[c], bounds[c + 1])
            at = placement[run] if rows is None else rows[placement[run]]
            rays[run] = unproject(models[c], uv[at, c, marker[run]]) @ poses[c].rotation  # R^T m

    seeing = np.flatnonzero(np.diff(bounds))
    half = int(np.searchsorted(bounds[seeing + 1], camera.size / 2))  # the cameras of about half of the rays
    both(
        lambda: unproject_cameras(seeing[:half]),
        lambda: unproject_cameras(seeing[half:]),
        split=camera.size > SPLIT_RAYS,
    )
    centres = np.stack([pose.center for pose in poses])
    points = triangulate_rays(placement * n_markers + marker, n_placements * n_markers, rays, centres, camera)
    return points.reshape(n_placements, n_markers, 3)


def unprojectable(
    models: tuple[CameraModel, ...], poses: tuple[Pose, ...], uv: FloatArray, points: FloatArray
) -> NDArray[np.bool_]:
    """(P,) placements some camera sees although its model gives the placed markers no image (a pinhole
    camera with a marker on or behind its image plane: the start is wrong there, not the view).

    Args:
        uv: (P, C, K, 2) pixels (NaN where not seen); ``points`` (P, K, 3) the markers, reference frame.
    """
    out = np.zeros(uv.shape[0], dtype=bool)
    for c, (model, pose) in enumerate(zip(models, poses, strict=True)):
        if not model.is_pinhole:
            continue  # the fisheye model images every direction
        seen = np.any(np.isfinite(uv[:, c, :, 0]), axis=1)
        depth = pose.apply(points[seen])[..., 2]  # (S, K)
        out[np.flatnonzero(seen)[np.any(~(depth > 0), axis=1)]] = True
    return out


def fit_placements(
    wand: WandSpec,
    cameras: BundleState,
    uv: FloatArray,
    timing: PlacementTiming | None = None,
    *,
    rows: NDArray[np.int64] | None = None,
    loss_scale: float | None = None,
    max_iterations: int = 10,
    tolerance: float = 1e-5,
    brightness: FloatArray | None = None,
) -> tuple[NDArray[np.int64], BundleResult]:
    """Each placement's wand (A and direction) fitted to its views with the cameras held fixed.

    Placements are triangulated first; those seen completely by two cameras with a usable
    triangulation are fitted (independent 5-parameter problems).

    Args:
        wand: the wand.
        cameras: the cameras' models, poses and timing (its placements are ignored).
        uv: (P, C, K, 2) pixels.
        timing: when each camera saw each placement (of ``rows``, where given) and how the wand moved (None:
            simultaneous).
        rows: (R,) the placements to fit (no copy of their views); None: all.
        loss_scale: Huber threshold (px) of the fit, or None for least squares.
        max_iterations, tolerance: of the Levenberg-Marquardt.
        brightness: (P, C, K) the points' brightness classes (their centres corrected by the cameras' bias; None:
            not known).

    Returns:
        The indices of the fitted placements (into ``rows`` where given) and the fit (its state holds only them).
    """
    models, poses = cameras.models, cameras.poses
    points = triangulate_placements(models, poses, uv, rows)
    usable = np.all(np.isfinite(points), axis=(1, 2)) & (np.linalg.norm(points[:, -1] - points[:, 0], axis=1) > 0)
    usable &= enough_views(uv, rows)
    placements = np.arange(len(uv)) if rows is None else rows
    if any(model.is_pinhole for model in models):  # (the fisheye model images every direction)
        usable[usable] &= ~unprojectable(models, poses, uv[placements[usable]], points[usable])
    index = np.flatnonzero(usable)
    start = BundleState(
        models,
        poses,
        points[index, 0],
        wand_directions(points[index, 0], points[index, -1]),
        cameras.timing,
        cameras.bias,
    )
    problem = BundleProblem.from_dense(
        wand, uv, None if timing is None else timing.subset(index), placements[index], brightness
    )
    if index.size == 0:
        return index, BundleResult(start, np.zeros((0, 2)), 0, True, np.zeros((len(models), N_CAMERA_PARAMS)),
                                   np.zeros((0, 0)), 0.0, (0, 0))  # fmt: skip
    fitted = bundle_adjust(
        start,
        problem,
        np.zeros((len(models), N_CAMERA_PARAMS), dtype=bool),
        loss_scale=loss_scale,
        max_iterations=max_iterations,
        tolerance=tolerance,
    )
    return index, fitted
