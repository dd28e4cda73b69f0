"""Step 4 of the paper (and Step 2 of Section III-B): wand bundle adjustment.

Unknowns: per camera the intrinsics k1..k5, u0, v0 (m fixed) and the pose
(reference camera's pose fixed), per wand placement j the point A_j and the
wand direction n_j; B_j = A_j + L1 n_j and C_j = A_j + L n_j (paper eq.
orientation). The paper writes n_j with spherical angles (phi_j, theta_j); the
solver updates n_j in its tangent plane instead, which is the same 2 degrees of
freedom without the pole singularity. Poses are updated as R <- exp([d]x) R.

The residual of one observation (camera c sees point p of placement j) is
``project(c, R_c (A_j + offset_p n_j) + T_c) - uv`` in px. The solver is a
Levenberg-Marquardt with exact Jacobians that eliminates the independent
5-dof placement blocks by a Schur complement, so each iteration only solves a
system of size 13 x cameras. Observation arrays are flat and sorted by
placement (the structure the Schur complement needs is computed once).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.linalg
import scipy.sparse
from numpy.typing import NDArray

from wand_calib_ros.core.camera_model import (
    N_INTRINSIC,
    CameraModel,
    project_with_jacobian_arrays,
)
from wand_calib_ros.core.errors import CalibrationFailedError, ModelError
from wand_calib_ros.core.geometry import Pose, rotation_from_rotvec, skew, tangent_basis
from wand_calib_ros.core.rig import WandSpec

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Parameters per camera: k1..k5, u0, v0, rotation (3), translation (3).
N_CAMERA_PARAMS = N_INTRINSIC + 6
#: Parameters per placement: A (3), wand direction (2, tangent plane).
N_PLACEMENT_PARAMS = 5
#: Names of the per-camera parameters in order (rotation as a small-angle update, rad).
CAMERA_PARAM_NAMES = ("k1", "k2", "k3", "k4", "k5", "u0", "v0", "rx", "ry", "rz", "tx", "ty", "tz")


@dataclass(frozen=True, eq=False)
class BundleProblem:
    """Flat observation arrays of a bundle adjustment, sorted by placement.

    Attributes:
        wand: wand lengths.
        n_cameras: number of cameras.
        n_placements: number of placements.
        camera: (M,) camera index of each observation.
        placement: (M,) placement index (non-decreasing).
        point: (M,) 0, 1, 2 for A, B, C.
        uv: (M, 2) observed pixels.
    """

    wand: WandSpec
    n_cameras: int
    n_placements: int
    camera: IntArray
    placement: IntArray
    point: IntArray
    uv: FloatArray

    @staticmethod
    def from_dense(wand: WandSpec, uv: FloatArray) -> BundleProblem:
        """Problem from dense (P, C, 3, 2) pixels with NaN for unseen points."""
        n_placements, n_cameras = uv.shape[:2]
        seen = np.all(np.isfinite(uv), axis=-1)  # (P, C, 3)
        placement, camera, point = np.nonzero(seen)
        return BundleProblem(
            wand,
            n_cameras,
            n_placements,
            camera.astype(np.int64),
            placement.astype(np.int64),
            point.astype(np.int64),
            uv[placement, camera, point],
        )

    @property
    def n_observations(self) -> int:
        return int(self.camera.size)


@dataclass(frozen=True, eq=False)
class BundleState:
    """Values of all unknowns.

    Attributes:
        models: per camera intrinsics.
        poses: per camera pose (X_cam = R X_ref + T).
        wand_a: (P, 3) point A of each placement in the reference frame, mm.
        wand_direction: (P, 3) unit vector from A to C.
    """

    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    wand_a: FloatArray
    wand_direction: FloatArray

    def points(self, wand: WandSpec) -> FloatArray:
        """(P, 3, 3) A, B, C of every placement in the reference frame, mm."""
        return self.wand_a[:, None, :] + wand.offsets[None, :, None] * self.wand_direction[:, None, :]


@dataclass(frozen=True, eq=False)
class BundleResult:
    """Outcome of a bundle adjustment.

    Attributes:
        state: the optimised unknowns.
        residuals: (M, 2) reprojection residuals (projected minus observed), px.
        iterations: LM iterations done.
        converged: whether a convergence criterion was met.
        camera_std: (C, 13) standard deviations of the camera parameters
            (:data:`CAMERA_PARAM_NAMES` order; 0 for fixed ones), from the final Jacobian.
        camera_covariance: (C*13, C*13) covariance of all camera parameters (0 rows/cols for fixed).
        sigma: estimated pixel noise sqrt(sum r^2 / (m - p)), px.
        dof: (m, p) residual scalars and free parameters.
    """

    state: BundleState
    residuals: FloatArray
    iterations: int
    converged: bool
    camera_std: FloatArray
    camera_covariance: FloatArray
    sigma: float
    dof: tuple[int, int]


def _camera_arrays(state: BundleState) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    k = np.stack([m.k for m in state.models])
    mm = np.stack([m.m for m in state.models])
    pp = np.stack([m.principal_point for m in state.models])
    rotations = np.stack([p.rotation for p in state.poses])
    translations = np.stack([p.translation for p in state.poses])
    return k, mm, pp, rotations, translations


def _world_points(state: BundleState, problem: BundleProblem) -> FloatArray:
    offsets = problem.wand.offsets[problem.point]
    return state.wand_a[problem.placement] + offsets[:, None] * state.wand_direction[problem.placement]


def residuals(state: BundleState, problem: BundleProblem) -> FloatArray:
    """(M, 2) reprojection residuals (projected minus observed) in px. Pure."""
    return _linearise(state, problem, jacobians=False)[0]


def _linearise(
    state: BundleState, problem: BundleProblem, *, jacobians: bool = True
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Residuals (M, 2), camera Jacobians (M, 2, 13) and placement Jacobians (M, 2, 5)."""
    k, mm, pp, rotations, translations = _camera_arrays(state)
    c = problem.camera
    world = _world_points(state, problem)
    rotated = np.einsum("mij,mj->mi", rotations[c], world)
    projection = project_with_jacobian_arrays(k[c], mm[c], pp[c], rotated + translations[c])
    res = projection.uv - problem.uv
    if not jacobians:
        return res, np.empty(0), np.empty(0)
    dp = projection.d_point  # (M, 2, 3)
    jc = np.empty((res.shape[0], 2, N_CAMERA_PARAMS))
    jc[:, :, :N_INTRINSIC] = projection.d_intrinsics
    jc[:, :, N_INTRINSIC : N_INTRINSIC + 3] = -np.einsum("mij,mjk->mik", dp, skew(rotated))
    jc[:, :, N_INTRINSIC + 3 :] = dp
    dp_r = np.einsum("mij,mjk->mik", dp, rotations[c])  # d uv / d world point
    basis = tangent_basis(state.wand_direction)[problem.placement]  # (M, 3, 2)
    offsets = problem.wand.offsets[problem.point]
    jp = np.empty((res.shape[0], 2, N_PLACEMENT_PARAMS))
    jp[:, :, :3] = dp_r
    jp[:, :, 3:] = offsets[:, None, None] * np.einsum("mij,mjk->mik", dp_r, basis)
    return res, jc, jp


def _apply_step(state: BundleState, delta_c: FloatArray, delta_p: FloatArray) -> BundleState:
    models, poses = [], []
    for model, pose, d in zip(state.models, state.poses, delta_c, strict=True):
        models.append(model.with_intrinsic_vector(model.intrinsic_vector() + d[:N_INTRINSIC]))
        rotation = rotation_from_rotvec(d[N_INTRINSIC : N_INTRINSIC + 3]) @ pose.rotation
        poses.append(Pose(rotation, pose.translation + d[N_INTRINSIC + 3 :]))
    basis = tangent_basis(state.wand_direction)
    direction = state.wand_direction + np.einsum("pij,pj->pi", basis, delta_p[:, 3:])
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return BundleState(tuple(models), tuple(poses), state.wand_a + delta_p[:, :3], direction)


@dataclass(frozen=True, eq=False)
class _Structure:
    """Index structure of the Schur complement, computed once per problem."""

    block_of_obs: IntArray  # (M,) block id of each observation; blocks = (placement, camera) pairs
    block_camera: IntArray  # (B,)
    block_placement: IntArray  # (B,)
    block_starts: IntArray  # (B,) first observation of each block (observations sorted by block)
    placement_block_starts: IntArray  # (P,) first block of each placement
    pair_first: IntArray  # (Q,) block pairs inside a placement
    pair_second: IntArray
    observations_of_camera: tuple[IntArray, ...]  # per camera, its observation indices
    block_to_camera: scipy.sparse.csr_matrix  # (C, B) indicator
    pair_to_camera_pair: scipy.sparse.csr_matrix  # (C*C, Q) indicator


def _structure(problem: BundleProblem) -> _Structure:
    order_key = problem.placement * problem.n_cameras + problem.camera
    if np.any(np.diff(order_key) < 0):
        raise ValueError("observations must be sorted by placement, then camera")
    keys, block_starts, block_of_obs = np.unique(order_key, return_index=True, return_inverse=True)
    block_camera = keys % problem.n_cameras
    block_placement = keys // problem.n_cameras
    if np.unique(block_placement).size != problem.n_placements:
        raise CalibrationFailedError("a placement has no observation")
    placement_block_starts = np.searchsorted(block_placement, np.arange(problem.n_placements))
    counts = np.diff(np.append(placement_block_starts, keys.size))
    firsts, seconds = [], []
    for count in np.unique(counts):
        starts = placement_block_starts[counts == count]
        a, b = np.meshgrid(np.arange(count), np.arange(count), indexing="ij")
        firsts.append((starts[:, None] + a.ravel()[None, :]).ravel())
        seconds.append((starts[:, None] + b.ravel()[None, :]).ravel())
    pair_first, pair_second = np.concatenate(firsts), np.concatenate(seconds)
    c = problem.n_cameras

    def indicator(rows: IntArray, n_rows: int) -> scipy.sparse.csr_matrix:
        return scipy.sparse.csr_matrix((np.ones(rows.size), (rows, np.arange(rows.size))), shape=(n_rows, rows.size))

    return _Structure(
        block_of_obs,
        block_camera,
        block_placement,
        block_starts,
        placement_block_starts,
        pair_first,
        pair_second,
        tuple(np.flatnonzero(problem.camera == i) for i in range(c)),
        indicator(block_camera, c),
        indicator(block_camera[pair_first] * c + block_camera[pair_second], c * c),
    )


def _normal_equations(
    res: FloatArray, jc: FloatArray, jp: FloatArray, structure: _Structure, problem: BundleProblem
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """U (C,13,13), V (P,5,5), W (B,13,5), gc (C,13), gp (P,5) with g = -J^T r."""
    n_c, n_p = problem.n_cameras, problem.n_placements
    u = np.empty((n_c, N_CAMERA_PARAMS, N_CAMERA_PARAMS))
    gc = np.empty((n_c, N_CAMERA_PARAMS))
    for c in range(n_c):
        rows = jc[structure.observations_of_camera[c]].reshape(-1, N_CAMERA_PARAMS)
        u[c] = rows.T @ rows
        gc[c] = -(rows.T @ res[structure.observations_of_camera[c]].reshape(-1))
    jc_t = jc.transpose(0, 2, 1)
    w = np.add.reduceat(jc_t @ jp, structure.block_starts, axis=0)
    obs_placement_starts = structure.block_starts[structure.placement_block_starts]
    v = np.add.reduceat(jp.transpose(0, 2, 1) @ jp, obs_placement_starts, axis=0)
    gp = -np.add.reduceat((jp.transpose(0, 2, 1) @ res[..., None])[..., 0], obs_placement_starts, axis=0)
    assert v.shape[0] == n_p
    return u, v, w, gc, gp


def _reduced_system(
    u: FloatArray,
    v_inv: FloatArray,
    w: FloatArray,
    gc: FloatArray,
    gp: FloatArray,
    structure: _Structure,
    n_cameras: int,
    chunk: int = 200_000,
) -> tuple[FloatArray, FloatArray]:
    """Schur complement S = U - W V^-1 W^T (dense, C*13 square) and its right-hand side."""
    y = w @ v_inv[structure.block_placement]  # (B, 13, 5)
    size = n_cameras * N_CAMERA_PARAMS
    reduced = np.zeros((n_cameras, n_cameras, N_CAMERA_PARAMS, N_CAMERA_PARAMS))
    for start in range(0, structure.pair_first.size, chunk):
        first = structure.pair_first[start : start + chunk]
        second = structure.pair_second[start : start + chunk]
        products = (y[first] @ w[second].transpose(0, 2, 1)).reshape(first.size, -1)
        reduced -= (structure.pair_to_camera_pair[:, start : start + chunk] @ products).reshape(reduced.shape)
    idx = np.arange(n_cameras)
    reduced[idx, idx] += u
    s = reduced.transpose(0, 2, 1, 3).reshape(size, size)
    y_gp = (y @ gp[structure.block_placement][..., None])[..., 0]
    rhs = (gc - structure.block_to_camera @ y_gp).reshape(size)
    return s, rhs


def _back_substitute(
    delta_c: FloatArray, v_inv: FloatArray, w: FloatArray, gp: FloatArray, structure: _Structure
) -> FloatArray:
    wt_dc = (w.transpose(0, 2, 1) @ delta_c[structure.block_camera][..., None])[..., 0]  # (B, 5)
    per_placement = np.add.reduceat(wt_dc, structure.placement_block_starts, axis=0)
    return (v_inv @ (gp - per_placement)[..., None])[..., 0]


def _damp(blocks: FloatArray, lam: float) -> FloatArray:
    diag = np.einsum("...ii->...i", blocks)
    floor = 1e-9 * max(float(np.max(diag, initial=0.0)), 1e-12)
    damped = blocks.copy()
    idx = np.arange(blocks.shape[-1])
    damped[..., idx, idx] += lam * np.maximum(diag, floor) + 1e-12 * floor
    return damped


def _solve_free(s: FloatArray, rhs: FloatArray, free: NDArray[np.bool_]) -> FloatArray:
    delta = np.zeros_like(rhs)
    if not free.any():
        return delta
    sub = s[np.ix_(free, free)]
    try:
        delta[free] = scipy.linalg.cho_solve(scipy.linalg.cho_factor(sub), rhs[free])
    except np.linalg.LinAlgError:
        delta[free] = np.linalg.lstsq(sub, rhs[free], rcond=None)[0]
    return delta


def default_free_mask(n_cameras: int, reference: int = 0) -> NDArray[np.bool_]:
    """(C, 13) mask: every intrinsic free, every pose but the reference camera's free."""
    free = np.ones((n_cameras, N_CAMERA_PARAMS), dtype=bool)
    free[reference, N_INTRINSIC:] = False
    return free


def bundle_adjust(
    state: BundleState,
    problem: BundleProblem,
    free: NDArray[np.bool_],
    *,
    max_iterations: int = 100,
    tolerance: float = 1e-8,
) -> BundleResult:
    """Sparse Levenberg-Marquardt over all unknowns (paper's bundle adjustment).

    Args:
        state: initial values (Step 3 result, placements from triangulation).
        problem: the observations, sorted by placement then camera.
        free: (C, 13) which camera parameters are estimated (see :func:`default_free_mask`).
        max_iterations: LM iteration cap.
        tolerance: stop when the relative cost decrease or the relative step falls below it.

    Returns:
        The optimised state, residuals and parameter uncertainties.
    """
    structure = _structure(problem)
    free_flat = free.reshape(-1)
    lam = 1e-4
    res, jc, jp = _linearise(state, problem)
    if not np.all(np.isfinite(res)):
        raise CalibrationFailedError("the bundle adjustment starts from non-finite reprojections")
    cost = float(np.sum(res**2))
    iterations, converged = 0, False
    while iterations < max_iterations and not converged:
        iterations += 1
        u, v, w, gc, gp = _normal_equations(res, jc, jp, structure, problem)
        accepted = False
        for _ in range(30):
            v_inv = np.linalg.inv(_damp(v, lam))
            s, rhs = _reduced_system(_damp(u, lam), v_inv, w, gc, gp, structure, problem.n_cameras)
            delta_c = _solve_free(s, rhs, free_flat).reshape(problem.n_cameras, N_CAMERA_PARAMS)
            delta_p = _back_substitute(delta_c, v_inv, w, gp, structure)
            try:
                candidate = _apply_step(state, delta_c, delta_p)
            except ModelError:  # e.g. k1 <= 0: not a camera, reject the step
                lam *= 10.0
                continue
            # Jacobians come with the trial residuals: steps are rarely rejected near a solution.
            new_res, new_jc, new_jp = _linearise(candidate, problem)
            new_cost = float(np.sum(new_res**2)) if np.all(np.isfinite(new_res)) else np.inf
            if new_cost < cost:
                accepted = True
                relative_decrease = (cost - new_cost) / max(cost, 1e-300)
                state, cost = candidate, new_cost
                lam = max(lam / 5.0, 1e-12)
                res, jc, jp = new_res, new_jc, new_jp
                step_small = np.max(np.abs(delta_c)) < tolerance and np.max(np.abs(delta_p)) < tolerance * 1e3
                converged = relative_decrease < tolerance or step_small
                break
            lam *= 10.0
        if not accepted:
            converged = True  # no decrease possible: at a minimum to machine precision
    u, v, w, gc, gp = _normal_equations(res, jc, jp, structure, problem)
    covariance, sigma, dof = _camera_covariance(res, u, v, w, gc, gp, structure, problem, free_flat)
    camera_std = np.sqrt(np.clip(np.diag(covariance), 0.0, None)).reshape(problem.n_cameras, N_CAMERA_PARAMS)
    return BundleResult(state, res, iterations, converged, camera_std, covariance, sigma, dof)


def _camera_covariance(
    res: FloatArray,
    u: FloatArray,
    v: FloatArray,
    w: FloatArray,
    gc: FloatArray,
    gp: FloatArray,
    structure: _Structure,
    problem: BundleProblem,
    free_flat: NDArray[np.bool_],
) -> tuple[FloatArray, float, tuple[int, int]]:
    """Marginal covariance of the camera parameters: sigma^2 * S^-1 (S = Schur complement of J^T J)."""
    m = res.size
    p = int(free_flat.sum()) + N_PLACEMENT_PARAMS * problem.n_placements
    sigma2 = float(np.sum(res**2)) / max(m - p, 1)
    v_inv = np.linalg.pinv(v)
    s, _ = _reduced_system(u, v_inv, w, gc, gp, structure, problem.n_cameras)
    covariance = np.zeros_like(s)
    sub = s[np.ix_(free_flat, free_flat)]
    covariance[np.ix_(free_flat, free_flat)] = np.linalg.pinv(sub, hermitian=True) * sigma2
    return covariance, float(np.sqrt(sigma2)), (m, p)


def with_placements(state: BundleState, wand_a: FloatArray, wand_direction: FloatArray) -> BundleState:
    """A copy of ``state`` with other placements."""
    return replace(state, wand_a=wand_a, wand_direction=wand_direction)
