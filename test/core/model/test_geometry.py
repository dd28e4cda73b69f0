"""Poses, n-view triangulation on the sphere and its derivatives."""

from __future__ import annotations

import numpy as np
import pytest

from wand_calib_ros.core.judge.metrics import rereference
from wand_calib_ros.core.model.geometry import (
    Pose,
    rotation_error_deg,
    rotation_from_rotvec,
    rotvec_from_rotation,
    spherical_angles,
    tangent_basis,
    translation_error,
    triangulate,
    triangulation_jacobian,
)


def _rig(rng: np.random.Generator, n_views: int) -> tuple[np.ndarray, np.ndarray]:
    rotations = [np.eye(3)] + [Pose.from_rotvec(rng.normal(size=3), np.zeros(3)).rotation for _ in range(n_views - 1)]
    translations = [np.zeros(3)] + [rng.normal(scale=800.0, size=3) for _ in range(n_views - 1)]
    return np.stack(rotations), np.stack(translations)


def _bearings(points: np.ndarray, rotations: np.ndarray, translations: np.ndarray) -> np.ndarray:
    in_cam = np.einsum("vij,nj->nvi", rotations, points) + translations
    return in_cam / np.linalg.norm(in_cam, axis=-1, keepdims=True)


@pytest.mark.parametrize("n_views", [2, 3, 5])
def test_noise_free_triangulation_is_exact_in_every_direction(n_views: int) -> None:
    rng = np.random.default_rng(n_views)
    rotations, translations = _rig(rng, n_views)
    points = rng.normal(scale=1500.0, size=(200, 3))  # all around the cameras: rays beyond 90 degrees too
    bearings = _bearings(points, rotations, translations)
    assert np.any(bearings[:, 0, 2] < 0)
    assert np.max(np.abs(triangulate(bearings, rotations, translations) - points)) < 1e-7


def test_missing_views_are_ignored_and_single_views_give_nan() -> None:
    rng = np.random.default_rng(7)
    rotations, translations = _rig(rng, 3)
    points = rng.normal(scale=1000.0, size=(10, 3)) + np.array([0.0, 0.0, 2000.0])
    bearings = _bearings(points, rotations, translations)
    bearings[:5, 1] = np.nan
    bearings[9, 1:] = np.nan
    result = triangulate(bearings, rotations, translations)
    assert np.allclose(result[:9], points[:9], atol=1e-7)
    assert np.all(np.isnan(result[9]))


def test_parallel_rays_give_nan() -> None:
    rotations = np.stack([np.eye(3), np.eye(3)])
    translations = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    bearings = np.array([[[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]]])
    assert np.all(np.isnan(triangulate(bearings, rotations, translations)))


def test_triangulation_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(3)
    rotations, translations = _rig(rng, 3)
    points = rng.normal(scale=1000.0, size=(20, 3)) + np.array([0.0, 0.0, 1500.0])
    rays = np.einsum("vji,nvj->nvi", rotations, _bearings(points, rotations, translations))  # R^T m
    rays += rng.normal(scale=0.01, size=rays.shape)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    centres = -np.einsum("vji,vj->vi", rotations, translations)
    d_rays = rng.normal(size=(*rays.shape, 4))
    d_centres = np.broadcast_to(rng.normal(size=(3, 3, 4)), (*rays.shape, 4))

    def solve(t: float, k: int) -> np.ndarray:
        r = rays + t * d_rays[..., k]
        c = centres + t * d_centres[0, ..., k]
        return triangulate(r, np.broadcast_to(np.eye(3), (3, 3, 3)), -c)

    x = solve(0.0, 0)
    jac = triangulation_jacobian(x, rays, centres, d_rays, d_centres)
    for k in range(4):
        numeric = (solve(1e-6, k) - solve(-1e-6, k)) / 2e-6
        assert np.allclose(jac[..., k], numeric, rtol=1e-5, atol=1e-4)


def test_pose_composition_follows_the_paper_transfer_equation() -> None:
    rng = np.random.default_rng(4)
    first = Pose.from_rotvec(rng.normal(size=3), rng.normal(size=3) * 100)
    second = Pose.from_rotvec(rng.normal(size=3), rng.normal(size=3) * 100)
    point = rng.normal(size=3)
    assert np.allclose(second.compose(first).apply(point), second.apply(first.apply(point)))
    poses = {"a": first, "b": second}
    moved = rereference(poses, "a")
    assert np.allclose(moved["a"].rotation, np.eye(3)) and np.allclose(moved["a"].translation, 0.0, atol=1e-12)
    assert np.allclose(moved["b"].apply(first.apply(point)), second.apply(point))


def test_paper_error_measures() -> None:
    rotation = Pose.from_rotvec(np.array([0.0, 0.0, np.radians(2.0)]), np.zeros(3)).rotation
    assert rotation_error_deg(np.eye(3), rotation) == pytest.approx(2.0)
    assert translation_error(np.array([100.0, 0, 0]), np.array([101.0, 0, 0])) == pytest.approx(0.01)


def test_wand_direction_helpers() -> None:
    directions = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.6, 0.8]])
    phi, theta = spherical_angles(directions)
    rebuilt = np.stack([np.sin(phi) * np.cos(theta), np.sin(phi) * np.sin(theta), np.cos(phi)], -1)
    assert np.allclose(rebuilt, directions)
    basis = tangent_basis(directions)
    assert np.allclose(np.einsum("ni,nik->nk", directions, basis), 0.0)
    assert np.allclose(np.einsum("nik,nil->nkl", basis, basis), np.eye(2))


def test_rotation_vectors_round_trip_at_every_angle() -> None:
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(3)
    axes = rng.normal(size=(200, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.concatenate([[0.0, 1e-9, 1e-5, 1e-3, np.pi - 1e-7, np.pi], rng.uniform(0, np.pi, 194)])
    for axis, angle in zip(axes, angles, strict=True):
        rotvec = angle * axis
        rotation = rotation_from_rotvec(rotvec)
        assert np.allclose(rotation, Rotation.from_rotvec(rotvec).as_matrix(), atol=1e-14)
        back = rotvec_from_rotation(rotation)
        if angle < np.pi - 1e-6:
            assert np.allclose(back, rotvec, atol=1e-9)
        else:  # at pi, r and -r are the same rotation
            assert np.allclose(rotation_from_rotvec(back), rotation, atol=1e-12)
    batch = angles[:, None] * axes
    assert np.allclose(rotation_from_rotvec(batch), Rotation.from_rotvec(batch).as_matrix(), atol=1e-14)
