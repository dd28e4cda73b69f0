"""Step 4 of the paper (and Step 2 of Section III-B): wand bundle adjustment.

Unknowns: per camera the intrinsics k1..k5, u0, v0 (m fixed; a pinhole model's tangential and
rational terms too), the pose (reference camera's pose fixed) and, for cameras that are not
hardware-triggered, a time offset and a rolling-shutter readout time; per wand placement j the point
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
Observation arrays are flat and sorted by placement; they are linearised and summed into the
normal equations chunk by chunk (:mod:`~wand_calib_ros.core.adjust.normal_equations`, whose layout is
computed once per adjustment).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.normal_equations import (
    CHUNK_OBSERVATIONS,
    N_PLACEMENT_PARAMS,
    BlockLayout,
    NormalEquations,
    ObservationChunk,
    accumulate,
    back_substitute,
    block_layout,
    damped,
    empty_normal_equations,
    reduced_system,
    scaled_inverse,
    scaling,
    solve_free,
    undamped,
)
from wand_calib_ros.core.errors import CalibrationFailedError, ModelError
from wand_calib_ros.core.model import pinhole
from wand_calib_ros.core.model.camera_model import (
    EQUIDISTANT,
    N_EXTRA,
    N_INTRINSIC,
    N_RADIAL,
    PLUMB_BOB,
    CameraModel,
    project_arrays,
    project_with_jacobian_arrays,
)
from wand_calib_ros.core.model.geometry import Pose, rotation_from_rotvec, tangent_basis
from wand_calib_ros.core.model.rig import WandSpec
from wand_calib_ros.core.model.views import observed_points
from wand_calib_ros.core.parallel import both

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)
IntArray = NDArray[np.int64]

#: Geometric parameters per camera: k1..k5, u0, v0, rotation (3), translation (3).
N_GEOMETRIC = N_INTRINSIC + 6
#: Parameters per camera: the geometric ones, the time offset and the rolling-shutter readout time, then
#: the pinhole models' tangential (t1, t2) and rational (d1, d2, d3) terms.
N_CAMERA_PARAMS = N_GEOMETRIC + 2 + N_EXTRA
#: Indices of the timing parameters in a camera's parameter vector.
TIME_OFFSET, READOUT = N_GEOMETRIC, N_GEOMETRIC + 1
TIMING = slice(TIME_OFFSET, READOUT + 1)
#: The pinhole models' further parameters in a camera's parameter vector (its ``CameraModel.lens_vector``).
LENS = slice(READOUT + 1, N_CAMERA_PARAMS)
#: Every intrinsic parameter's index in a camera's parameter vector.
INTRINSICS = np.r_[0:N_INTRINSIC, LENS.start : LENS.stop]
#: Names of the per-camera parameters in order (rotation as a small-angle update, rad; the timing
#: parameters in the time unit of the observations; t1, t2 in mm, d1..d3 dimensionless).
CAMERA_PARAM_NAMES = (
    "k1", "k2", "k3", "k4", "k5", "u0", "v0", "rx", "ry", "rz", "tx", "ty", "tz", "time_offset", "readout",
    "t1", "t2", "d1", "d2", "d3",
)  # fmt: skip


def parameter_mask(models: tuple[CameraModel, ...] | list[CameraModel]) -> NDArray[np.bool_]:
    """(C, N_CAMERA_PARAMS) the parameters each camera's model has: the fisheye model none of the lens
    terms, plumb_bob no k5 and no rational terms, rational_polynomial no k5."""
    mask = np.ones((len(models), N_CAMERA_PARAMS), dtype=bool)
    for c, model in enumerate(models):
        if model.distortion_model == EQUIDISTANT:
            mask[c, LENS] = False
            continue
        mask[c, N_RADIAL - 1] = False
        if model.distortion_model == PLUMB_BOB:
            mask[c, LENS.start + pinhole.DENOMINATOR.start : LENS.stop] = False
    return mask


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
    def from_dense(
        wand: WandSpec, uv: FloatArray, timing: PlacementTiming | None = None, rows: IntArray | None = None
    ) -> BundleProblem:
        """Problem from dense (P, C, 3, 2) pixels with NaN for unseen points, or from their placements ``rows``
        (R,) only (no copy of those), and the timing of those placements."""
        n_placements, n_cameras = (uv.shape[0] if rows is None else rows.size), uv.shape[1]
        flat, placement, camera, point = observed_points(uv, rows)
        observed = uv.reshape(-1, 2)[flat]
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
class CameraSystem:
    """The cameras' normal equations at an adjusted state, the placements eliminated (Schur complement).

    Attributes:
        columns: (K,) the camera parameters carried per camera (indices into :data:`CAMERA_PARAM_NAMES`),
            fixed ones included: every geometric parameter and the timing ones in use.
        matrix: (C K, C K) S, camera-major, unscaled (the covariance is sigma^2 S^-1 over the free ones).
        rhs: (C K,) its right-hand side: the Gauss-Newton step solves ``S delta = rhs``.
    """

    columns: IntArray
    matrix: FloatArray
    rhs: FloatArray

    def step(self, free: NDArray[np.bool_], moves: FloatArray | None = None) -> FloatArray:
        """(C, 20) the Gauss-Newton step with the camera parameters ``free`` (C, 20) estimated and the
        others moved by ``moves`` (C, 20; e.g. a term fixed at zero: minus its value; None: they stay).

        With other parameters free than the adjustment's (e.g. distortion terms it held at zero
        released), this is the linearised estimate of that other model: no new linearisation, the
        placements follow implicitly. Timing parameters only where the system carries them (and lens
        terms only where it carries them: else no camera's model has them).
        """
        missing = np.setdiff1d(np.arange(N_CAMERA_PARAMS), self.columns)
        if free[:, missing[missing < LENS.start]].any():  # lens terms not carried are of no camera's model
            raise ValueError("a timing parameter the adjustment did not carry cannot be estimated")
        n_cameras = free.shape[0]
        free_flat = free[:, self.columns].reshape(-1)
        fixed = (
            np.zeros(free_flat.size) if moves is None else np.where(free_flat, 0.0, moves[:, self.columns].reshape(-1))
        )
        step = fixed + solve_free(self.matrix, self.rhs - self.matrix @ fixed, free_flat)
        delta = np.zeros((n_cameras, N_CAMERA_PARAMS))
        delta[:, self.columns] = step.reshape(n_cameras, self.columns.size)
        return delta

    def covariance(self, free: NDArray[np.bool_], sigma: float, prior_std: FloatArray | None = None) -> FloatArray:
        """(C*20, C*20) sigma^2 S^-1 over the ``free`` (C, 20) camera parameters (0 rows and columns elsewhere).

        With ``prior_std`` (C, 20), the parameters with a positive one are estimated too, each with a
        Gaussian prior of that standard deviation (in its own unit) around its value: sigma^2 (S + sigma^2
        diag(1 / prior_std^2))^-1 over the free and those.
        """
        n_cameras = free.shape[0]
        with_prior = free if prior_std is None else free | (prior_std > 0)
        free_flat = with_prior[:, self.columns].reshape(-1)
        carried = (np.arange(n_cameras)[:, None] * N_CAMERA_PARAMS + self.columns[None, :]).reshape(-1)[free_flat]
        matrix = self.matrix[np.ix_(free_flat, free_flat)]
        if prior_std is not None:
            std = prior_std[:, self.columns].reshape(-1)[free_flat]
            information = np.where(std > 0, sigma**2 / np.where(std > 0, std, 1.0) ** 2, 0.0)
            matrix = matrix + np.diag(information)
        covariance = np.zeros((n_cameras * N_CAMERA_PARAMS,) * 2)
        covariance[np.ix_(carried, carried)] = scaled_inverse(matrix)
        return covariance * sigma**2


def camera_std(covariance: FloatArray) -> FloatArray:
    """(C, 20) the standard deviations on the diagonal of a (C*20, C*20) camera covariance (0 for fixed ones)."""
    return np.sqrt(np.clip(np.diag(covariance), 0.0, None)).reshape(-1, N_CAMERA_PARAMS)


#: A choice of the parameters to estimate made on the normal equations at an adjustment's start (see
#: :func:`bundle_adjust`): called with the start, its cameras' system and its noise estimate (px), it
#: returns the (C, 20) parameters to estimate and the (C, 20) steps of those it fixes, or None.
ChooseFree = Callable[["BundleState", CameraSystem, float], "tuple[NDArray[np.bool_], FloatArray] | None"]


@dataclass(frozen=True, eq=False)
class BundleResult:
    """Outcome of a bundle adjustment.

    Attributes:
        state: the optimised unknowns.
        residuals: (M, 2) reprojection residuals (projected minus observed), px.
        iterations: LM iterations done.
        converged: whether a convergence criterion was met.
        camera_std: (C, 20) standard deviations of the camera parameters
            (:data:`CAMERA_PARAM_NAMES` order; 0 for fixed ones), from the final Jacobian.
        camera_covariance: (C*20, C*20) covariance of all camera parameters (0 rows/cols for fixed).
        sigma: estimated pixel noise sqrt(sum r^2 / (m - p)), px.
        dof: (m, p) residual scalars and free parameters.
        system: the cameras' normal equations at ``state`` (None: no camera parameter was free).
    """

    state: BundleState
    residuals: FloatArray
    iterations: int
    converged: bool
    camera_std: FloatArray
    camera_covariance: FloatArray
    sigma: float
    dof: tuple[int, int]
    system: CameraSystem | None = None

    def camera_block(self, camera: int, parameters: slice) -> FloatArray:
        """The covariance of some of one camera's parameters (a slice of :data:`CAMERA_PARAM_NAMES`)."""
        first = camera * N_CAMERA_PARAMS
        block = slice(first + (parameters.start or 0), first + (parameters.stop or N_CAMERA_PARAMS))
        return self.camera_covariance[block, block]


#: Columns of :class:`_Unknowns`' camera table: k (5), m (2), principal point (2), rotation (9, row-major),
#: translation (3), time offset and readout (2), the pinhole models' further terms (5).
_K, _M, _PP, _ROT, _T, _TIMING, _EXTRA = 0, 5, 7, 9, 18, 21, 23
#: Columns of its placement table: A (3), the direction (3), its tangent basis e1 (3) and e2 (3).
_A, _DIRECTION, _E1, _E2 = 0, 3, 6, 9


@dataclass(frozen=True, eq=False)
class _Unknowns:
    """The state as two tables the linearisation gathers rows from, one gather per chunk.

    Attributes:
        cameras: (C, 28) per camera k, m, principal point, rotation (row-major), translation, time
            offset and readout time, the pinhole models' further terms.
        placements: (P, 12) per placement A, the unit direction A -> C and its tangent basis e1, e2.
        pinhole: (C,) which cameras have a pinhole model (None: none has).
    """

    cameras: FloatArray
    placements: FloatArray
    pinhole: NDArray[np.bool_] | None = None

    @staticmethod
    def of(state: BundleState) -> _Unknowns:
        k = np.stack([m.k for m in state.models])
        cameras = np.concatenate(
            [
                k,
                np.stack([m.m for m in state.models]),
                np.stack([m.principal_point for m in state.models]),
                np.stack([p.rotation.reshape(9) for p in state.poses]),
                np.stack([p.translation for p in state.poses]),
                state.camera_timing,
                np.stack([m.lens_vector() for m in state.models]),
            ],
            axis=1,
        )
        basis = tangent_basis(state.wand_direction)  # (P, 3, 2)
        placements = np.concatenate([state.wand_a, state.wand_direction, basis[:, :, 0], basis[:, :, 1]], axis=1)
        pinhole = np.array([m.is_pinhole for m in state.models], dtype=bool)
        return _Unknowns(cameras, placements, pinhole if pinhole.any() else None)


def _project_rows(
    unknowns: _Unknowns, cam: FloatArray, c: IntArray, points: FloatArray, *, jacobians: bool, intrinsics: bool
) -> tuple[FloatArray, FloatArray | None, FloatArray | None, FloatArray | None]:
    """Pixels (n, 2) of camera-frame points (n, 3) seen by the cameras ``c`` (n,) whose parameters ``cam``
    (28, n) holds, each by its own model, and with ``jacobians`` d_point (n, 2, 3), d_intrinsics (n, 2, 7
    or 0 without ``intrinsics``) and the pinhole models' d_extra (n, 2, 5; None when no camera has one)."""
    k, m, pp = cam[_K : _K + N_RADIAL].T, cam[_M : _M + 2].T, cam[_PP : _PP + 2].T
    if unknowns.pinhole is None:  # the common case: fisheye-model cameras only
        if not jacobians:
            return project_arrays(k, m, pp, points), None, None, None
        kb = project_with_jacobian_arrays(k, m, pp, points, intrinsics=intrinsics)
        return kb.uv, kb.d_point, kb.d_intrinsics, None
    extra = cam[_EXTRA : _EXTRA + N_EXTRA].T
    rows = unknowns.pinhole[c]
    if not jacobians:
        uv = np.empty((points.shape[0], 2))
        uv[rows] = pinhole.project_arrays(k[rows], extra[rows], m[rows], pp[rows], points[rows])
        other = ~rows
        if other.any():
            uv[other] = project_arrays(k[other], m[other], pp[other], points[other])
        return uv, None, None, None
    if rows.all():
        ph = pinhole.project_with_jacobian_arrays(k, extra, m, pp, points, intrinsics=intrinsics)
        return ph.uv, ph.d_point, ph.d_intrinsics, ph.d_extra if intrinsics else None
    n, width = points.shape[0], N_INTRINSIC if intrinsics else 0
    uv, d_point = np.empty((n, 2)), np.empty((n, 2, 3))
    d_intrinsics, d_extra = np.empty((n, 2, width)), np.zeros((n, 2, N_EXTRA))
    ph = pinhole.project_with_jacobian_arrays(
        k[rows], extra[rows], m[rows], pp[rows], points[rows], intrinsics=intrinsics
    )
    other = ~rows
    kb = project_with_jacobian_arrays(k[other], m[other], pp[other], points[other], intrinsics=intrinsics)
    for target, pinhole_part, fisheye_part in ((uv, ph.uv, kb.uv), (d_point, ph.d_point, kb.d_point),
                                               (d_intrinsics, ph.d_intrinsics, kb.d_intrinsics)):  # fmt: skip
        target[rows], target[other] = pinhole_part, fisheye_part
    if intrinsics:
        d_extra[rows] = ph.d_extra
    return uv, d_point, d_intrinsics, d_extra if intrinsics else None


def _linearise_rows(
    unknowns: _Unknowns,
    problem: BundleProblem,
    first: int,
    stop: int,
    *,
    jacobians: bool,
    cameras: bool,
    carried: IntArray,
) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
    """The observations ``first:stop`` linearised: residuals (n, 2) and, when ``jacobians``, the camera
    Jacobians (n, 2, 13 + len(carried) + 1; None unless ``cameras``) and the placement Jacobians
    (n, 2, 5 + 1), each with the residuals as last column (:func:`accumulate` sums [J | r]^T [J | r]).
    ``carried`` are the camera parameters beyond the 13 geometric ones: the timing ones, then the
    pinhole models' lens terms.

    Written on component arrays (n,) of a chunk small enough to stay in cache (see
    :mod:`~wand_calib_ros.core.adjust.normal_equations`); the projection and its derivatives come from
    :func:`~wand_calib_ros.core.model.camera_model.project_with_jacobian_arrays` (and the pinhole models'
    :func:`~wand_calib_ros.core.model.pinhole.project_with_jacobian_arrays`), the rotation columns are
    ``d uv / d rotvec = -d_point [R X]x`` (R <- exp([d]x) R), row by row the cross product ``R X x
    d_point_row``; the placement's ``d_point R`` and ``offset d_point R e``.
    """
    c = problem.camera[first:stop]
    pl = problem.placement[first:stop]
    cam = np.take(unknowns.cameras, c, axis=0).T  # (28, n)
    placed = np.take(unknowns.placements, pl, axis=0).T  # (12, n)
    offsets = problem.wand.offsets[problem.point[first:stop]]
    world = placed[_A : _A + 3] + offsets * placed[_DIRECTION : _DIRECTION + 3]  # (3, n) reference frame
    along_time = None
    if problem.timing is not None:  # carried along the wand's motion to the instant the camera saw it
        obs = problem.timing
        tau = obs.time[first:stop] - cam[_TIMING] + cam[_TIMING + 1] * obs.row[first:stop]
        velocity, acceleration = obs.velocity[first:stop].T, obs.acceleration[first:stop].T
        jerk = obs.jerk[first:stop].T
        half = 0.5 * tau * tau
        world = world + tau * (velocity + half / 3.0 * jerk) + half * acceleration
        along_time = velocity + tau * acceleration + half * jerk  # d world / d tau
    n = stop - first
    rot = cam[_ROT : _ROT + 9]
    rotated = np.empty((n, 3))  # R X
    for i in range(3):
        rotated[:, i] = rot[3 * i] * world[0] + rot[3 * i + 1] * world[1] + rot[3 * i + 2] * world[2]
    in_camera = rotated + cam[_T : _T + 3].T
    uv, d_camera, d_intrinsics, d_extra = _project_rows(
        unknowns, cam, c, in_camera, jacobians=jacobians, intrinsics=cameras
    )
    res = uv - problem.uv[first:stop]
    if not jacobians:
        return res, None, None
    assert d_camera is not None and d_intrinsics is not None
    timing = carried[carried < LENS.start]
    q0, q1, q2 = rotated.T
    d_point = d_camera.transpose(1, 2, 0)  # (2, 3, n): d(u, v) / d(x, y, z), camera frame
    e1, e2 = placed[_E1 : _E1 + 3], placed[_E2 : _E2 + 3]
    width = N_GEOMETRIC + carried.size
    jc = np.empty((n, 2, width + 1)) if cameras else None
    jp = np.empty((n, 2, N_PLACEMENT_PARAMS + 1))
    jp[:, :, N_PLACEMENT_PARAMS] = res
    if jc is not None:
        jc[:, :, :N_INTRINSIC] = d_intrinsics
        jc[:, :, N_INTRINSIC + 3 : N_GEOMETRIC] = d_camera  # translation
        lens = carried[carried >= LENS.start]
        if lens.size:
            if d_extra is None:
                raise ValueError("lens terms are carried only for pinhole cameras")
            jc[:, :, N_GEOMETRIC + timing.size : width] = d_extra[:, :, lens - LENS.start]
        jc[:, :, width] = res
    for i, (p0, p1, p2) in enumerate(d_point):
        w0 = p0 * rot[0] + p1 * rot[3] + p2 * rot[6]  # d uv_i / d world point: d_point R
        w1 = p0 * rot[1] + p1 * rot[4] + p2 * rot[7]
        w2 = p0 * rot[2] + p1 * rot[5] + p2 * rot[8]
        jp[:, i, 0], jp[:, i, 1], jp[:, i, 2] = w0, w1, w2
        jp[:, i, 3] = offsets * (w0 * e1[0] + w1 * e1[1] + w2 * e1[2])
        jp[:, i, 4] = offsets * (w0 * e2[0] + w1 * e2[1] + w2 * e2[2])
        if jc is None:
            continue
        jc[:, i, N_INTRINSIC] = q1 * p2 - q2 * p1  # rotation
        jc[:, i, N_INTRINSIC + 1] = q2 * p0 - q0 * p2
        jc[:, i, N_INTRINSIC + 2] = q0 * p1 - q1 * p0
        if timing.size:
            if along_time is None or problem.timing is None:
                raise ValueError("timing parameters need the observations' timing")
            along = w0 * along_time[0] + w1 * along_time[1] + w2 * along_time[2]  # d uv_i / d tau
            for column, parameter in enumerate(timing, start=N_GEOMETRIC):
                jc[:, i, column] = -along if parameter == TIME_OFFSET else problem.timing.row[first:stop] * along
    return res, jc, jp


def residuals(state: BundleState, problem: BundleProblem) -> FloatArray:
    """(M, 2) reprojection residuals (projected minus observed) in px. Pure."""
    unknowns = _Unknowns.of(state)
    out = np.empty((problem.n_observations, 2))
    firsts = range(0, problem.n_observations, CHUNK_OBSERVATIONS)

    def run(chunk_firsts: range) -> None:
        for first in chunk_firsts:
            stop = min(first + CHUNK_OBSERVATIONS, problem.n_observations)
            out[first:stop] = _linearise_rows(
                unknowns, problem, first, stop, jacobians=False, cameras=False, carried=_NO_TIMING
            )[0]

    half = len(firsts) // 2
    both(lambda: run(firsts[:half]), lambda: run(firsts[half:]), split=len(firsts) >= THREADED_CHUNKS)
    return out


def timing_columns(free: NDArray[np.bool_]) -> IntArray:
    """Timing parameters (indices into :data:`CAMERA_PARAM_NAMES`) free for at least one camera.

    The adjustment carries the 13 geometric parameters of every camera and only these timing
    ones, so a synchronised rig costs what it did before timing was modelled.
    """
    return (np.flatnonzero(free[:, TIMING].any(axis=0)) + TIMING.start).astype(np.int64)


def lens_columns(models: tuple[CameraModel, ...]) -> IntArray:
    """The pinhole models' lens terms (indices into :data:`CAMERA_PARAM_NAMES`) some camera's model has:
    the adjustment carries them (fixed or free) only then, so a fisheye-model rig costs what it did."""
    return (np.flatnonzero(parameter_mask(models)[:, LENS].any(axis=0)) + LENS.start).astype(np.int64)


#: No timing parameter carried.
_NO_TIMING = np.empty(0, dtype=np.int64)


def _linearise(
    state: BundleState, problem: BundleProblem, *, carried: IntArray = _NO_TIMING
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Residuals (M, 2), camera Jacobians (M, 2, 13 + len(carried)) and placement Jacobians (M, 2, 5) of
    the whole problem at once (the adjustment sums them chunk by chunk instead: :func:`_evaluate`)."""
    unknowns = _Unknowns.of(state)
    res, jc, jp = [], [], []
    for first in range(0, problem.n_observations, CHUNK_OBSERVATIONS):
        stop = min(first + CHUNK_OBSERVATIONS, problem.n_observations)
        part, camera, placement = _linearise_rows(
            unknowns, problem, first, stop, jacobians=True, cameras=True, carried=carried
        )
        assert camera is not None and placement is not None
        res.append(part)
        jc.append(camera[:, :, :-1])
        jp.append(placement[:, :, :-1])
    return np.concatenate(res), np.concatenate(jc), np.concatenate(jp)


#: An evaluation of at least this many chunks is shared by two threads (:func:`~wand_calib_ros.core.parallel.both`):
#: the chunks' sums are disjoint but for the cameras' (U and their gradient, each half's own, added at the end).
#: Mocap16's 452k observations: 0.21 -> 0.16 s per evaluation (from 65,000 observations on).
THREADED_CHUNKS = 8


def _evaluate(
    state: BundleState,
    problem: BundleProblem,
    layout: BlockLayout,
    carried: IntArray,
    loss_scale: float | None,
    reuse: NormalEquations | None = None,
) -> tuple[FloatArray, NormalEquations]:
    """(M, 2) residuals at ``state`` and the normal equations of the (Huber-weighted) problem there,
    chunk by chunk (into the arrays of ``reuse``, normal equations of ``layout`` no longer needed, if given)."""
    unknowns = _Unknowns.of(state)
    res = np.empty((problem.n_observations, 2))
    normal = empty_normal_equations(layout, reuse)
    cameras = layout.width > 0

    def run(chunks: tuple[ObservationChunk, ...], into: NormalEquations) -> None:
        for chunk in chunks:
            part, jc, jp = _linearise_rows(
                unknowns, problem, chunk.first, chunk.stop, jacobians=True, cameras=cameras, carried=carried
            )
            assert jp is not None
            res[chunk.first : chunk.stop] = part
            weights = None if loss_scale is None else _huber_weights(part, loss_scale)
            accumulate(into, layout, chunk, jc, jp, weights)

    chunks, half = layout.chunks, len(layout.chunks) // 2
    if len(chunks) < THREADED_CHUNKS:
        run(chunks, normal)
        return res, normal
    second = normal._replace(u=np.zeros_like(normal.u), gc=np.zeros_like(normal.gc))  # V, W and gp: disjoint rows
    both(lambda: run(chunks[:half], normal), lambda: run(chunks[half:], second))
    np.add(normal.u, second.u, out=normal.u)
    np.add(normal.gc, second.gc, out=normal.gc)
    return res, normal


def moved_camera(model: CameraModel, pose: Pose, delta: FloatArray, *, lens: bool = True) -> tuple[CameraModel, Pose]:
    """A camera moved by a (20,) step of its parameters (:data:`CAMERA_PARAM_NAMES`): intrinsics added, the
    rotation vector left-multiplied, the translation added; the lens terms only with ``lens`` and a pinhole
    model; timing is not the camera's (see :class:`BundleState`)."""
    extra = model.lens_vector() + delta[LENS] if lens and model.is_pinhole else None
    moved = model.with_intrinsic_vector(model.intrinsic_vector() + delta[:N_INTRINSIC], extra)
    rotation = rotation_from_rotvec(delta[N_INTRINSIC : N_INTRINSIC + 3]) @ pose.rotation
    return moved, Pose(rotation, pose.translation + delta[N_INTRINSIC + 3 : N_GEOMETRIC])


def _apply_step(state: BundleState, delta_c: FloatArray, delta_p: FloatArray, carried: IntArray) -> BundleState:
    """The state moved by camera steps (C, 13 + len(carried)) and placement steps (P, 5)."""
    delta = np.zeros((len(state.models), N_CAMERA_PARAMS))
    delta[:, np.concatenate([np.arange(N_GEOMETRIC), carried])] = delta_c
    delta[~parameter_mask(state.models)] = 0.0  # what a camera's model does not have stays as it is
    lens = bool(np.any(carried >= LENS.start))
    moved = [moved_camera(m, p, d, lens=lens) for m, p, d in zip(state.models, state.poses, delta, strict=True)]
    models, poses = [m for m, _ in moved], [p for _, p in moved]
    camera_timing = state.timing
    if np.any(carried < LENS.start):
        camera_timing = state.camera_timing + delta[:, TIMING]
    basis = tangent_basis(state.wand_direction)
    direction = state.wand_direction + np.einsum("pij,pj->pi", basis, delta_p[:, 3:])
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return BundleState(tuple(models), tuple(poses), state.wand_a + delta_p[:, :3], direction, camera_timing)


#: An adjustment stops when the cameras' next step is worth less than this fraction of a chi-square
#: unit (sigma^2): every camera parameter within a few hundredths of its standard deviation of where
#: the step would take it. Left alone, placements seen by two nearly parallel rays make a large rig
#: creep by 1e-8 of its cost per iteration for tens of iterations without moving a camera.
CAMERAS_SETTLED = 1e-3
#: Near a solution (a step that lowered the cost by less than NEAR of it, as much as it promised to
#: within TRUSTED_GAIN), and after a Gauss-Newton step that did as much as it promised, the next iteration
#: first tries the undamped (Gauss-Newton) step.
NEAR = 1e-4
TRUSTED_GAIN = 0.75
#: What passes that only decide outliers or test the timing settle at: every camera parameter within
#: about a third of its standard deviation of the optimum (the passes after them finish the job).
DECIDING_SETTLED = 0.1


def squared_norms(res: FloatArray) -> FloatArray:
    """(M,) each (M, 2) residual's squared length, px^2: its two columns added (the same numbers as numpy's sum or
    norm over the rows' two entries, which run a reduction per row: 20x slower on mocap16's 452,000 rows)."""
    return res[:, 0] * res[:, 0] + res[:, 1] * res[:, 1]


def _huber_weights(res: FloatArray, loss_scale: float | None) -> FloatArray:
    """(M,) IRLS weights of the Huber loss on each observation's 2D residual norm (1 = least squares)."""
    if loss_scale is None:
        return np.ones(res.shape[0])
    norm = np.sqrt(squared_norms(res))
    return np.where(norm <= loss_scale, 1.0, loss_scale / np.maximum(norm, 1e-300))


def _observation_costs(res: FloatArray, loss_scale: float | None) -> FloatArray:
    """(M,) the Huber loss of each observation's 2D residual norm (its square when loss_scale is None)."""
    squared = squared_norms(res)
    if loss_scale is None:
        return squared
    norm = np.sqrt(squared)
    return np.where(norm <= loss_scale, squared, 2 * loss_scale * norm - loss_scale**2)


def robust_cost(res: FloatArray, loss_scale: float | None) -> float:
    """Sum of the Huber loss of the 2D residual norms (sum of squares when loss_scale is None); inf when a
    residual is not finite (a point the state cannot project: no cost compares below it)."""
    total = float(np.sum(_observation_costs(res, loss_scale)))
    return total if np.isfinite(total) else np.inf


def _hold_worse_placements(
    state: BundleState,
    candidate: BundleState,
    problem: BundleProblem,
    res: FloatArray,
    loss_scale: float | None,
    cost: float,
) -> BundleState | None:
    """``candidate`` with the placements whose own cost its step raised held where ``state`` had them;
    None when that would not cost less than ``cost`` (nothing to hold, or the cameras' step is wrong).

    The cameras' step is shared, the placements' steps are each their own: a step the linearisation
    got wrong is often wrong only for a few poorly conditioned placements (seen by nearly parallel
    rays), whose linearised steps run far off. Given the cameras, each placement's cost depends on
    that placement alone, so each can keep whichever of its two values costs less.

    Args:
        res: (M, 2) the residuals at ``candidate``.
    """
    held = BundleState(candidate.models, candidate.poses, state.wand_a, state.wand_direction, candidate.timing)
    n = problem.n_placements
    stepped = np.bincount(problem.placement, _observation_costs(res, loss_scale), minlength=n)
    kept = np.bincount(problem.placement, _observation_costs(residuals(held, problem), loss_scale), minlength=n)
    worse = ~(stepped <= kept)  # NaN costs count as worse
    if not worse.any() or not float(np.sum(np.where(worse, kept, stepped))) < cost:
        return None
    return BundleState(
        candidate.models,
        candidate.poses,
        np.where(worse[:, None], state.wand_a, candidate.wand_a),
        np.where(worse[:, None], state.wand_direction, candidate.wand_direction),
        candidate.timing,
    )


def default_free_mask(
    n_cameras: int, reference: int = 0, models: tuple[CameraModel, ...] | None = None
) -> NDArray[np.bool_]:
    """(C, 20) mask: every intrinsic free (of the cameras' ``models``, when given: the adjustment leaves out
    what a model does not have anyway), every pose but the reference camera's free, no timing."""
    free = np.ones((n_cameras, N_CAMERA_PARAMS), dtype=bool)
    free[reference, N_INTRINSIC:N_GEOMETRIC] = False
    free[:, TIMING] = False
    return free if models is None else free & parameter_mask(models)


def bundle_adjust(
    state: BundleState,
    problem: BundleProblem,
    free: NDArray[np.bool_],
    *,
    loss_scale: float | None = None,
    max_iterations: int = 100,
    tolerance: float = 1e-8,
    settled: float = CAMERAS_SETTLED,
    last_step: bool = True,
    choose: ChooseFree | None = None,
) -> BundleResult:
    """Sparse Levenberg-Marquardt over all unknowns (paper's bundle adjustment).

    Args:
        state: initial values (Step 3 result, placements from triangulation).
        problem: the observations, sorted by placement then camera.
        free: (C, 20) which camera parameters are estimated (see :func:`default_free_mask`; only those
            of each camera's model are, :func:`parameter_mask`); the timing ones need ``problem.timing``.
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
        settled: stop when the cameras' step is worth less than this fraction of a chi-square unit
            (:data:`CAMERAS_SETTLED`; passes that only decide outliers or a test settle at
            :data:`DECIDING_SETTLED`).
        last_step: end with a step not linearised again, when the convergence so far says the step after it
            would end the adjustment: its cameras' worth w times the ratio of w to the previous step's (the
            rate at which the steps shrink) below ``settled``, or the decrease it promises times its ratio to
            the previous one's below ``tolerance``. The step is Gauss-Newton's, taken once its residuals (a
            fraction of the cost of a linearisation) show a lower cost; the covariance comes from the system
            it was computed on, its gradient moved along the step. The rate guesses the next step within a
            few times: mocap16's final adjustment, steps worth 1,075 and 0.056 chi-square units (the second
            taken so: next 3e-6 by the rate, 1e-7 measured); a two-camera pair, 14.5, 0.41 and 0.0072 (the
            third taken so: next 1.2e-4 by the rate, 5.6e-4 measured, both settled). The state is the one
            the linearisation after it would have stopped at. False: every step is linearised again.
        choose: decides on the normal equations at the start which camera parameters to estimate
            (e.g. the model order on all placements,
            :class:`~wand_calib_ros.core.adjust.model_order.OrderOnAllPlacements`),
            the timing ones as ``free`` has them. When it changes them, the adjustment starts from the
            new choice's linearised solution (cameras and placements), so its first linearisation
            serves the choice too.

    Returns:
        The optimised state, residuals and parameter uncertainties.
    """
    n_cameras = problem.n_cameras
    exists = parameter_mask(state.models)
    free = free & exists
    timing = timing_columns(free)
    carried = np.concatenate([timing, lens_columns(state.models)])  # beyond the geometric parameters
    columns = np.concatenate([np.arange(N_GEOMETRIC), carried])  # the camera parameters carried
    free_flat = free[:, columns].reshape(-1)
    cameras = bool(free_flat.any())
    layout = block_layout(
        problem.camera,
        problem.placement,
        problem.point,
        n_cameras,
        problem.n_placements,
        problem.wand.n_points,
        columns.size if cameras else 0,
    )
    lam, growth, trusted = 1e-6, 2.0, False
    known: _Reduced | None = None  # the state's undamped system, once reduced
    previous = 0.0  # the cameras' part of the last step taken, chi-square units (0: none yet)
    promised = 0.0  # the decrease the last step taken promised (0: none yet)

    def worth_of(delta_c: FloatArray, rhs: FloatArray) -> float:
        """The cameras' part of a step, in chi-square units (inf without camera parameters)."""
        return float(delta_c.reshape(-1) @ rhs) / (cost / dof) if cameras else np.inf

    def successor_ends(worth: float, predicted: float) -> bool:
        """Whether the step after one worth ``worth`` (chi-square units) promising ``predicted`` would end the
        adjustment, at the rate the steps shrink."""
        return last_step and (worth * worth < settled * previous or predicted * predicted < tolerance * cost * promised)

    res, normal = _evaluate(state, problem, layout, carried, loss_scale)
    if not np.all(np.isfinite(res)):
        raise CalibrationFailedError("the bundle adjustment starts from non-finite reprojections")
    cost = robust_cost(res, loss_scale)
    m, p = res.size, int(free_flat.sum()) + N_PLACEMENT_PARAMS * problem.n_placements
    dof = max(m - p, 1)
    if choose is not None and cameras:
        gauss_newton = undamped(normal)
        s, rhs, v_inv = reduced_system(gauss_newton, layout)
        start = CameraSystem(columns, s, rhs)
        choice = choose(state, start, _sigma(res, loss_scale, dof))
        if choice is not None:
            free, moves = choice
            free = free & exists
            if not np.array_equal(timing_columns(free), timing):
                raise ValueError("a choice of the parameters to estimate cannot change the timing ones carried")
            free_flat = free[:, columns].reshape(-1)
            p = int(free_flat.sum()) + N_PLACEMENT_PARAMS * problem.n_placements
            dof = max(m - p, 1)
            delta_c = start.step(free, moves)[:, columns]
            moved = np.where(free[:, columns], 0.0, moves[:, columns])
            no_step = np.zeros((problem.n_placements, N_PLACEMENT_PARAMS))
            try:
                chosen = _apply_step(state, delta_c, back_substitute(delta_c, v_inv, gauss_newton, layout), carried)
            except ModelError:  # the linearised solution leaves the camera model: only the fixed ones move
                chosen = None
            del gauss_newton  # its W is ``normal``'s, whose arrays the chosen start's are summed into
            if chosen is not None:
                res, normal = _evaluate(chosen, problem, layout, carried, loss_scale, normal)
            if chosen is None or not np.all(np.isfinite(res)):  # (or puts a point behind a pinhole camera)
                chosen, delta_c = _apply_step(state, moved, no_step, carried), moved
                res, normal = _evaluate(chosen, problem, layout, carried, loss_scale, normal)
            state = chosen
            flat = delta_c.reshape(-1)
            previous = float(flat @ s @ flat) / (cost / dof)  # the move's length, chi-square units
            cost = robust_cost(res, loss_scale)
            if not np.isfinite(cost):
                raise CalibrationFailedError("the bundle adjustment's chosen start has non-finite reprojections")
            trusted = True  # from the linearised solution, Gauss-Newton's step first
        else:  # the order stands: the start's Gauss-Newton system is the first iteration's first try
            known, trusted = (gauss_newton, s, rhs, v_inv), True
            del gauss_newton
    iterations, converged = 0, False
    spare: NormalEquations | None = None  # the arrays of normal equations no longer needed, for the next ones
    final: CameraSystem | None = None  # the undamped reduced system at the final state, once known
    while iterations < max_iterations and not converged:
        iterations += 1
        accepted = False
        for attempt in range(30):
            # Near a solution the first try is Gauss-Newton's step: its system is the one the
            # covariance needs, kept should it end the adjustment.
            used = 0.0 if attempt == 0 and trusted else lam
            s, rhs, delta_c, delta_p, predicted, known = _solve_step(
                normal, layout, free_flat, used, known, columns.size
            )
            worth = worth_of(delta_c, rhs)
            if attempt == 0 and (predicted < tolerance * cost or worth < settled):
                # the step is not worth taking, or the cameras' step (their marginal: the placements
                # follow) is worth less than ``settled`` of a chi-square unit: what is left moves
                # poorly seen placements only
                accepted = converged = True
                final = CameraSystem(columns, s, rhs) if cameras and used == 0.0 else None
                break
            if attempt == 0 and successor_ends(worth, predicted):
                if used != 0.0:  # (a damped step is shorter: Gauss-Newton's is checked too)
                    used = 0.0
                    s, rhs, delta_c, delta_p, predicted, known = _solve_step(
                        normal, layout, free_flat, used, known, columns.size
                    )
                    worth = worth_of(delta_c, rhs)
                last = (
                    _last_step(state, delta_c, delta_p, carried, problem, loss_scale, cost)
                    if successor_ends(worth, predicted)
                    else None
                )
                if last is not None:
                    state, res, cost = last
                    # the system where the step was computed, its gradient moved along the step (linearly)
                    final = CameraSystem(columns, s, rhs - s @ delta_c.reshape(-1)) if cameras else None
                    accepted = converged = True
                    break
            try:
                candidate = _apply_step(state, delta_c, delta_p, carried)
            except ModelError:  # e.g. k1 <= 0: not a camera, reject the step
                lam, growth = (lam, growth) if used == 0.0 else (lam * growth, 2.0 * growth)
                trusted = False
                continue
            # The normal equations come with the trial residuals: steps are rarely rejected near a solution,
            # Gauss-Newton's least of all: theirs are summed into the state's own arrays (one W held, not two;
            # the state's are summed again should the step fail). After a rejection the next try is likelier
            # rejected too: its residuals first, its normal equations once it is taken (a rejected try then
            # costs a pass over the residuals, not two linearisations).
            over = spare is None and used == 0.0
            new_normal: NormalEquations | None = None
            if attempt == 0:
                new_res, new_normal = _evaluate(
                    candidate, problem, layout, carried, loss_scale, normal if over else spare
                )
                spare, known = None, None if over else known
            else:
                new_res = residuals(candidate, problem)
            new_cost = robust_cost(new_res, loss_scale)
            if not new_cost < cost:  # before damping every step: the placements the step made worse held
                held = _hold_worse_placements(state, candidate, problem, new_res, loss_scale, cost)
                if held is not None:
                    candidate = held
                    if new_normal is None:
                        new_res = residuals(candidate, problem)
                    else:
                        new_res, new_normal = _evaluate(candidate, problem, layout, carried, loss_scale, new_normal)
                    new_cost = robust_cost(new_res, loss_scale)
            if new_cost < cost:
                if new_normal is None:  # (taken: its normal equations now)
                    new_res, new_normal = _evaluate(candidate, problem, layout, carried, loss_scale, spare)
                    new_cost, spare = robust_cost(new_res, loss_scale), None
                accepted = True
                relative_decrease = (cost - new_cost) / max(cost, 1e-300)
                log.debug(
                    "LM iteration %d: cost %.6g, relative decrease %.3g, lambda %.1e",
                    iterations,
                    new_cost,
                    relative_decrease,
                    lam,
                )
                # Nielsen's update, its decrease bounded at tenfold (not threefold: easy problems, most,
                # keep converging in few iterations): lam follows the gain (actual over promised
                # decrease), and rejections grow it by doubling factors. Tenfold up and down by turns
                # had a badly started 64-camera robust pass ping-pong between two dampings for 80
                # iterations (now 30)
                gain = (cost - new_cost) / max(predicted, 1e-300)
                state, cost, res, normal, spare = candidate, new_cost, new_res, new_normal, None if over else normal
                known, previous, promised = None, worth, predicted
                lam, growth = max(lam * max(0.1, 1.0 - (2.0 * gain - 1.0) ** 3), 1e-12), 2.0
                trusted = gain > TRUSTED_GAIN and (relative_decrease < NEAR or used == 0.0)
                converged = relative_decrease < tolerance
                break
            # rejected: after an undamped try, lam itself; after a damped one, lam grown (doubling growth)
            if new_normal is not None:  # (a first try's; a later one's were not formed)
                if over:  # the state's normal equations again, in the arrays the step's took
                    _, normal = _evaluate(state, problem, layout, carried, loss_scale, new_normal)
                else:
                    spare = new_normal
            lam, growth = (lam, growth) if used == 0.0 else (lam * growth, 2.0 * growth)
            trusted = False
        if not accepted:
            converged = True  # no decrease possible: at a minimum to machine precision
    sigma = _sigma(res, loss_scale, dof)
    if cameras and final is None:  # the normal equations are always those of the final state
        s, rhs, _ = known[1:] if known is not None else reduced_system(undamped(normal), layout)
        final = CameraSystem(columns, s, rhs)
    covariance = final.covariance(free, sigma) if final is not None else np.zeros((n_cameras * N_CAMERA_PARAMS,) * 2)
    return BundleResult(state, res, iterations, converged, camera_std(covariance), covariance, sigma, (m, p), final)


#: An undamped system reduced: its normal equations, S, rhs and V^-1 (see :func:`reduced_system`).
_Reduced = tuple[NormalEquations, FloatArray, FloatArray, FloatArray]


def _solve_step(
    normal: NormalEquations,
    layout: BlockLayout,
    free_flat: NDArray[np.bool_],
    damping: float,
    known: _Reduced | None,
    n_columns: int,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float, _Reduced | None]:
    """One Levenberg-Marquardt step of the normal equations ``normal`` damped by ``damping`` (0: Gauss-Newton's).

    Args:
        free_flat: (C K,) the camera parameters estimated.
        known: the undamped system of ``normal`` reduced already, or None.
        n_columns: the camera parameters carried per camera (also without a camera parameter free).

    Returns:
        S and rhs of the damped system (empty without camera parameters), the steps of the cameras (C, K) and the
        placements (P, 5), the decrease of the cost the linearised problem promises, and the undamped system
        reduced so far (``known``, or the one this step reduced).
    """
    n_cameras = layout.n_cameras
    if damping == 0.0 and known is not None:
        step, s, rhs, v_inv = known
    else:
        step = undamped(normal) if damping == 0.0 else damped(normal, damping)
        if layout.width:
            s, rhs, v_inv = reduced_system(step, layout)
            if damping == 0.0:
                known = (step, s, rhs, v_inv)
    if layout.width:
        delta_c = solve_free(s, rhs, free_flat).reshape(n_cameras, layout.width)
        delta_p = back_substitute(delta_c, v_inv, step, layout)
        # the decrease the linearised problem promises: delta^T g + lambda delta^T D delta
        predicted = float(np.sum(delta_c * normal.gc)) + damping * float(np.sum(scaling(normal.u) * delta_c**2))
    else:  # placements only: independent 5x5 systems
        s, rhs = np.zeros((0, 0)), np.zeros(0)
        delta_c = np.zeros((n_cameras, n_columns))
        delta_p = np.asarray(np.linalg.solve(step.v, normal.gp[..., None])[..., 0], dtype=np.float64)
        predicted = 0.0
    predicted += float(np.sum(delta_p * normal.gp)) + damping * float(np.sum(scaling(normal.v) * delta_p**2))
    return s, rhs, delta_c, delta_p, predicted, known


def _last_step(
    state: BundleState,
    delta_c: FloatArray,
    delta_p: FloatArray,
    carried: IntArray,
    problem: BundleProblem,
    loss_scale: float | None,
    cost: float,
) -> tuple[BundleState, FloatArray, float] | None:
    """The state moved by an adjustment's last Gauss-Newton step, with its residuals and cost,
    if it costs less than ``cost``; None: it does not (or leaves the camera model)."""
    try:
        candidate = _apply_step(state, delta_c, delta_p, carried)
    except ModelError:
        return None
    res = residuals(candidate, problem)
    new_cost = robust_cost(res, loss_scale)
    return (candidate, res, new_cost) if new_cost < cost else None


def _sigma(res: FloatArray, loss_scale: float | None, dof: int) -> float:
    """The pixel noise estimate from (M, 2) residuals: sqrt(sum w r^2 / dof), Huber weights w."""
    return float(np.sqrt(np.sum(_huber_weights(res, loss_scale)[:, None] * res**2) / dof))
