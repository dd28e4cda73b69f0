"""The world frame adjusted together with the cameras: the floor's views weighted like every other view.

The two-stage fit of :mod:`~wand_calib_ros.core.after.world_frame` (triangulate the still lays, fit a
plane) takes the cameras as exact. This module re-estimates the floor with them. The unknowns are:

- every free camera parameter of the calibration;
- the floor frame, X_ref = R_f X_world + t_f;
- each lay of the wand after the first, as (x, y) of its A on the floor and its angle psi about z.

The first lay defines the origin (its A, or its centre) and the x axis. With a floor tool (an L-frame
or a square of markers at known positions), the markers' world positions are given and only the floor
frame is estimated.

The residuals are:

- the floor views' reprojection errors over the calibration's pixel noise sigma;
- the calibration itself as a prior on the cameras, with its information matrix (the wand's placements
  eliminated from the bundle adjustment's normal equations, sigma^-2 Sigma^-1).

To first order, this is the bundle adjustment of the waved placements and the floor placements
together. The floor's covariance, from the joint normal equations, so includes the calibration's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import camera_std
from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS, TIMING, moved_camera
from wand_calib_ros.core.errors import DegenerateDataError
from wand_calib_ros.core.model.camera_model import CameraModel, project
from wand_calib_ros.core.model.geometry import Pose, rotation_from_rotvec

FloatArray = NDArray[np.float64]

#: The camera parameters a still view depends on: all but the timing ones (indices of CAMERA_PARAM_NAMES).
STILL_PARAMETERS = np.setdiff1d(np.arange(N_CAMERA_PARAMS), np.arange(TIMING.start, TIMING.stop))
#: Gauss-Newton stops when the step changes no unknown by more than this fraction of its standard deviation.
SETTLED = 1e-4
MAX_ITERATIONS = 20


@dataclass(frozen=True, eq=False)
class FloorSolution:
    """The floor frame of the joint adjustment.

    Attributes:
        reference_from_world: X_ref = R X_world + T (mm): the world's axes and origin in the reference frame.
        normal_std_deg: the standard deviation of the floor normal's direction, degrees (its RMS angle).
        origin_std_mm: the standard deviation of the origin, mm (the RMS length of its error vector).
        rms_px: RMS reprojection error of the floor views, px.
        lays: (L, 3) x, y (mm) and psi (rad) of each lay (the first is the origin's).
        models, poses: the cameras of the joint solution (the floor views moved them a little).
    """

    reference_from_world: Pose
    normal_std_deg: float
    origin_std_mm: float
    rms_px: float
    lays: FloatArray
    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]


def _lay_points(lays: FloatArray, positions: FloatArray) -> FloatArray:
    """(L, K, 3) world points of the markers of lays (L, 3: x, y, psi) at ``positions`` (K,) along the wand."""
    direction = np.stack([np.cos(lays[:, 2]), np.sin(lays[:, 2]), np.zeros(len(lays))], axis=1)
    points = lays[:, None, :2] + positions[None, :, None] * direction[:, None, :2]
    return np.concatenate([points, np.zeros((*points.shape[:2], 1))], axis=2)


def _prior(covariance: FloatArray, free: NDArray[np.intp]) -> FloatArray:
    """(r, n) the whitening matrix W of the calibration's prior: |W delta|^2 = delta^T Sigma^-1 delta."""
    block = covariance[np.ix_(free, free)]
    scale = np.sqrt(np.clip(np.diag(block), 1e-300, None))
    values, vectors = np.linalg.eigh(block / np.outer(scale, scale))
    kept = values > 1e-12 * values.max()
    return (vectors[:, kept] / np.sqrt(values[kept])).T / scale[None, :]


def adjust_floor(
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    covariance: FloatArray,
    sigma_px: float,
    uv: FloatArray,
    start: Pose,
    *,
    lay_of_frame: NDArray[np.intp] | None = None,
    positions_mm: FloatArray | None = None,
    lay_starts: FloatArray | None = None,
    tool_mm: FloatArray | None = None,
) -> FloorSolution:
    """The floor frame and the cameras adjusted together (see the module docstring).

    Args:
        models, poses: the calibrated cameras (poses relative to the reference camera).
        covariance: (C*N_CAMERA_PARAMS, C*N_CAMERA_PARAMS) the calibration's covariance of the camera parameters
            (rig order).
        sigma_px: the calibration's pixel noise.
        uv: (F, C, K, 2) the floor frames' views, NaN where not seen.
        start: X_ref = R X_world + T to start from (the two-stage fit).
        lay_of_frame: (F,) each frame's lay (0: the first, the origin's) for a wand laid on the floor.
        positions_mm: (K,) the markers' positions along the lays' x in the world (the first lay's
            origin at 0: A at 0, or minus half the wand's length for its centre).
        lay_starts: (L, 3) x, y, psi of each lay to start from (the first is held at 0).
        tool_mm: (K, 3) a floor tool's markers in the world frame, mm (instead of lays).

    Raises:
        DegenerateDataError: the floor's views do not determine the floor frame.
    """
    if tool_mm is None:
        assert lay_of_frame is not None and positions_mm is not None and lay_starts is not None
    std = camera_std(covariance)
    free_mask = np.zeros((len(models), N_CAMERA_PARAMS), dtype=bool)
    free_mask[:, STILL_PARAMETERS] = std[:, STILL_PARAMETERS] > 0
    free = np.flatnonzero(free_mask.reshape(-1))
    frame, camera, marker = np.nonzero(np.isfinite(uv).all(axis=-1))  # the views seen: (F, C, K) -> (M,) each
    problem = _FloorProblem(models, poses, start, free, _prior(covariance, free), std, sigma_px, frame, camera, marker,
                            uv[frame, camera, marker], lay_of_frame, positions_mm, lay_starts, tool_mm)  # fmt: skip
    x, information = _gauss_newton(problem)
    covariance_x = np.linalg.pinv(information)
    cameras, floor, lays = problem.unpack(x)
    floor_views = problem.residuals(x)[: problem.n_views]
    n_free = problem.n_free
    rotation_cov = covariance_x[n_free : n_free + 3, n_free : n_free + 3]
    normal = floor.rotation[:, 2]
    across = np.eye(3) - np.outer(normal, normal)  # a rotation about the normal leaves it
    normal_var = float(np.trace(across @ rotation_cov @ across.T))
    origin_var = float(np.trace(covariance_x[n_free + 3 : n_free + 6, n_free + 3 : n_free + 6]))
    return FloorSolution(
        floor,
        float(np.degrees(np.sqrt(max(normal_var, 0.0)))),
        float(np.sqrt(max(origin_var, 0.0))),
        float(np.sqrt(np.mean(floor_views**2)) * sigma_px),
        lays,
        tuple(model for model, _ in cameras),
        tuple(pose for _, pose in cameras),
    )


@dataclass(frozen=True, eq=False)
class _FloorProblem:
    """The joint adjustment's residuals on a flat vector of unknowns x: the free camera parameters' steps, the
    floor frame's (rotation vector, translation) and each lay's after the first (x, y, psi).

    Attributes:
        models, poses: the calibrated cameras.
        start: the floor frame at x = 0.
        free: (n,) the free camera parameters' indices into the (C*20,) rig order.
        prior: (r, n) the whitening matrix of the calibration's prior (:func:`_prior`).
        std: (C, N_CAMERA_PARAMS) the calibration's standard deviations.
        sigma_px: the calibration's pixel noise.
        frame, camera, marker: (M,) each floor view's frame, camera and marker.
        observed: (M, 2) its pixels.
        lay_of_frame, positions_mm, lay_starts, tool_mm: as :func:`adjust_floor` has them.
    """

    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    start: Pose
    free: NDArray[np.intp]
    prior: FloatArray
    std: FloatArray
    sigma_px: float
    frame: NDArray[np.intp]
    camera: NDArray[np.intp]
    marker: NDArray[np.intp]
    observed: FloatArray
    lay_of_frame: NDArray[np.intp] | None
    positions_mm: FloatArray | None
    lay_starts: FloatArray | None
    tool_mm: FloatArray | None

    @property
    def n_free(self) -> int:
        return int(self.free.size)

    @property
    def n_lays(self) -> int:
        return 0 if self.lay_starts is None or self.tool_mm is not None else len(self.lay_starts)

    @property
    def n_unknowns(self) -> int:
        return self.n_free + 6 + 3 * max(self.n_lays - 1, 0)

    @property
    def n_views(self) -> int:
        """Residual rows of the floor views (two per view); the prior's follow."""
        return 2 * self.observed.shape[0]

    def rows_of(self, camera: int) -> NDArray[np.intp]:
        """The views of ``camera``."""
        return np.flatnonzero(self.camera == camera)

    def moved(self, x: FloatArray, camera: int) -> tuple[CameraModel, Pose]:
        """``camera`` moved by its free parameters' steps in ``x``."""
        flat = np.zeros(len(self.models) * N_CAMERA_PARAMS)
        flat[self.free] = x[: self.n_free]
        delta = flat.reshape(len(self.models), N_CAMERA_PARAMS)
        return moved_camera(self.models[camera], self.poses[camera], delta[camera])

    def unpack(self, x: FloatArray) -> tuple[list[tuple[CameraModel, Pose]], Pose, FloatArray]:
        """The cameras, the floor frame and the (L, 3) lays at ``x``."""
        cameras = [self.moved(x, c) for c in range(len(self.models))]
        w = x[self.n_free : self.n_free + 6]
        floor = Pose(rotation_from_rotvec(w[:3]) @ self.start.rotation, self.start.translation + w[3:])
        lays = np.zeros((max(self.n_lays, 1), 3))
        if self.n_lays:
            lays = np.array(self.lay_starts, dtype=float)
            lays[1:] += x[self.n_free + 6 :].reshape(-1, 3)
        return cameras, floor, lays

    def reference_points(self, floor: Pose, lays: FloatArray) -> FloatArray:
        """(M, 3) each view's marker in the reference frame."""
        if self.tool_mm is None:
            assert self.positions_mm is not None and self.lay_of_frame is not None
            return floor.apply(_lay_points(lays, self.positions_mm)[self.lay_of_frame[self.frame], self.marker])
        return floor.apply(self.tool_mm[self.marker])

    def residuals(self, x: FloatArray) -> FloatArray:
        """Floor views over sigma (2M, camera by camera in observation order), then the prior."""
        cameras, floor, lays = self.unpack(x)
        reference = self.reference_points(floor, lays)
        projected = np.empty_like(self.observed)
        for c in range(len(self.models)):
            rows = self.rows_of(c)
            if rows.size:
                model, pose = cameras[c]
                projected[rows] = project(model, pose.apply(reference[rows]))
        return np.concatenate(
            [((projected - self.observed) / self.sigma_px).reshape(-1), self.prior @ x[: self.n_free]]
        )

    def steps(self) -> FloatArray:
        """(n_unknowns,) the numeric derivatives' steps: 1e-3 of a camera parameter's standard deviation, 1e-7 rad
        and 1e-4 mm for the floor frame and the lays."""
        return np.concatenate([self.std.reshape(-1)[self.free] * 1e-3, np.full(3, 1e-7), np.full(3, 1e-4),
                               np.tile([1e-4, 1e-4, 1e-7], max(self.n_lays - 1, 0))])  # fmt: skip

    def jacobian(self, x: FloatArray, r: FloatArray) -> FloatArray:
        """(2M + r, n_unknowns) the residuals' Jacobian at ``x`` (residuals ``r``) by forward differences: a
        camera parameter moves only its own camera's views, the prior is linear, the floor and lays move all."""
        n_free, n_views, steps = self.n_free, self.n_views, self.steps()
        jacobian = np.zeros((r.size, self.n_unknowns))
        jacobian[n_views:, :n_free] = self.prior
        _, floor, lays = self.unpack(x)
        reference = self.reference_points(floor, lays)
        base = r[:n_views].reshape(-1, 2)
        owner = self.free // N_CAMERA_PARAMS  # the camera of each free camera parameter
        for i in range(n_free):
            rows = self.rows_of(int(owner[i]))
            if not rows.size:
                continue
            moved = x.copy()
            moved[i] += steps[i]
            model, pose = self.moved(moved, int(owner[i]))
            change = (project(model, pose.apply(reference[rows])) - self.observed[rows]) / self.sigma_px - base[rows]
            column = np.zeros((self.observed.shape[0], 2))
            column[rows] = change / steps[i]
            jacobian[:n_views, i] = column.reshape(-1)
        for i in range(n_free, self.n_unknowns):
            moved = x.copy()
            moved[i] += steps[i]
            jacobian[:, i] = (self.residuals(moved) - r) / steps[i]
        return jacobian


def _gauss_newton(problem: _FloorProblem) -> tuple[FloatArray, FloatArray]:
    """The unknowns x that minimise the problem's residuals, and the information matrix J^T J there.

    Undamped Gauss-Newton, not the bundle adjustment's Levenberg-Marquardt: a few dense unknowns started from the
    two-stage fit, the prior keeping the cameras where the calibration put them. Stops when no unknown moves by
    more than SETTLED of its standard deviation, or after MAX_ITERATIONS.

    Raises:
        DegenerateDataError: the views cannot be projected, or do not determine the floor.
    """
    x = np.zeros(problem.n_unknowns)
    information = np.eye(problem.n_unknowns)
    for _ in range(MAX_ITERATIONS):
        r = problem.residuals(x)
        if not np.all(np.isfinite(r)):
            raise DegenerateDataError("the floor frames' views cannot be projected with the calibrated cameras")
        jacobian = problem.jacobian(x, r)
        information = jacobian.T @ jacobian
        try:
            step = -np.linalg.solve(information, jacobian.T @ r)
        except np.linalg.LinAlgError:
            raise DegenerateDataError("the floor frames' views do not determine the floor") from None
        x = x + step
        scale = np.sqrt(np.clip(np.diag(np.linalg.pinv(information)), 1e-300, None))
        if np.all(np.abs(step) < SETTLED * scale):
            break
    return x, information
