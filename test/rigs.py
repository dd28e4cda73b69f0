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
from wand_calib_ros.core.camera_model import CameraModel
from wand_calib_ros.core.geometry import Pose
from wand_calib_ros.core.metrics import camera_errors, heldout_wand_rms, rereference
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


def in_truth_frame(result: CalibrationResult, scenario: Scenario) -> tuple[list[CameraModel], list[Pose]]:
    """The result's cameras in scenario order, poses re-expressed in camera 0's frame like the truth."""
    names = [c.spec.name for c in scenario.cameras]
    poses = rereference({n: result.camera(n).pose for n in names}, names[0])
    return [result.camera(n).model for n in names], [poses[n] for n in names]


def errors_against_truth(
    scenario: Scenario,
    held: SimulatedData,
    models: list[CameraModel] | tuple[CameraModel, ...],
    poses: list[Pose] | tuple[Pose, ...],
) -> dict[str, float]:
    """Per camera focal and principal-point errors (px), E_r and E_t, and the held-out D_RMS (mm)."""
    out: dict[str, float] = {}
    for c, camera in enumerate(scenario.cameras):
        e = camera_errors(models[c], poses[c], camera.model, camera.pose)
        out[f"{camera.spec.name} focal"] = e.focal_px
        out[f"{camera.spec.name} principal point"] = e.principal_point_px
        if c > 0:
            out[f"{camera.spec.name} E_r"] = e.rotation_deg
            out[f"{camera.spec.name} E_t"] = e.translation
    out["D_RMS"] = heldout_wand_rms(tuple(models), tuple(poses), held.observations.uv, scenario.wand)
    return out
