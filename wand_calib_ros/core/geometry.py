"""Rigid-body and ray geometry shared by every calibration step.

Frames: a camera pose (R, T) maps reference-frame points to the camera frame,
``X_cam = R @ X_ref + T`` (mm). Bearing vectors are unit vectors in a camera
frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

FloatArray = NDArray[np.float64]


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
        return Rotation.from_matrix(self.rotation).as_rotvec()

    @property
    def center(self) -> FloatArray:
        """(3,) camera centre in the reference frame, mm."""
        return -self.rotation.T @ self.translation

    def apply(self, points: FloatArray) -> FloatArray:
        """Map (..., 3) reference-frame points into this frame."""
        return np.asarray(points) @ self.rotation.T + self.translation

    def compose(self, first: Pose) -> Pose:
        """The transform ``self after first`` (paper eq. 'transfer': R_ik = R_jk R_ij, T_ik = R_jk T_ij + T_jk)."""
        return Pose(self.rotation @ first.rotation, self.rotation @ first.translation + self.translation)

    def inverse(self) -> Pose:
        """The transform back: X_ref = R^T X - R^T T."""
        return Pose(self.rotation.T, -self.rotation.T @ self.translation)


def rotation_from_rotvec(rotvec: FloatArray) -> FloatArray:
    """(3, 3) rotation matrix of a Rodrigues vector, R = exp([r]x)."""
    return Rotation.from_rotvec(np.asarray(rotvec, dtype=np.float64)).as_matrix()


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
    seen = np.isfinite(m[..., 0] + m[..., 1] + m[..., 2])  # (N, V): unit vectors, finite or NaN
    m = np.where(seen[..., None], m, 0.0)
    w = np.matmul(m.transpose(1, 0, 2), rotations).transpose(1, 0, 2)  # (N, V, 3) R^T m: one product per view
    centres = -np.einsum("vji,vj->vi", rotations, translations)  # (V, 3)
    count = seen.sum(axis=1).astype(np.float64)
    # lhs = count * I - sum w w^T ; rhs = sum c - sum w (w . c): sums over the views of (N, V) products
    lhs = np.empty((m.shape[0], 3, 3))
    for i in range(3):
        for j in range(i, 3):
            lhs[:, i, j] = lhs[:, j, i] = (count if i == j else 0.0) - np.sum(w[..., i] * w[..., j], axis=1)
    along = np.sum(w * centres, axis=-1)  # (N, V) w . c
    rhs = seen.astype(np.float64) @ centres - np.sum(w * along[..., None], axis=1)
    adjugate, det = _adjugate_sym3(lhs)
    # A tiny determinant relative to (trace/3)^3 means (nearly) parallel rays.
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
    """(N, 3, 2) orthonormal bases of the planes perpendicular to unit vectors."""
    n = np.asarray(directions, dtype=np.float64)
    helper = np.where(np.abs(n[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    e1 = np.cross(n, helper)
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(n, e1)
    return np.stack([e1, e2], axis=-1)
