"""Labels settled across cameras: an ambiguous view is ordered so that the wand it makes with the
other cameras' views has the right lengths.

Given a calibration (e.g. from the unambiguous views alone), both orders of an
ambiguous view are triangulated together with the frame's labelled views of
the other cameras; the order whose reconstructed |AB| and |BC| match L1 and L2
clearly better wins.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import WandObservations, WandSpec

FloatArray = NDArray[np.float64]

#: The better order must have at most this fraction of the other's wand-length error ...
CONSISTENCY_MARGIN = 0.25
#: ... and reconstruct the wand within this fraction of its length.
CONSISTENCY_TOLERANCE = 0.03


def label_across_cameras(
    observations: WandObservations,
    ambiguous: list[tuple[int, str, FloatArray, float]],
    result: CalibrationResult,
    wand: WandSpec,
) -> tuple[WandObservations, list[str]]:
    """Add the ambiguous views that the other cameras settle.

    Args:
        observations: labelled views (frame ids as in ``ambiguous``).
        ambiguous: (frame id, camera, (3, 2) points in either order, the image's stamp in s).
        result: a calibration of the same cameras.
        wand: the wand lengths.

    Returns:
        The observations with the settled views added, and the camera of each settled view.
    """
    names = observations.camera_names
    models = tuple(result.camera(n).model for n in names)
    poses = tuple(result.camera(n).pose for n in names)
    row_of = {int(f): i for i, f in enumerate(observations.frames)}
    uv = observations.uv.copy()
    stamps = None if observations.stamps is None else observations.stamps.copy()
    settled: list[str] = []
    for frame, camera, points, stamp in ambiguous:
        row = row_of.get(frame)
        if row is None:
            continue
        c = names.index(camera)
        others = np.all(np.isfinite(uv[row]), axis=(1, 2))
        others[c] = False
        if not others.any():
            continue
        errors = []
        for order in (points, points[::-1]):
            trial = np.where(others[:, None, None], uv[row], np.nan)
            trial[c] = order
            wand_points = triangulate_placements(models, poses, trial[None])[0]
            ab = np.linalg.norm(wand_points[1] - wand_points[0])
            bc = np.linalg.norm(wand_points[2] - wand_points[1])
            errors.append(abs(ab - wand.L1) + abs(bc - wand.L2))
        if not np.all(np.isfinite(errors)):
            continue
        best = int(np.argmin(errors))
        if errors[best] <= CONSISTENCY_MARGIN * errors[1 - best] and errors[best] <= CONSISTENCY_TOLERANCE * wand.L:
            uv[row, c] = points if best == 0 else points[::-1]
            if stamps is not None:
                stamps[row, c] = stamp
            settled.append(camera)
    return WandObservations(observations.frames, names, uv, stamps), settled
