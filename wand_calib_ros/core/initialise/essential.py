"""Step 2 of the paper: relative pose from the essential matrix on the unit sphere.

Bearing vectors satisfy m1^T E m0 = 0 with E = [T]x R (paper eq. essential).
Minimal samples of five correspondences go to Nister's 5-point solver (OpenCV's
implementation) after each camera's sample is rotated so its rays lie around
the +z axis: that keeps the planar normalisation OpenCV uses valid for rays at
or beyond 90 degrees. Hypotheses are scored on the whole sphere by the angle
between each ray and its epipolar plane; the winner is refined linearly on its
inliers, decomposed with a cheirality test on triangulated points, and scaled
by the wand length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.model.geometry import Pose, triangulate

FloatArray = NDArray[np.float64]

#: Rays of a minimal sample must lie within this angle of the sample's mean ray.
_MAX_SAMPLE_SPREAD = np.radians(80.0)


@dataclass(frozen=True, eq=False)
class RelativePose:
    """Result of Step 2.

    Attributes:
        pose: camera 1 relative to camera 0 (X_1 = R X_0 + T), T scaled to mm.
        inliers: (N,) bool over the correspondences given.
        essential: (3, 3) essential matrix (for unit-norm T).
        scale_spread: relative median absolute deviation of the per-placement scales.
    """

    pose: Pose
    inliers: NDArray[np.bool_]
    essential: FloatArray
    scale_spread: float


def epipolar_angles(essential: FloatArray, m0: FloatArray, m1: FloatArray) -> FloatArray:
    """Symmetric angular epipolar error (rad) of (N, 3) bearing pairs, valid on the whole sphere.

    The larger of the angles between m1 and the epipolar plane with normal
    E m0 and between m0 and the plane with normal E^T m1. ``essential`` (3, 3) gives (N,) angles,
    a stack (S, 3, 3) of them (S, N).
    """
    n1 = m0 @ np.swapaxes(essential, -1, -2)
    n0 = m1 @ essential
    algebraic = np.abs(np.sum(m1 * n1, axis=-1))
    with np.errstate(divide="ignore", invalid="ignore"):
        s1 = algebraic / np.linalg.norm(n1, axis=-1)
        s0 = algebraic / np.linalg.norm(n0, axis=-1)
    return np.arcsin(np.clip(np.nan_to_num(np.maximum(s0, s1), nan=1.0), 0.0, 1.0))


def _rotation_to_z(direction: FloatArray) -> FloatArray:
    """(3, 3) rotation Q with Q @ direction = +z."""
    x, y, z = (float(v) for v in direction)
    length = math.sqrt(x * x + y * y + z * z)
    x, y, c = x / length, y / length, z / length
    s = math.hypot(x, y)  # |d x z|: the axis (y, -x, 0) / s, the angle's sine s and cosine c
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    kx = np.array([[0.0, 0.0, -x / s], [0.0, 0.0, -y / s], [x / s, y / s, 0.0]])
    return np.eye(3) + s * kx + (1 - c) * kx @ kx


def minimal_solutions(m0: FloatArray, m1: FloatArray) -> list[FloatArray]:
    """Essential matrices through five bearing pairs (Nister's solver in rotated frames)."""
    q0 = _rotation_to_z(m0.mean(axis=0))
    q1 = _rotation_to_z(m1.mean(axis=0))
    r0, r1 = m0 @ q0.T, m1 @ q1.T
    if min(r0[:, 2].min(), r1[:, 2].min()) < np.cos(_MAX_SAMPLE_SPREAD):
        return []
    x0 = np.ascontiguousarray(r0[:, :2] / r0[:, 2:])
    x1 = np.ascontiguousarray(r1[:, :2] / r1[:, 2:])
    stacked, _ = cv2.findEssentialMat(x0, x1, np.eye(3), method=cv2.RANSAC, prob=0.99, threshold=1.0)
    if stacked is None:
        return []
    return [q1.T @ e @ q0 for e in stacked.reshape(-1, 3, 3)]


def linear_essential(m0: FloatArray, m1: FloatArray) -> FloatArray:
    """Least-squares E from many bearing pairs, projected onto the essential manifold."""
    design = np.einsum("ni,nj->nij", m1, m0).reshape(-1, 9)
    _, _, vt = np.linalg.svd(design, full_matrices=False)
    return _project_essential(vt[-1].reshape(3, 3))


def _project_essential(matrix: FloatArray) -> FloatArray:
    u, _, vt = np.linalg.svd(matrix)
    return u @ np.diag([1.0, 1.0, 0.0]) @ vt


def ransac_essential(
    m0: FloatArray,
    m1: FloatArray,
    *,
    threshold_rad: float,
    rng: np.random.Generator,
    confidence: float = 0.999,
    max_iterations: int = 2000,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """5-point RANSAC for E on bearing vectors, then a linear refit on the inliers.

    Args:
        m0, m1: (N, 3) unit bearings of the same points in cameras 0 and 1.
        threshold_rad: inlier threshold on :func:`epipolar_angles`.
        rng: seeded generator (results are reproducible).
        confidence: stop when an outlier-free sample was drawn with this probability.
        max_iterations: hard cap on samples.

    Returns:
        E (3, 3) and the (N,) inlier mask.
    """
    n = m0.shape[0]
    if n < 8:
        raise InsufficientDataError(f"the essential matrix needs at least 8 correspondences, got {n}")
    best_e, best_count, best_score = np.eye(3), -1, np.inf
    needed, iteration = max_iterations, 0
    while iteration < min(needed, max_iterations):
        iteration += 1
        sample = rng.choice(n, 5, replace=False)
        solutions = minimal_solutions(m0[sample], m1[sample])
        if not solutions:
            continue
        errors = epipolar_angles(np.stack(solutions), m0, m1)  # (S, N): every solution of the sample at once
        counts = np.sum(errors < threshold_rad, axis=1)
        scores = np.sum(np.minimum(errors, threshold_rad) ** 2, axis=1)  # MSAC tie-break
        for e, count, score in zip(solutions, counts.tolist(), scores.tolist(), strict=True):
            if count > best_count or (count == best_count and score < best_score):
                best_e, best_count, best_score = e, count, score
                ratio = count / n
                fail = 1.0 - ratio**5
                needed = 0 if fail <= 0 else int(np.ceil(np.log(1 - confidence) / np.log(max(fail, 1e-12))))
    if best_count < 8:
        raise DegenerateDataError(
            f"no essential matrix explains the data: the best of {iteration} samples has "
            f"{max(best_count, 0)} of {n} correspondences within {np.degrees(threshold_rad):.2f} deg"
        )
    inliers = epipolar_angles(best_e, m0, m1) < threshold_rad
    refined = linear_essential(m0[inliers], m1[inliers])
    refined_inliers = epipolar_angles(refined, m0, m1) < threshold_rad
    if refined_inliers.sum() >= inliers.sum():
        return refined, refined_inliers
    return best_e, inliers


def decompose_essential(essential: FloatArray, m0: FloatArray, m1: FloatArray) -> tuple[Pose, int]:
    """The (R, t) of E (|t| = 1) that puts most triangulated points in front of both cameras.

    "In front" means along the ray: m . X > 0 in each camera, valid beyond 90 degrees.

    Returns:
        The pose and how many points passed the cheirality test.
    """
    u, _, vt = np.linalg.svd(essential)
    if np.linalg.det(u) < 0:
        u = -u
    if np.linalg.det(vt) < 0:
        vt = -vt
    w = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    best: tuple[Pose, int] = (Pose.identity(), -1)
    bearings = np.stack([m0, m1], axis=1)
    for rotation in (u @ w @ vt, u @ w.T @ vt):
        for t in (u[:, 2], -u[:, 2]):
            pose = Pose(rotation, t)
            points = triangulate(bearings, np.stack([np.eye(3), rotation]), np.stack([np.zeros(3), t]))
            in_cam1 = pose.apply(points)
            front = (np.sum(points * m0, axis=1) > 0) & (np.sum(in_cam1 * m1, axis=1) > 0)
            count = int(np.sum(front))
            if count > best[1]:
                best = (pose, count)
    return best


def wand_scale(pose: Pose, bearings0: FloatArray, bearings1: FloatArray, wand_length: float) -> tuple[float, float]:
    """Scale factor lambda of the paper: wand length over reconstructed |AC|.

    Args:
        pose: relative pose with unit translation.
        bearings0, bearings1: (N, K, 3) bearings of the markers per placement in each camera.
        wand_length: L = |AC| in mm.

    Returns:
        (lambda, relative spread): the median of L / |A^r C^r| over placements
        (the paper's mean, made robust) and the relative median absolute deviation.
    """
    n = bearings0.shape[0]
    pair = np.stack([bearings0[:, [0, -1]].reshape(-1, 3), bearings1[:, [0, -1]].reshape(-1, 3)], axis=1)
    points = triangulate(pair, np.stack([np.eye(3), pose.rotation]), np.stack([np.zeros(3), pose.translation])).reshape(
        n, 2, 3
    )
    lengths = np.linalg.norm(points[:, 1] - points[:, 0], axis=1)
    ratios = wand_length / lengths[np.isfinite(lengths) & (lengths > 0)]
    if ratios.size == 0:
        raise DegenerateDataError("no placement could be triangulated to fix the scale")
    scale = float(np.median(ratios))
    return scale, float(np.median(np.abs(ratios - scale)) / scale)


def relative_pose(
    bearings0: FloatArray,
    bearings1: FloatArray,
    wand_length: float,
    *,
    threshold_rad: float,
    rng: np.random.Generator,
) -> RelativePose:
    """Step 2 on placements both cameras see completely.

    Args:
        bearings0, bearings1: (N, K, 3) unit bearings of the markers per placement.
        wand_length: L = |AC|, mm.
        threshold_rad: RANSAC inlier threshold (angle to the epipolar plane).
        rng: seeded generator.
    """
    m0, m1 = bearings0.reshape(-1, 3), bearings1.reshape(-1, 3)
    usable = np.all(np.isfinite(m0), axis=1) & np.all(np.isfinite(m1), axis=1)
    if usable.sum() < 8:
        raise InsufficientDataError(
            f"only {int(usable.sum())} wand points can be unprojected in both cameras; need at least 8"
        )
    essential, inliers_u = ransac_essential(m0[usable], m1[usable], threshold_rad=threshold_rad, rng=rng)
    inliers = np.zeros(m0.shape[0], dtype=bool)
    inliers[np.flatnonzero(usable)[inliers_u]] = True
    unit_pose, _ = decompose_essential(essential, m0[inliers], m1[inliers])
    placement_ok = inliers.reshape(-1, bearings0.shape[1]).all(axis=1)
    if placement_ok.sum() < 3:
        raise DegenerateDataError("fewer than 3 placements agree with the epipolar geometry")
    scale, spread = wand_scale(unit_pose, bearings0[placement_ok], bearings1[placement_ok], wand_length)
    pose = Pose(unit_pose.rotation, unit_pose.translation * scale)
    return RelativePose(pose, inliers, essential, spread)
