"""What a narrow field of view lets the data determine, and what it holds instead.

At a few degrees across, a camera's image is nearly an affine one: a principal point shift trades
with a rotation of the camera (the views fix it to a hundred pixels or worse), and the distortion terms
bend the image by less than the noise. Left free, they wander along that valley (a principal point
thousands of pixels outside the image) and the adjustment diverges. A camera whose declared field is
narrower than NARROW_FIELD_DEG is therefore calibrated as a pinhole (plumb_bob with zero distortion),
its principal point held at the image centre with the standard deviation of a sensor's mounting
tolerance (a prior): the reported covariance carries that uncertainty into the pose, so the
standard deviations still cover the errors. Where the views determine the principal point better than
the prior, it is estimated instead (:func:`determined_by_views`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import CameraSystem, camera_std
from wand_calib_ros.core.adjust.bundle_problem import LENS, N_CAMERA_PARAMS
from wand_calib_ros.core.adjust.model_order import Pinned
from wand_calib_ros.core.model.camera_model import N_RADIAL, PLUMB_BOB, CameraModel
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec

FloatArray = NDArray[np.float64]

#: A camera whose declared diagonal field of view is narrower than this (degrees) is a narrow one.
NARROW_FIELD_DEG = 10.0
#: Standard deviation (mm on the sensor) of the principal point's offset from the image centre: how
#: far a lens mount centres the optical axis on the sensor (0.15 mm: 15 px at 10 um pixels).
MOUNTING_TOLERANCE_MM = 0.15
#: The principal point's indices in a camera's parameter vector.
PRINCIPAL_POINT = np.array([N_RADIAL, N_RADIAL + 1])
#: The distortion terms a narrow camera holds at zero: k2..k5 (OpenCV's k1..k3) and the lens terms.
DISTORTION = np.r_[1:N_RADIAL, LENS.start : LENS.stop]


def field_of_view_deg(spec: CameraSpec, focal_mm: float | None = None) -> float:
    """The diagonal field of view (degrees) of a pinhole of ``focal_mm`` (default: the given intrinsics' focal,
    else the nominal one) over the camera's image."""
    if focal_mm is None:
        focal_mm = float(spec.intrinsics.k[0]) if spec.intrinsics is not None else spec.nominal_focal_mm
    half_diagonal_mm = 0.5 * float(np.hypot(*(np.asarray(spec.image_size) / spec.m)))
    return float(np.degrees(2.0 * np.arctan(half_diagonal_mm / focal_mm)))


def narrow_fields(rig: RigSpec) -> NDArray[np.bool_]:
    """(C,) the cameras whose field (:func:`field_of_view_deg`) is under NARROW_FIELD_DEG."""
    return np.array([field_of_view_deg(spec) < NARROW_FIELD_DEG for spec in rig.cameras], dtype=bool)


def narrow_cameras(rig: RigSpec) -> NDArray[np.bool_]:
    """(C,) the narrow cameras (:func:`narrow_fields`) whose intrinsics are estimated or given as a start: what
    their views cannot fix is held (:func:`narrow_pins`)."""
    held = np.array([spec.holds_intrinsics for spec in rig.cameras], dtype=bool)
    return narrow_fields(rig) & ~held


def narrow_start(model: CameraModel, spec: CameraSpec) -> CameraModel:
    """A narrow camera's start: intrinsics given as a start as given (their principal point and distortion
    are then the ones held), else :func:`pinhole_at_centre`."""
    return model if spec.intrinsics is not None else pinhole_at_centre(model)


def pinhole_at_centre(model: CameraModel) -> CameraModel:
    """The pinhole (plumb_bob without distortion) of ``model``'s focal, its principal point at the image centre."""
    centre = (np.asarray(model.image_size, dtype=np.float64) - 1.0) / 2.0
    k = np.zeros(N_RADIAL)
    k[0] = model.k[0]
    return CameraModel(k, model.m, centre, model.image_size, PLUMB_BOB)


def narrow_pins(rig: RigSpec, narrow: NDArray[np.bool_]) -> Pinned:
    """The parameters the ``narrow`` (C,) cameras hold: the principal point at a prior of MOUNTING_TOLERANCE_MM
    (in pixels), the distortion terms exactly (at zero)."""
    mask = np.zeros((len(rig.cameras), N_CAMERA_PARAMS), dtype=bool)
    std = np.zeros(mask.shape)
    for c in np.flatnonzero(narrow):
        mask[c, PRINCIPAL_POINT] = mask[c, DISTORTION] = True
        std[c, PRINCIPAL_POINT] = MOUNTING_TOLERANCE_MM * rig.cameras[c].m
    return Pinned(mask, std)


def views_std(system: CameraSystem, free: NDArray[np.bool_], sigma: float, pinned: Pinned) -> FloatArray:
    """(C, N_CAMERA_PARAMS) standard deviations of the parameters held at a prior as the views alone determine them
    (released with the other free parameters, without the prior), 0 elsewhere."""
    at_prior = pinned.std > 0
    return np.where(at_prior, camera_std(system.covariance(free | at_prior, sigma)), 0.0)


def determined_by_views(views: FloatArray, pinned: Pinned) -> NDArray[np.bool_]:
    """(C,) cameras whose principal point the views determine better than its prior (both coordinates)."""
    at_prior = pinned.std > 0
    better = np.where(at_prior, (views > 0) & (views < pinned.std), True)
    return np.asarray(at_prior.any(axis=1) & better.all(axis=1), dtype=bool)
