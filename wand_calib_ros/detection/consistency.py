"""Labels settled across cameras: the wand each camera sees must be the wand the others see.

Given a calibration of the detections themselves (its robust adjustment sets wrong views
aside), each view's order is tested by triangulating the frame with the other cameras'
views: the order whose reconstructed |AB| and |BC| match L1 and L2 clearly better wins.

- An ambiguous view (neither its image nor its track settled A and C) takes the order
  that wins (:func:`label_across_cameras`).
- A track (a camera's views labelled together, :mod:`~wand_calib_ros.detection.tracking`)
  whose views the other cameras find exchanged, in most of the frames that decide, is
  exchanged as a whole (:func:`flip_contradicted_tracks`): a vote of image ratios misleads
  a whole track when the wand points at the camera throughout it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec, WandObservations, WandSpec
from wand_calib_ros.detection.recording import Detections
from wand_calib_ros.errors import WandCalibError

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

#: The better order must have at most this fraction of the other's wand-length error ...
CONSISTENCY_MARGIN = 0.25
#: ... and reconstruct the wand within this fraction of its length.
CONSISTENCY_TOLERANCE = 0.03
#: A track is exchanged when at least this many of its views ...
FLIP_MIN_VIEWS = 3
#: ... and this fraction of those the other cameras decide are found exchanged.
FLIP_FRACTION = 0.75


def wand_length_errors(result: CalibrationResult, uv: FloatArray, wand: WandSpec) -> FloatArray:
    """(F,) |AB| - L1| + ||BC| - L2| (mm) of each frame triangulated from its complete views (NaN: fewer than two).

    Args:
        result: a calibration of the cameras of ``uv``'s axis 1, in that order.
        uv: (F, C, 3, 2) the views.
        wand: the wand's lengths.
    """
    names = [c.name for c in result.cameras]
    models = tuple(c.model for c in result.cameras)
    poses = tuple(c.pose for c in result.cameras)
    if len(names) != uv.shape[1]:
        raise ValueError(f"{len(names)} calibrated cameras for {uv.shape[1]} in the views")
    complete = np.all(np.isfinite(uv), axis=(2, 3))
    points = triangulate_placements(models, poses, np.where(complete[..., None, None], uv, np.nan))
    ab = np.linalg.norm(points[:, 1] - points[:, 0], axis=-1)
    bc = np.linalg.norm(points[:, 2] - points[:, 1], axis=-1)
    return np.where(complete.sum(axis=1) >= 2, np.abs(ab - wand.L1) + np.abs(bc - wand.L2), np.nan)


def flip_contradicted_tracks(
    observations: WandObservations, tracks: NDArray[np.int64], result: CalibrationResult, wand: WandSpec
) -> tuple[WandObservations, list[tuple[str, int, int]]]:
    """Exchange A and C in the tracks the other cameras contradict (see the module docstring).

    Args:
        observations: labelled views of a three-marker wand.
        tracks: (F, C) each view's track in its camera (-1: none).
        result: a calibration of the same cameras.
        wand: the wand's lengths.

    Returns:
        The observations with those tracks exchanged, and (camera, track, views) of each one exchanged.
    """
    names = observations.camera_names
    order = [names.index(c.name) for c in result.cameras]
    uv = observations.uv[:, order].copy()
    own = tracks[:, order]
    flipped: list[tuple[str, int, int]] = []
    for _ in range(2):  # a second round sees the first's corrections
        base = wand_length_errors(result, uv, wand)
        complete = np.all(np.isfinite(uv), axis=(2, 3))
        for c in range(uv.shape[1]):
            trial = uv.copy()
            trial[:, c] = uv[:, c, ::-1]
            other = wand_length_errors(result, trial, wand)
            with np.errstate(invalid="ignore"):
                keep = complete[:, c] & (base <= CONSISTENCY_MARGIN * other)
                swap = complete[:, c] & (other <= CONSISTENCY_MARGIN * base)
            for track in np.unique(own[swap, c]):
                rows = own[:, c] == track
                n_swap, n_keep = int(swap[rows].sum()), int(keep[rows].sum())
                if track < 0 or n_swap < FLIP_MIN_VIEWS or n_swap < FLIP_FRACTION * (n_swap + n_keep):
                    continue
                uv[rows, c] = uv[rows, c, ::-1]
                base = wand_length_errors(result, uv, wand)
                flipped.append((result.cameras[c].name, int(track), int(rows.sum())))
    back = np.empty_like(uv)
    back[:, order] = uv
    return observations.with_uv(back), flipped


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


@dataclass
class Settled:
    """What the other cameras decided.

    Attributes:
        views: per camera the ambiguous views they ordered.
        tracks: (camera, track, views) of each track they exchanged.
        calibrated: whether a calibration of the detections was there to decide with.
    """

    views: dict[str, int] = field(default_factory=dict)
    tracks: list[tuple[str, int, int]] = field(default_factory=list)
    calibrated: bool = False


def settle_labels(rig: RigSpec, detections: Detections) -> tuple[WandObservations, Settled]:
    """The detections' labels checked against the other cameras: a calibration of the detections, then the
    tracks it contradicts exchanged and the ambiguous views it orders added (a rig of two or more cameras and
    a three-marker wand; else the observations as they are). ``detections.stats`` is updated."""
    from wand_calib_ros.core.pipeline import calibrate

    observations, settled = detections.observations, Settled()
    if len(rig.cameras) < 2 or rig.wand.n_points != 3:
        return observations, settled
    try:
        result = calibrate(rig, observations)
    except WandCalibError as error:
        log.info("no calibration of the detections to check their labels across cameras: %s", error)
        return observations, settled
    settled.calibrated = True
    observations, settled.tracks = flip_contradicted_tracks(observations, detections.tracks, result, rig.wand)
    for camera, track, views in settled.tracks:
        log.info(
            "%s: the other cameras see track %d (%d views) with A and C exchanged: exchanged", camera, track, views
        )
    if detections.ambiguous:
        observations, cameras = label_across_cameras(observations, detections.ambiguous, result, rig.wand)
        for camera in cameras:
            detections.stats[camera].rejected["ambiguous"] -= 1
            detections.stats[camera].detected += 1
            settled.views[camera] = settled.views.get(camera, 0) + 1
        log.info("%d of %d ambiguous views settled by the other cameras", len(cameras), len(detections.ambiguous))
    return observations, settled
