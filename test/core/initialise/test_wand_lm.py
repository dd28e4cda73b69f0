"""Step 3: Levenberg-Marquardt on the wand-length errors."""

from __future__ import annotations

import numpy as np

from wand_calib_ros.core.initialise.wand_lm import _STEP3_INTRINSICS, _WandProblem, optimise_wand_lengths
from wand_calib_ros.core.model.geometry import Pose, rotation_error_deg
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate


def _perturbed_start(scenario):  # type: ignore[no-untyped-def]
    models = []
    for camera, (dk1, du) in zip(scenario.cameras, [(0.05, 6.0), (-0.04, -5.0)], strict=True):
        vector = camera.model.intrinsic_vector()
        vector[0] += dk1
        vector[5:] += du
        models.append(camera.model.with_intrinsic_vector(vector))
    truth = scenario.cameras[1].pose
    pose = Pose.from_rotvec(truth.rotvec + 0.02, truth.translation * 1.05 + 10.0)
    return (models[0], models[1]), pose


def test_noise_free_data_converge_to_the_truth() -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 0.0, np.random.default_rng(0), n=120)
    uv = data.observations.uv
    models, pose = _perturbed_start(scenario)
    # Step 3 estimates only k1, k2, u0, v0: give it the true k3..k5 so the truth is a zero of g.
    models = tuple(
        m.with_intrinsic_vector(np.r_[m.k[:2], c.model.k[2:], m.principal_point])
        for m, c in zip(models, scenario.cameras, strict=True)
    )
    tolerance = 1e-8  # the solver's relative tolerance on the cost and the parameters (MINPACK's ftol, xtol)
    fit = optimise_wand_lengths(models, pose, uv[:, 0], uv[:, 1], scenario.wand, tolerance=tolerance)
    problem = _WandProblem(models, uv[:, 0], uv[:, 1], scenario.wand)

    def vector(fitted, fitted_pose):  # type: ignore[no-untyped-def]
        intrinsics = [m.intrinsic_vector()[_STEP3_INTRINSICS] for m in fitted]
        return np.concatenate([*intrinsics, fitted_pose.rotvec, fitted_pose.translation])

    truth = vector(tuple(c.model for c in scenario.cameras), scenario.cameras[1].pose)
    found = vector(fit.models, fit.pose)
    # Noise-free data: the cost goes down to the rounding of the residuals' evaluation (the truth's own
    # residuals), and the solver stops once a step moves the parameters by less than its tolerance relative to
    # them, in its own scaling (the Jacobian's column norms: mm, rad and px weigh alike), or gains less than
    # that of the cost. The solution is then within about that tolerance of the truth in the same scaled norm
    # (measured 0.3-0.8 of it with different CPUs' kernels); 10x covers the last step's size. No fixed number
    # of degrees: which rounding a CPU's kernels make moves it by 1e-6 deg (the problem's condition, ~1e8).
    rounding = problem.residuals(truth)
    sigma = max(float(np.sqrt(np.mean(rounding**2))), np.finfo(float).eps * scenario.wand.L)
    assert fit.rms_mm < 100 * sigma  # the cost went down to the rounding floor
    scale = np.linalg.norm(problem.jacobian(found), axis=0)
    assert np.linalg.norm(scale * (found - truth)) <= 10 * tolerance * np.linalg.norm(scale * truth)
    assert rotation_error_deg(scenario.cameras[1].pose.rotation, fit.pose.rotation) < 1e-4  # and that is tiny


def test_analytic_jacobian_matches_finite_differences() -> None:
    scenario = paper_fisheye_scenario()
    data = simulate(scenario, 1.0, np.random.default_rng(1), n=20)
    uv = data.observations.uv
    models, pose = _perturbed_start(scenario)
    problem = _WandProblem(models, uv[:, 0], uv[:, 1], scenario.wand)
    x = np.r_[
        models[0].intrinsic_vector()[_STEP3_INTRINSICS],
        models[1].intrinsic_vector()[_STEP3_INTRINSICS],
        pose.rotvec,
        pose.translation,
    ]
    jac = problem.jacobian(x).copy()
    for i in range(14):
        h = 1e-6 * max(1.0, abs(x[i]))
        step = np.zeros(14)
        step[i] = h
        numeric = (problem.residuals(x + step) - problem.residuals(x - step)) / (2 * h)
        assert np.allclose(jac[:, i], numeric, rtol=1e-5, atol=1e-6 * np.max(np.abs(numeric)))
