"""Camera model: round trips to 185 degrees, exact Jacobians, OpenCV equivalence."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.model.camera_model import (
    CameraModel,
    from_opencv_fisheye,
    inverse_radius,
    monotonic_limit,
    project,
    project_with_jacobian,
    radius,
    to_opencv_fisheye,
    turns_over_in_image,
    unproject,
    unproject_with_jacobian,
)
from wand_calib_ros.sim.scenarios import equisolid_taylor

MODELS = {
    "fisheye185": (CameraModel(equisolid_taylor(2.0), [178.57, 178.57], [310.0, 250.0], (640, 480)), 92.5),
    "fisheye_k5": (
        CameraModel([1.8, 0.03, -0.004, 0.0005, -0.00002], [178.6, 180.0], [330.2, 241.7], (658, 492)),
        95.0,
    ),
    "conventional": (CameraModel([4.3, 1.18, 0.27, 0.19, -0.19], [178.57, 178.57], [335.0, 238.0], (658, 492)), 45.0),
}


def _bearings(max_angle_deg: float, rng: np.random.Generator, n: int = 4000) -> np.ndarray:
    theta = np.radians(rng.uniform(0.0, max_angle_deg, n))
    theta[:3] = [0.0, 1e-9, np.radians(max_angle_deg)]
    phi = rng.uniform(-np.pi, np.pi, n)
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_round_trip_over_the_whole_field_of_view(name: str) -> None:
    model, max_angle = MODELS[name]
    bearings = _bearings(max_angle, np.random.default_rng(0))
    uv = project(model, bearings * 1234.5)
    back = unproject(model, uv)
    assert np.max(np.abs(project(model, back) - uv)) < 1e-9
    assert np.max(np.linalg.norm(back - bearings, axis=1)) < 1e-11


def test_rays_beyond_ninety_degrees_project_outside_the_ninety_degree_circle() -> None:
    model, _ = MODELS["fisheye185"]
    at_90 = project(model, np.array([1.0, 0.0, 0.0]))
    at_92 = project(model, np.array([np.cos(np.radians(2.0)), 0.0, -np.sin(np.radians(2.0))]))
    assert at_92[0] > at_90[0] > model.principal_point[0]


@pytest.mark.parametrize("name", sorted(MODELS))
def test_projection_jacobian_matches_finite_differences(name: str) -> None:
    model, max_angle = MODELS[name]
    points = _bearings(max_angle * 0.99, np.random.default_rng(1), 50) * 900.0
    points[0] = [0.0, 0.0, 900.0]  # on the optical axis
    jac = project_with_jacobian(model, points)
    h = 1e-4
    for i in range(3):
        step = np.zeros(3)
        step[i] = h
        numeric = (project(model, points + step) - project(model, points - step)) / (2 * h)
        assert np.allclose(jac.d_point[:, :, i], numeric, atol=1e-7)
    vector = model.intrinsic_vector()
    for i in range(7):
        step = np.zeros(7)
        step[i] = 1e-6
        numeric = (
            project(model.with_intrinsic_vector(vector + step), points)
            - project(model.with_intrinsic_vector(vector - step), points)
        ) / 2e-6
        assert np.allclose(jac.d_intrinsics[:, :, i], numeric, atol=1e-5)
    assert np.allclose(jac.uv, project(model, points))


def test_unprojection_jacobian_matches_finite_differences() -> None:
    model, max_angle = MODELS["fisheye_k5"]
    uv = project(model, _bearings(max_angle * 0.98, np.random.default_rng(2), 40))
    uv[0] = model.principal_point
    _, jac = unproject_with_jacobian(model, uv)
    vector = model.intrinsic_vector()
    for i in range(7):
        step = np.zeros(7)
        step[i] = 1e-7
        numeric = (
            unproject(model.with_intrinsic_vector(vector + step), uv)
            - unproject(model.with_intrinsic_vector(vector - step), uv)
        ) / 2e-7
        assert np.allclose(jac[:, :, i], numeric, atol=1e-6)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_agrees_with_opencv_fisheye_project_points(name: str) -> None:
    model, max_angle = MODELS[name]
    bearings = _bearings(min(max_angle, 89.0), np.random.default_rng(3))
    opencv = to_opencv_fisheye(model)
    expected, _ = cv2.fisheye.projectPoints(
        (bearings * 1000.0)[:, None, :], np.zeros(3), np.zeros(3), opencv.camera_matrix, opencv.distortion
    )
    assert np.max(np.abs(expected[:, 0, :] - project(model, bearings))) < 1e-6
    back = from_opencv_fisheye(opencv.camera_matrix, opencv.distortion, model.m, model.image_size)
    assert np.allclose(back.k, model.k, rtol=1e-14) and np.allclose(back.principal_point, model.principal_point)


def test_monotonic_limit_matches_polynomial_roots() -> None:
    for k in ([2.0, -0.0833, 0, 0, 0], [2.0, -0.05, 0.01, -0.01, 0.001], [4.3, 1.18, 0.27, 0.19, -0.19]):
        k = np.array(k)
        roots = np.roots([9 * k[4], 7 * k[3], 5 * k[2], 3 * k[1], k[0]])
        real = roots[np.abs(roots.imag) < 1e-9].real
        expected = np.sqrt(real[(real > 0) & (real < np.pi**2)].min())
        assert monotonic_limit(k) == pytest.approx(expected, abs=1e-12)
    assert monotonic_limit(np.array([2.0, 0.0, 0.0, 0.0, 0.0])) == np.pi


def test_inverse_radius_is_nan_beyond_the_reachable_radius() -> None:
    k = np.array([2.0, -0.2, 0.0, 0.0, 0.0])  # turns over at 1.826 rad
    limit = monotonic_limit(k)
    r_max = float(radius(k, np.array(limit)))
    theta = inverse_radius(k, np.array([0.0, 0.5 * r_max, r_max * (1 - 1e-12), r_max * 1.01, np.nan]))
    assert theta[0] == 0.0 and theta[2] == pytest.approx(limit, abs=1e-5)
    assert np.isnan(theta[3]) and np.isnan(theta[4])
    assert radius(k, theta[1]) == pytest.approx(0.5 * r_max, abs=1e-14)


def test_turn_over_inside_the_image_is_detected() -> None:
    good, _ = MODELS["fisheye185"]
    assert not turns_over_in_image(good, np.radians(92.5))
    bad = CameraModel([2.0, -0.4, 0.0, 0.0, 0.0], good.m, good.principal_point, good.image_size)
    assert turns_over_in_image(bad, np.radians(92.5))


def test_invalid_models_and_shapes_are_rejected() -> None:
    with pytest.raises(ModelError, match="k1"):
        CameraModel([0.0, 0, 0, 0, 0], [1.0, 1.0], [0.0, 0.0], (10, 10))
    with pytest.raises(ModelError, match="shape"):
        CameraModel([1.0, 0, 0], [1.0, 1.0], [0.0, 0.0], (10, 10))
    with pytest.raises(ModelError, match="finite"):
        CameraModel([1.0, np.nan, 0, 0, 0], [1.0, 1.0], [0.0, 0.0], (10, 10))
    model, _ = MODELS["fisheye185"]
    with pytest.raises(ValueError, match="shape"):
        project(model, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="shape"):
        unproject(model, np.zeros((4, 3)))


def test_inverse_radius_keeps_shape_and_handles_radii_near_the_turning_point() -> None:
    k = np.array([2.0, -0.2, 0.0, 0.0, 0.0])
    scalar = inverse_radius(k, np.array(1.0))
    assert scalar.shape == () and radius(k, scalar) == pytest.approx(1.0, abs=1e-13)
    limit = monotonic_limit(k)
    r_max = float(radius(k, np.array(limit)))
    near = r_max * (1 - np.logspace(-12, -3, 10))  # Newton is slow where dr/dtheta -> 0
    theta = inverse_radius(k, near.reshape(2, 5))
    assert theta.shape == (2, 5)
    assert np.allclose(radius(k, theta).ravel(), near, atol=1e-12)
