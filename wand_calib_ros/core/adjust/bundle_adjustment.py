"""Step 4 of the paper (and Step 2 of Section III-B): wand bundle adjustment.

The problem (unknowns, residuals) is :mod:`~wand_calib_ros.core.adjust.bundle_problem`'s, its
linearisation :mod:`~wand_calib_ros.core.adjust.linearisation`'s. The solver is a Levenberg-Marquardt
with exact Jacobians (:mod:`~wand_calib_ros.core.adjust.levenberg_marquardt`) that eliminates the
independent 5-dof placement blocks by a Schur complement, so each iteration only solves a system of
size 13 (plus the timing parameters in use) x cameras. :func:`bundle_adjust` reads from top to bottom:
the parameters to estimate, the normal equations at the start, an optional start re-chosen on them,
the loop, and the covariance of the cameras.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_problem import (
    BIAS,
    LENS,
    N_CAMERA_PARAMS,
    N_GEOMETRIC,
    BundleProblem,
    BundleState,
    apply_step,
    bias_columns,
    lens_columns,
    parameter_mask,
    timing_columns,
)
from wand_calib_ros.core.adjust.levenberg_marquardt import Damping, Iterate, Stopping, Workspace, minimise
from wand_calib_ros.core.adjust.linearisation import noise_sigma, robust_cost
from wand_calib_ros.core.adjust.normal_equations import (
    N_PLACEMENT_PARAMS,
    back_substitute,
    block_layout,
    scaled_inverse,
    solve_free,
)
from wand_calib_ros.core.errors import CalibrationFailedError, ModelError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


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
        """(C, N_CAMERA_PARAMS) the Gauss-Newton step with the camera parameters ``free`` (C, N_CAMERA_PARAMS)
        estimated and the others moved by ``moves`` (C, N_CAMERA_PARAMS; e.g. a term fixed at zero: minus its
        value; None: they stay).

        With other parameters free than the adjustment's (e.g. distortion terms it held at zero
        released), this is the linearised estimate of that other model: no new linearisation, the
        placements follow implicitly. Timing parameters only where the system carries them (and lens
        terms only where it carries them: else no camera's model has them).
        """
        missing = np.setdiff1d(np.arange(N_CAMERA_PARAMS), self.columns)
        if free[:, missing[(missing < LENS.start) | (missing >= BIAS.start)]].any():  # (lens terms not carried
            # are of no camera's model)
            raise ValueError("a timing or centre-bias parameter the adjustment did not carry cannot be estimated")
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
        """(C*N_CAMERA_PARAMS, C*N_CAMERA_PARAMS) sigma^2 S^-1 over the ``free`` (C, N_CAMERA_PARAMS) camera
        parameters (0 rows and columns elsewhere).

        With ``prior_std`` (C, N_CAMERA_PARAMS), the parameters with a positive one are estimated too, each with a
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
    """(C, N_CAMERA_PARAMS) the standard deviations on the diagonal of a (C*N_CAMERA_PARAMS,
    C*N_CAMERA_PARAMS) camera covariance (0 for fixed ones)."""
    return np.sqrt(np.clip(np.diag(covariance), 0.0, None)).reshape(-1, N_CAMERA_PARAMS)


#: A choice of the parameters to estimate made on the normal equations at an adjustment's start (see
#: :func:`bundle_adjust`): called with the start, its cameras' system and its noise estimate (px), it
#: returns the (C, N_CAMERA_PARAMS) parameters to estimate and the (C, N_CAMERA_PARAMS) steps of those it fixes,
#: or None.
ChooseFree = Callable[["BundleState", CameraSystem, float], "tuple[NDArray[np.bool_], FloatArray] | None"]


@dataclass(frozen=True, eq=False)
class BundleResult:
    """Outcome of a bundle adjustment.

    Attributes:
        state: the optimised unknowns.
        residuals: (M, 2) reprojection residuals (projected minus observed), px.
        iterations: LM iterations done.
        converged: whether a convergence criterion was met.
        camera_std: (C, N_CAMERA_PARAMS) standard deviations of the camera parameters
            (:data:`CAMERA_PARAM_NAMES` order; 0 for fixed ones), from the final Jacobian.
        camera_covariance: (C*N_CAMERA_PARAMS, C*N_CAMERA_PARAMS) covariance of all camera parameters (0
            rows/cols for fixed).
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


#: An adjustment stops when the cameras' next step is worth less than this fraction of a chi-square
#: unit (sigma^2): every camera parameter within a few hundredths of its standard deviation of where
#: the step would take it. Left alone, placements seen by two nearly parallel rays make a large rig
#: creep by 1e-8 of its cost per iteration for tens of iterations without moving a camera.
CAMERAS_SETTLED = 1e-3
#: What passes that only decide outliers or test the timing settle at: every camera parameter within
#: about a third of its standard deviation of the optimum (the passes after them finish the job).
DECIDING_SETTLED = 0.1


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
        free: (C, N_CAMERA_PARAMS) which camera parameters are estimated (see :func:`default_free_mask`; only those
            of each camera's model are, :func:`parameter_mask`); the timing ones need ``problem.timing``.
        loss_scale: Huber threshold on each observation's 2D residual (px), or None for least
            squares. The robust problem is solved by iteratively reweighted least squares.
        max_iterations: LM iteration cap.
        tolerance: stop when the relative decrease of the cost falls below it, or when the
            undamped step promises less (then without taking it). On 1,000,000 residuals at 1 px the
            default leaves the state within 0.01 of a chi-square unit of the optimum (1e-6 left 1-2
            units on a 64-camera rig: its focal lengths 25 % worse).
        settled: stop when the cameras' step is worth less than this fraction of a chi-square unit
            (:data:`CAMERAS_SETTLED`: on a 64-camera rig after 3 iterations instead of 14, every camera
            parameter within 0.005 of its standard deviation of where the 14 took it; passes that only
            decide outliers or a test settle at :data:`DECIDING_SETTLED`).
        last_step: end with a Gauss-Newton step not linearised again when the convergence so far says the step
            after it would end the adjustment: its cameras' worth w times the ratio of w to the previous step's
            below ``settled``, or the decrease it promises times its ratio to the previous one's below
            ``tolerance`` (:func:`~wand_calib_ros.core.adjust.levenberg_marquardt._last_step`). The covariance
            then comes from the system it was computed on, its gradient moved along the step. False: every
            step is linearised again.
        choose: decides on the normal equations at the start which camera parameters to estimate
            (e.g. the model order on all placements,
            :class:`~wand_calib_ros.core.adjust.model_order.OrderOnAllPlacements`), the timing ones as
            ``free`` has them (:func:`_chosen_start`).

    Returns:
        The optimised state, residuals and parameter uncertainties.
    """
    exists = parameter_mask(state.models)
    carried = np.concatenate(  # beyond the geometric ones
        [timing_columns(free & exists), lens_columns(state.models), bias_columns(free & exists)]
    )
    estimated = _Estimated(free & exists, np.concatenate([np.arange(N_GEOMETRIC), carried]), problem)
    cameras = bool(estimated.free_flat.any())
    layout = block_layout(
        problem.camera,
        problem.placement,
        problem.point,
        problem.n_cameras,
        problem.n_placements,
        problem.wand.n_points,
        estimated.columns.size if cameras else 0,
    )
    work = Workspace(problem, layout, carried, loss_scale)
    res = work.linearise(state)
    if not np.all(np.isfinite(res)):
        raise CalibrationFailedError("the bundle adjustment starts from non-finite reprojections")
    current, damping = Iterate(state, res, robust_cost(res, loss_scale)), Damping()
    if choose is not None and cameras:  # from the start's linearised solution, Gauss-Newton's step first
        current, estimated = _chosen_start(work, current, estimated, choose, exists)
        damping = Damping(trusted=True)
    stopping = Stopping(tolerance, settled, last_step, estimated.dof, cameras)
    current, iterations, converged, system = minimise(
        work, current, estimated.free_flat, stopping, damping, max_iterations
    )
    sigma = noise_sigma(current.res, loss_scale, estimated.dof)
    final = None
    if cameras:  # the normal equations are always those of the final state
        final = CameraSystem(estimated.columns, *(system or work.reduced()[1:3]))
        covariance = final.covariance(estimated.free, sigma)
    else:
        covariance = np.zeros((problem.n_cameras * N_CAMERA_PARAMS,) * 2)
    dof = (estimated.n_residuals, estimated.n_parameters)
    return BundleResult(
        current.state, current.res, iterations, converged, camera_std(covariance), covariance, sigma, dof, final
    )


@dataclass(frozen=True, eq=False)
class _Estimated:
    """What an adjustment estimates.

    Attributes:
        free: (C, N_CAMERA_PARAMS) the camera parameters estimated (of each camera's model only).
        columns: (K,) the camera parameters carried per camera (fixed ones included): the geometric ones, the
            timing ones free for some camera, and the lens terms some camera's model has.
        problem: the adjustment's observations.
    """

    free: NDArray[np.bool_]
    columns: IntArray
    problem: BundleProblem

    @property
    def free_flat(self) -> NDArray[np.bool_]:
        """(C K,) ``free`` over the columns carried, camera-major."""
        return self.free[:, self.columns].reshape(-1)

    @property
    def n_residuals(self) -> int:
        """m: the residual scalars (two per observation)."""
        return 2 * self.problem.n_observations

    @property
    def n_parameters(self) -> int:
        """p: the free camera parameters and every placement's 5."""
        return int(self.free_flat.sum()) + N_PLACEMENT_PARAMS * self.problem.n_placements

    @property
    def dof(self) -> int:
        """m - p, at least 1."""
        return max(self.n_residuals - self.n_parameters, 1)


def _chosen_start(
    work: Workspace, start: Iterate, estimated: _Estimated, choose: ChooseFree, exists: NDArray[np.bool_]
) -> tuple[Iterate, _Estimated]:
    """The start re-chosen on its own normal equations: which camera parameters to estimate, and the cameras and
    placements moved to that choice's linearised solution (so the start's linearisation serves the choice too).

    Where ``choose`` keeps the parameters, the start stays, its reduced system the first iteration's first try.
    Where the linearised solution leaves the camera model (or puts a point behind a pinhole camera), only the
    parameters the choice fixes move.

    Raises:
        CalibrationFailedError: the chosen start cannot be projected.
    """
    system, s, rhs, v_inv = work.reduced()
    start_system = CameraSystem(estimated.columns, s, rhs)
    choice = choose(start.state, start_system, noise_sigma(start.res, work.loss_scale, estimated.dof))
    if choice is None:
        return start, estimated
    free, moves = choice[0] & exists, choice[1]
    if not np.array_equal(timing_columns(free), work.carried[work.carried < LENS.start]) or not np.array_equal(
        bias_columns(free), work.carried[work.carried >= BIAS.start]
    ):
        raise ValueError("a choice of the parameters to estimate cannot change the timing or bias ones carried")
    chosen_estimate = _Estimated(free, estimated.columns, estimated.problem)
    columns = estimated.columns
    delta_c = start_system.step(free, moves)[:, columns]
    delta_p = back_substitute(delta_c, v_inv, system, work.layout)
    del system  # its W is the workspace's, which the chosen start's normal equations are summed into
    chosen = _linearised_at(work, start.state, delta_c, delta_p)
    if chosen is None:  # only the parameters the choice fixes move
        delta_c = np.where(free[:, columns], 0.0, moves[:, columns])
        state = apply_step(start.state, delta_c, np.zeros_like(delta_p), work.carried)
        chosen = state, work.linearise(state)
    state, res = chosen
    flat = delta_c.reshape(-1)
    previous = float(flat @ s @ flat) / (start.cost / chosen_estimate.dof)  # the move's length, chi-square units
    cost = robust_cost(res, work.loss_scale)
    if not np.isfinite(cost):
        raise CalibrationFailedError("the bundle adjustment's chosen start has non-finite reprojections")
    return Iterate(state, res, cost, previous), chosen_estimate


def _linearised_at(
    work: Workspace, state: BundleState, delta_c: FloatArray, delta_p: FloatArray
) -> tuple[BundleState, FloatArray] | None:
    """``state`` moved by the cameras' (C, K) and the placements' (P, 5) steps, linearised by ``work``, with its
    (M, 2) residuals; None where the step leaves the camera model or puts a point where it cannot be seen."""
    try:
        moved = apply_step(state, delta_c, delta_p, work.carried)
    except ModelError:
        return None
    res = work.linearise(moved)
    return (moved, res) if np.all(np.isfinite(res)) else None
