"""Step 1-3 lens trials of a camera pair."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from rigs import scenario_data

from wand_calib_ros.core.initialise import pairwise
from wand_calib_ros.core.model.camera_model import monotonic_limit
from wand_calib_ros.core.pipeline import calibrate


def test_a_start_whose_curve_turns_over_at_the_centre_does_not_win(monkeypatch: pytest.MonkeyPatch) -> None:
    scenario, data, _ = scenario_data("paper", 0)
    fit_lengths = pairwise.optimise_wand_lengths

    first_start: list[np.ndarray] = []

    def folding_equidistant(models, *args, **kwargs):  # type: ignore[no-untyped-def]
        fit = fit_lengths(models, *args, **kwargs)
        first_start[:] = first_start or [models[0].k.copy()]
        if not np.array_equal(models[0].k, first_start[0]):  # only cam0's first start folds
            return fit
        first = fit.models[0]
        folded = first.with_intrinsic_vector(np.r_[first.k[0], -1e5, 0.0, 0.0, 0.0, first.principal_point])
        assert monotonic_limit(folded.k) < pairwise.FOLDED_RAD
        return replace(fit, models=(folded, fit.models[1]), length_errors=fit.length_errors * 0.01)  # "better"

    monkeypatch.setattr(pairwise, "optimise_wand_lengths", folding_equidistant)
    result = calibrate(scenario.rig, data.observations)
    failed = [t for t in result.lens_trials if t.failure and "turns over at the image centre" in t.failure]
    assert failed, result.lens_trials
    assert monotonic_limit(result.camera("cam0").model.k) > np.radians(60)
