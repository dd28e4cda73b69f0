"""OpenCV's pinhole models (plumb_bob, rational_polynomial) as camera models of their own: OpenCV's own
projection exactly, the inverse over the whole image, the exact conversions, the radial curve."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from wand_calib_ros.core.errors import ModelError
from wand_calib_ros.core.model import pinhole
from wand_calib_ros.core.model.camera_model import (
    PLUMB_BOB,
    RATIONAL_POLYNOMIAL,
    CameraModel,
    angle_of_radius,
    from_opencv_pinhole,
    project,
    project_with_jacobian,
    radius_limit,
    radius_mm,
    to_opencv,
    turns_over_in_image,
    unproject,
)

K = np.array([[1612.0, 0.0, 1275.0], [0.0, 1618.0, 806.0], [0.0, 0.0, 1.0]])
SIZE = (2560, 1600)
M = np.array([100.0, 100.0 * 1618.0 / 1612.0])
LENSES = {
    PLUMB_BOB: [-0.15, 0.11, 3e-4, -2e-4, 0.01],
    RATIONAL_POLYNOMIAL: [-0.15, 0.11, 3e-4, -2e-4, 0.01, 0.05, 0.01, 0.002],
}


def _model(name: str) -> CameraModel:
    return from_opencv_pinhole(K, np.array(LENSES[name]), M, SIZE, name)


def _points(n: int = 500) -> np.ndarray:
    rng = np.random.default_rng(3)
    return rng.uniform([-900.0, -600.0, 1000.0], [900.0, 600.0, 2500.0], size=(n, 3))


@pytest.mark.parametrize("name", [PLUMB_BOB, RATIONAL_POLYNOMIAL])
def test_projection_is_opencv_projectpoints(name: str) -> None:
    points = _points()
    theirs = cv2.projectPoints(points, np.zeros(3), np.zeros(3), K, np.array(LENSES[name]))[0].reshape(-1, 2)
    assert np.abs(project(_model(name), points) - theirs).max() < 1e-9


@pytest.mark.parametrize("name", [PLUMB_BOB, RATIONAL_POLYNOMIAL])
def test_opencv_parameters_round_trip_exactly(name: str) -> None:
    opencv = to_opencv(_model(name))
    assert opencv.distortion_model == name
    assert np.array_equal(opencv.camera_matrix, K) or np.abs(opencv.camera_matrix - K).max() < 1e-12
    assert np.abs(opencv.distortion - np.array(LENSES[name])).max() < 1e-15


@pytest.mark.parametrize("name", [PLUMB_BOB, RATIONAL_POLYNOMIAL])
def test_unprojection_inverts_the_projection_over_the_whole_image(name: str) -> None:
    model = _model(name)
    u, v = np.meshgrid(np.linspace(-0.5, SIZE[0] - 0.5, 41), np.linspace(-0.5, SIZE[1] - 0.5, 33))
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    bearings = unproject(model, pixels)
    assert np.all(np.isfinite(bearings))
    assert np.abs(project(model, bearings) - pixels).max() < 1e-8
    assert np.allclose(np.linalg.norm(bearings, axis=1), 1.0)


def test_points_behind_a_pinhole_camera_have_no_image() -> None:
    uv = project(_model(PLUMB_BOB), np.array([[10.0, 5.0, -100.0], [1.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    assert np.all(np.isnan(uv[:2])) and np.all(np.isfinite(uv[2]))


def test_jacobians_match_finite_differences() -> None:
    model = _model(RATIONAL_POLYNOMIAL)
    points = _points(50)
    jacobian = pinhole.project_with_jacobian_arrays(
        model.k[None], model.lens_vector()[None], model.m[None], model.principal_point[None], points
    )
    h = 1e-4
    for i in range(3):
        step = np.zeros(3)
        step[i] = h
        numeric = (project(model, points + step) - project(model, points - step)) / (2 * h)
        assert np.allclose(jacobian.d_point[:, :, i], numeric, rtol=1e-6, atol=1e-8)
    vector, extra = model.intrinsic_vector(), model.lens_vector()
    for i in (0, 1, 2, 3, 5, 6):
        step = np.zeros(7)
        step[i] = 1e-5 * max(abs(vector[i]), 1.0)
        numeric = (
            project(model.with_intrinsic_vector(vector + step), points)
            - project(model.with_intrinsic_vector(vector - step), points)
        ) / (2 * step[i])
        assert np.allclose(jacobian.d_intrinsics[:, :, i], numeric, rtol=1e-5, atol=1e-5)
    for j in range(5):
        step = np.zeros(5)
        step[j] = 1e-7
        numeric = (
            project(model.with_intrinsic_vector(vector, extra + step), points)
            - project(model.with_intrinsic_vector(vector, extra - step), points)
        ) / 2e-7
        assert np.allclose(jacobian.d_extra[:, :, j], numeric, rtol=1e-5, atol=1e-4)
    assert np.array_equal(project_with_jacobian(model, points).d_point, jacobian.d_point)


def test_the_radial_curve_is_inverted_on_its_increasing_branch() -> None:
    model = _model(PLUMB_BOB)
    theta = np.radians(np.linspace(0.0, 60.0, 61))
    assert np.allclose(angle_of_radius(model, radius_mm(model, theta)), theta, atol=1e-12)
    assert radius_limit(model) == pytest.approx(np.pi / 2) and not turns_over_in_image(model, np.radians(50))
    folding = from_opencv_pinhole(K, np.array([-0.45, 0.05, 0.0, 0.0, 0.0]), M, SIZE)
    peak = np.sqrt((1.35 - np.sqrt(1.35**2 - 1.0)) / 0.5)  # dr/ds = 1 - 1.35 s^2 + 0.25 s^4 = 0
    assert radius_limit(folding) == pytest.approx(np.arctan(peak), abs=1e-9)
    assert turns_over_in_image(folding, np.radians(50))


def test_terms_a_model_does_not_have_are_refused() -> None:
    with pytest.raises(ModelError, match="plumb_bob model has no such terms"):
        CameraModel([16.0, 0, 0, 0, 0], M, (1280, 800), SIZE, PLUMB_BOB, [0, 0, 0.1, 0, 0])
    with pytest.raises(ModelError, match="equidistant model has no such terms"):
        CameraModel([16.0, 0, 0, 0, 0], M, (1280, 800), SIZE, extra=[1e-3, 0, 0, 0, 0])
    with pytest.raises(ModelError, match="unknown camera model 'radtan'"):
        CameraModel([16.0, 0, 0, 0, 0], M, (1280, 800), SIZE, "radtan")
