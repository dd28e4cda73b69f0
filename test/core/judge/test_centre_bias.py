"""Centres of saturated LEDs biased on purpose are named with what they pull, and keep the grade from excellent;
unbiased ones are not named, whatever their share."""

from __future__ import annotations

import numpy as np
import pytest

from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import WandObservations
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.sim.scenarios import SCENARIOS, SimulatedData, simulate

SEEDS = range(4)
#: The detector's centre noise on these spots, px per coordinate.
NOISE_PX = 0.1
#: Saturated centres drawn this far outward from each camera's principal point, px (the issue's bias).
BIAS_PX = 0.5


def _saturated(data: SimulatedData, fraction: float) -> np.ndarray:
    """(F, C, K) the points nearest their camera, ``fraction`` of each camera's (the near LEDs saturate)."""
    scenario = SCENARIOS["small_room"]()
    offsets = scenario.wand.offsets
    points = data.wand_a[:, None, :] + offsets[None, :, None] * data.wand_direction[:, None, :]  # (F, K, 3)
    flags = np.zeros(data.observations.uv.shape[:3], dtype=bool)
    for c, camera in enumerate(scenario.cameras):
        distance = np.linalg.norm(camera.pose.apply(points.reshape(-1, 3)), axis=1).reshape(points.shape[:2])
        seen = np.isfinite(data.observations.uv[:, c, :, 0])
        limit = np.quantile(distance[seen], fraction)
        flags[:, c] = seen & (distance <= limit)
    return flags


def _outward(observations: WandObservations, flags: np.ndarray, shift_px: float) -> WandObservations:
    """The observations with the flagged points moved ``shift_px`` away from their true principal point."""
    scenario = SCENARIOS["small_room"]()
    centres = np.array([c.model.principal_point for c in scenario.cameras])
    away = observations.uv - centres[None, :, None, :]
    away /= np.linalg.norm(away, axis=-1, keepdims=True)
    uv = np.where(flags[..., None], observations.uv + shift_px * away, observations.uv)
    return WandObservations(observations.frames, observations.camera_names, uv, observations.stamps, flags)


def _calibrated(seed: int, fraction: float, shift_px: float) -> CalibrationResult:
    """The small room's take calibrated with ``fraction`` of each camera's points flagged saturated (the nearest)
    and moved ``shift_px`` outward."""
    scenario = SCENARIOS["small_room"]()
    data = simulate(scenario, NOISE_PX, np.random.default_rng(seed))
    flags = _saturated(data, fraction)
    return calibrate(scenario.rig, _outward(data.observations, flags, shift_px))


@pytest.mark.parametrize("fraction", [0.5, 0.9])
def test_saturated_centres_biased_outward_are_named_and_the_result_is_not_excellent(fraction: float) -> None:
    for seed in SEEDS:
        result = _calibrated(seed, fraction, BIAS_PX)
        assert result.systematic, seed
        assert result.quality is not None and result.quality.grade != "excellent"
        named = " ".join(result.systematic)
        assert "centres of saturated LEDs sit" in named and "focal length" in named and "dim the LEDs" in named
        assert all(line in result.warnings for line in result.systematic)


@pytest.mark.parametrize("fraction", [0.5, 0.9])
def test_unbiased_saturated_centres_are_not_named(fraction: float) -> None:
    for seed in SEEDS:
        result = _calibrated(seed, fraction, 0.0)
        assert result.systematic == (), (seed, result.systematic)
