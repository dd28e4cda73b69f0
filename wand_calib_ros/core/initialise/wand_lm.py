"""Step 3 of the paper: Levenberg-Marquardt on the wand-length errors.

With the current intrinsics (k1, k2, u0, v0 of both cameras; m fixed) and the
relative pose (Rodrigues vector, T), every placement is triangulated linearly
and compared with the wand: g1 = L1 - |AB|, g2 = L2 - |BC|, g3 = L - |AC|
(paper eqs. object1-object3; a two-marker wand has g = L - |AB| only). The 14
unknowns are found by a Levenberg-Marquardt with Marquardt's scaling (the Jacobian's
column norms, as MINPACK's ``lmder`` scales them): our own, so that a calibration's start
imports no scipy.optimize.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import CalibrationFailedError
from wand_calib_ros.core.model.camera_model import CameraModel, unproject, unproject_with_jacobian
from wand_calib_ros.core.model.geometry import Pose, rotation_from_rotvec, triangulate, triangulation_jacobian
from wand_calib_ros.core.model.rig import WandSpec

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: Index of the intrinsics that Step 3 estimates inside CameraModel.intrinsic_vector(): k1, k2, u0, v0.
_STEP3_INTRINSICS = np.array([0, 1, 5, 6])


@dataclass(frozen=True, eq=False)
class WandFit:
    """Result of Step 3.

    Attributes:
        models: the two cameras' intrinsics.
        pose: camera 1 relative to camera 0.
        length_errors: (N, G) the wand-length errors (g1, g2, g3) per placement at the solution, mm.
    """

    models: tuple[CameraModel, CameraModel]
    pose: Pose
    length_errors: FloatArray

    @property
    def rms_mm(self) -> float:
        """RMS of all wand-length errors, mm (NaN placements ignored)."""
        finite = self.length_errors[np.isfinite(self.length_errors)]
        return float(np.sqrt(np.mean(finite**2))) if finite.size else float("inf")


def reconstruct_wands(
    models: tuple[CameraModel, CameraModel], pose: Pose, uv0: FloatArray, uv1: FloatArray
) -> FloatArray:
    """Linear two-view reconstruction of A, B, C in camera 0's frame.

    Args:
        models: intrinsics of cameras 0 and 1.
        pose: camera 1 relative to camera 0.
        uv0, uv1: (N, K, 2) pixels of the markers.

    Returns:
        (N, K, 3) points, mm (NaN where a point cannot be unprojected).
    """
    n, k = uv0.shape[:2]
    bearings = np.stack([unproject(models[0], uv0).reshape(-1, 3), unproject(models[1], uv1).reshape(-1, 3)], 1)
    rotations = np.stack([np.eye(3), pose.rotation])
    translations = np.stack([np.zeros(3), pose.translation])
    return triangulate(bearings, rotations, translations).reshape(n, k, 3)


def wand_pairs(n_points: int) -> tuple[tuple[int, int], ...]:
    """The marker pairs whose distances Step 3 matches: AB, BC, AC for the paper's wand; every
    consecutive pair and the ends for longer wands; AB for a two-marker wand."""
    consecutive = tuple((i, i + 1) for i in range(n_points - 1))
    return consecutive if n_points == 2 else (*consecutive, (0, n_points - 1))


def wand_length_errors(points: FloatArray, wand: WandSpec) -> FloatArray:
    """(N, G) nominal minus reconstructed distances of :func:`wand_pairs` (g1, g2, g3 = |AB|, |BC|, |AC|), mm."""
    offsets = wand.offsets
    return np.stack(
        [
            offsets[q] - offsets[p] - np.linalg.norm(points[:, q] - points[:, p], axis=-1)
            for p, q in wand_pairs(wand.n_points)
        ],
        axis=-1,
    )


def _unpack(x: FloatArray, models: tuple[CameraModel, CameraModel]) -> tuple[tuple[CameraModel, CameraModel], Pose]:
    updated = []
    for i, model in enumerate(models):
        vector = model.intrinsic_vector()
        vector[_STEP3_INTRINSICS] = x[4 * i : 4 * i + 4]
        updated.append(model.with_intrinsic_vector(vector))
    pose = Pose(rotation_from_rotvec(x[8:11]), x[11:14])
    return (updated[0], updated[1]), pose


def _rotation_derivatives(rotvec: FloatArray, step: float = 1e-7) -> FloatArray:
    """(3, 3, 3) dR/d(rotvec_i) by central differences on the 3x3 matrix (accurate to ~1e-9)."""
    eye = np.eye(3) * step
    plus = rotation_from_rotvec(rotvec[None, :] + eye)
    minus = rotation_from_rotvec(rotvec[None, :] - eye)
    return (plus - minus) / (2 * step)


class _WandProblem:
    """Residuals g and their exact Jacobian for Step 3 (x = 4 + 4 intrinsics, rotvec, T)."""

    def __init__(self, models: tuple[CameraModel, CameraModel], uv0: FloatArray, uv1: FloatArray, wand: WandSpec):
        self.models, self.uv0, self.uv1, self.wand = models, uv0.reshape(-1, 2), uv1.reshape(-1, 2), wand
        self.pairs = wand_pairs(wand.n_points)
        self.lengths = np.array([wand.offsets[q] - wand.offsets[p] for p, q in self.pairs])
        self._cache_x: FloatArray | None = None
        self._cache: tuple[FloatArray, FloatArray] | None = None

    def _evaluate(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        if self._cache_x is not None and np.array_equal(x, self._cache_x) and self._cache is not None:
            return self._cache
        k, g = self.wand.n_points, len(self.pairs)
        n = self.uv0.shape[0] // k
        if x[0] <= 0 or x[4] <= 0:
            return np.full(g * n, self.wand.L), np.zeros((g * n, 14))
        models, pose = _unpack(x, self.models)
        m0, dm0 = unproject_with_jacobian(models[0], self.uv0)
        m1, dm1 = unproject_with_jacobian(models[1], self.uv1)
        rotation, translation = pose.rotation, pose.translation
        rays = np.stack([m0, m1 @ rotation], axis=1)  # w = R^T m
        centres = np.stack([np.zeros(3), -rotation.T @ translation])
        points = triangulate(rays, np.stack([np.eye(3), np.eye(3)]), -centres)
        d_rays = np.zeros((rays.shape[0], 2, 3, 14))
        d_centres = np.zeros((2, 3, 14))
        d_rays[:, 0, :, 0:4] = dm0[:, :, _STEP3_INTRINSICS]
        d_rays[:, 1, :, 4:8] = rotation.T @ dm1[:, :, _STEP3_INTRINSICS]
        d_rotation = _rotation_derivatives(x[8:11])  # (3 params, 3, 3)
        d_rays[:, 1, :, 8:11] = (m1 @ d_rotation).transpose(1, 2, 0)  # (dR_k^T m1)_i = (m1 @ dR_k)_i
        d_centres[1, :, 8:11] = -(translation @ d_rotation).T
        d_centres[1, :, 11:14] = -rotation.T
        d_points = triangulation_jacobian(points, rays, centres, d_rays, d_centres).reshape(n, k, 3, 14)
        points = points.reshape(n, k, 3)
        residuals = np.empty((n, g))
        jacobian = np.empty((n, g, 14))
        for column, (p, q) in enumerate(self.pairs):
            delta = points[:, q] - points[:, p]
            distance = np.linalg.norm(delta, axis=-1)
            residuals[:, column] = self.lengths[column] - distance
            unit = delta / distance[:, None]
            jacobian[:, column] = -(unit[:, None, :] @ (d_points[:, q] - d_points[:, p]))[:, 0, :]
        bad = ~np.isfinite(residuals) | ~np.all(np.isfinite(jacobian), axis=-1)
        # A placement that cannot be reconstructed costs as much as a wand of length zero.
        residuals[bad] = self.wand.L
        jacobian[bad] = 0.0
        self._cache_x, self._cache = x.copy(), (residuals.ravel(), jacobian.reshape(-1, 14))
        return self._cache

    def residuals(self, x: FloatArray) -> FloatArray:
        return self._evaluate(x)[0]

    def jacobian(self, x: FloatArray) -> FloatArray:
        return self._evaluate(x)[1]


def optimise_wand_lengths(
    models: tuple[CameraModel, CameraModel],
    pose: Pose,
    uv0: FloatArray,
    uv1: FloatArray,
    wand: WandSpec,
    *,
    max_evaluations: int = 200,
    tolerance: float = 1e-8,
) -> WandFit:
    """Step 3: minimise sum(g1^2 + g2^2 + g3^2) over 8 intrinsics and 6 extrinsics (m fixed).

    Args:
        models: Step 1 intrinsics of cameras 0 and 1 (k3..k5 are kept as they are).
        pose: Step 2 pose of camera 1 relative to camera 0.
        uv0, uv1: (N, K, 2) pixels of the markers of placements both cameras see.
        wand: the wand lengths.
        max_evaluations: cap on residual evaluations.
        tolerance: relative tolerance on the cost and the parameters (MINPACK ftol, xtol).
    """
    x0 = np.concatenate(
        [
            models[0].intrinsic_vector()[_STEP3_INTRINSICS],
            models[1].intrinsic_vector()[_STEP3_INTRINSICS],
            pose.rotvec,
            pose.translation,
        ]
    )
    problem = _WandProblem(models, uv0, uv1, wand)
    x = _levenberg_marquardt(problem, x0, max_evaluations=max_evaluations, tolerance=tolerance)
    if x[0] <= 0 or x[4] <= 0:
        raise CalibrationFailedError("Step 3 diverged (a focal length became negative): the data do not fix the scale")
    fitted, fitted_pose = _unpack(x, models)
    return wand_fit(fitted, fitted_pose, uv0, uv1, wand)


def wand_fit(
    models: tuple[CameraModel, CameraModel], pose: Pose, uv0: FloatArray, uv1: FloatArray, wand: WandSpec
) -> WandFit:
    """The two cameras ``models``, camera 1 at ``pose`` relative to camera 0, with their wand-length errors on
    the (N, K, 2) pixels ``uv0``, ``uv1`` of the markers of placements both see."""
    return WandFit(models, pose, wand_length_errors(reconstruct_wands(models, pose, uv0, uv1), wand))


def _levenberg_marquardt(
    problem: _WandProblem, x0: FloatArray, *, max_evaluations: int, tolerance: float
) -> FloatArray:
    """The least-squares solution of ``problem`` from ``x0`` (dense, a few parameters).

    Damping ``mu D^2`` with D the largest column norms of the Jacobian seen so far (MINPACK's
    scaling, so that parameters in mm, rad and px weigh alike); mu falls tenfold after a step that
    does what the linearisation promised (so that the last steps are Gauss-Newton's and converge
    quadratically) and grows after a rejected one. Stops after ``max_evaluations`` residual
    evaluations, or when a step decreases the cost by less than ``tolerance`` of it (and promised no
    more), or when a rejected step changed the scaled parameters by less than ``tolerance``
    relatively (MINPACK's ftol and xtol).
    """
    x = np.asarray(x0, dtype=np.float64).copy()
    r, jac = problem.residuals(x), problem.jacobian(x)
    cost = float(r @ r)
    scale = np.zeros_like(x)
    mu, growth = 0.0, 2.0
    for _ in range(max_evaluations - 1):
        norms = np.linalg.norm(jac, axis=0)
        scale = np.maximum(scale, np.where(norms > 0, norms, 1.0))
        normal, gradient = jac.T @ jac, jac.T @ r
        if mu == 0.0:  # start with a damping of 1e-3 of the largest curvature, as Marquardt's
            mu = 1e-3 * float(np.max(np.diag(normal)) / np.max(scale**2))
        try:
            step = np.linalg.solve(normal + mu * np.diag(scale**2), -gradient)
        except np.linalg.LinAlgError:
            mu, growth = mu * growth, growth * 2.0
            continue
        candidate = x + step
        r_new = problem.residuals(candidate)
        new_cost = float(r_new @ r_new)
        predicted = -float(2.0 * step @ gradient + step @ normal @ step)  # decrease of |r|^2, linearised
        actual = cost - new_cost
        if actual > 0 and predicted > 0:
            x, r, jac = candidate, r_new, problem.jacobian(candidate)
            gain = actual / predicted
            mu *= 0.1 if gain > 0.75 else 1.0 if gain > 0.25 else 2.0
            growth = 2.0
            small = actual <= tolerance * cost and predicted <= tolerance * cost
            cost = new_cost
            if small:
                break
        elif np.linalg.norm(scale * step) <= tolerance * (np.linalg.norm(scale * x) + tolerance):
            break  # not even a step this small decreases the cost: converged to rounding
        else:
            mu, growth = mu * growth, growth * 2.0
    return x
