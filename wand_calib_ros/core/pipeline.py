"""The calibration entry point: rig description + observations -> CalibrationResult."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from wand_calib_ros.core.errors import InsufficientDataError
from wand_calib_ros.core.geometry import Pose
from wand_calib_ros.core.pairwise import PairOptions, initialise_pair
from wand_calib_ros.core.refine import refine_calibration
from wand_calib_ros.core.result import CalibrationResult
from wand_calib_ros.core.rig import RigSpec, WandObservations

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CalibrationOptions:
    """User-facing settings of :func:`calibrate`.

    Attributes:
        reference_camera: name of the camera whose frame is the reference (default: the first).
        pair: settings of the pairwise initialisation (Steps 1-3).
    """

    reference_camera: str | None = None
    pair: PairOptions = field(default_factory=PairOptions)


def calibrate(
    rig: RigSpec, observations: WandObservations, options: CalibrationOptions = CalibrationOptions()
) -> CalibrationResult:
    """Calibrate intrinsics and extrinsics of the rig's cameras from wand observations.

    Args:
        rig: wand and camera descriptions.
        observations: image points; cameras are matched by name.
        options: settings.

    Raises:
        WandCalibError subclasses with a message naming the problem.
    """
    names = rig.camera_names
    for name in names:
        if name not in observations.camera_names:
            raise InsufficientDataError(f"camera '{name}' has no observations")
    obs = observations.select_cameras(names)
    if len(names) != 2:
        raise InsufficientDataError(
            f"this version calibrates exactly two cameras; the rig has {len(names)} ({', '.join(names)})"
        )
    reference = names.index(options.reference_camera) if options.reference_camera else 0
    if options.reference_camera and options.reference_camera not in names:
        raise InsufficientDataError(f"reference camera '{options.reference_camera}' is not in the rig")
    other = 1 - reference
    complete = obs.complete
    both = complete[:, reference] & complete[:, other]
    uv = obs.uv[both]
    log.info("%d placements seen completely by %s and %s", both.sum(), names[reference], names[other])
    init = initialise_pair(
        (rig.cameras[reference], rig.cameras[other]), uv[:, reference], uv[:, other], rig.wand, options.pair
    )
    models = [None, None]
    models[reference], models[other] = init.fit.models
    poses = [Pose.identity(), Pose.identity()]
    poses[other] = init.fit.pose
    projections = ["", ""]
    projections[reference], projections[other] = init.projections
    # Placements seen completely by one camera only constrain nothing and are left out.
    usable = complete.sum(axis=1) >= 2
    return refine_calibration(
        rig,
        np.where(complete[usable][..., None, None], obs.uv[usable], np.nan),
        (models[0], models[1]),
        (poses[0], poses[1]),
        reference=reference,
        initial_projections=(projections[0], projections[1]),
        lens_trials=init.trials,
    )
