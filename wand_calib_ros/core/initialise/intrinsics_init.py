"""Step 1 of the paper: initial intrinsics from the manufacturer's data.

k1, k2 come from fitting r = k1*theta + k2*theta^3 to each of the five classic
projections (paper eq. fitmodel) with the nominal focal length over
[0, theta_max]; the principal point starts at the image centre and m comes
from the pixel size. The paper keeps the projection with the smallest fit
residual, which says nothing about the lens; :func:`lens_candidates` instead
returns every plausible projection so the calibration can let the data choose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import CoreError, ModelError
from wand_calib_ros.core.model.bearings import BearingTable
from wand_calib_ros.core.model.camera_model import CameraModel, monotonic_limit
from wand_calib_ros.core.model.rig import LENS_CLASSES, CameraSpec

FloatArray = NDArray[np.float64]


def _perspective(f: float, theta: FloatArray) -> FloatArray:
    return f * np.tan(theta)


def _equidistant(f: float, theta: FloatArray) -> FloatArray:
    return f * theta


def _orthogonal(f: float, theta: FloatArray) -> FloatArray:
    return f * np.sin(theta)


def _stereographic(f: float, theta: FloatArray) -> FloatArray:
    return 2 * f * np.tan(theta / 2)


def _equisolid(f: float, theta: FloatArray) -> FloatArray:
    return 2 * f * np.sin(theta / 2)


#: The five classic projections r_s(f, theta) of the paper (eqs. perspective .. equisolid).
PROJECTIONS = {
    "perspective": _perspective,
    "equidistant": _equidistant,
    "orthogonal": _orthogonal,
    "stereographic": _stereographic,
    "equisolid": _equisolid,
}

FISHEYE_PROJECTIONS = ("equidistant", "orthogonal", "stereographic", "equisolid")

#: Number of samples of [0, theta_max] in the fit (the paper's p).
N_FIT_SAMPLES = 100


@dataclass(frozen=True)
class LensCandidate:
    """One initialisation of k1, k2 from a classic projection.

    Attributes:
        projection: name of the projection it was fitted to.
        k1: mm.
        k2: mm.
        fit_rms_mm: RMS of the fit over [0, theta_max], mm (the paper's criterion).
    """

    projection: str
    k1: float
    k2: float
    fit_rms_mm: float


def fit_projection(projection: str, focal_mm: float, max_view_angle: float) -> LensCandidate:
    """Least-squares k1, k2 for one projection (paper eq. fitobject for a fixed s).

    Args:
        projection: one of :data:`PROJECTIONS`.
        focal_mm: nominal focal length, mm.
        max_view_angle: theta_max, rad.
    """
    if projection not in PROJECTIONS:
        raise ModelError(f"unknown projection '{projection}', expected one of {sorted(PROJECTIONS)}")
    theta = np.linspace(0.0, max_view_angle, N_FIT_SAMPLES + 1)[1:]
    target = PROJECTIONS[projection](focal_mm, theta)
    design = np.stack([theta, theta**3], axis=1)
    (k1, k2), *_ = np.linalg.lstsq(design, target, rcond=None)
    rms = float(np.sqrt(np.mean((design @ [k1, k2] - target) ** 2)))
    return LensCandidate(projection, float(k1), float(k2), rms)


def _plausible(candidate: LensCandidate, max_view_angle: float) -> bool:
    """A curve that is finite, starts increasing and keeps increasing to theta_max."""
    if not (np.isfinite(candidate.k1) and np.isfinite(candidate.k2) and candidate.k1 > 0):
        return False
    return monotonic_limit(np.array([candidate.k1, candidate.k2, 0.0, 0.0, 0.0])) >= max_view_angle


def projection_names_for(spec: CameraSpec) -> tuple[str, ...]:
    """Projections worth trying for a camera, narrowed by its ``lens`` hint."""
    lens = spec.lens
    if lens is None:
        names: tuple[str, ...] = tuple(PROJECTIONS)
    elif lens == "fisheye":
        names = FISHEYE_PROJECTIONS
    elif lens == "conventional":
        names = ("perspective",)
    elif lens in PROJECTIONS:
        names = (lens,)
    else:
        raise ModelError(
            f"camera '{spec.name}': unknown lens '{lens}', expected one of {list(LENS_CLASSES) + sorted(PROJECTIONS)}"
        )
    if spec.max_view_angle >= np.pi / 2:
        names = tuple(n for n in names if n != "perspective")
    return names


def lens_candidates(spec: CameraSpec, *, min_separation_px: float = 2.0) -> tuple[LensCandidate, ...]:
    """Every plausible k1, k2 initialisation for a camera, best paper-fit first.

    Projections that cannot cover theta_max (perspective at 90 degrees and
    beyond, curves that turn over) are dropped; candidates whose curves differ
    by less than ``min_separation_px`` anywhere on [0, theta_max] are merged
    (they would lead to the same calibration).

    Raises:
        ModelError: no projection fits the camera's data sheet.
    """
    theta_max = spec.max_view_angle
    if not (0 < theta_max < np.pi):
        raise ModelError(f"camera '{spec.name}': max_view_angle_deg must be in (0, 180), got {spec.max_view_angle_deg}")
    if not (spec.nominal_focal_mm > 0):
        raise ModelError(f"camera '{spec.name}': nominal_focal_mm must be positive")
    fits = [fit_projection(name, spec.nominal_focal_mm, theta_max) for name in projection_names_for(spec)]
    fits = sorted((c for c in fits if _plausible(c, theta_max)), key=lambda c: c.fit_rms_mm)
    if not fits:
        raise ModelError(
            f"camera '{spec.name}': no classic projection gives a usable curve for "
            f"f={spec.nominal_focal_mm} mm up to {spec.max_view_angle_deg} deg (lens: {spec.lens})"
        )
    theta = np.linspace(0.0, theta_max, N_FIT_SAMPLES)
    px_per_mm = float(np.max(spec.m))
    kept: list[LensCandidate] = []
    for candidate in fits:
        curve = candidate.k1 * theta + candidate.k2 * theta**3
        if all(
            np.max(np.abs(curve - (other.k1 * theta + other.k2 * theta**3))) * px_per_mm >= min_separation_px
            for other in kept
        ):
            kept.append(candidate)
    return tuple(kept)


def initial_model(spec: CameraSpec, candidate: LensCandidate) -> CameraModel:
    """CameraModel of Step 1: (k1, k2, 0, 0, 0), m from the pixel size, centre principal point."""
    return CameraModel(
        np.array([candidate.k1, candidate.k2, 0.0, 0.0, 0.0]), spec.m, spec.image_center, spec.image_size
    )


def nominal_bearings(spec: CameraSpec) -> BearingTable | None:
    """Bearings under the camera's Step 1 model (best classic projection at the nominal focal length)."""
    try:
        return BearingTable(initial_model(spec, lens_candidates(spec)[0]))
    except CoreError:
        return None
