"""Rigid-body and ray geometry shared by every calibration step.

Frames: a camera pose (R, T) maps reference-frame points to the camera frame,
``X_cam = R @ X_ref + T`` (mm). Bearing vectors are unit vectors in a camera
frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class Pose:
    """A rigid transform X_cam = rotation @ X_ref + translation.

    Attributes:
        rotation: (3, 3) rotation matrix.
        translation: (3,) translation, mm.
    """

    rotation: FloatArray
    translation: FloatArray

    def __post_init__(self) -> None:
        rotation = np.array(self.rotation, dtype=np.float64).reshape(3, 3)
        translation = np.array(self.translation, dtype=np.float64).reshape(3)
        rotation.setflags(write=False)
        translation.setflags(write=False)
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation", translation)

    @staticmethod
    def identity() -> Pose:
        """The reference camera's pose."""
        return Pose(np.eye(3), np.zeros(3))

    @staticmethod
    def from_rotvec(rotvec: FloatArray, translation: FloatArray) -> Pose:
        """Pose from a Rodrigues vector (rad) and a translation (mm)."""
        return Pose(rotation_from_rotvec(rotvec), translation)

    @property
    def rotvec(self) -> FloatArray:
        """(3,) Rodrigues vector of the rotation, rad."""
        return rotvec_from_rotation(self.rotation)

    @property
    def center(self) -> FloatArray:
        """(3,) camera centre in the reference frame, mm."""
        return -self.rotation.T @ self.translation

    def apply(self, points: FloatArray) -> FloatArray:
        """Map (..., 3) reference-frame points into this frame (as one (N, 3) product: a stack of (3, 3) ones costs
        twice as much)."""
        points = np.asarray(points)
        return np.asarray(points.reshape(-1, 3) @ self.rotation.T + self.translation).reshape(points.shape)

    def compose(self, first: Pose) -> Pose:
        """The transform ``self after first`` (paper eq. 'transfer': R_ik = R_jk R_ij, T_ik = R_jk T_ij + T_jk)."""
        return Pose(self.rotation @ first.rotation, self.rotation @ first.translation + self.translation)

    def inverse(self) -> Pose:
        """The transform back: X_ref = R^T X - R^T T."""
        return Pose(self.rotation.T, -self.rotation.T @ self.translation)


def rotation_from_rotvec(rotvec: FloatArray) -> FloatArray:
    """(..., 3, 3) rotation matrices of (..., 3) Rodrigues vectors (rad), R = exp([r]x) (Rodrigues' formula)."""
    r = np.asarray(rotvec, dtype=np.float64)
    if r.shape == (3,):  # one vector (the common case, in inner loops): scalars
        x, y, z = float(r[0]), float(r[1]), float(r[2])
        t2 = x * x + y * y + z * z
        if t2 < 1e-12:
            a1, b1 = 1.0 - t2 / 6.0, 0.5 - t2 / 24.0
        else:
            t = math.sqrt(t2)
            a1, b1 = math.sin(t) / t, (1.0 - math.cos(t)) / t2
        return np.array(
            [
                [1.0 - b1 * (y * y + z * z), b1 * x * y - a1 * z, b1 * x * z + a1 * y],
                [b1 * x * y + a1 * z, 1.0 - b1 * (x * x + z * z), b1 * y * z - a1 * x],
                [b1 * x * z - a1 * y, b1 * y * z + a1 * x, 1.0 - b1 * (x * x + y * y)],
            ]
        )
    angle2 = np.sum(r * r, axis=-1)[..., None, None]
    small = angle2 < 1e-12  # there the Taylor series of sin(t)/t and (1 - cos(t))/t^2
    angle = np.sqrt(np.where(small, 1.0, angle2))
    a = np.where(small, 1.0 - angle2 / 6.0, np.sin(angle) / angle)
    b = np.where(small, 0.5 - angle2 / 24.0, (1.0 - np.cos(angle)) / (angle * angle))
    k = skew(r)
    return np.asarray(np.eye(3) + a * k + b * (k @ k), dtype=np.float64)


def rotvec_from_rotation(rotation: FloatArray) -> FloatArray:
    """(3,) Rodrigues vector (rad, angle in [0, pi]) of a (3, 3) rotation matrix, through its unit quaternion.

    The quaternion is taken from the largest of its four squared components (Shepperd), so it is
    accurate at every angle, 0 and pi included.
    """
    m = np.asarray(rotation, dtype=np.float64)
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    choice = int(np.argmax([m[0, 0], m[1, 1], m[2, 2], trace]))
    q = np.empty(4)  # x, y, z, w
    if choice == 3:
        q[3] = 1.0 + trace
        q[:3] = m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]
    else:
        i, j, k = choice, (choice + 1) % 3, (choice + 2) % 3
        q[i] = 1.0 - trace + 2.0 * m[i, i]
        q[j] = m[j, i] + m[i, j]
        q[k] = m[k, i] + m[i, k]
        q[3] = m[k, j] - m[j, k]
    q /= np.linalg.norm(q)
    if q[3] < 0:
        q = -q
    sine = float(np.linalg.norm(q[:3]))  # sin(angle / 2)
    angle = 2.0 * np.arctan2(sine, q[3])
    scale = 2.0 + angle**2 / 12.0 + 7.0 * angle**4 / 2880.0 if angle < 1e-3 else angle / sine
    return np.asarray(scale * q[:3], dtype=np.float64)


def skew(vectors: FloatArray) -> FloatArray:
    """(..., 3, 3) cross-product matrices [v]x of (..., 3) vectors."""
    v = np.asarray(vectors, dtype=np.float64)
    out = np.zeros((*v.shape[:-1], 3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def rotation_error_deg(true_rotation: FloatArray, rotation: FloatArray) -> float:
    """The paper's E_r: largest angle (deg) between corresponding columns."""
    cosines = np.clip(np.sum(true_rotation * rotation, axis=0), -1.0, 1.0)
    return float(np.degrees(np.max(np.arccos(cosines))))


def translation_error(true_translation: FloatArray, translation: FloatArray) -> float:
    """The paper's E_t = |T_true - T| / |T_true| (dimensionless)."""
    return float(np.linalg.norm(true_translation - translation) / np.linalg.norm(true_translation))


def triangulate(bearings: FloatArray, rotations: FloatArray, translations: FloatArray) -> FloatArray:
    """Linear n-view triangulation on the unit sphere (paper Section II-C).

    For each view the cross product removes the unknown scale:
    ``[m]x (R X + T) = 0`` (all three rows, so rays at or beyond 90 degrees keep
    two independent constraints). Stacking the views gives the paper's linear
    system (rebuild6); it is solved in least squares with the homogeneous
    coordinate fixed to 1. With w = R^T m (the ray in the reference frame) and
    c = -R^T T (the camera centre) the normal equations are
    ``sum_v (I - w_v w_v^T) X = sum_v (I - w_v w_v^T) c_v``: X is the point
    closest to all rays, exact on noise-free data. Views whose bearing is NaN
    are left out.

    Args:
        bearings: (N, V, 3) unit bearing vectors of N points in V views (NaN = not seen).
        rotations: (V, 3, 3) camera rotations (reference to camera).
        translations: (V, 3) camera translations, mm.

    Returns:
        (N, 3) points in the reference frame, mm; NaN where fewer than two
        views see the point or the rays are (nearly) parallel.
    """
    m = np.asarray(bearings, dtype=np.float64)
    point, view = np.nonzero(np.isfinite(m[..., 0] + m[..., 1] + m[..., 2]))  # unit vectors, finite or NaN
    rays = np.einsum("mj,mji->mi", m[point, view], rotations[view])  # R^T m
    centres = -np.einsum("vji,vj->vi", rotations, translations)  # (V, 3)
    return triangulate_rays(point, m.shape[0], rays, centres[view])


def triangulate_rays(
    point: IntArray, n_points: int, rays: FloatArray, centres: FloatArray, view: IntArray | None = None
) -> FloatArray:
    """The points closest to their rays (the normal equations of :func:`triangulate`), from flat arrays.

    Args:
        point: (M,) which point each ray belongs to (0 <= point < n_points).
        n_points: number of points.
        rays: (M, 3) unit ray directions in the reference frame (w = R^T m).
        centres: (M, 3) the rays' origins, the camera centres, mm; with ``view``, (V, 3) the centres of the views.
        view: (M,) each ray's view (an index into ``centres``), or None.

    Returns:
        (n_points, 3) the points, mm; NaN where fewer than two rays or (nearly) parallel ones.
    """
    return solve_ray_sums(*ray_sums(point, n_points, rays, centres, view))


def ray_sums(
    point: IntArray, n_points: int, rays: FloatArray, centres: FloatArray, view: IntArray | None = None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Each point's normal equations ``sum_v (I - w w^T) X = sum_v (I - w w^T) c`` (see :func:`triangulate_rays`,
    whose arguments these are).

    Written component by component on (M,) arrays: no (M, 3) temporary beyond the rays themselves.

    Returns:
        (n_points,) rays per point, (n_points, 3, 3) the left-hand sides and (n_points, 3) the right-hand sides.
    """
    count = np.bincount(point, minlength=n_points).astype(np.float64)
    # lhs = count * I - sum w w^T ; rhs = sum c - sum w (w . c): sums over each point's rays
    lhs = np.empty((n_points, 3, 3))
    w = rays.T
    for i in range(3):
        for j in range(i, 3):
            summed = np.bincount(point, w[i] * w[j], minlength=n_points)
            lhs[:, i, j] = lhs[:, j, i] = (count if i == j else 0.0) - summed
    c = centres.T if view is None else centres.T[:, view]  # (3, M)
    along = w[0] * c[0] + w[1] * c[1] + w[2] * c[2]  # w . c
    rhs = np.stack([np.bincount(point, c[i] - w[i] * along, minlength=n_points) for i in range(3)], axis=1)
    return count, lhs, rhs.astype(np.float64)


def ray_terms(rays: FloatArray, centres: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(M, 3, 3) ``I - w w^T`` and (M, 3) ``(I - w w^T) c`` of single rays: what each adds to :func:`ray_sums`."""
    projector = np.eye(3) - rays[:, :, None] * rays[:, None, :]
    return projector, centres - rays * np.sum(rays * centres, axis=1)[:, None]


def solve_ray_sums(count: FloatArray, lhs: FloatArray, rhs: FloatArray) -> FloatArray:
    """(N, 3) the points of :func:`ray_sums`' normal equations; NaN where fewer than two rays or (nearly)
    parallel ones (a determinant below 1e-12 of (trace / 3)^3)."""
    adjugate, det = _adjugate_sym3(lhs)
    ok = (count >= 2) & (det > 1e-12 * (np.trace(lhs, axis1=1, axis2=2) / 3.0) ** 3)
    with np.errstate(divide="ignore", invalid="ignore"):
        points = np.einsum("nij,nj->ni", adjugate, rhs) / det[:, None]
    return np.where(ok[:, None], points, np.nan)


def _adjugate_sym3(matrices: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Adjugates (N, 3, 3) and determinants (N,) of symmetric 3x3 matrices (closed form)."""
    a, b, c = matrices[:, 0, 0], matrices[:, 0, 1], matrices[:, 0, 2]
    d, e, f = matrices[:, 1, 1], matrices[:, 1, 2], matrices[:, 2, 2]
    adjugate = np.stack(
        [
            d * f - e * e,
            c * e - b * f,
            b * e - c * d,
            c * e - b * f,
            a * f - c * c,
            b * c - a * e,
            b * e - c * d,
            b * c - a * e,
            a * d - b * b,
        ],
        axis=-1,
    ).reshape(-1, 3, 3)
    return adjugate, a * adjugate[:, 0, 0] + b * adjugate[:, 0, 1] + c * adjugate[:, 0, 2]


def triangulation_jacobian(
    points: FloatArray, rays: FloatArray, centres: FloatArray, d_rays: FloatArray, d_centres: FloatArray
) -> FloatArray:
    """Derivatives of :func:`triangulate`'s points with respect to parameters.

    Differentiates ``sum_v (I - w_v w_v^T)(X - c_v) = 0``:
    ``dX = H^-1 sum_v [-(dw_v (w_v . e_v) + w_v (dw_v . e_v)) + (I - w_v w_v^T) dc_v]``
    with ``e_v = c_v - X`` and ``H = sum_v (I - w_v w_v^T)``.

    Args:
        points: (N, 3) triangulated points X.
        rays: (N, V, 3) unit rays w_v = R_v^T m_v in the reference frame.
        centres: (N, V, 3) or (V, 3) camera centres c_v.
        d_rays: (N, V, 3, K) derivatives of the rays.
        d_centres: (N, V, 3, K) or (V, 3, K) derivatives of the centres.

    Returns:
        (N, 3, K) dX/dparameters.
    """
    n, n_views = rays.shape[:2]
    offsets = np.broadcast_to(centres, (n, n_views, 3)) - points[:, None, :]  # e_v
    along = np.sum(rays * offsets, axis=-1)  # w . e
    d_along = (offsets[..., None, :] @ d_rays)[..., 0, :]  # dw . e
    outer = rays[..., :, None] * rays[..., None, :]
    projector = np.eye(3) - outer
    rhs = -(d_rays * along[..., None, None] + rays[..., :, None] * d_along[..., None, :])
    rhs = rhs + projector @ d_centres
    adjugate, det = _adjugate_sym3(n_views * np.eye(3) - outer.sum(axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        return (adjugate @ rhs.sum(axis=1)) / det[:, None, None]


def wand_directions(a: FloatArray, c: FloatArray) -> FloatArray:
    """(N, 3) unit vectors from A to C."""
    d = np.asarray(c) - np.asarray(a)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def spherical_angles(directions: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The paper's wand angles: n = [sin(phi) cos(theta), sin(phi) sin(theta), cos(phi)].

    Returns:
        (phi, theta), each (N,), rad.
    """
    d = np.asarray(directions)
    return np.arccos(np.clip(d[..., 2], -1.0, 1.0)), np.arctan2(d[..., 1], d[..., 0])


def tangent_basis(directions: FloatArray) -> FloatArray:
    """(N, 3, 2) orthonormal bases of the planes perpendicular to unit vectors: e1 = n x h / |n x h| with
    h the x axis (the y axis where n is within 26 degrees of x), e2 = n x e1."""
    n = np.asarray(directions, dtype=np.float64)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    near_x = np.abs(x) >= 0.9
    zero = np.zeros_like(x)
    # n x (1, 0, 0) = (0, z, -y); n x (0, 1, 0) = (-z, 0, x)
    e1 = np.stack([np.where(near_x, -z, zero), np.where(near_x, zero, z), np.where(near_x, x, -y)], axis=-1)
    e1 /= np.sqrt(np.sum(e1 * e1, axis=-1, keepdims=True))
    a, b, c = e1[..., 0], e1[..., 1], e1[..., 2]
    e2 = np.stack([y * c - z * b, z * a - x * c, x * b - y * a], axis=-1)
    return np.stack([e1, e2], axis=-1)
