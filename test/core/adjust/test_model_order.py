"""The distortion model's order: decided on a coarse subset, then again on all placements."""

from __future__ import annotations

import numpy as np
from rigs import scenario_data

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult, bundle_adjust
from wand_calib_ros.core.adjust.bundle_problem import BundleProblem, BundleState
from wand_calib_ros.core.adjust.model_order import (
    FixedParameters,
    OrderOnAllPlacements,
    free_mask,
    reduce_radial,
    zero_fixed,
)
from wand_calib_ros.core.model.rig import RigSpec

PLACEMENTS = 1200  # 16 narrow-angle cameras: k3 2-5 sigma once k4, k5 are dropped (camera 2: 5.1), k4, k5 about 1


def _adjusted(per_camera: tuple[tuple[int, ...], ...]) -> tuple[RigSpec, BundleProblem, FixedParameters, BundleResult]:
    """mocap16's simulated data adjusted from the truth with the radial terms ``per_camera`` held at zero."""
    scenario, data, _ = scenario_data("mocap16", 3, n_placements=PLACEMENTS)
    n_cameras = len(scenario.cameras)
    problem = BundleProblem.from_dense(scenario.wand, data.observations.uv)
    fixed = FixedParameters(per_camera, np.zeros((n_cameras, 2), bool), np.zeros(n_cameras, bool))
    models = zero_fixed(tuple(c.model for c in scenario.cameras), fixed)
    state = BundleState(models, tuple(c.pose for c in scenario.cameras), data.wand_a, data.wand_direction)
    return scenario.rig, problem, fixed, bundle_adjust(state, problem, free_mask(n_cameras, 0, fixed))


def _orders(per_camera: tuple[tuple[int, ...], ...]) -> list[tuple[int, ...]]:
    return [tuple(sorted(order)) for order in per_camera]


def test_the_decision_on_all_placements_is_the_sequential_test_of_the_full_adjustment() -> None:
    # From an adjustment with k4 and k5 held at zero, releasing k3..k5 on its normal equations decides as
    # the Wald tests on an adjustment with all of them free do, at 2 sqrt(P / coarse) sigma.
    rig, _, _, full = _adjusted(((),) * 16)
    _, _, fixed, low = _adjusted(((3, 4),) * 16)
    assert low.system is not None
    decisions = []
    for coarse in (PLACEMENTS, PLACEMENTS // 4, PLACEMENTS // 16):
        significance = 2.0 * np.sqrt(PLACEMENTS / coarse)
        expected = tuple(
            reduce_radial(spec, full.state.models[c], full.camera_block(c, slice(0, 7)), (), significance)[0]
            for c, spec in enumerate(rig.cameras)
        )
        order = OrderOnAllPlacements(rig, fixed, 0, coarse)
        choice = order(low.state, low.system, low.sigma)
        assert order.decision is not None and (choice is None) == (order.decision is fixed)
        assert _orders(order.decision.per_camera) == _orders(expected), coarse
        decisions.append(_orders(order.decision.per_camera))
    assert decisions[0] != decisions[2]  # not vacuous: k3 goes as the threshold rises


def test_a_term_dropped_by_the_coarse_draw_comes_back_in_the_final_adjustment() -> None:
    rig, problem, wrong, adjusted = _adjusted(((3, 4), (3, 4), (2, 3, 4)) + ((3, 4),) * 13)  # camera 2 lost k3
    order = OrderOnAllPlacements(rig, wrong, 0, PLACEMENTS)
    result = bundle_adjust(adjusted.state, problem, free_mask(len(rig.cameras), 0, wrong), choose=order)
    assert order.decision is not None and 2 not in order.decision.per_camera[2]
    assert result.camera_std[2, 2] > 0 and result.state.models[2].k[2] != 0.0  # k3 estimated
    assert result.iterations <= 2  # from the new order's linearised solution
    again = OrderOnAllPlacements(rig, order.decision, 0, PLACEMENTS)
    assert result.system is not None and again(result.state, result.system, result.sigma) is None  # it stands


def test_a_conditional_shift_that_leaves_the_camera_model_does_not_fail_the_tests() -> None:
    # k5 (0.5 sigma) is dropped and, correlated with k1 (0.9), shifts it by -2.25 k1: the tests of k4 and
    # k3 go on (judging the curve with k5 at zero) and the camera restarts from its terms zeroed. Before,
    # a ring6 take (free-running, seed 8) failed its calibration with "k1 and m must be positive".
    scenario, _, _ = scenario_data("paper", 0, n_placements=20)
    spec, model = scenario.rig.cameras[0], scenario.cameras[0].model
    vector = model.intrinsic_vector()
    vector[2:5] = (0.0, 0.0, 5.0)
    k1_std = 5.0 * vector[0]
    covariance = np.diag([k1_std**2, 1.0, 1e-6, 1e-6, 100.0, 1.0, 1.0])
    covariance[0, 4] = covariance[4, 0] = 0.9 * k1_std * 10.0
    fixed, reduced = reduce_radial(spec, model.with_intrinsic_vector(vector), covariance, ())
    assert sorted(fixed) == [2, 3, 4]  # k3, k4 (0 sigma) tested after k5, not failed
    assert reduced.k[0] == vector[0] and reduced.k[1] == vector[1] and np.all(reduced.k[2:] == 0.0)
