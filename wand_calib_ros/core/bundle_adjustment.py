"""Step 4 of the paper (and Step 2 of Section III-B): wand bundle adjustment.

Unknowns: per camera the intrinsics k1..k5, u0, v0 (m fixed), the pose
(reference camera's pose fixed) and, for cameras that are not hardware-triggered,
a time offset and a rolling-shutter readout time; per wand placement j the point
A_j and the wand direction n_j; B_j = A_j + L1 n_j and C_j = A_j + L n_j (paper
eq. orientation). The paper writes n_j with spherical angles (phi_j, theta_j);
the solver updates n_j in its tangent plane instead, which is the same 2 degrees
of freedom without the pole singularity. Poses are updated as R <- exp([d]x) R.

The residual of one observation (camera c sees point p of placement j) is
``project(c, R_c X + T_c) - uv`` in px with ``X = A_j + offset_p n_j``. Cameras
that are not synchronised see the moving wand at their own instants: with timing,
the point is carried along the wand's motion to the instant its camera saw it,
``X + tau V + tau^2 / 2 Acc + tau^3 / 6 Jerk``, ``tau = time - dt_c + readout_c * v / H`` (``time``
the stamp of the observation's image relative to its placement's time, ``dt_c`` the
camera's time offset: exposure = stamp - dt_c; v the observed row, H the image
height; V, Acc and Jerk the point's velocity and its derivatives at the placement's
time, held fixed during one adjustment).

The solver is a Levenberg-Marquardt with exact Jacobians that eliminates the
independent 5-dof placement blocks by a Schur complement, so each iteration only
solves a system of size 13 (plus the timing parameters in use) x cameras.
Observation arrays are flat and sorted by placement (the structure the Schur
complement needs is computed once).
"""

from __future__ import annotations

import itertools
import logging
from dataclasses import dataclass

import numpy as np
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
log = logging.getLogger(__name__)
IntArray = NDArray[np.int64]

#: Geometric parameters per camera: k1..k5, u0, v0, rotation (3), translation (3).
N_GEOMETRIC = N_INTRINSIC + 6
#: Parameters per camera: the geometric ones, then the time offset and the rolling-shutter readout time.
N_CAMERA_PARAMS = N_GEOMETRIC + 2
#: Indices of the timing parameters in a camera's parameter vector.
TIME_OFFSET, READOUT = N_GEOMETRIC, N_GEOMETRIC + 1
#: Parameters per placement: A (3), wand direction (2, tangent plane).
N_PLACEMENT_PARAMS = 5
#: Names of the per-camera parameters in order (rotation as a small-angle update, rad; the timing
#: parameters in the time unit of the observations).
CAMERA_PARAM_NAMES = (
    "k1", "k2", "k3", "k4", "k5", "u0", "v0", "rx", "ry", "rz", "tx", "ty", "tz", "time_offset", "readout",
)  # fmt: skip


@dataclass(frozen=True, eq=False)
class ObservationTiming:
    """When each observation of a :class:`BundleProblem` was seen, and how its point moved.

    Attributes:
        time: (M,) stamp of the observation's image relative to its placement's time.
        row: (M,) observed v / image height (0 at the top row).
        velocity: (M, 3) velocity of the observed point at its placement's time, reference frame.
        acceleration: (M, 3) its acceleration.
        jerk: (M, 3) its jerk (the derivative of the acceleration).
    """

    time: FloatArray
    row: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    jerk: FloatArray


@dataclass(frozen=True, eq=False)
class PlacementTiming:
    """When each camera saw each placement, and how the wand moved there.

    Attributes:
        times: (P, C) stamp of each camera's image relative to the placement's time (0 for
            synchronised cameras; any value where unseen), in the time unit of the observations.
        heights: (C,) image heights, px (a rolling shutter reads row v at v / H of its readout time).
        velocity: (P, 3, 3) velocity of A, B, C at the placement's time, reference frame, mm per time unit.
        acceleration: (P, 3, 3) their acceleration, mm per time unit squared.
        jerk: (P, 3, 3) their jerk, mm per time unit cubed.
    """

    times: FloatArray
    heights: FloatArray
    velocity: FloatArray
    acceleration: FloatArray
    jerk: FloatArray

    def __post_init__(self) -> None:
        n_placements, n_cameras = self.times.shape
        if self.heights.shape != (n_cameras,):
            raise ValueError(f"heights must have shape ({n_cameras},), got {self.heights.shape}")
        for name in ("velocity", "acceleration", "jerk"):
            shape = getattr(self, name).shape
            if len(shape) != 3 or shape[0] != n_placements or shape[2] != 3:
                raise ValueError(f"{name} must have shape ({n_placements}, K, 3), got {shape}")

    def subset(self, index: IntArray | NDArray[np.bool_]) -> PlacementTiming:
        """The timing of some placements (an index or mask over axis 0)."""
        return PlacementTiming(
            self.times[index], self.heights, self.velocity[index], self.acceleration[index], self.jerk[index]
        )

    def observations(self, placement: IntArray, camera: IntArray, point: IntArray, uv: FloatArray) -> ObservationTiming:
        """The flat per-observation arrays of the views ``(placement, camera, point)`` seen at ``uv`` (M, 2)."""
        return ObservationTiming(
            self.times[placement, camera],
            uv[:, 1] / self.heights[camera],
            self.velocity[placement, point],
            self.acceleration[placement, point],
            self.jerk[placement, point],
        )


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
        timing: when each observation was seen and how its point moved (None: every camera saw a
            placement at one instant, as hardware-triggered global shutters do).
    """

    wand: WandSpec
    n_cameras: int
    n_placements: int
    camera: IntArray
    placement: IntArray
    point: IntArray
    uv: FloatArray
    timing: ObservationTiming | None = None

    @staticmethod
    def from_dense(wand: WandSpec, uv: FloatArray, timing: PlacementTiming | None = None) -> BundleProblem:
        """Problem from dense (P, C, 3, 2) pixels with NaN for unseen points, and their timing."""
        n_placements, n_cameras = uv.shape[:2]
        seen = np.all(np.isfinite(uv), axis=-1)  # (P, C, 3)
        placement, camera, point = (i.astype(np.int64) for i in np.nonzero(seen))
        observed = uv[placement, camera, point]
        return BundleProblem(
            wand,
            n_cameras,
            n_placements,
            camera,
            placement,
            point,
            observed,
            None if timing is None else timing.observations(placement, camera, point, observed),
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
        timing: (C, 2) per camera time offset (exposure = stamp - offset) and rolling-shutter readout
            time, in the time unit of the observations; None: all zero.
    """

    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    wand_a: FloatArray
    wand_direction: FloatArray
    timing: FloatArray | None = None

    @property
    def camera_timing(self) -> FloatArray:
        """(C, 2) time offset and readout time per camera (zeros when not modelled)."""
        return np.zeros((len(self.models), 2)) if self.timing is None else self.timing

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
        camera_std: (C, 15) standard deviations of the camera parameters
            (:data:`CAMERA_PARAM_NAMES` order; 0 for fixed ones), from the final Jacobian.
        camera_covariance: (C*15, C*15) covariance of all camera parameters (0 rows/cols for fixed).
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

    def camera_block(self, camera: int, parameters: slice) -> FloatArray:
        """The covariance of some of one camera's parameters (a slice of :data:`CAMERA_PARAM_NAMES`)."""
        first = camera * N_CAMERA_PARAMS
        block = slice(first + (parameters.start or 0), first + (parameters.stop or N_CAMERA_PARAMS))
        return self.camera_covariance[block, block]


def _camera_arrays(state: BundleState) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    k = np.stack([m.k for m in state.models])
    mm = np.stack([m.m for m in state.models])
    pp = np.stack([m.principal_point for m in state.models])
    rotations = np.stack([p.rotation for p in state.poses])
    translations = np.stack([p.translation for p in state.poses])
    return k, mm, pp, rotations, translations


def _world_points(state: BundleState, problem: BundleProblem) -> tuple[FloatArray, FloatArray | None]:
    """(M, 3) observed points where their cameras saw them, and d(point)/d(tau) (None without timing)."""
    offsets = problem.wand.offsets[problem.point]
    world = state.wand_a[problem.placement] + offsets[:, None] * state.wand_direction[problem.placement]
    timing = problem.timing
    if timing is None:
        return world, None
    dt, readout = state.camera_timing[problem.camera].T
    tau = timing.time - dt + readout * timing.row
    half = (0.5 * tau * tau)[:, None]
    world = world + tau[:, None] * (timing.velocity + half / 3.0 * timing.jerk) + half * timing.acceleration
    return world, timing.velocity + tau[:, None] * timing.acceleration + half * timing.jerk


def residuals(state: BundleState, problem: BundleProblem) -> FloatArray:
    """(M, 2) reprojection residuals (projected minus observed) in px. Pure."""
    return _linearise(state, problem, jacobians=False)[0]


def timing_columns(free: NDArray[np.bool_]) -> IntArray:
    """Timing parameters (indices into :data:`CAMERA_PARAM_NAMES`) free for at least one camera.

    The adjustment carries the 13 geometric parameters of every camera and only these timing
    ones, so a synchronised rig costs what it did before timing was modelled.
    """
    return (np.flatnonzero(free[:, N_GEOMETRIC:].any(axis=0)) + N_GEOMETRIC).astype(np.int64)


#: No timing parameter carried.
_NO_TIMING = np.empty(0, dtype=np.int64)


def _linearise(
    state: BundleState,
    problem: BundleProblem,
    *,
    jacobians: bool = True,
    cameras: bool = True,
    timing: IntArray = _NO_TIMING,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Residuals (M, 2), camera Jacobians (M, 2, 13 + len(timing); empty unless ``cameras``) and
    placement Jacobians (M, 2, 5)."""
    k, mm, pp, rotations, translations = _camera_arrays(state)
    c = problem.camera
    world, d_tau = _world_points(state, problem)
    camera_rotations = rotations[c]
    rotated = (camera_rotations @ world[..., None])[..., 0]
    projection = project_with_jacobian_arrays(k[c], mm[c], pp[c], rotated + translations[c])
    res = projection.uv - problem.uv
    if not jacobians:
        return res, np.empty(0), np.empty(0)
    dp = projection.d_point  # (M, 2, 3)
    dp_r = dp @ camera_rotations  # d uv / d world point
    width = N_GEOMETRIC + timing.size
    jc = np.empty((0, 2, width))
    if cameras:
        jc = np.empty((res.shape[0], 2, width))
        jc[:, :, :N_INTRINSIC] = projection.d_intrinsics
        jc[:, :, N_INTRINSIC : N_INTRINSIC + 3] = -(dp @ skew(rotated))
        jc[:, :, N_INTRINSIC + 3 : N_GEOMETRIC] = dp
        if timing.size:
            if d_tau is None or problem.timing is None:
                raise ValueError("timing parameters need the observations' timing")
            along = (dp_r @ d_tau[..., None])[..., 0]  # d uv / d tau, (M, 2)
            for i, column in enumerate(timing):
                jc[:, :, N_GEOMETRIC + i] = -along if column == TIME_OFFSET else problem.timing.row[:, None] * along
    basis = tangent_basis(state.wand_direction)[problem.placement]  # (M, 3, 2)
    offsets = problem.wand.offsets[problem.point]
    jp = np.empty((res.shape[0], 2, N_PLACEMENT_PARAMS))
    jp[:, :, :3] = dp_r
    jp[:, :, 3:] = offsets[:, None, None] * (dp_r @ basis)
    return res, jc, jp


def _apply_step(state: BundleState, delta_c: FloatArray, delta_p: FloatArray, timing: IntArray) -> BundleState:
    """The state moved by camera steps (C, 13 + len(timing)) and placement steps (P, 5)."""
    models, poses = [], []
    for model, pose, d in zip(state.models, state.poses, delta_c, strict=True):
        models.append(model.with_intrinsic_vector(model.intrinsic_vector() + d[:N_INTRINSIC]))
        rotation = rotation_from_rotvec(d[N_INTRINSIC : N_INTRINSIC + 3]) @ pose.rotation
        poses.append(Pose(rotation, pose.translation + d[N_INTRINSIC + 3 : N_GEOMETRIC]))
    camera_timing = state.timing
    if timing.size:
        camera_timing = state.camera_timing.copy()
        camera_timing[:, timing - N_GEOMETRIC] += delta_c[:, N_GEOMETRIC:]
    basis = tangent_basis(state.wand_direction)
    direction = state.wand_direction + np.einsum("pij,pj->pi", basis, delta_p[:, 3:])
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return BundleState(tuple(models), tuple(poses), state.wand_a + delta_p[:, :3], direction, camera_timing)


@dataclass(frozen=True, eq=False)
class _Structure:
    """Index structure of the normal equations and the Schur complement, computed once per adjustment.

    A block is one (placement, camera) pair. Every sum over observations is the product of a sparse
    matrix whose nonzeros are the Jacobian entries themselves (the Jacobian array is its data, in place)
    with a dense Jacobian: one C loop over the nonzeros instead of a stack of tiny matrix products.
    """

    block_camera: IntArray  # (B,)
    block_placement: IntArray  # (B,) non-decreasing
    placement_block_starts: IntArray  # (P,) first block of each placement
    block_to_camera: scipy.sparse.csr_matrix  # (C, B) sums blocks into their camera
    schur_chunks: tuple[_SchurChunk, ...]  # placements with similar cameras, for S = U - Z Z^T
    width: int  # camera parameters carried: 13 + timing ones
    # CSC layouts of (rows x params) -> (params x rows) scatter matrices, data filled per iteration:
    # row r (of the 2M residual rows) with parameter j goes to output row index[r * n + j].
    by_block: NDArray[np.int32]  # (2M * 5,) 5 * block + j
    by_placement: NDArray[np.int32]  # (2M * 5,) 5 * placement + j
    by_camera: NDArray[np.int32]  # (2M * width,) width * camera + j


@dataclass(frozen=True, eq=False)
class _SchurChunk:
    """Placements accumulated into the Schur complement together, and the cameras they are seen by.

    Attributes:
        n_placements: placements in the chunk (n).
        blocks: (b,) their blocks.
        position: (b,) each block's row in the chunk's dense (n * u, 5, K) array: placement-major.
        cameras: (u,) the cameras seeing them, ascending.
    """

    n_placements: int
    blocks: IntArray
    position: IntArray
    cameras: IntArray


#: An adjustment stops when the cameras' next step is worth less than this fraction of a chi-square
#: unit (sigma^2): every camera parameter within a few hundredths of its standard deviation of where
#: the step would take it. Left alone, placements seen by two nearly parallel rays make a large rig
#: creep by 1e-8 of its cost per iteration for tens of iterations without moving a camera.
CAMERAS_SETTLED = 1e-3

#: Placements per Schur chunk: small enough that a chunk's placements share most of their cameras
#: once sorted by which cameras see them, large enough for one BLAS product to pay.
_SCHUR_CHUNK = 128


def _schur_chunks(block_camera: IntArray, block_placement: IntArray, n_cameras: int) -> tuple[_SchurChunk, ...]:
    """Placements sorted by the set of cameras seeing them (lexicographically), cut into chunks."""
    n_placements = int(block_placement[-1]) + 1
    seen = np.zeros((n_placements, n_cameras), dtype=bool)
    seen[block_placement, block_camera] = True
    rank = np.empty(n_placements, dtype=np.int64)
    rank[np.lexsort(seen[:, ::-1].T)] = np.arange(n_placements)
    block_rank = rank[block_placement]
    order = np.argsort(block_rank, kind="stable")
    bounds = np.searchsorted(block_rank[order], np.arange(0, n_placements + _SCHUR_CHUNK, _SCHUR_CHUNK))
    chunks = []
    for i, (first, last) in enumerate(itertools.pairwise(bounds)):
        if first == last:
            continue
        blocks = order[first:last]
        cameras, local = np.unique(block_camera[blocks], return_inverse=True)
        n = int(block_rank[blocks[-1]] - i * _SCHUR_CHUNK + 1)
        chunks.append(_SchurChunk(n, blocks, (block_rank[blocks] - i * _SCHUR_CHUNK) * cameras.size + local, cameras))
    return tuple(chunks)


def _scatter(index: NDArray[np.int32], data: FloatArray, n_out: int) -> scipy.sparse.csc_matrix:
    """(n_out, R) sparse matrix whose column r holds ``data[r]`` (R, n) at rows ``index[r * n : r * n + n]``."""
    n_rows, n = data.shape
    indptr = np.arange(0, n_rows * n + 1, n, dtype=np.int32)
    matrix = scipy.sparse.csc_matrix((n_out, n_rows))
    matrix.data, matrix.indices, matrix.indptr = data.reshape(-1), index, indptr  # trusted: no format check
    return matrix


def _spread(rows: IntArray, n: int) -> NDArray[np.int32]:
    """(2M * n,) output rows ``n * rows[r] + j`` for each residual row r (two per observation) and j < n."""
    per_row = np.repeat(rows, 2)
    return (n * per_row[:, None] + np.arange(n)).reshape(-1).astype(np.int32)


def _structure(problem: BundleProblem, width: int) -> _Structure:
    """The index structure of ``problem`` with ``width`` camera parameters carried (0: placements only)."""
    order_key = problem.placement * problem.n_cameras + problem.camera
    if np.any(np.diff(order_key) < 0):
        raise ValueError("observations must be sorted by placement, then camera")
    keys, block_of_obs = np.unique(order_key, return_inverse=True)
    block_camera = keys % problem.n_cameras
    block_placement = keys // problem.n_cameras
    if np.unique(block_placement).size != problem.n_placements:
        raise CalibrationFailedError("a placement has no observation")
    c, p, b = problem.n_cameras, problem.n_placements, keys.size
    if 2 * problem.n_observations * max(width, N_PLACEMENT_PARAMS) >= np.iinfo(np.int32).max:
        raise CalibrationFailedError(f"{problem.n_observations} observations: more than one adjustment can hold")
    cameras = width > 0
    return _Structure(
        block_camera,
        block_placement,
        np.searchsorted(block_placement, np.arange(p)),
        scipy.sparse.csr_matrix((np.ones(b), (block_camera, np.arange(b))), shape=(c, b)),
        _schur_chunks(block_camera, block_placement, c) if cameras else (),
        width,
        _spread(block_of_obs, N_PLACEMENT_PARAMS if cameras else 0),
        _spread(problem.placement, N_PLACEMENT_PARAMS),
        _spread(problem.camera, width),
    )


def _huber_weights(res: FloatArray, loss_scale: float | None) -> FloatArray:
    """(M,) IRLS weights of the Huber loss on each observation's 2D residual norm (1 = least squares)."""
    if loss_scale is None:
        return np.ones(res.shape[0])
    norm = np.linalg.norm(res, axis=1)
    return np.where(norm <= loss_scale, 1.0, loss_scale / np.maximum(norm, 1e-300))


def robust_cost(res: FloatArray, loss_scale: float | None) -> float:
    """Sum of the Huber loss of the 2D residual norms (sum of squares when loss_scale is None)."""
    squared = np.sum(res**2, axis=1)
    if loss_scale is None:
        return float(np.sum(squared))
    norm = np.sqrt(squared)
    return float(np.sum(np.where(norm <= loss_scale, squared, 2 * loss_scale * norm - loss_scale**2)))


def _normal_equations(
    res: FloatArray, jc: FloatArray, jp: FloatArray, weights: FloatArray, structure: _Structure, n_cameras: int
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """U (C,K,K), V (P,5,5), W (B,K,5), gc (C,K), gp (P,5) of the weighted problem, g = -J^T W r (K = jc width)."""
    if not np.all(weights == 1.0):
        root = np.sqrt(weights)[:, None, None]
        jc, jp, res = jc * root[: jc.shape[0]], jp * root, res * root[:, :, 0]
    rows = 2 * res.shape[0]
    jp_rows, res_rows = jp.reshape(rows, N_PLACEMENT_PARAMS), res.reshape(rows)
    n_placements = int(structure.placement_block_starts.size)
    to_placement = _scatter(structure.by_placement, jp_rows, N_PLACEMENT_PARAMS * n_placements)
    v = (to_placement @ jp_rows).reshape(-1, N_PLACEMENT_PARAMS, N_PLACEMENT_PARAMS)
    gp = -(to_placement @ res_rows).reshape(-1, N_PLACEMENT_PARAMS)
    if jc.shape[0] == 0:  # placements only
        return np.empty((0,)), v, np.empty((0,)), np.empty((0,)), gp
    width = jc.shape[2]
    jc_rows = jc.reshape(rows, width)
    to_camera = _scatter(structure.by_camera, jc_rows, width * n_cameras)
    u = (to_camera @ jc_rows).reshape(n_cameras, width, width)
    gc = -(to_camera @ res_rows).reshape(n_cameras, width)
    to_block = _scatter(structure.by_block, jp_rows, N_PLACEMENT_PARAMS * structure.block_camera.size)
    w = (to_block @ jc_rows).reshape(-1, N_PLACEMENT_PARAMS, width).transpose(0, 2, 1)
    return u, v, w, gc, gp


def _inverse_and_root(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """V^-1 and a factor L with L L^T = V^-1 for (P, 5, 5) symmetric positive definite blocks."""
    v_inv = np.linalg.inv(v)
    v_inv = 0.5 * (v_inv + v_inv.transpose(0, 2, 1))
    try:
        return v_inv, np.asarray(np.linalg.cholesky(v_inv), dtype=np.float64)
    except np.linalg.LinAlgError:  # numerically semi-definite: symmetric square root
        values, vectors = np.linalg.eigh(v_inv)
        return v_inv, vectors * np.sqrt(np.clip(values, 0.0, None))[:, None, :]


def _reduced_system(
    u: FloatArray,
    v: FloatArray,
    w: FloatArray,
    gc: FloatArray,
    gp: FloatArray,
    structure: _Structure,
    n_cameras: int,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Schur complement S = U - W V^-1 W^T (dense, KC square), its right-hand side and V^-1.

    With L L^T = V_j^-1 and Z_b = W_b L_j, S = U - Z Z^T where Z is the (KC x 5P) matrix of the
    blocks Z_b: one BLAS product per chunk of placements, over the cameras that chunk's placements
    are seen by (so cameras that share no placement cost nothing).
    """
    v_inv, root = _inverse_and_root(v)
    z = w @ root[structure.block_placement]  # (B, K, 5)
    width = u.shape[1]
    size = n_cameras * width
    by_block = np.zeros((n_cameras, n_cameras, width, width))  # camera-block layout: whole blocks per update
    by_block[np.arange(n_cameras), np.arange(n_cameras)] = u
    z_t = z.transpose(0, 2, 1)  # (B, 5, K)
    for chunk in structure.schur_chunks:
        n, u_local = chunk.n_placements, chunk.cameras.size
        blocks = np.zeros((n * u_local, N_PLACEMENT_PARAMS, width))  # (placement, camera) major
        blocks[chunk.position] = z_t[chunk.blocks]
        dense = blocks.reshape(n, u_local, N_PLACEMENT_PARAMS, width).transpose(0, 2, 1, 3)
        flat = dense.reshape(n * N_PLACEMENT_PARAMS, u_local * width)  # rows (placement, j), columns (camera, k)
        product = (flat.T @ flat).reshape(u_local, width, u_local, width).transpose(0, 2, 1, 3)
        by_block[chunk.cameras[:, None], chunk.cameras[None, :]] -= product
    s = by_block.transpose(0, 2, 1, 3).reshape(size, size)
    # rhs = gc - sum_b W_b V_j^-1 gp_j = gc - sum_b Z_b (L_j^T gp_j)
    projected = (root.transpose(0, 2, 1) @ gp[..., None])[..., 0]  # (P, 5)
    per_block = (z @ projected[structure.block_placement][..., None])[..., 0]  # (B, K)
    rhs = (gc - structure.block_to_camera @ per_block).reshape(size)
    return s, rhs, v_inv


def _back_substitute(
    delta_c: FloatArray, v_inv: FloatArray, w: FloatArray, gp: FloatArray, structure: _Structure
) -> FloatArray:
    wt_dc = (w.transpose(0, 2, 1) @ delta_c[structure.block_camera][..., None])[..., 0]  # (B, 5)
    per_placement = np.add.reduceat(wt_dc, structure.placement_block_starts, axis=0)
    return (v_inv @ (gp - per_placement)[..., None])[..., 0]


def _scaling(blocks: FloatArray) -> FloatArray:
    """(..., n) the Levenberg-Marquardt scaling D of (..., n, n) diagonal blocks: their diagonal, floored."""
    diag = np.einsum("...ii->...i", blocks)
    return np.maximum(diag, 1e-9 * max(float(np.max(diag, initial=0.0)), 1e-12))


def _damp(blocks: FloatArray, lam: float) -> FloatArray:
    """The blocks plus lam D (and a trace of D, so that zero rows stay solvable)."""
    scaling = _scaling(blocks)
    damped = blocks.copy()
    idx = np.arange(blocks.shape[-1])
    damped[..., idx, idx] += lam * scaling + 1e-12 * float(np.min(scaling, initial=1.0))
    return damped


def _solve_free(s: FloatArray, rhs: FloatArray, free: NDArray[np.bool_]) -> FloatArray:
    delta = np.zeros_like(rhs)
    if not free.any():
        return delta
    sub = s[np.ix_(free, free)]
    try:
        # numpy's LAPACK throughout: scipy's is a second BLAS thread pool, and the two contend
        np.linalg.cholesky(sub)  # positive definite, else least squares
        delta[free] = np.linalg.solve(sub, rhs[free])
    except np.linalg.LinAlgError:
        delta[free] = np.linalg.lstsq(sub, rhs[free], rcond=None)[0]
    return delta


def default_free_mask(n_cameras: int, reference: int = 0) -> NDArray[np.bool_]:
    """(C, 15) mask: every intrinsic free, every pose but the reference camera's free, no timing."""
    free = np.ones((n_cameras, N_CAMERA_PARAMS), dtype=bool)
    free[reference, N_INTRINSIC:] = False
    free[:, N_GEOMETRIC:] = False
    return free


def bundle_adjust(
    state: BundleState,
    problem: BundleProblem,
    free: NDArray[np.bool_],
    *,
    loss_scale: float | None = None,
    max_iterations: int = 100,
    tolerance: float = 1e-8,
) -> BundleResult:
    """Sparse Levenberg-Marquardt over all unknowns (paper's bundle adjustment).

    Args:
        state: initial values (Step 3 result, placements from triangulation).
        problem: the observations, sorted by placement then camera.
        free: (C, 15) which camera parameters are estimated (see :func:`default_free_mask`); the
            timing ones need ``problem.timing``.
        loss_scale: Huber threshold on each observation's 2D residual (px), or None for least
            squares. The robust problem is solved by iteratively reweighted least squares.
        max_iterations: LM iteration cap.
        tolerance: stop when the relative decrease of the cost falls below it, or when the
            undamped step promises less (then without taking it). On 1,000,000 residuals at 1 px the
            default leaves the state within 0.01 of a chi-square unit of the optimum (1e-6 left 1-2
            units on a 64-camera rig: its focal lengths 25 % worse). The adjustment also stops when
            the cameras' step is worth less than :data:`CAMERAS_SETTLED` (on a 64-camera rig after
            3 iterations instead of 14, every camera parameter within 0.005 of its standard
            deviation of where the 14 took it).

    Returns:
        The optimised state, residuals and parameter uncertainties.
    """
    n_cameras = problem.n_cameras
    timing = timing_columns(free)
    columns = np.concatenate([np.arange(N_GEOMETRIC), timing])  # the camera parameters carried
    free_flat = free[:, columns].reshape(-1)
    cameras = bool(free_flat.any())
    structure = _structure(problem, columns.size if cameras else 0)
    lam = 1e-6
    res, jc, jp = _linearise(state, problem, cameras=cameras, timing=timing)
    if not np.all(np.isfinite(res)):
        raise CalibrationFailedError("the bundle adjustment starts from non-finite reprojections")
    cost = robust_cost(res, loss_scale)
    m, p = res.size, int(free_flat.sum()) + N_PLACEMENT_PARAMS * problem.n_placements
    dof = max(m - p, 1)
    iterations, converged = 0, False
    normal = None  # the normal equations at the current state, once computed
    while iterations < max_iterations and not converged:
        iterations += 1
        weights = _huber_weights(res, loss_scale)
        normal = _normal_equations(res, jc, jp, weights, structure, n_cameras)
        u, v, w, gc, gp = normal
        accepted = False
        for attempt in range(30):
            if cameras:
                s, rhs, v_inv = _reduced_system(_damp(u, lam), _damp(v, lam), w, gc, gp, structure, n_cameras)
                delta_c = _solve_free(s, rhs, free_flat).reshape(n_cameras, columns.size)
                delta_p = _back_substitute(delta_c, v_inv, w, gp, structure)
                # the decrease the linearised problem promises: delta^T g + lambda delta^T D delta
                predicted = float(np.sum(delta_c * gc)) + lam * float(np.sum(_scaling(u) * delta_c**2))
            else:  # placements only: independent 5x5 systems
                delta_c = np.zeros((n_cameras, columns.size))
                delta_p = np.asarray(np.linalg.solve(_damp(v, lam), gp[..., None])[..., 0], dtype=np.float64)
                predicted = 0.0
            predicted += float(np.sum(delta_p * gp)) + lam * float(np.sum(_scaling(v) * delta_p**2))
            if attempt == 0 and predicted < tolerance * cost:  # the undamped step is not worth taking: converged
                accepted = converged = True
                break
            if attempt == 0 and cameras and float(delta_c.reshape(-1) @ rhs) < CAMERAS_SETTLED * cost / dof:
                # the cameras' step (their marginal: the placements follow) is worth less than
                # CAMERAS_SETTLED of a chi-square unit: what is left moves poorly seen placements only
                accepted = converged = True
                break
            try:
                candidate = _apply_step(state, delta_c, delta_p, timing)
            except ModelError:  # e.g. k1 <= 0: not a camera, reject the step
                lam *= 10.0
                continue
            # Jacobians come with the trial residuals: steps are rarely rejected near a solution.
            new_res, new_jc, new_jp = _linearise(candidate, problem, cameras=cameras, timing=timing)
            new_cost = robust_cost(new_res, loss_scale) if np.all(np.isfinite(new_res)) else np.inf
            if new_cost < cost:
                accepted = True
                relative_decrease = (cost - new_cost) / max(cost, 1e-300)
                log.debug(
                    "LM iteration %d: cost %.6g, relative decrease %.3g, lambda %.1e",
                    iterations,
                    new_cost,
                    relative_decrease,
                    lam,
                )
                state, cost, normal = candidate, new_cost, None
                lam = max(lam / 10.0, 1e-12)
                res, jc, jp = new_res, new_jc, new_jp
                converged = relative_decrease < tolerance
                break
            lam *= 10.0
        if not accepted:
            converged = True  # no decrease possible: at a minimum to machine precision
    weights = _huber_weights(res, loss_scale)
    sigma = float(np.sqrt(np.sum(weights[:, None] * res**2) / dof))
    size = n_cameras * N_CAMERA_PARAMS
    covariance = np.zeros((size, size))
    if cameras:  # stopped before a step: the iteration's normal equations are the state's
        u, v, w, gc, gp = (
            normal if normal is not None else _normal_equations(res, jc, jp, weights, structure, n_cameras)
        )
        s, _, _ = _reduced_system(u, _damp(v, 0.0), w, gc, gp, structure, n_cameras)
        carried = (np.arange(n_cameras)[:, None] * N_CAMERA_PARAMS + columns[None, :]).reshape(-1)[free_flat]
        covariance[np.ix_(carried, carried)] = np.linalg.pinv(s[np.ix_(free_flat, free_flat)], hermitian=True)
        covariance *= sigma**2
    camera_std = np.sqrt(np.clip(np.diag(covariance), 0.0, None)).reshape(n_cameras, N_CAMERA_PARAMS)
    return BundleResult(state, res, iterations, converged, camera_std, covariance, sigma, (m, p))
