"""One round of the running estimate (:mod:`wand_calib_ros.collection.estimate`), as the worker process
(:mod:`wand_calib_ros.collection.estimate_worker`) computes it: calibrate the buffer, draw the scene."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from wand_calib_ros.core.after.rig_scene import RigScene, rig_scene
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate
from wand_calib_ros.errors import WandCalibError


@dataclass(frozen=True, eq=False)
class Round:
    """What the worker sends back for one round.

    Attributes:
        result: the calibration (None: it failed, see ``failure``).
        scene: its cameras and placements for RViz (None with ``result``).
        failure: why there is no result, in the pipeline's words.
        frames: frames of the buffer the round saw.
        seconds: its computing time, s.
    """

    result: CalibrationResult | None
    scene: RigScene | None
    failure: str | None
    frames: int
    seconds: float


def calibrate_round(rig: RigSpec, observations: WandObservations, options: CalibrationOptions, frames: int) -> Round:
    """One round (in the worker process): calibrate, judge, draw; a failure becomes its message."""
    started = time.perf_counter()
    try:
        result = calibrate(rig, observations, options)
    except (WandCalibError, ValueError, np.linalg.LinAlgError) as error:
        return Round(None, None, str(error), frames, time.perf_counter() - started)
    scene = rig_scene(result, rig.camera_names, observations.uv)
    return Round(result, scene, None, frames, time.perf_counter() - started)
