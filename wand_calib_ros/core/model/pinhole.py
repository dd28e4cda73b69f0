"""OpenCV's pinhole camera with radial-tangential distortion (ROS ``plumb_bob`` and ``rational_polynomial``).

A point ``X = (x, y, z)`` in the camera frame (mm, z > 0) has normalised coordinates ``a = x / z``,
``b = y / z`` and ``s^2 = a^2 + b^2`` (``s = tan(theta)``). In this package's terms (lengths in mm on the
sensor, as the Kannala-Brandt model of :mod:`wand_calib_ros.core.model.camera_model` has them)::

    g(s^2) = (k1 + k2 s^2 + k3 s^4 + k4 s^6) / (1 + d1 s^2 + d2 s^4 + d3 s^6)      (mm)
    X = a g + 2 t1 a b + t2 (s^2 + 2 a^2),   Y = b g + t1 (s^2 + 2 b^2) + 2 t2 a b  (mm)
    u = m_u X + u0,   v = m_v Y + v0                                                  (px)

so that the radial part alone is ``r = k1 s + k2 s^3 + k3 s^5 + k4 s^7`` (over the denominator), the
same polynomial as the fisheye model's with ``tan(theta)`` for ``theta``. It is exactly OpenCV's
``projectPoints``: ``fx = k1 m_u``, ``fy = k1 m_v``, OpenCV's ``(k1, k2, k3) = (k2, k3, k4) / k1``,
``(p1, p2) = (t1, t2) / k1`` and the rational denominator's ``(k4, k5, k6) = (d1, d2, d3)``
(:func:`opencv_distortion`). ``k5`` has no place in this model and stays 0.

Arrays of intrinsics come one row per point, as the bundle adjustment gathers them: ``k`` (N, 5),
``extra`` (N, 5) = ``t1, t2, d1, d2, d3``, ``m`` and ``principal_point`` (N, 2) (or (1, .) rows for one
camera). Points on or behind the camera's plane (z <= 0) have no image: NaN.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Parameters of the model beyond k and the principal point: t1, t2 (tangential, mm), d1, d2, d3 (the
#: rational denominator's, dimensionless).
N_EXTRA = 5
#: Tangential terms (indices into ``extra``).
TANGENTIAL = slice(0, 2)
#: The rational denominator's terms (indices into ``extra``).
DENOMINATOR = slice(2, 5)


class PinholeJacobian(NamedTuple):
    """Projection with its exact derivatives.

    Attributes:
        uv: (N, 2) pixels (NaN behind the camera).
        d_point: (N, 2, 3) d(u, v)/d(x, y, z) in the camera frame.
        d_intrinsics: (N, 2, 7) d(u, v)/d(k1..k5, u0, v0) (the k5 column is zero).
        d_extra: (N, 2, 5) d(u, v)/d(t1, t2, d1, d2, d3).
    """

    uv: FloatArray
    d_point: FloatArray
    d_intrinsics: FloatArray
    d_extra: FloatArray


def radial_terms(k: FloatArray, extra: FloatArray, s2: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """g(s^2) (mm), its derivative dg/d(s^2) and the denominator, for (N, 5) rows (or (5,) and any shape)."""
    k = k.T if k.ndim == 2 else k
    extra = extra.T if extra.ndim == 2 else extra
    numerator = k[0] + s2 * (k[1] + s2 * (k[2] + s2 * k[3]))
    d_numerator = k[1] + s2 * (2.0 * k[2] + 3.0 * s2 * k[3])
    denominator = 1.0 + s2 * (extra[2] + s2 * (extra[3] + s2 * extra[4]))
    d_denominator = extra[2] + s2 * (2.0 * extra[3] + 3.0 * s2 * extra[4])
    g = numerator / denominator
    return g, (d_numerator - g * d_denominator) / denominator, denominator


def _distorted(
    k: FloatArray, extra: FloatArray, a: FloatArray, b: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Sensor coordinates X, Y (mm) of normalised (a, b), with g, dg/d(s^2) and the denominator."""
    s2 = a * a + b * b
    g, dg, denominator = radial_terms(k, extra, s2)
    e = extra.T if extra.ndim == 2 else extra
    t1, t2 = e[0], e[1]
    ab = a * b
    x = a * g + 2.0 * t1 * ab + t2 * (s2 + 2.0 * a * a)
    y = b * g + t1 * (s2 + 2.0 * b * b) + 2.0 * t2 * ab
    return x, y, g, dg, denominator


def _normalised(points: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """a = x/z, b = y/z and 1/z of (N, 3) points (NaN where z <= 0)."""
    z = points[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_z = np.where(z > 0, 1.0 / z, np.nan)
    return points[:, 0] * inv_z, points[:, 1] * inv_z, inv_z


def project_arrays(
    k: FloatArray, extra: FloatArray, m: FloatArray, principal_point: FloatArray, points: FloatArray
) -> FloatArray:
    """(N, 2) pixels of (N, 3) camera-frame points (see the module docstring for the rows)."""
    a, b, _ = _normalised(points)
    x, y, *_ = _distorted(k, extra, a, b)
    uv = np.empty((points.shape[0], 2))
    uv[:, 0] = m[:, 0] * x + principal_point[:, 0]
    uv[:, 1] = m[:, 1] * y + principal_point[:, 1]
    return uv


def project_with_jacobian_arrays(
    k: FloatArray,
    extra: FloatArray,
    m: FloatArray,
    principal_point: FloatArray,
    points: FloatArray,
    *,
    intrinsics: bool = True,
) -> PinholeJacobian:
    """Projection of (N, 3) points with exact Jacobians (:class:`PinholeJacobian`); without ``intrinsics``
    the intrinsic derivatives are (N, 2, 0)."""
    n = points.shape[0]
    a, b, inv_z = _normalised(points)
    s2 = a * a + b * b
    x, y, g, dg, denominator = _distorted(k, extra, a, b)
    e = extra.T if extra.ndim == 2 else extra
    t1, t2 = e[0], e[1]
    mu, mv = m[:, 0], m[:, 1]
    # d(X, Y) / d(a, b)
    xa = g + 2.0 * a * a * dg + 2.0 * t1 * b + 6.0 * t2 * a
    cross = 2.0 * a * b * dg + 2.0 * t1 * a + 2.0 * t2 * b
    yb = g + 2.0 * b * b * dg + 6.0 * t1 * b + 2.0 * t2 * a
    d_point = np.empty((n, 2, 3))
    d_point[:, 0, 0] = mu * xa * inv_z
    d_point[:, 0, 1] = mu * cross * inv_z
    d_point[:, 0, 2] = -mu * (xa * a + cross * b) * inv_z
    d_point[:, 1, 0] = mv * cross * inv_z
    d_point[:, 1, 1] = mv * yb * inv_z
    d_point[:, 1, 2] = -mv * (cross * a + yb * b) * inv_z
    uv = np.empty((n, 2))
    uv[:, 0] = mu * x + principal_point[:, 0]
    uv[:, 1] = mv * y + principal_point[:, 1]
    if not intrinsics:
        return PinholeJacobian(uv, d_point, np.empty((n, 2, 0)), np.empty((n, 2, 0)))
    d_intrinsics = np.zeros((n, 2, 7))
    power = 1.0 / denominator
    for j in range(4):  # d / d k_j: (a, b) s^(2j) / denominator
        d_intrinsics[:, 0, j] = mu * a * power
        d_intrinsics[:, 1, j] = mv * b * power
        power = power * s2
    d_intrinsics[:, 0, 5:] = (1.0, 0.0)
    d_intrinsics[:, 1, 5:] = (0.0, 1.0)
    d_extra = np.empty((n, 2, N_EXTRA))
    ab2 = 2.0 * a * b
    d_extra[:, 0, 0] = mu * ab2
    d_extra[:, 1, 0] = mv * (s2 + 2.0 * b * b)
    d_extra[:, 0, 1] = mu * (s2 + 2.0 * a * a)
    d_extra[:, 1, 1] = mv * ab2
    power = -g * s2 / denominator  # d g / d d_j = -g s^(2j) / denominator
    for j in range(3):
        d_extra[:, 0, 2 + j] = mu * a * power
        d_extra[:, 1, 2 + j] = mv * b * power
        power = power * s2
    return PinholeJacobian(uv, d_point, d_intrinsics, d_extra)


#: Angles (rad) at which the radial curve's limit is looked for (up to just short of 90 degrees).
_LIMIT_GRID = np.linspace(0.0, np.radians(89.9), 2049)


def radius(k: FloatArray, extra: FloatArray, theta: FloatArray) -> FloatArray:
    """r(theta) = tan(theta) g(tan^2 theta) in mm for (5,) k and extra (NaN from 90 degrees on)."""
    theta = np.asarray(theta, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        s = np.where(theta < 0.5 * np.pi, np.tan(np.minimum(theta, 0.5 * np.pi)), np.nan)
    return s * radial_terms(k, extra, s * s)[0]


def _radius_slope(k: FloatArray, extra: FloatArray, s: FloatArray) -> FloatArray:
    """dr/ds of r(s) = s g(s^2), mm."""
    g, dg, _ = radial_terms(k, extra, s * s)
    return g + 2.0 * s * s * dg


def radial_limit(k: FloatArray, extra: FloatArray) -> float:
    """First angle (rad) where r(theta) stops increasing, or 90 degrees (the pinhole's own limit)."""
    s = np.tan(_LIMIT_GRID)
    slope = _radius_slope(k, extra, s)
    bad = np.flatnonzero(~(slope > 0))
    if bad.size == 0:
        return float(0.5 * np.pi)
    first = int(bad[0])
    if first == 0:
        return 0.0
    lo, hi = float(_LIMIT_GRID[first - 1]), float(_LIMIT_GRID[first])
    for _ in range(60):  # bisection on the slope's sign
        middle = 0.5 * (lo + hi)
        if _radius_slope(k, extra, np.array(np.tan(middle))) > 0:
            lo = middle
        else:
            hi = middle
    return lo


def inverse_radius(k: FloatArray, extra: FloatArray, r: FloatArray) -> FloatArray:
    """theta with r(theta) = r on the increasing branch (NaN beyond the largest radius it reaches)."""
    r = np.asarray(r, dtype=np.float64)
    shape = r.shape
    r = r.reshape(-1)
    limit = radial_limit(k, extra)
    s_limit = np.tan(min(limit, float(_LIMIT_GRID[-1])))
    r_max = float(s_limit * radial_terms(k, extra, np.array(s_limit * s_limit))[0])
    outside = ~(r <= r_max)
    target = np.where(outside, 0.0, r)
    s = _inverse_s(k, extra, target, s_limit)
    return np.where(outside, np.nan, np.arctan(s)).reshape(shape)


def _inverse_s(k: FloatArray, extra: FloatArray, target: FloatArray, s_limit: float) -> FloatArray:
    """s in [0, s_limit] with s g(s^2) = target: Newton's method, bisection wherever a step leaves the bracket."""
    lo = np.zeros_like(target)
    hi = np.full_like(target, s_limit)
    s = np.clip(target / k[0], 0.0, s_limit)
    for _ in range(100):
        f = s * radial_terms(k, extra, s * s)[0] - target
        lo = np.where(f <= 0, s, lo)
        hi = np.where(f > 0, s, hi)
        slope = _radius_slope(k, extra, s)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = s - f / slope
        bad = ~((step >= lo) & (step <= hi)) | ~(slope > 0)
        new = np.where(bad, 0.5 * (lo + hi), step)
        done = np.max(np.abs(new - s), initial=0.0) <= 1e-15 * max(s_limit, 1.0)
        s = new
        if done:
            break
    return s


def unproject(
    k: FloatArray, extra: FloatArray, m: FloatArray, principal_point: FloatArray, uv: FloatArray
) -> FloatArray:
    """(N, 3) unit bearings of (N, 2) pixels for one camera ((5,) k and extra, (2,) m and principal point).

    The radial part is inverted first, then Newton's method on (a, b) takes the tangential terms in.
    Pixels beyond where the distortion turns back, or where the iteration does not settle, give NaN.
    """
    x = (uv[:, 0] - principal_point[0]) / m[0]
    y = (uv[:, 1] - principal_point[1]) / m[1]
    rho = np.hypot(x, y)
    theta = inverse_radius(k, extra, rho)
    s = np.tan(theta)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(rho > 0, s / np.where(rho > 0, rho, 1.0), 1.0 / k[0])
    a, b = x * scale, y * scale
    if np.any(extra[TANGENTIAL] != 0):
        a, b = _newton_tangential(k, extra, a, b, x, y)
    bearings = np.stack([a, b, np.ones_like(a)], axis=1)
    return bearings / np.linalg.norm(bearings, axis=1, keepdims=True)


def _newton_tangential(
    k: FloatArray, extra: FloatArray, a: FloatArray, b: FloatArray, x: FloatArray, y: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(a, b) with distorted(a, b) = (x, y), by Newton's method from the radial solution (NaN: unsettled)."""
    t1, t2 = float(extra[0]), float(extra[1])
    for _ in range(20):
        fx, fy, g, dg, _ = _distorted(k, extra, a, b)
        rx, ry = fx - x, fy - y
        xa = g + 2.0 * a * a * dg + 2.0 * t1 * b + 6.0 * t2 * a
        cross = 2.0 * a * b * dg + 2.0 * t1 * a + 2.0 * t2 * b
        yb = g + 2.0 * b * b * dg + 6.0 * t1 * b + 2.0 * t2 * a
        det = xa * yb - cross * cross
        with np.errstate(divide="ignore", invalid="ignore"):
            da = (yb * rx - cross * ry) / det
            db = (xa * ry - cross * rx) / det
        a, b = a - da, b - db
        if np.nanmax(np.abs(np.concatenate([da, db])), initial=0.0) <= 1e-15 * float(k[0]) + 1e-15:
            break
    fx, fy, *_ = _distorted(k, extra, a, b)
    unsettled = ~(np.hypot(fx - x, fy - y) <= 1e-9 * max(float(k[0]), 1.0))
    return np.where(unsettled, np.nan, a), np.where(unsettled, np.nan, b)


def opencv_distortion(k: FloatArray, extra: FloatArray, rational: bool) -> FloatArray:
    """OpenCV's D of the model: (k1, k2, p1, p2, k3), or with ``rational`` (k1, k2, p1, p2, k3, k4, k5, k6)."""
    f = float(k[0])
    plumb_bob = [k[1] / f, k[2] / f, extra[0] / f, extra[1] / f, k[3] / f]
    return np.array(plumb_bob + ([float(v) for v in extra[DENOMINATOR]] if rational else []), dtype=np.float64)


def from_opencv_distortion(focal_mm: float, distortion: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(k (5,), extra (5,)) of OpenCV's (k1, k2, p1, p2[, k3[, k4, k5, k6]]) for a focal length in mm."""
    d = np.zeros(8)
    values = np.asarray(distortion, dtype=np.float64).ravel()
    d[: values.size] = values
    k = np.array([1.0, d[0], d[1], d[4], 0.0]) * focal_mm
    extra = np.array([d[2] * focal_mm, d[3] * focal_mm, d[5], d[6], d[7]])
    return k, extra
