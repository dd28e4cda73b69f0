"""Reported standard deviations cover the errors on a weak rig, and what the views fix weakly is said: a short
sparse take of four plumb_bob cameras with their intrinsics estimated (principal points known to 15-90 px,
focal lengths to 0.6-2.5 %, orientations to 0.3-3.5 deg, seed to seed)."""

from __future__ import annotations

import numpy as np
from rigs import rms, scenario_data, z_scores

from wand_calib_ros.core.errors import CoreError
from wand_calib_ros.core.pipeline import calibrate


def test_standard_deviations_cover_the_errors_of_a_weak_take() -> None:
    pooled: dict[str, list[float]] = {}
    calibrated = flagged = 0
    for seed in range(8):
        scenario, data, _ = scenario_data("sparse4", seed, 1.0, n_placements=200)
        try:
            result = calibrate(scenario.rig, data.observations)
        except CoreError as error:  # a take too weak is refused (one of eight) naming what is missing
            assert "wave longer" in str(error) or "give" in str(error), str(error)
            continue
        calibrated += 1
        weak = [w for w in result.warnings if "principal point is uncertain" in w]
        assert weak, "a principal point known to tens of pixels is flagged"
        for camera in result.cameras:  # a focal or orientation the views fix weakly is said, the others not
            std = camera.parameter_std
            focal = std["k1"] / camera.model.k[0] > 0.01
            turned = max(np.degrees(std.get(axis, 0.0)) for axis in ("rx", "ry", "rz")) > 1.0
            said = [w for w in result.warnings if w.startswith(f"{camera.name}: the views fix its")]
            assert bool(said) == (focal or turned)
            assert not said or (("focal length" in said[0]) == focal and ("orientation" in said[0]) == turned)
            flagged += bool(said)
        for kind, values in z_scores(result, scenario).items():
            pooled.setdefault(kind, []).extend(values)
    assert calibrated >= 6
    assert flagged >= 4  # the weakest seeds' cameras (focal to 2 %, orientation to 3 deg)
    for kind, values in pooled.items():
        assert 0.5 <= rms(values) <= 1.6, (kind, rms(values))
