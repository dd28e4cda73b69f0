"""Detection followed by calibration reaches the statistical limit of the detection noise."""

from __future__ import annotations

import numpy as np
from rigs import true_views

from wand_calib_ros.collection.recording import detect_recording
from wand_calib_ros.core.pipeline import calibrate
from wand_calib_ros.io.bags import ImageFrame
from wand_calib_ros.sim.render import RenderOptions, render_recording
from wand_calib_ros.sim.scenarios import paper_fisheye_scenario


def test_calibration_from_rendered_images_is_as_good_as_its_noise_allows() -> None:
    scenario = paper_fisheye_scenario()
    rng = np.random.default_rng(6)
    recording = render_recording(scenario, 300, 30.0, RenderOptions(), rng)
    frames = [ImageFrame(camera, stamp, image, "mono8") for camera, stamp, image in recording.frames]
    observations = detect_recording(frames, scenario.rig).observations
    result = calibrate(scenario.rig, observations)
    # Errors against the truth, in units of the calibration's own standard deviations: a biased
    # detector (or labels swapped) would show up as many-sigma errors.
    z = []
    for camera in scenario.cameras:
        mine = result.camera(camera.spec.name)
        std = mine.parameter_std
        z += [
            (mine.model.k[0] - camera.model.k[0]) / std["k1"],
            (mine.model.principal_point[0] - camera.model.principal_point[0]) / std["u0"],
            (mine.model.principal_point[1] - camera.model.principal_point[1]) / std["v0"],
        ]
    assert np.max(np.abs(z)) < 4.0
    assert np.sqrt(np.mean(np.square(z))) < 2.0
    assert result.sigma_px < 0.1  # the detector's centre noise
    # The true projections with Gaussian noise of the detector's level, on the same frames:
    # the detected data must determine the cameras within 1.2x as well.
    found = np.isfinite(observations.uv)
    truth = true_views(recording.drawn, observations)
    sigma = float(np.sqrt(np.mean((observations.uv - truth)[found] ** 2)))
    synthetic = np.where(found, truth + rng.normal(scale=sigma, size=found.shape), np.nan)
    reference = calibrate(scenario.rig, observations.with_uv(synthetic))
    for camera in scenario.cameras:
        mine, best = result.camera(camera.spec.name), reference.camera(camera.spec.name)
        for name in ("k1", "u0", "v0"):
            assert mine.parameter_std[name] <= 1.2 * best.parameter_std[name], (camera.spec.name, name)
