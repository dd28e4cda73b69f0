"""The distortion model's order: decided on a coarse subset, then again on all placements."""

from __future__ import annotations

import numpy as np
from rigs import scenario_data

from wand_calib_ros.core.bundle_adjustment import BundleProblem, BundleResult, BundleState, bundle_adjust
from wand_calib_ros.core.model_order import (
    FixedParameters,
    OrderOnAllPlacements,
    free_mask,
    reduce_radial,
    zero_fixed,
)
from wand_calib_ros.core.rig import RigSpec

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
