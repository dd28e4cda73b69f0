"""Intrinsics a user already has (a board calibration) as this package's camera models.

Each is taken in its own model, exactly: OpenCV's fisheye (ROS ``equidistant``) parameters as the
Kannala-Brandt model (:func:`wand_calib_ros.core.model.camera_model.from_opencv_fisheye`), OpenCV's pinhole
model with radial and tangential distortion (ROS ``plumb_bob``, Kalibr ``radtan``,
``rational_polynomial``) as the pinhole models (:func:`wand_calib_ros.core.model.camera_model.from_opencv_pinhole`).

Only where the rig description asks for the equidistant model of a camera whose intrinsics are given
in a pinhole model (``camera_model: equidistant``) is one converted to the other: the radial part
f * rho_d(tan theta) is fitted by r(theta) = k1 theta + ... + k5 theta^9 over the angles the image
reaches, and accepted only when the fit and the neglected tangential terms stay below
:data:`MAX_CONVERSION_ERROR_PX` everywhere in the image.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.model.camera_model import (
    EQUIDISTANT,
    PLUMB_BOB,
    RATIONAL_POLYNOMIAL,
    CameraModel,
    from_opencv_fisheye,
    from_opencv_pinhole,
    radius_derivative,
)

FloatArray = NDArray[np.float64]

#: Distortion models accepted, by their ROS (and Kalibr) names, and the camera model each names.
EQUIDISTANT_NAMES = (EQUIDISTANT, "fisheye")
PINHOLE_RADTAN = (PLUMB_BOB, "radtan", RATIONAL_POLYNOMIAL)

#: Largest image error (px) a conversion from a pinhole model may introduce.
MAX_CONVERSION_ERROR_PX = 0.1
#: Samples of the fitted angle range.
N_SAMPLES = 400


def _pinhole_radius(distortion: FloatArray, rho: FloatArray) -> FloatArray:
    """Distorted normalised radius rho_d of OpenCV's radial model (k1, k2, [p1, p2], k3, [k4, k5, k6])."""
    d = np.zeros(8)
    d[: min(distortion.size, 8)] = distortion[:8]
    k1, k2, _, _, k3, k4, k5, k6 = d
    r2 = rho * rho
    numerator = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    denominator = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    return rho * numerator / denominator


def _corner_radius_px(camera_matrix: FloatArray, image_size: tuple[int, int]) -> float:
    """Distance (px) from the principal point to the farthest image corner (OpenCV pixel centres)."""
    width, height = image_size
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [-0.5, height - 0.5], [width - 0.5, height - 0.5]])
    return float(np.max(np.linalg.norm(corners - camera_matrix[:2, 2], axis=1)))


def from_pinhole_radtan(
    camera_matrix: FloatArray,
    distortion: FloatArray,
    m: FloatArray,
    image_size: tuple[int, int],
    *,
    name: str = "camera",
) -> tuple[CameraModel, float]:
    """A camera model equivalent (within :data:`MAX_CONVERSION_ERROR_PX`) to OpenCV's pinhole model.

    Args:
        camera_matrix: (3, 3) K.
        distortion: OpenCV's (k1, k2, p1, p2[, k3[, k4, k5, k6]]).
        m: (2,) pixel densities px/mm of the rig description (m_v follows K's fy/fx).
        image_size: (width, height) px.
        name: the camera, for messages.

    Returns:
        The model and the largest image difference (px) between it and the given one.

    Raises:
        ModelError: the distortion folds back inside the image, or the conversion would move image
            points by more than MAX_CONVERSION_ERROR_PX (tangential terms, a radial shape the
            polynomial cannot follow).
    """
    K = np.asarray(camera_matrix, dtype=np.float64)
    d = np.asarray(distortion, dtype=np.float64).ravel()
    if d.size not in (4, 5, 8):
        raise ModelError(f"{name}: plumb_bob/radtan distortion has 4, 5 or 8 coefficients, got {d.size}")
    fx, fy = K[0, 0], K[1, 1]
    reach = _corner_radius_px(K, image_size) / fx  # normalised distorted radius of the farthest corner
    rho = np.linspace(0.0, 20.0, 20001)  # undistorted radius up to 87 deg
    rho_d = _pinhole_radius(d, rho)
    growing = np.diff(rho_d) > 0
    last = int(np.argmin(growing)) if not growing.all() else growing.size
    if rho_d[last] < reach:
        raise ModelError(
            f"{name}: the plumb_bob distortion folds back at {np.degrees(np.arctan(rho[last])):.0f} deg, inside "
            "the image: it cannot describe this lens there"
        )
    theta_max = float(np.arctan(np.interp(reach, rho_d[: last + 1], rho[: last + 1])))
    theta = np.linspace(0.0, theta_max, N_SAMPLES)
    target_mm = fx * _pinhole_radius(d, np.tan(theta)) / m[0]
    powers = np.stack([theta ** (2 * i + 1) for i in range(5)], axis=1)
    scale = np.max(np.abs(powers), axis=0)
    k = np.linalg.lstsq(powers / scale, target_mm, rcond=None)[0] / scale
    fit_px = float(np.max(np.abs(powers @ k - target_mm)) * m[0])
    if k[0] <= 0 or np.any(radius_derivative(k, theta) <= 0):
        raise ModelError(f"{name}: the plumb_bob distortion cannot be written as a monotonic r(theta)")
    p1, p2 = (d[2], d[3]) if d.size >= 4 else (0.0, 0.0)
    x = reach * np.cos(np.linspace(0, 2 * np.pi, 73))
    y = reach * np.sin(np.linspace(0, 2 * np.pi, 73))
    r2 = x * x + y * y
    tangential_px = float(
        np.max(np.hypot(fx * (2 * p1 * x * y + p2 * (r2 + 2 * x * x)), fy * (p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)))
    )
    error = fit_px + tangential_px
    if error > MAX_CONVERSION_ERROR_PX:
        what = "tangential terms" if tangential_px >= fit_px else "radial shape"
        raise ModelError(
            f"{name}: the plumb_bob intrinsics differ from the nearest equidistant model by {error:.2f} px in the "
            f"image ({what}; at most {MAX_CONVERSION_ERROR_PX} px): drop camera_model: equidistant to calibrate "
            "the camera in the plumb_bob model the intrinsics are given in"
        )
    model = CameraModel(k, np.array([m[0], m[0] * fy / fx]), K[:2, 2], image_size)
    return model, error


def from_equidistant(
    camera_matrix: FloatArray, distortion: FloatArray, m: FloatArray, image_size: tuple[int, int]
) -> CameraModel:
    """The exact model of OpenCV fisheye parameters; m_v follows K's fy/fx (the rig's m_u is kept)."""
    K = np.asarray(camera_matrix, dtype=np.float64)
    d = np.asarray(distortion, dtype=np.float64).ravel()
    if d.size != 4:
        raise ModelError(f"equidistant distortion has 4 coefficients (k1..k4), got {d.size}")
    return from_opencv_fisheye(K, d, np.array([m[0], m[0] * K[1, 1] / K[0, 0]]), image_size)


def from_pinhole(
    distortion_model: str,
    camera_matrix: FloatArray,
    distortion: FloatArray,
    m: FloatArray,
    image_size: tuple[int, int],
    *,
    name: str = "camera",
) -> CameraModel:
    """The exact pinhole model of OpenCV parameters (plumb_bob: 4 or 5 coefficients; rational_polynomial:
    8, or 5 with k4..k6 = 0); m_v follows K's fy/fx (the rig's m_u is kept).

    Raises:
        ModelError: a coefficient count the model does not have.
    """
    K = np.asarray(camera_matrix, dtype=np.float64)
    d = np.asarray(distortion, dtype=np.float64).ravel()
    rational = distortion_model == RATIONAL_POLYNOMIAL
    if d.size not in ((5, 8) if rational else (4, 5)):
        counts = "8 coefficients (k1, k2, p1, p2, k3, k4, k5, k6)" if rational else "4 or 5 (k1, k2, p1, p2[, k3])"
        raise ModelError(f"{name}: {distortion_model} distortion has {counts}, got {d.size}")
    m_camera = np.array([m[0], m[0] * K[1, 1] / K[0, 0]])
    return from_opencv_pinhole(K, d, m_camera, image_size, RATIONAL_POLYNOMIAL if rational else PLUMB_BOB)


def _other_model(name: str, given: str, asked: str) -> ModelError:
    """The error of intrinsics given in one model for a camera the rig asks to calibrate in another."""
    return ModelError(
        f"{name}: its intrinsics are given in the {given} model but camera_model is {asked}: give them in that "
        "model, or drop camera_model"
    )


def known_model(
    distortion_model: str,
    camera_matrix: FloatArray,
    distortion: FloatArray,
    m: FloatArray,
    image_size: tuple[int, int],
    *,
    name: str = "camera",
    camera_model: str | None = None,
) -> CameraModel:
    """The camera model of given intrinsics in any accepted distortion model (see module docstring).

    Args:
        distortion_model: the intrinsics' ROS (or Kalibr) distortion model name.
        camera_matrix, distortion: OpenCV's K and D.
        m: (2,) the rig's pixel densities, px/mm.
        image_size: (width, height) px.
        name: the camera, for messages.
        camera_model: the model the rig description asks the camera to be calibrated in (None: the
            intrinsics' own); ``equidistant`` for pinhole intrinsics converts them (within
            :data:`MAX_CONVERSION_ERROR_PX`).

    Raises:
        ModelError: an unknown distortion model, or one that does not convert (the message says why).
    """
    K = np.asarray(camera_matrix, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0 or K[0, 1] != 0:
        raise ModelError(f"{name}: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0 (no skew)")
    if not np.all(np.isfinite(np.asarray(distortion, dtype=np.float64))):
        raise ModelError(f"{name}: distortion coefficients must be finite numbers")
    if distortion_model in EQUIDISTANT_NAMES:
        if camera_model not in (None, EQUIDISTANT):
            raise _other_model(name, EQUIDISTANT, camera_model)
        return from_equidistant(K, distortion, m, image_size)
    if distortion_model in PINHOLE_RADTAN:
        if camera_model == EQUIDISTANT:
            return from_pinhole_radtan(K, distortion, m, image_size, name=name)[0]
        own = RATIONAL_POLYNOMIAL if distortion_model == RATIONAL_POLYNOMIAL else PLUMB_BOB
        if camera_model == PLUMB_BOB and own == RATIONAL_POLYNOMIAL:
            raise _other_model(name, own, camera_model)
        return from_pinhole(own if camera_model is None else camera_model, K, distortion, m, image_size, name=name)
    raise ModelError(
        f"{name}: distortion model {distortion_model!r} is not supported; give {EQUIDISTANT} (OpenCV fisheye), "
        f"{PLUMB_BOB} (radtan) or {RATIONAL_POLYNOMIAL}"
    )
