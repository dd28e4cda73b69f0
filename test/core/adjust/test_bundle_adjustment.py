"""Step 4: the Schur-complement bundle adjustment."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wand_calib_ros.core.adjust.bundle_adjustment import CameraSystem, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import (
    BIAS,
    N_CAMERA_PARAMS,
    READOUT,
    TIME_OFFSET,
    BundleProblem,
    BundleState,
    CameraBias,
    PlacementTiming,
    apply_step,
    default_free_mask,
    parameter_mask,
)
from wand_calib_ros.core.adjust.levenberg_marquardt import held_placements
from wand_calib_ros.core.adjust.linearisation import evaluate, huber_weights, linearise, residuals
from wand_calib_ros.core.adjust.normal_equations import SCHUR_OVERHEAD, SCHUR_WASTE, block_layout, reduced_system
from wand_calib_ros.core.model.brightness import CLASSES, LINEAR, N_BIAS, PROPORTIONAL
from wand_calib_ros.core.model.camera_model import from_opencv_pinhole
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario, simulate


def _setup(noise: float, n: int, seed: int, n_cameras: int = 2):  # type: ignore[no-untyped-def]
    scenario = paper_fisheye_scenario(n_cameras=n_cameras)
    data = simulate(scenario, noise, np.random.default_rng(seed), n=n)
    state = BundleState(
        tuple(c.model for c in scenario.cameras),
        tuple(c.pose for c in scenario.cameras),
        data.wand_a,
        data.wand_direction,
    )
    return scenario, data, state, BundleProblem.from_dense(scenario.wand, data.observations.uv)


def test_residuals_vanish_at_the_truth_without_noise() -> None:
    _, _, state, problem = _setup(0.0, 30, 0)
    assert np.max(np.abs(residuals(state, problem))) < 1e-9


def _with_timing(scenario, data, state, seed: int, uv=None, brightness=None):  # type: ignore[no-untyped-def]
    """The same views (``uv``, default the data's) seen at random instants around their placements, the wand moving,
    their points of the given (P, C, 3) ``brightness``."""
    rng = np.random.default_rng(seed)
    uv = data.observations.uv if uv is None else uv
    n_placements, n_cameras = uv.shape[:2]
    timing = PlacementTiming(
        rng.uniform(-0.02, 0.02, (n_placements, n_cameras)),
        np.array([c.spec.image_size[1] for c in scenario.cameras], dtype=float),
        rng.normal(scale=800.0, size=(n_placements, 3, 3)),
        rng.normal(scale=5000.0, size=(n_placements, 3, 3)),
        rng.normal(scale=50000.0, size=(n_placements, 3, 3)),
    )
    timed = BundleState(
        state.models, state.poses, state.wand_a, state.wand_direction, rng.normal(0.004, 0.003, (n_cameras, 2))
    )
    return timed, BundleProblem.from_dense(scenario.wand, uv, timing, brightness=brightness)


def _with_bias(state: BundleState, seed: int) -> BundleState:
    """The state with a centre bias in each camera's of three: by classes, linear from class 2, proportional
    from class 1."""
    values = np.random.default_rng(seed).normal(scale=0.3, size=(3, N_BIAS))
    shapes, starts = np.array([CLASSES, LINEAR, PROPORTIONAL], dtype=np.int8), np.array([1, 2, 1], dtype=np.int8)
    return replace(state, bias=CameraBias(values, shapes, starts))


def _pinhole_cameras(state: BundleState) -> BundleState:
    """The state with camera 1 a plumb_bob and camera 2 a rational_polynomial camera (camera 0 stays a fisheye)."""
    models = list(state.models)
    for c, (name, d) in enumerate(
        (
            ("plumb_bob", [-0.2, 0.05, 2e-3, -1e-3, 0.01]),
            ("rational_polynomial", [-0.2, 0.05, 2e-3, -1e-3, 0.01, 0.1, 0.02, 0.003]),
        ),
        start=1,
    ):
        k, m = models[c].focal_px, models[c].m
        camera_matrix = np.array([[k[0], 0.0, 300.0], [0.0, k[1], 250.0], [0.0, 0.0, 1.0]])
        models[c] = from_opencv_pinhole(camera_matrix, np.array(d), m, models[c].image_size, name)
    return replace(state, models=tuple(models))


@pytest.mark.parametrize("lenses", ["fisheye", "pinhole"])
def test_jacobians_match_finite_differences(lenses: str) -> None:
    scenario, data, state, _ = _setup(1.0, 8, 1, n_cameras=3)
    stops = np.random.default_rng(9).uniform(-2.0, 6.0, data.observations.uv.shape[:3])
    state, problem = _with_timing(scenario, data, state, 7, brightness=stops)
    state = _with_bias(state, 8)
    every = np.r_[TIME_OFFSET, READOUT, BIAS.start : BIAS.stop]
    if lenses == "pinhole":
        state = _pinhole_cameras(state)
        every = np.arange(TIME_OFFSET, N_CAMERA_PARAMS)
    _, jc, jp = linearise(state, problem, carried=every)
    assert jc.shape[2] == 13 + every.size
    finite = np.all(np.isfinite(jc), axis=(1, 2))
    assert finite.mean() > 0.9  # points behind a pinhole camera have no image
    h = 1e-6
    exists = parameter_mask(state.models)
    for c in range(3):
        for i in range(jc.shape[2]):
            delta = np.zeros((3, jc.shape[2]))
            delta[c, i] = h
            plus = residuals(apply_step(state, delta, np.zeros((8, 5)), every), problem)
            minus = residuals(apply_step(state, -delta, np.zeros((8, 5)), every), problem)
            numeric = (plus - minus) / (2 * h)
            analytic = np.where((problem.camera == c)[:, None], jc[:, :, i], 0.0)
            if not exists[c, np.r_[0:13, every][i]]:
                assert np.all(numeric[finite] == 0)  # not a parameter of its model: the step does not move it
                continue
            scale = max(1.0, np.max(np.abs(numeric[finite])))
            assert np.allclose(analytic[finite], numeric[finite], atol=1e-4 * scale), (c, i)
    for j in range(5):
        delta = np.zeros((8, 5))
        delta[:, j] = h
        zero = np.zeros((3, jc.shape[2]))
        numeric = (
            residuals(apply_step(state, zero, delta, every), problem)
            - residuals(apply_step(state, zero, -delta, every), problem)
        ) / (2 * h)
        assert np.allclose(jp[finite, :, j], numeric[finite], atol=1e-5)


@pytest.mark.parametrize("threaded", [False, True])
def test_sparse_normal_equations_and_schur_complement_match_the_dense_jacobian(monkeypatch, threaded: bool) -> None:  # type: ignore[no-untyped-def]
    # Three cameras, each view missing with probability 0.3 (placements seen by two or three), some
    # single markers missing (views of one or two points), Huber weights on some residuals, a timing
    # column, chunks of about 64 observations: the sums chunk by chunk (by one thread, or shared by
    # two) and the chunked Schur complement against J^T W J and its dense elimination.
    monkeypatch.setattr("wand_calib_ros.core.adjust.normal_equations.CHUNK_OBSERVATIONS", 64)
    monkeypatch.setattr("wand_calib_ros.core.adjust.linearisation.THREADED_CHUNKS", 2 if threaded else 10**9)
    monkeypatch.setattr("wand_calib_ros.core.parallel.cores", lambda: 2)
    scenario, data, state, _ = _setup(1.0, 300, 4, n_cameras=3)
    uv = data.observations.uv.copy()
    rng = np.random.default_rng(5)
    uv[rng.random(uv.shape[:2]) < 0.3] = np.nan
    seen = np.all(np.isfinite(uv), axis=(2, 3)).sum(axis=1) >= 2
    uv[rng.random(uv.shape[:3]) < 0.05] = np.nan
    state = BundleState(state.models, state.poses, data.wand_a[seen], data.wand_direction[seen])
    state, problem = _with_timing(scenario, data, state, 6, uv[seen])
    every = np.array([TIME_OFFSET])
    res, jc, jp = linearise(state, problem, carried=every)
    weights = huber_weights(res, 1.5)
    assert 0 < np.sum(weights < 1) < weights.size
    layout = block_layout(problem.camera, problem.placement, problem.point, 3, problem.n_placements, 3, jc.shape[2])
    assert len(layout.chunks) > 10 and len(layout.schur_chunks) > 1
    assert not all(chunk.full for chunk in layout.chunks)
    chunked_res, normal = evaluate(state, problem, layout, every, 1.5)
    assert np.array_equal(chunked_res, res)
    assert np.array_equal(residuals(state, problem), res)
    s, rhs, _ = reduced_system(normal, layout)
    u, gc = normal.u, normal.gc

    m, k, n_p = problem.n_observations, jc.shape[2], problem.n_placements
    dense = np.zeros((m, 2, 3 * k + 5 * n_p))
    rows = np.arange(m)
    for i in range(k):
        dense[rows, :, problem.camera * k + i] = jc[:, :, i]
    for j in range(5):
        dense[rows, :, 3 * k + problem.placement * 5 + j] = jp[:, :, j]
    dense = dense.reshape(2 * m, -1)
    root = np.repeat(np.sqrt(weights), 2)
    jtj = (dense * root[:, None] ** 2).T @ dense
    g = -(dense * root[:, None] ** 2).T @ res.reshape(-1)
    a, b, d = jtj[: 3 * k, : 3 * k], jtj[: 3 * k, 3 * k :], jtj[3 * k :, 3 * k :]
    d_inv = np.linalg.inv(d)
    scale = np.max(np.abs(a))
    assert np.allclose(np.stack([a[i * k : (i + 1) * k, i * k : (i + 1) * k] for i in range(3)]), u, atol=1e-12 * scale)
    assert np.allclose(gc.reshape(-1), g[: 3 * k], atol=1e-12 * np.max(np.abs(g)))
    assert np.allclose(s, a - b @ d_inv @ b.T, atol=1e-9 * scale)
    assert np.allclose(rhs, g[: 3 * k] - b @ d_inv @ g[3 * k :], atol=1e-9 * np.max(np.abs(g)))


def test_recovers_the_truth_from_a_perturbed_start_without_noise() -> None:
    scenario, _data, truth, problem = _setup(0.0, 80, 2, n_cameras=3)
    rng = np.random.default_rng(3)
    models = tuple(
        m.with_intrinsic_vector(m.intrinsic_vector() + np.r_[0.02, -0.01, 0, 0, 0, 4.0, -3.0]) for m in truth.models
    )
    poses = (
        truth.poses[0],
        *tuple(
            Pose.from_rotvec(p.rotvec + rng.normal(scale=0.01, size=3), p.translation + rng.normal(scale=10.0, size=3))
            for p in truth.poses[1:]
        ),
    )
    start = BundleState(
        models, poses, truth.wand_a + rng.normal(scale=5.0, size=truth.wand_a.shape), truth.wand_direction
    )
    result = bundle_adjust(start, problem, default_free_mask(3))
    assert result.converged
    assert np.max(np.abs(result.residuals)) < 1e-6
    for got, want in zip(result.state.models, scenario.cameras, strict=True):
        assert np.allclose(got.k, want.model.k, atol=1e-7)
        assert np.allclose(got.principal_point, want.model.principal_point, atol=1e-5)
    for got, want in zip(result.state.poses, scenario.cameras, strict=True):
        assert np.allclose(got.rotation, want.pose.rotation, atol=1e-9)
        assert np.allclose(got.translation, want.pose.translation, atol=1e-5)


def test_noise_estimate_and_parameter_uncertainty_are_consistent() -> None:
    # Over repeated noise draws the spread of u0 must match the reported standard deviation.
    scenario = paper_fisheye_scenario()
    estimates, stds, sigmas = [], [], []
    rng = np.random.default_rng(10)
    base = simulate(scenario, 0.0, rng, n=150)
    for _ in range(25):
        uv = base.observations.uv + rng.normal(scale=1.0, size=base.observations.uv.shape)
        problem = BundleProblem.from_dense(scenario.wand, uv)
        free = default_free_mask(2)
        free[:, 2:5] = False
        models = tuple(
            c.model.with_intrinsic_vector(np.r_[c.model.k[:2], 0, 0, 0, c.model.principal_point])
            for c in scenario.cameras
        )
        state = BundleState(models, tuple(c.pose for c in scenario.cameras), base.wand_a, base.wand_direction)
        result = bundle_adjust(state, problem, free)
        estimates.append(result.state.models[1].principal_point[0])
        stds.append(result.camera_std[1, 5])
        sigmas.append(result.sigma)
    assert abs(np.mean(sigmas) - 1.0) < 0.03
    assert 0.6 < np.std(estimates) / np.mean(stds) < 1.5


def test_a_placement_whose_step_raises_its_cost_is_held() -> None:
    # Every placement stepped onto the truth but one, thrown 300 mm off: that one alone is held where
    # it was; and nothing is held when holding would not beat the cost before the step.
    _, _, truth, problem = _setup(0.0, 40, 11, n_cameras=3)
    rng = np.random.default_rng(12)
    before = BundleState(
        truth.models, truth.poses, truth.wand_a + rng.normal(scale=2.0, size=truth.wand_a.shape), truth.wand_direction
    )
    thrown = truth.wand_a.copy()
    thrown[7] += 300.0
    candidate = BundleState(truth.models, truth.poses, thrown, truth.wand_direction)
    res = residuals(candidate, problem)
    held = held_placements(before, candidate, problem, res, None, np.inf)
    assert held is not None
    moved = np.flatnonzero(np.any(held.wand_a != candidate.wand_a, axis=1))
    assert moved.tolist() == [7] and np.array_equal(held.wand_a[7], before.wand_a[7])
    assert held_placements(before, candidate, problem, res, None, 0.0) is None
    assert held_placements(before, truth, problem, residuals(truth, problem), None, np.inf) is None


def test_schur_chunks_keep_apart_placements_of_cameras_that_share_none() -> None:
    # Two rings of four cameras, each ring seeing its own 300 placements by two or three of its
    # cameras: the sort keeps each ring's placements together (only the chunk at their boundary may
    # hold both), and no chunk's dense product costs more than SCHUR_WASTE times its placements' own
    # blocks and SCHUR_OVERHEAD.
    rng = np.random.default_rng(3)
    camera, placement = [], []
    for p in range(600):
        ring = 4 * (p % 2)
        for c in np.sort(rng.choice(4, size=rng.integers(2, 4), replace=False)) + ring:
            camera += [c] * 3
            placement += [p] * 3
    camera_array, placement_array = np.array(camera), np.array(placement)
    point = np.tile(np.arange(3), camera_array.size // 3)
    layout = block_layout(camera_array, placement_array, point, 8, 600, 3, 13)
    own = np.bincount(layout.block_placement) ** 2
    assert sum(chunk.placements.size for chunk in layout.schur_chunks) == 600
    mixed = [not (np.all(chunk.cameras < 4) or np.all(chunk.cameras >= 4)) for chunk in layout.schur_chunks]
    assert sum(mixed) <= 1
    for chunk in layout.schur_chunks:
        product = chunk.placements.size * chunk.cameras.size**2
        assert product <= SCHUR_WASTE * own[chunk.placements].sum() + SCHUR_OVERHEAD
        assert np.array_equal(chunk.cameras[chunk.local_camera], layout.block_camera[chunk.blocks])
        assert np.array_equal(chunk.placements[chunk.local_placement], layout.block_placement[chunk.blocks])


def test_the_released_step_is_the_adjustment_of_the_larger_model_and_a_choice_starts_at_the_smaller() -> None:
    # From a low-order adjustment's own normal equations: k3..k5 released (one Gauss-Newton step) land
    # where adjusting them does, with its covariance. A choice at the start that fixes k5 at zero has
    # the adjustment land where adjusting without k5 does.
    scenario, data, truth, _ = _setup(1.0, 400, 4, n_cameras=3)
    problem = BundleProblem.from_dense(scenario.wand, data.observations.uv)
    low = default_free_mask(3)
    low[:, 2:5] = False
    models = tuple(m.with_intrinsic_vector(np.r_[m.k[:2], 0, 0, 0, m.principal_point]) for m in truth.models)
    tight = {"tolerance": 1e-14, "settled": 1e-9, "last_step": False}  # converged beyond the linearisation's own error
    start = BundleState(models, truth.poses, truth.wand_a, truth.wand_direction)
    adjusted = bundle_adjust(start, problem, low, **tight)
    assert adjusted.system is not None
    full = default_free_mask(3)
    delta = adjusted.system.step(full)
    exact = bundle_adjust(adjusted.state, problem, full, **tight)
    for c in range(3):
        stepped = adjusted.state.models[c].intrinsic_vector() + delta[c, :7]
        error = (stepped - exact.state.models[c].intrinsic_vector()) / exact.camera_std[c, :7]
        assert np.max(np.abs(error)) < 0.1, (c, error)  # 0.03 here: plenty for a test at 2 sigma
    std = np.sqrt(np.diag(adjusted.system.covariance(full, adjusted.sigma))).reshape(3, N_CAMERA_PARAMS)
    assert np.allclose(std[full], exact.camera_std[full], rtol=0.01)

    without_k5 = full.copy()
    without_k5[:, 4] = False
    seen = []

    def choose(state: BundleState, system: CameraSystem, sigma: float) -> tuple[np.ndarray, np.ndarray]:
        seen.append(sigma)
        moves = np.zeros((3, N_CAMERA_PARAMS))
        moves[:, 4] = -np.array([m.k[4] for m in state.models])
        return without_k5, moves

    chosen = bundle_adjust(exact.state, problem, full, choose=choose, **tight)
    zeroed = tuple(m.with_intrinsic_vector(np.r_[m.k[:4], 0.0, m.principal_point]) for m in exact.state.models)
    cold = bundle_adjust(replace(exact.state, models=zeroed), problem, without_k5, **tight)
    assert len(seen) == 1 and abs(seen[0] - exact.sigma) < 1e-9
    assert all(m.k[4] == 0.0 for m in chosen.state.models)
    assert chosen.dof == cold.dof and np.allclose(chosen.camera_std, cold.camera_std, rtol=1e-3)
    for c in range(3):
        error = (chosen.state.models[c].intrinsic_vector() - cold.state.models[c].intrinsic_vector()) / cold.camera_std[
            c, :7
        ].clip(1e-300)
        assert np.max(np.abs(error[[0, 1, 2, 3, 5, 6]])) < 0.01, (c, error)
