"""The generic radially symmetric camera model of the paper (Section II-A).

A point ``X = (x, y, z)`` in the camera frame (mm; z along the optical axis,
x right, y down) makes the angle ``theta = atan2(hypot(x, y), z)`` with the
optical axis and has the azimuth ``phi = atan2(y, x)``. It is imaged at

    r(theta) = k1*theta + k2*theta^3 + k3*theta^5 + k4*theta^7 + k5*theta^9   (mm)
    u = m_u * r * cos(phi) + u0,   v = m_v * r * sin(phi) + v0               (px)

with pixel densities ``m_u, m_v`` (px/mm) and principal point ``(u0, v0)`` in
the OpenCV pixel convention ((0, 0) is the centre of the top-left pixel).
Angles beyond 90 degrees (z < 0) are valid, so 185-degree lenses work.

Only ``k1*m_u``, ``k1*m_v`` and ``k_i/k1`` are identifiable from images, so
``m`` stays fixed at the value of the pixel size. The model is exactly
OpenCV's / ROS's ``equidistant`` (fisheye) model with ``fx = k1*m_u``,
``fy = k1*m_v``, ``cx = u0``, ``cy = v0`` and ``D = [k2, k3, k4, k5] / k1``
(see :func:`to_opencv_fisheye`).

Conventional lenses may instead be described by OpenCV's pinhole model with radial-tangential
distortion (ROS ``plumb_bob``, ``rational_polynomial``; :mod:`wand_calib_ros.core.model.pinhole`), a camera
model of its own (``CameraModel.distortion_model``): the same k1..k5 slots hold the radial polynomial
in tan(theta) instead of theta (k5 unused), and five more parameters (``extra``) the tangential terms
and the rational denominator. The functions here take either.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.model import pinhole

FloatArray = NDArray[np.float64]

#: Number of radial coefficients k1..k5.
N_RADIAL = 5
#: Free intrinsic parameters in the optimisers: k1..k5, u0, v0 (m stays fixed).
N_INTRINSIC = 7
#: Parameters of the pinhole models beyond those: t1, t2 (tangential), d1, d2, d3 (rational denominator).
N_EXTRA = pinhole.N_EXTRA

#: The camera models by their ROS ``distortion_model`` names: Kannala-Brandt (OpenCV fisheye), OpenCV's
#: pinhole with radial-tangential distortion, and the same with the rational radial term.
EQUIDISTANT = "equidistant"
PLUMB_BOB = "plumb_bob"
RATIONAL_POLYNOMIAL = "rational_polynomial"
CAMERA_MODELS = (EQUIDISTANT, PLUMB_BOB, RATIONAL_POLYNOMIAL)
PINHOLE_MODELS = (PLUMB_BOB, RATIONAL_POLYNOMIAL)


def _frozen_array(values: object, shape: tuple[int, ...], name: str) -> FloatArray:
    array = np.array(values, dtype=np.float64)
    if array.shape != shape:
        raise ModelError(f"{name} must have shape {shape}, got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ModelError(f"{name} must be finite, got {array.tolist()}")
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class CameraModel:
    """Intrinsics of one camera.

    Attributes:
        k: (5,) radial coefficients k1..k5 of r(theta), mm (theta in rad); for the pinhole models the
            coefficients of r(s) = k1 s + k2 s^3 + k3 s^5 + k4 s^7 in s = tan(theta) (k5 = 0).
        m: (2,) pixel densities m_u, m_v, px/mm.
        principal_point: (2,) u0, v0, px (OpenCV pixel origin).
        image_size: (width, height), px.
        distortion_model: one of :data:`CAMERA_MODELS`.
        extra: (5,) the pinhole models' tangential terms t1, t2 (mm) and rational denominator d1, d2,
            d3 (zero for ``equidistant``; d zero for ``plumb_bob``).
    """

    k: FloatArray
    m: FloatArray
    principal_point: FloatArray
    image_size: tuple[int, int]
    distortion_model: str = EQUIDISTANT
    extra: FloatArray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "k", _frozen_array(self.k, (N_RADIAL,), "k"))
        object.__setattr__(self, "m", _frozen_array(self.m, (2,), "m"))
        object.__setattr__(self, "principal_point", _frozen_array(self.principal_point, (2,), "principal_point"))
        extra = np.zeros(N_EXTRA) if self.extra is None else self.extra
        object.__setattr__(self, "extra", _frozen_array(extra, (N_EXTRA,), "extra"))
        width, height = (int(s) for s in self.image_size)
        object.__setattr__(self, "image_size", (width, height))
        if self.k[0] <= 0 or np.any(self.m <= 0):
            raise ModelError(f"k1 and m must be positive, got k1={self.k[0]}, m={self.m.tolist()}")
        if self.distortion_model not in CAMERA_MODELS:
            raise ModelError(f"unknown camera model {self.distortion_model!r}, expected one of {list(CAMERA_MODELS)}")
        unused = {EQUIDISTANT: slice(0, N_EXTRA), PLUMB_BOB: pinhole.DENOMINATOR}.get(self.distortion_model)
        if (unused is not None and np.any(self.lens_vector()[unused] != 0)) or (self.is_pinhole and self.k[4] != 0):
            raise ModelError(f"the {self.distortion_model} model has no such terms: k5 or extra {self.lens_vector()}")

    @property
    def is_pinhole(self) -> bool:
        """Whether the model is one of OpenCV's pinhole models (:data:`PINHOLE_MODELS`)."""
        return self.distortion_model in PINHOLE_MODELS

    @property
    def focal_px(self) -> FloatArray:
        """(2,) identifiable focal lengths fx = k1*m_u, fy = k1*m_v in px."""
        return self.k[0] * self.m

    def intrinsic_vector(self) -> FloatArray:
        """(7,) free intrinsics [k1..k5, u0, v0] in the optimisers' order."""
        return np.concatenate([self.k, self.principal_point])

    def lens_vector(self) -> FloatArray:
        """(5,) the pinhole models' further parameters [t1, t2, d1, d2, d3] (zeros for ``equidistant``)."""
        assert self.extra is not None  # set in __post_init__
        return self.extra

    def with_intrinsic_vector(self, vector: FloatArray, extra: FloatArray | None = None) -> CameraModel:
        """A copy with k and principal point taken from a (7,) vector (and the (5,) ``extra`` if given)."""
        return CameraModel(
            vector[:N_RADIAL],
            self.m,
            vector[N_RADIAL:N_INTRINSIC],
            self.image_size,
            self.distortion_model,
            self.lens_vector() if extra is None else extra,
        )


def _odd_powers(theta: FloatArray) -> FloatArray:
    """(N, 5) theta, theta^3, ..., theta^9 by repeated multiplication."""
    out = np.empty((theta.shape[0], N_RADIAL))
    out[:, 0] = theta
    t2 = theta * theta
    for i in range(1, N_RADIAL):
        out[:, i] = out[:, i - 1] * t2
    return out


def radius(k: FloatArray, theta: FloatArray) -> FloatArray:
    """r(theta) in mm for (5,) coefficients and any-shaped angles in rad."""
    t2 = theta * theta
    return theta * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * (k[3] + t2 * k[4]))))


def radius_over_theta(k: FloatArray, theta: FloatArray) -> FloatArray:
    """r(theta)/theta, finite at theta = 0 (equals k1 there)."""
    t2 = theta * theta
    return k[0] + t2 * (k[1] + t2 * (k[2] + t2 * (k[3] + t2 * k[4])))


def radius_derivative(k: FloatArray, theta: FloatArray) -> FloatArray:
    """dr/dtheta in mm/rad."""
    t2 = theta * theta
    return k[0] + t2 * (3 * k[1] + t2 * (5 * k[2] + t2 * (7 * k[3] + t2 * 9 * k[4])))


_LIMIT_GRID = np.linspace(0.0, np.pi, 1025)


def monotonic_limit(k: FloatArray) -> float:
    """First angle in (0, pi] where dr/dtheta reaches zero, or pi if it never does.

    r(theta) is invertible on [0, monotonic_limit(k)]. A fine grid brackets the
    first sign change of dr/dtheta; a safeguarded Newton iteration pins it down.
    """
    slope = radius_derivative(k, _LIMIT_GRID)
    nonpositive = np.flatnonzero(slope <= 0)
    if nonpositive.size == 0:
        return float(np.pi)
    first = int(nonpositive[0])
    if first == 0:
        return 0.0
    lo, hi = float(_LIMIT_GRID[first - 1]), float(_LIMIT_GRID[first])
    k1, k2, k3, k4, k5 = (float(c) for c in k)
    theta = 0.5 * (lo + hi)
    for _ in range(60):  # safeguarded Newton on dr/dtheta, scalar floats
        t2 = theta * theta
        f = k1 + t2 * (3 * k2 + t2 * (5 * k3 + t2 * (7 * k4 + t2 * 9 * k5)))
        if abs(f) <= 1e-14 * abs(k1) or hi - lo < 1e-15:
            break
        if f > 0:
            lo = theta
        else:
            hi = theta
        df = theta * (6 * k2 + t2 * (20 * k3 + t2 * (42 * k4 + t2 * 72 * k5)))
        step = theta - f / df if df != 0 else lo - 1.0
        theta = step if lo < step < hi else 0.5 * (lo + hi)
    return theta


def max_image_radius_mm(model: CameraModel) -> float:
    """Largest distance (mm) from the principal point to an image corner."""
    width, height = model.image_size
    corners = np.array([[-0.5, -0.5], [width - 0.5, -0.5], [-0.5, height - 0.5], [width - 0.5, height - 0.5]])
    return float(np.max(np.hypot(*((corners - model.principal_point) / model.m).T)))


def radius_mm(model: CameraModel, theta: FloatArray) -> FloatArray:
    """The model's radial curve r(theta) in mm at any-shaped angles (rad): the image radius of a ray without
    the pinhole models' tangential terms (NaN from 90 degrees on for those)."""
    if model.is_pinhole:
        return pinhole.radius(model.k, model.lens_vector(), theta)
    return radius(model.k, np.asarray(theta, dtype=np.float64))


def radial_basis(model: CameraModel, theta: float) -> FloatArray:
    """(5,) d r(theta) / d k1..k5 (mm per mm) of the model's curve at one angle: theta^(2i+1) for the fisheye
    model, tan(theta)^(2i+1) over the rational denominator for the pinhole ones (0 for their k5)."""
    if not model.is_pinhole:
        return np.asarray(theta ** (2 * np.arange(N_RADIAL) + 1), dtype=np.float64)
    s = float(np.tan(theta))
    _, _, denominator = pinhole.radial_terms(model.k, model.lens_vector(), np.array(s * s))
    return np.r_[s ** (2 * np.arange(N_RADIAL - 1) + 1) / float(denominator), 0.0]


def radius_limit(model: CameraModel) -> float:
    """First angle (rad) where the model's r(theta) stops increasing (pi if it never does; at most 90
    degrees for the pinhole models): the curve is invertible up to it."""
    if model.is_pinhole:
        return pinhole.radial_limit(model.k, model.lens_vector())
    return monotonic_limit(model.k)


def angle_of_radius(model: CameraModel, r: FloatArray) -> FloatArray:
    """theta with r(theta) = r (mm) on the increasing branch of the model's curve; NaN beyond its reach."""
    if model.is_pinhole:
        return pinhole.inverse_radius(model.k, model.lens_vector(), r)
    return inverse_radius(model.k, r)


def turns_over_in_image(model: CameraModel, max_view_angle: float) -> bool:
    """True when r(theta) stops increasing inside both the lens's field and the image.

    Args:
        model: the camera.
        max_view_angle: theta_max of the lens in rad (half the field of view).
    """
    limit = radius_limit(model)
    if limit >= max_view_angle or (model.is_pinhole and limit >= 0.5 * np.pi - 1e-3):
        return False
    return float(radius_mm(model, np.array(limit))) < max_image_radius_mm(model)


def inverse_radius(k: FloatArray, r: FloatArray, *, tol: float = 1e-13) -> FloatArray:
    """theta with r(theta) = r on the monotonic branch [0, monotonic_limit(k)].

    Newton's method from theta = r / k1, kept inside the branch; elements it does
    not settle in a few steps finish with a bracketed (bisection-safeguarded)
    Newton iteration. Vectorised over any shape. Radii beyond the largest one the
    model reaches give NaN: such pixels cannot be explained by the model.

    Args:
        k: (5,) radial coefficients, mm.
        r: image radii in mm, any shape, >= 0.
        tol: absolute tolerance on theta (rad).
    """
    r = np.asarray(r, dtype=np.float64)
    shape = r.shape
    r = r.reshape(-1)
    limit = monotonic_limit(k)
    r_max = float(radius(k, np.array(limit)))
    outside = ~(r <= r_max)  # also catches NaN
    target = np.where(outside, 0.0, r)
    theta = np.clip(target / k[0], 0.0, limit)
    for _ in range(8):
        step = (radius(k, theta) - target) / np.maximum(radius_derivative(k, theta), 1e-300)
        theta = np.clip(theta - step, 0.0, limit)
        if np.max(np.abs(step), initial=0.0) <= tol:
            break
    else:
        slow = np.abs(radius(k, theta) - target) > tol * np.maximum(radius_derivative(k, theta), 1e-3)
        if np.any(slow):
            theta[slow] = _bracketed_inverse(k, target[slow], limit, tol)
    return np.where(outside, np.nan, theta).reshape(shape)


def _bracketed_inverse(k: FloatArray, target: FloatArray, limit: float, tol: float) -> FloatArray:
    """Safeguarded Newton iteration on [0, limit] (bisection whenever a step leaves the bracket)."""
    lo = np.zeros_like(target)
    hi = np.full_like(target, limit)
    theta = 0.5 * (lo + hi)
    for _ in range(200):
        f = radius(k, theta) - target
        lo = np.where(f <= 0, theta, lo)
        hi = np.where(f > 0, theta, hi)
        slope = radius_derivative(k, theta)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = theta - f / slope
        bad = ~((step >= lo) & (step <= hi)) | (slope <= 0)
        new = np.where(bad, 0.5 * (lo + hi), step)
        done = np.max(np.abs(new - theta), initial=0.0) <= tol
        theta = new
        if done:
            break
    return theta


def _split_points(points: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim < 1 or points.shape[-1] != 3:
        raise ValueError(f"points must have shape (..., 3), got {points.shape}")
    return points[..., 0], points[..., 1], points[..., 2]


def _angles(points: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """theta, rho, unit (cos phi, sin phi) and r/rho-ready ratio theta/rho."""
    x, y, z = _split_points(points)
    rho = np.hypot(x, y)
    theta = np.arctan2(rho, z)
    tiny = rho <= 1e-12 * np.maximum(np.abs(z), 1e-300)
    if not tiny.any():  # the common case, in the bundle adjustment's inner loop: no axis points
        return theta, rho, x / rho, y / rho, theta / rho
    safe_rho = np.where(tiny, 1.0, rho)
    cos_phi = np.where(tiny, 1.0, x / safe_rho)
    sin_phi = np.where(tiny, 0.0, y / safe_rho)
    # theta/rho -> 1/z on the axis (z > 0).
    theta_over_rho = np.where(tiny, 1.0 / np.where(z == 0, 1.0, z), theta / safe_rho)
    return theta, rho, cos_phi, sin_phi, theta_over_rho


def project(model: CameraModel, points: FloatArray) -> FloatArray:
    """Pixels of points (or bearing vectors) in the camera frame.

    Args:
        model: the camera.
        points: (..., 3) points in the camera frame (any positive scale).

    Returns:
        (..., 2) pixel coordinates u, v (NaN where a pinhole model has no image: z <= 0).
    """
    points = np.asarray(points, dtype=np.float64)
    _split_points(points)  # the shape checked
    one = model.k[None, :], model.m[None, :], model.principal_point[None, :]
    flat = points.reshape(-1, 3)
    if model.is_pinhole:
        uv = pinhole.project_arrays(one[0], model.lens_vector()[None, :], one[1], one[2], flat)
    else:
        uv = project_arrays(*one, flat)
    return uv.reshape(*points.shape[:-1], 2)


def project_arrays(k: FloatArray, m: FloatArray, principal_point: FloatArray, points: FloatArray) -> FloatArray:
    """(N, 2) pixels of (N, 3) camera-frame points, one set of intrinsics per point ((N, 5), (N, 2), (N, 2);
    or (1, .) for one camera)."""
    theta, _, cos_phi, sin_phi, _ = _angles(points)
    r = radius(k.T, theta)
    uv = np.empty((theta.shape[0], 2))
    uv[:, 0] = m[:, 0] * r * cos_phi + principal_point[:, 0]
    uv[:, 1] = m[:, 1] * r * sin_phi + principal_point[:, 1]
    return uv


class ProjectionJacobian(NamedTuple):
    """Projection with its exact derivatives.

    Attributes:
        uv: (N, 2) pixels.
        d_point: (N, 2, 3) d(u, v)/d(x, y, z) in the camera frame.
        d_intrinsics: (N, 2, 7) d(u, v)/d(k1..k5, u0, v0).
    """

    uv: FloatArray
    d_point: FloatArray
    d_intrinsics: FloatArray


def project_with_jacobian(model: CameraModel, points: FloatArray) -> ProjectionJacobian:
    """Project (N, 3) camera-frame points and return exact Jacobians (see ProjectionJacobian; a pinhole
    model's derivatives with respect to its lens terms come from
    :func:`wand_calib_ros.core.model.pinhole.project_with_jacobian_arrays`)."""
    one = model.k[None, :], model.m[None, :], model.principal_point[None, :]
    if model.is_pinhole:
        jacobian = pinhole.project_with_jacobian_arrays(one[0], model.lens_vector()[None, :], one[1], one[2], points)
        return ProjectionJacobian(jacobian.uv, jacobian.d_point, jacobian.d_intrinsics)
    return project_with_jacobian_arrays(*one, points)


def project_with_jacobian_arrays(
    k: FloatArray, m: FloatArray, principal_point: FloatArray, points: FloatArray, *, intrinsics: bool = True
) -> ProjectionJacobian:
    """Vectorised projection with Jacobians, one set of intrinsics per point.

    Written on component arrays (N,): it is the inner loop of the bundle adjustment, called on
    chunks of a few thousand points.

    Args:
        k: (N, 5) or (1, 5) radial coefficients.
        m: (N, 2) or (1, 2) pixel densities.
        principal_point: (N, 2) or (1, 2).
        points: (N, 3) camera-frame points.
        intrinsics: also the derivatives with respect to the intrinsics (else ``d_intrinsics`` is
            (N, 2, 0): the placements alone are adjusted).
    """
    x, y, z = _split_points(points)
    n = x.shape[0]
    theta, rho, cos_phi, sin_phi, theta_over_rho = _angles(points)
    r_over_theta = radius_over_theta(k.T, theta)
    r = r_over_theta * theta
    dr = radius_derivative(k.T, theta)
    t2 = theta * theta
    d2 = rho * rho + z * z
    b = r_over_theta * theta_over_rho  # r / rho
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where(d2 > 0, dr * z / d2, b)  # dr/dtheta * dtheta/drho
        dz_common = np.where(d2 > 0, -dr / d2, 0.0)
    a_minus_b = a - b
    mu, mv = m.T
    mixed = a_minus_b * cos_phi * sin_phi
    d_point = np.empty((n, 2, 3))
    d_point[:, 0, 0] = mu * (b + a_minus_b * cos_phi * cos_phi)
    d_point[:, 0, 1] = mu * mixed
    d_point[:, 0, 2] = mu * dz_common * x
    d_point[:, 1, 0] = mv * mixed
    d_point[:, 1, 1] = mv * (b + a_minus_b * sin_phi * sin_phi)
    d_point[:, 1, 2] = mv * dz_common * y
    uv = np.empty((n, 2))
    uv[:, 0] = mu * r * cos_phi + principal_point[:, 0]
    uv[:, 1] = mv * r * sin_phi + principal_point[:, 1]
    if not intrinsics:
        return ProjectionJacobian(uv, d_point, np.empty((n, 2, 0)))
    d_intrinsics = np.empty((n, 2, N_INTRINSIC))
    for row, radial in enumerate((mu * cos_phi, mv * sin_phi)):
        power = radial * theta
        for j in range(N_RADIAL):  # d / d k_j: m cos(phi) theta^(2j + 1) (sin for v)
            d_intrinsics[:, row, j] = power
            power = power * t2
    d_intrinsics[:, 0, 5:] = (1.0, 0.0)
    d_intrinsics[:, 1, 5:] = (0.0, 1.0)
    return ProjectionJacobian(uv, d_point, d_intrinsics)


def _unproject_parts(
    model: CameraModel, uv: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """theta, rho, cos(phi), sin(phi), sin(theta), cos(theta) of pixels (shared by the unprojections)."""
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim < 1 or uv.shape[-1] != 2:
        raise ValueError(f"uv must have shape (..., 2), got {uv.shape}")
    x = (uv[..., 0] - model.principal_point[0]) / model.m[0]
    y = (uv[..., 1] - model.principal_point[1]) / model.m[1]
    rho = np.hypot(x, y)
    theta = inverse_radius(model.k, rho)
    positive = rho > 0
    safe = np.where(positive, rho, 1.0)
    cos_phi = np.where(positive, x / safe, 1.0)
    sin_phi = np.where(positive, y / safe, 0.0)
    return theta, rho, cos_phi, sin_phi, np.sin(theta), np.cos(theta)


def unproject(model: CameraModel, uv: FloatArray) -> FloatArray:
    """Unit bearing vectors of pixels (the inverse of :func:`project`).

    Args:
        model: the camera.
        uv: (..., 2) pixel coordinates.

    Returns:
        (..., 3) unit vectors in the camera frame; NaN for pixels the model
        cannot reach (beyond the radius where r(theta) stops increasing).
    """
    if model.is_pinhole:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.ndim < 1 or uv.shape[-1] != 2:
            raise ValueError(f"uv must have shape (..., 2), got {uv.shape}")
        flat = uv.reshape(-1, 2)
        bearings = pinhole.unproject(model.k, model.lens_vector(), model.m, model.principal_point, flat)
        return bearings.reshape(*uv.shape[:-1], 3)
    _, _, cos_phi, sin_phi, sin_theta, cos_theta = _unproject_parts(model, uv)
    return np.stack([sin_theta * cos_phi, sin_theta * sin_phi, cos_theta], axis=-1)


def unproject_with_jacobian(model: CameraModel, uv: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Bearings of (N, 2) pixels and their derivatives with respect to the intrinsics.

    Returns:
        (N, 3) unit bearings (NaN where unreachable) and (N, 3, 7) their
        derivatives with respect to k1..k5, u0, v0 (implicit differentiation of
        r(theta) = rho).

    Raises:
        ModelError: for the pinhole models (Step 3 starts from the fisheye model's curves).
    """
    if model.is_pinhole:
        raise ModelError(f"bearing derivatives are computed for the {EQUIDISTANT} model only")
    theta, rho, cos_phi, sin_phi, sin_theta, cos_theta = _unproject_parts(model, uv)
    bearings = np.stack([sin_theta * cos_phi, sin_theta * sin_phi, cos_theta], axis=-1)
    # sin(theta)/rho -> 1/k1 at the centre.
    sin_over_rho = np.where(rho > 0, sin_theta / np.where(rho > 0, rho, 1.0), 1.0 / model.k[0])
    d_theta_d_rho = 1.0 / radius_derivative(model.k, theta)
    dm_dtheta = np.stack([cos_theta * cos_phi, cos_theta * sin_phi, -sin_theta], axis=-1)
    dm_dphi_over_sin = np.stack([-sin_phi, cos_phi, np.zeros_like(rho)], axis=-1)  # dm/dphi / sin(theta)
    jac = np.empty((bearings.shape[0], 3, N_INTRINSIC))
    powers = _odd_powers(theta)
    jac[:, :, :N_RADIAL] = dm_dtheta[:, :, None] * (-powers * d_theta_d_rho[:, None])[:, None, :]
    mu, mv = model.m
    # u0: rho changes by -cos(phi)/mu, phi by sin(phi)/(rho mu); v0 likewise.
    jac[:, :, 5] = (
        dm_dtheta * (-cos_phi * d_theta_d_rho / mu)[:, None] + dm_dphi_over_sin * (sin_over_rho * sin_phi / mu)[:, None]
    )
    jac[:, :, 6] = (
        dm_dtheta * (-sin_phi * d_theta_d_rho / mv)[:, None] - dm_dphi_over_sin * (sin_over_rho * cos_phi / mv)[:, None]
    )
    return bearings, jac


class OpenCVFisheye(NamedTuple):
    """OpenCV / ROS ``equidistant`` parameters equivalent to a CameraModel.

    Attributes:
        camera_matrix: (3, 3) K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]].
        distortion: (4,) D = [k2, k3, k4, k5] / k1.
    """

    camera_matrix: FloatArray
    distortion: FloatArray


def to_opencv_fisheye(model: CameraModel) -> OpenCVFisheye:
    """Exact conversion to OpenCV's fisheye (ROS ``equidistant``) parameters.

    OpenCV maps theta to theta_d = theta (1 + D1 theta^2 + D2 theta^4 + D3 theta^6 + D4 theta^8)
    and u = fx * theta_d * cos(phi) + cx, which equals this model's
    m_u * r(theta) * cos(phi) + u0 with fx = k1 m_u and D = k[1:] / k1.

    Raises:
        ModelError: the model is a pinhole one (see :func:`to_opencv`).
    """
    if model.is_pinhole:
        raise ModelError(f"a {model.distortion_model} camera has no OpenCV fisheye parameters")
    return OpenCVFisheye(opencv_camera_matrix(model), model.k[1:] / model.k[0])


def opencv_camera_matrix(model: CameraModel) -> FloatArray:
    """(3, 3) OpenCV's K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] of any model."""
    fx, fy = model.focal_px
    return np.array([[fx, 0.0, model.principal_point[0]], [0.0, fy, model.principal_point[1]], [0.0, 0.0, 1.0]])


class OpenCVCamera(NamedTuple):
    """A camera in OpenCV's (and ROS camera_info's) terms.

    Attributes:
        distortion_model: the ROS name: ``equidistant`` (``cv2.fisheye``), ``plumb_bob`` or
            ``rational_polynomial`` (``cv2.projectPoints``).
        camera_matrix: (3, 3) K.
        distortion: D: 4 (equidistant), 5 (plumb_bob: k1, k2, p1, p2, k3) or 8 (rational_polynomial).
    """

    distortion_model: str
    camera_matrix: FloatArray
    distortion: FloatArray


def to_opencv(model: CameraModel) -> OpenCVCamera:
    """Exact OpenCV parameters of any model, in its own distortion model."""
    if model.is_pinhole:
        rational = model.distortion_model == RATIONAL_POLYNOMIAL
        distortion = pinhole.opencv_distortion(model.k, model.lens_vector(), rational)
        return OpenCVCamera(model.distortion_model, opencv_camera_matrix(model), distortion)
    fisheye = to_opencv_fisheye(model)
    return OpenCVCamera(EQUIDISTANT, fisheye.camera_matrix, fisheye.distortion)


def from_opencv_fisheye(
    camera_matrix: FloatArray, distortion: FloatArray, m: FloatArray, image_size: tuple[int, int]
) -> CameraModel:
    """Inverse of :func:`to_opencv_fisheye` for a given pixel density m (px/mm)."""
    camera_matrix = np.asarray(camera_matrix, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)
    k1 = camera_matrix[0, 0] / m[0]
    k = np.concatenate([[k1], k1 * np.asarray(distortion, dtype=np.float64).ravel()[:4]])
    return CameraModel(k, m, camera_matrix[:2, 2], image_size)


def from_opencv_pinhole(
    camera_matrix: FloatArray,
    distortion: FloatArray,
    m: FloatArray,
    image_size: tuple[int, int],
    distortion_model: str = PLUMB_BOB,
) -> CameraModel:
    """The exact model of OpenCV pinhole parameters (D = k1, k2, p1, p2[, k3[, k4, k5, k6]]) for a pixel
    density m (px/mm; fx = k1 m_u)."""
    camera_matrix = np.asarray(camera_matrix, dtype=np.float64)
    m = np.asarray(m, dtype=np.float64)
    k, extra = pinhole.from_opencv_distortion(float(camera_matrix[0, 0] / m[0]), distortion)
    return CameraModel(k, m, camera_matrix[:2, 2], image_size, distortion_model, extra)
