"""The bundle adjustment's problem: its unknowns, its observations and how a step moves the unknowns.

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
time, held fixed during one adjustment). The residuals and their Jacobians are
:mod:`~wand_calib_ros.core.adjust.linearisation`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model import pinhole
from wand_calib_ros.core.model.brightness import BIAS_COMPONENTS, N_BIAS, N_BIAS_CLASSES
from wand_calib_ros.core.model.camera_model import EQUIDISTANT, N_EXTRA, N_INTRINSIC, N_RADIAL, PLUMB_BOB, CameraModel
from wand_calib_ros.core.model.geometry import Pose, rotation_from_rotvec, tangent_basis
from wand_calib_ros.core.model.rig import WandSpec
from wand_calib_ros.core.model.views import observed_points

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Geometric parameters per camera: k1..k5, u0, v0, rotation (3), translation (3).
N_GEOMETRIC = N_INTRINSIC + 6
#: Parameters per camera: the geometric ones, the time offset and the rolling-shutter readout time, the
#: pinhole models' tangential (t1, t2) and rational (d1, d2, d3) terms, then the centre bias of each brightness
#: class (:mod:`~wand_calib_ros.core.model.brightness`).
N_CAMERA_PARAMS = N_GEOMETRIC + 2 + N_EXTRA + N_BIAS
#: Indices of the timing parameters in a camera's parameter vector.
TIME_OFFSET, READOUT = N_GEOMETRIC, N_GEOMETRIC + 1
TIMING = slice(TIME_OFFSET, READOUT + 1)
#: The pinhole models' further parameters in a camera's parameter vector (its ``CameraModel.lens_vector``).
LENS = slice(READOUT + 1, READOUT + 1 + N_EXTRA)
#: The centre bias in a camera's parameter vector: per brightness class 1.. its offsets along u, v and radially.
BIAS = slice(LENS.stop, N_CAMERA_PARAMS)
#: A camera's geometry as a user names it: (name, its indices in a camera's parameter vector).
GEOMETRY_PARTS = (
    ("focal length", (0,)),
    ("principal point", (5, 6)),
    ("orientation", (7, 8, 9)),
    ("position", (10, 11, 12)),
)
#: Every intrinsic parameter's index in a camera's parameter vector.
INTRINSICS = np.r_[0:N_INTRINSIC, LENS.start : LENS.stop]
#: Names of the per-camera parameters in order (rotation as a small-angle update, rad; the timing
#: parameters in the time unit of the observations; t1, t2 in mm, d1..d3 dimensionless; the bias in px).
CAMERA_PARAM_NAMES = (
    "k1", "k2", "k3", "k4", "k5", "u0", "v0", "rx", "ry", "rz", "tx", "ty", "tz", "time_offset", "readout",
    "t1", "t2", "d1", "d2", "d3",
    *(f"bias{k}_{axis}" for k in range(1, N_BIAS_CLASSES + 1) for axis in BIAS_COMPONENTS),
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
        brightness: (M,) each observation's brightness, stops over full scale (:mod:`~wand_calib_ros.core.model.
            brightness`; NaN: not known; None: none known, no centre bias modelled).
    """

    wand: WandSpec
    n_cameras: int
    n_placements: int
    camera: IntArray
    placement: IntArray
    point: IntArray
    uv: FloatArray
    timing: ObservationTiming | None = None
    brightness: FloatArray | None = None

    @staticmethod
    def from_dense(
        wand: WandSpec,
        uv: FloatArray,
        timing: PlacementTiming | None = None,
        rows: IntArray | None = None,
        brightness: FloatArray | None = None,
    ) -> BundleProblem:
        """Problem from dense (P, C, 3, 2) pixels with NaN for unseen points, or from their placements ``rows``
        (R,) only (no copy of those), the timing of those placements and the points' (P, C, 3) brightness (of
        all P placements, as ``uv``)."""
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
            None if brightness is None else brightness.reshape(-1)[flat],
        )

    @property
    def n_observations(self) -> int:
        return int(self.camera.size)


@dataclass(frozen=True, eq=False)
class CameraBias:
    """The cameras' centre bias (:mod:`~wand_calib_ros.core.model.brightness`).

    Attributes:
        values: (C, N_BIAS) each camera's terms (u, v, r each), px (per stop for a linear shape's second term).
        shapes: (C,) each camera's shape: CLASSES, LINEAR or CONSTANT.
        starts: (C,) the brightness class a LINEAR or CONSTANT shape starts from (1: full scale).
        noise: (C, N_BIAS_CLASSES + 1) the centres' noise in each brightness class (class 0 first) relative to the
            camera's as a whole: each observation's residual is divided by its class's (None: all alike).
    """

    values: FloatArray
    shapes: NDArray[np.int8]
    starts: NDArray[np.int8]
    noise: FloatArray | None = None


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
        bias: the cameras' centre bias; None: none.
    """

    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    wand_a: FloatArray
    wand_direction: FloatArray
    timing: FloatArray | None = None
    bias: CameraBias | None = None

    @property
    def camera_timing(self) -> FloatArray:
        """(C, 2) time offset and readout time per camera (zeros when not modelled)."""
        return np.zeros((len(self.models), 2)) if self.timing is None else self.timing

    @property
    def camera_bias(self) -> FloatArray:
        """(C, N_BIAS) the centre bias's terms per camera (zeros when not modelled)."""
        return np.zeros((len(self.models), N_BIAS)) if self.bias is None else self.bias.values

    @property
    def bias_shapes(self) -> NDArray[np.int8]:
        """(C,) the shape of each camera's centre bias (:data:`~wand_calib_ros.core.model.brightness.CLASSES` when
        not modelled)."""
        return np.zeros(len(self.models), dtype=np.int8) if self.bias is None else self.bias.shapes

    @property
    def bias_starts(self) -> NDArray[np.int8]:
        """(C,) the class each camera's LINEAR or CONSTANT bias starts from (1 when not modelled)."""
        return np.ones(len(self.models), dtype=np.int8) if self.bias is None else self.bias.starts

    @property
    def bias_noise(self) -> FloatArray | None:
        """(C, N_BIAS_CLASSES + 1) the centres' relative noise by brightness class (None: all alike)."""
        return None if self.bias is None else self.bias.noise

    def points(self, wand: WandSpec) -> FloatArray:
        """(P, 3, 3) A, B, C of every placement in the reference frame, mm."""
        return self.wand_a[:, None, :] + wand.offsets[None, :, None] * self.wand_direction[:, None, :]


def timing_columns(free: NDArray[np.bool_]) -> IntArray:
    """Timing parameters (indices into :data:`CAMERA_PARAM_NAMES`) free for at least one camera.

    The adjustment carries the 13 geometric parameters of every camera and only these timing
    ones, so a synchronised rig costs what it did before timing was modelled.
    """
    return (np.flatnonzero(free[:, TIMING].any(axis=0)) + TIMING.start).astype(np.int64)


def bias_columns(free: NDArray[np.bool_]) -> IntArray:
    """The centre-bias parameters (indices into :data:`CAMERA_PARAM_NAMES`) free for at least one camera: the
    adjustment carries only these, so a take without brightness costs what it did."""
    return (np.flatnonzero(free[:, BIAS].any(axis=0)) + BIAS.start).astype(np.int64)


def lens_columns(models: tuple[CameraModel, ...]) -> IntArray:
    """The pinhole models' lens terms (indices into :data:`CAMERA_PARAM_NAMES`) some camera's model has:
    the adjustment carries them (fixed or free) only then, so a fisheye-model rig costs what it did."""
    return (np.flatnonzero(parameter_mask(models)[:, LENS].any(axis=0)) + LENS.start).astype(np.int64)


def default_free_mask(
    n_cameras: int, reference: int = 0, models: tuple[CameraModel, ...] | None = None
) -> NDArray[np.bool_]:
    """(C, N_CAMERA_PARAMS) mask: every intrinsic free (of the cameras' ``models``, when given: the adjustment
    leaves out what a model does not have anyway), every pose but the reference camera's free, no timing, no
    centre bias."""
    free = np.ones((n_cameras, N_CAMERA_PARAMS), dtype=bool)
    free[reference, N_INTRINSIC:N_GEOMETRIC] = False
    free[:, TIMING] = False
    free[:, BIAS] = False
    return free if models is None else free & parameter_mask(models)


def moved_camera(model: CameraModel, pose: Pose, delta: FloatArray, *, lens: bool = True) -> tuple[CameraModel, Pose]:
    """A camera moved by a (20,) step of its parameters (:data:`CAMERA_PARAM_NAMES`): intrinsics added, the
    rotation vector left-multiplied, the translation added; the lens terms only with ``lens`` and a pinhole
    model; timing is not the camera's (see :class:`BundleState`)."""
    extra = model.lens_vector() + delta[LENS] if lens and model.is_pinhole else None
    moved = model.with_intrinsic_vector(model.intrinsic_vector() + delta[:N_INTRINSIC], extra)
    rotation = rotation_from_rotvec(delta[N_INTRINSIC : N_INTRINSIC + 3]) @ pose.rotation
    return moved, Pose(rotation, pose.translation + delta[N_INTRINSIC + 3 : N_GEOMETRIC])


def apply_step(state: BundleState, delta_c: FloatArray, delta_p: FloatArray, carried: IntArray) -> BundleState:
    """The state moved by camera steps (C, 13 + len(carried)) and placement steps (P, 5)."""
    delta = np.zeros((len(state.models), N_CAMERA_PARAMS))
    delta[:, np.concatenate([np.arange(N_GEOMETRIC), carried])] = delta_c
    delta[~parameter_mask(state.models)] = 0.0  # what a camera's model does not have stays as it is
    lens = bool(np.any((carried >= LENS.start) & (carried < LENS.stop)))
    moved = [moved_camera(m, p, d, lens=lens) for m, p, d in zip(state.models, state.poses, delta, strict=True)]
    models, poses = [m for m, _ in moved], [p for _, p in moved]
    camera_timing = state.timing
    if np.any(carried < LENS.start):
        camera_timing = state.camera_timing + delta[:, TIMING]
    bias = state.bias
    if np.any(carried >= BIAS.start):
        bias = CameraBias(state.camera_bias + delta[:, BIAS], state.bias_shapes, state.bias_starts, state.bias_noise)
    basis = tangent_basis(state.wand_direction)
    direction = state.wand_direction + np.einsum("pij,pj->pi", basis, delta_p[:, 3:])
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    return BundleState(tuple(models), tuple(poses), state.wand_a + delta_p[:, :3], direction, camera_timing, bias)
