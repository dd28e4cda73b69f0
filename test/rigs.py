"""Synthetic rigs with known truth (seeded) and the bundle adjustment started from the truth."""

from __future__ import annotations

from functools import cache

import numpy as np

from wand_calib_ros.core.bundle_adjustment import (
    BundleProblem,
    BundleResult,
    BundleState,
    bundle_adjust,
    default_free_mask,
)
from wand_calib_ros.core.result import CalibrationResult
from wand_calib_ros.sim.scenarios import SCENARIOS, Scenario, SimulatedData, simulate


@cache
def scenario_data(
    name: str, seed: int, noise: float = 1.0, heldout: int = 100, **kwargs: float | tuple[float, float]
) -> tuple[Scenario, SimulatedData, SimulatedData]:
    """A scenario, its observations and held-out placements (cached: treat as read-only)."""
    scenario = SCENARIOS[name](**kwargs)
    rng = np.random.default_rng(seed)
    data = simulate(scenario, noise, rng)
    held = simulate(scenario, noise, rng, n=heldout)
    return scenario, data, held


def truth_bundle(
    scenario: Scenario, data: SimulatedData, fixed: tuple[tuple[str, ...], ...] | None = None
) -> BundleResult:
    """Bundle adjustment of the same data started from the truth.

    Args:
        scenario: the rig with its true cameras.
        data: the observations and true placements.
        fixed: per camera radial coefficients held at zero (as the pipeline chose), or None for all free.
    """
    free = default_free_mask(len(scenario.cameras))
    models = []
    for c, camera in enumerate(scenario.cameras):
        vector = camera.model.intrinsic_vector()
        for name in fixed[c] if fixed else ():
            index = int(name[1]) - 1
            free[c, index] = False
            vector[index] = 0.0
        models.append(camera.model.with_intrinsic_vector(vector))
    state = BundleState(tuple(models), tuple(c.pose for c in scenario.cameras), data.wand_a, data.wand_direction)
    return bundle_adjust(state, BundleProblem.from_dense(scenario.wand, data.observations.uv), free)


def fixed_of(result: CalibrationResult, scenario: Scenario) -> tuple[tuple[str, ...], ...]:
    """The pipeline's fixed coefficients in the scenario's camera order."""
    return tuple(result.camera(c.spec.name).fixed_coefficients for c in scenario.cameras)
