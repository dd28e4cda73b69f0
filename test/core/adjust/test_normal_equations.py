"""The cameras' normal equations solved and inverted where their parameters span many orders of magnitude."""

from __future__ import annotations

import numpy as np

from wand_calib_ros.core.adjust.normal_equations import (
    ILL_CONDITIONED,
    _inverse_and_root,
    jacobi_scale,
    scaled_inverse,
    solve_free,
)


def _badly_scaled(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(S, D): S = D A D, A a well-conditioned random SPD matrix, D spanning 1e-5 .. 1e5 (a 25,000 px focal's
    column beside a rotation's in radians and a principal point's in px)."""
    rng = np.random.default_rng(seed)
    n = 12
    q, _ = np.linalg.qr(rng.normal(size=(n, n)))
    a = q @ np.diag(rng.uniform(0.5, 2.0, n)) @ q.T  # condition 4
    d = 10.0 ** rng.uniform(-5, 5, n)
    return d[:, None] * a * d[None, :], d


def test_badly_scaled_normal_equations_keep_every_standard_deviation() -> None:
    for seed in range(6):
        s, d = _badly_scaled(seed)
        exact = np.linalg.inv(s / d[:, None] / d[None, :]) / d[:, None] / d[None, :]  # D^-1 A^-1 D^-1
        assert np.allclose(
            np.diag(scaled_inverse(s)), np.diag(exact), rtol=1e-10, atol=0.0
        )  # A's condition 4: rounding
        unscaled = np.diag(np.linalg.pinv(s, hermitian=True))  # what it was: off by rounding amplified
        assert np.max(np.abs(unscaled / np.diag(exact) - 1)) > 1e3 * np.max(
            np.abs(np.diag(scaled_inverse(s)) / np.diag(exact) - 1)
        )


def test_badly_scaled_steps_are_solved_exactly_over_the_free_unknowns() -> None:
    for seed in range(6):
        s, d = _badly_scaled(seed)
        x = np.random.default_rng(seed + 10).normal(size=s.shape[0]) / d
        free = np.ones(s.shape[0], dtype=bool)
        free[3] = False
        x[3] = 0.0
        rhs = s @ x
        rhs[3] = 0.0  # (its equation is not solved: its unknown is held)
        solved = solve_free(s, rhs, free)
        assert np.allclose(solved * d, x * d, rtol=0.0, atol=1e-9)


def test_a_prior_adds_its_information_to_the_parameters_it_holds() -> None:
    """CameraSystem.covariance with a prior: sigma^2 (S + sigma^2 / prior^2)^-1 over the free parameters and
    those held at a prior; a parameter the data do not see at all gets the prior's own variance."""
    from wand_calib_ros.core.adjust.bundle_adjustment import CameraSystem
    from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS

    rng = np.random.default_rng(5)
    columns = np.arange(13)  # the geometric parameters of one camera
    jacobian = rng.normal(size=(40, 13))
    jacobian[:, 6] = 0.0  # v0 unseen by the data
    matrix = jacobian.T @ jacobian
    system = CameraSystem(columns, matrix, np.zeros(13))
    free = np.zeros((1, N_CAMERA_PARAMS), dtype=bool)
    free[0, [0, 7, 8, 9]] = True  # k1 and the rotation
    prior = np.zeros((1, N_CAMERA_PARAMS))
    prior[0, [5, 6]] = 15.0  # u0, v0 held at a prior of 15 px
    sigma = 0.5
    covariance = system.covariance(free, sigma, prior)
    index = [0, 5, 6, 7, 8, 9]
    expected = sigma**2 * np.linalg.inv(matrix[np.ix_(index, index)] + np.diag([0, 1, 1, 0, 0, 0]) * sigma**2 / 225.0)
    rounding = 1e-12 * float(np.max(np.abs(expected)))  # the inverse's rounding (condition number ~1e3 here)
    assert np.allclose(covariance[np.ix_(index, index)], expected, rtol=1e-9, atol=rounding)
    assert np.isclose(np.sqrt(covariance[6, 6]), 15.0, rtol=1e-12)  # only the prior knows v0
    assert np.all(covariance[np.ix_([1, 2, 3], [1, 2, 3])] == 0.0)  # neither free nor at a prior


def test_the_inverse_is_the_pseudo_inverse_whether_taken_directly_or_by_eigenvalues() -> None:
    """A well-conditioned matrix is inverted directly; a singular one (a direction the data leave undetermined) or
    an ill-conditioned one takes the pseudo-inverse: that direction gets no variance."""
    for seed in range(6):
        s, d = _badly_scaled(seed)
        scaled = s / d[:, None] / d[None, :]
        by_eigenvalues = np.linalg.pinv(scaled, hermitian=True) / d[:, None] / d[None, :]
        assert np.allclose(scaled_inverse(s), by_eigenvalues, rtol=1e-10, atol=0.0)
        for smallest in (0.0, 1e-14):  # singular, and beyond DIRECT_INVERSE_CONDITION
            values, vectors = np.linalg.eigh(scaled)
            values[0] = smallest * values[-1]
            near = d[:, None] * (vectors * values) @ vectors.T * d[None, :]
            unit = jacobi_scale(near)  # (its diagonal, as scaled_inverse scales it)
            expected = np.linalg.pinv(near * unit[:, None] * unit[None, :], hermitian=True) * unit[:, None] * unit
            assert np.array_equal(scaled_inverse(near), expected)


def _placement_blocks(seed: int, n: int, condition: float) -> np.ndarray:
    """(n, 5, 5) random symmetric positive definite blocks with the given condition number, scaled as a placement's
    V is (A in mm beside the direction's two angles, a wand of 600 mm: entries a few hundred thousand times apart)."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(n, 5, 5)))
    values = np.geomspace(1.0, condition, 5)[None, :] * rng.uniform(0.5, 2.0, (n, 5))
    units = np.array([1.0, 1.0, 1.0, 600.0, 600.0])
    return units[:, None] * ((q * values[:, None, :]) @ q.transpose(0, 2, 1)) * units[None, :]


def test_the_placements_inverse_and_its_factor_are_those_of_the_blocks() -> None:
    """V^-1 (by the Cholesky factor's forward substitution) agrees with numpy's inverse, and its factor L (returned
    as L^T) gives L L^T = V^-1, to the blocks' condition number times the rounding; also beside ill-conditioned
    blocks in one batch (routed apart, :func:`test_ill_conditioned_blocks_take_numpys_inverse`)."""
    for seed, condition in ((0, 1.0), (1, 10.0), (2, 1e2)):  # (times up to 600^2 for the units)
        v = _placement_blocks(seed, 200, condition)
        v[100:150] = _placement_blocks(seed + 10, 50, 1e8)  # beyond ILL_CONDITIONED
        v_inv, root_t = _inverse_and_root(v)
        assert root_t.flags.c_contiguous and np.array_equal(v_inv, v_inv.transpose(0, 2, 1))
        fine = np.r_[0:100, 150:200]
        expected = np.linalg.inv(v[fine])
        scale = np.max(np.abs(expected), axis=(1, 2))[:, None, None]
        tolerance = 1e3 * np.finfo(float).eps * np.linalg.cond(v[fine])[:, None, None] * scale
        assert np.all(tolerance <= 1e-4 * scale)  # (a test that tests)
        assert np.all(np.abs(v_inv[fine] - expected) <= tolerance)
        assert np.all(np.abs(root_t[fine].transpose(0, 2, 1) @ root_t[fine] - v_inv[fine]) <= tolerance)


def test_ill_conditioned_blocks_take_numpys_inverse() -> None:
    """Blocks whose condition number may exceed ILL_CONDITIONED are inverted as before the forward substitution
    (numpy's LU inverse, symmetrised): the same numbers; the others by the substitution."""
    ill, fine = _placement_blocks(3, 50, 1e8), _placement_blocks(4, 50, 10.0)  # (the units add up to 600^2)
    assert np.all(np.linalg.cond(ill) > ILL_CONDITIONED) and np.all(np.linalg.cond(fine) < ILL_CONDITIONED / 25)
    v_inv, _ = _inverse_and_root(np.concatenate([ill, fine]))
    expected = np.linalg.inv(ill)
    assert np.array_equal(v_inv[:50], 0.5 * (expected + expected.transpose(0, 2, 1)))
    assert not np.array_equal(v_inv[50:], np.linalg.inv(fine))  # (rounded otherwise: another route)
