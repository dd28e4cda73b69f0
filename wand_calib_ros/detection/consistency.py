"""Labels settled across cameras: the wand each camera sees must be the wand the others see.

Given a calibration of the detections themselves (its robust adjustment sets wrong views
aside), each view's order is tested by triangulating the frame with the other cameras'
views: the order whose reconstructed |AB| and |BC| match L1 and L2 clearly better wins.

- An ambiguous view (neither its image nor its track settled A and C) takes the order
  that wins (:func:`label_across_cameras`).
- A track (a camera's views labelled together, :mod:`~wand_calib_ros.detection.tracking`)
  is right or exchanged stretch by stretch, between the places where continuity paired its
  ends wrongly (the wand spun about its middle): the stretches the other cameras find
  exchanged are exchanged (:func:`flip_contradicted_tracks`); a vote of image ratios misleads
  a whole track when the wand points at the camera throughout it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.model.brightness import saturated_of
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import RigSpec, WandObservations, WandSpec
from wand_calib_ros.detection.recording import Detections, Unsettled
from wand_calib_ros.errors import WandCalibError

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

#: The better order must have at most this fraction of the other's wand-length error ...
CONSISTENCY_MARGIN = 0.25
#: ... and reconstruct the wand within this fraction of its length.
CONSISTENCY_TOLERANCE = 0.03
#: A track's labels change between as labelled and exchanged at this cost (in views the other cameras
#: contradict): a stretch in the middle of a track is exchanged when more than twice this many of its views say so.
SWITCH_COST = 1.5


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


#: Up to this many cameras, every combination of orders of a frame's views is tried (else one view at a time).
JOINT_CAMERAS = 5


def _order_evidence(result: CalibrationResult, uv: FloatArray, wand: WandSpec) -> NDArray[np.int64]:
    """(F, C) what the frame says of each complete view's order: +1 as labelled, -1 exchanged, 0 it does not tell.

    The frame's views are tried in every combination of orders (one view at a time for a rig of more than
    JOINT_CAMERAS cameras): the combination that makes the wand of the right lengths (|AB| = L1, |BC| = L2) wins,
    and a view's order is told when the best combination with that view the other way round is CONSISTENCY_MARGIN
    times worse. (Exchanging every view makes a consistent wand of the wrong lengths: L1 and L2 differ.)
    """
    n_frames, n_cameras = uv.shape[:2]
    complete = np.all(np.isfinite(uv), axis=(2, 3))
    if n_cameras <= JOINT_CAMERAS:
        patterns = np.array([[(m >> c) & 1 for c in range(n_cameras)] for m in range(2**n_cameras)], dtype=bool)
    else:
        patterns = np.vstack([np.zeros((1, n_cameras), dtype=bool), np.eye(n_cameras, dtype=bool)])
    errors = np.full((patterns.shape[0], n_frames), np.inf)
    for k, pattern in enumerate(patterns):
        trial = np.where(pattern[None, :, None, None], uv[:, :, ::-1], uv)
        with np.errstate(invalid="ignore"):
            errors[k] = np.nan_to_num(wand_length_errors(result, trial, wand), nan=np.inf)
    # a pattern that exchanges a camera without a view repeats another pattern: leave it out
    valid = ~np.any(patterns[:, None, :] & ~complete[None], axis=2)  # (K, F)
    errors = np.where(valid, errors, np.inf)
    evidence = np.zeros((n_frames, n_cameras), dtype=np.int64)
    for c in range(n_cameras):
        straight = errors[~patterns[:, c]].min(axis=0)
        swapped = errors[patterns[:, c]].min(axis=0)
        with np.errstate(invalid="ignore"):
            evidence[:, c] = (straight <= CONSISTENCY_MARGIN * swapped).astype(np.int64)
            evidence[:, c] -= swapped <= CONSISTENCY_MARGIN * straight
        evidence[~complete[:, c] | (complete.sum(axis=1) < 2), c] = 0
    return evidence


def exchanged_stretches(evidence: NDArray[np.int64], switch_cost: float = SWITCH_COST) -> NDArray[np.bool_]:
    """(N,) which of a track's views (in time order) are exchanged: the labelling, as labelled or exchanged
    view by view, that disagrees least with the evidence (+1: the other cameras find the view right, -1:
    exchanged, 0: they do not tell) at SWITCH_COST per change between the two along the track (Viterbi).

    A track's labels can only go wrong where continuity paired its ends wrongly: from there on, they are
    exchanged until the next such place. A stretch is exchanged when enough of its views say so to pay for
    its two ends.
    """
    n = evidence.size
    cost = np.zeros(2)  # best cost so far ending labelled as is (0) or exchanged (1)
    came = np.zeros((n, 2), dtype=np.int64)
    for i, e in enumerate(evidence):
        stay, switch = cost, cost[::-1] + switch_cost
        came[i] = np.where(stay <= switch, [0, 1], [1, 0])
        cost = np.minimum(stay, switch) + np.array([float(e < 0), float(e > 0)])
    state = int(np.argmin(cost))
    exchanged = np.zeros(n, dtype=bool)
    for i in range(n - 1, -1, -1):
        exchanged[i] = state == 1
        state = int(came[i, state])
    return exchanged


def flip_contradicted_tracks(
    observations: WandObservations, tracks: NDArray[np.int64], result: CalibrationResult, wand: WandSpec
) -> tuple[WandObservations, list[tuple[str, int, int]]]:
    """Exchange A and C in the stretches of tracks the other cameras contradict (see the module docstring and
    :func:`exchanged_stretches`).

    Args:
        observations: labelled views of a three-marker wand.
        tracks: (F, C) each view's track in its camera (-1: none).
        result: a calibration of the same cameras.
        wand: the wand's lengths.

    Returns:
        The observations with those stretches exchanged, and (camera, track, views exchanged) of each track.
    """
    names = observations.camera_names
    order = [names.index(c.name) for c in result.cameras]
    uv = observations.uv[:, order].copy()
    own = tracks[:, order]
    flipped: list[tuple[str, int, int]] = []
    for _ in range(2):  # a second round sees the first's corrections
        evidence = _order_evidence(result, uv, wand)
        for c in range(uv.shape[1]):
            for track in np.unique(own[evidence[:, c] < 0, c]):
                rows = np.flatnonzero(own[:, c] == track)
                exchanged = rows[exchanged_stretches(evidence[rows, c])]
                if track < 0 or exchanged.size == 0:
                    continue
                uv[exchanged, c] = uv[exchanged, c, ::-1]
                evidence[exchanged, c] *= -1
                flipped.append((result.cameras[c].name, int(track), int(exchanged.size)))
    back = np.empty_like(uv)
    back[:, order] = uv
    return observations.with_uv(back), flipped


def label_across_cameras(
    observations: WandObservations,
    ambiguous: list[Unsettled],
    result: CalibrationResult,
    wand: WandSpec,
) -> tuple[WandObservations, list[str]]:
    """Add the ambiguous views that the other cameras settle.

    Args:
        observations: labelled views (frame ids as in ``ambiguous``).
        ambiguous: the views whose labels their camera could not settle (frame ids as in ``observations``).
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
    brightness = None if observations.brightness is None else observations.brightness.copy()
    settled: list[str] = []
    for frame, camera, points, stamp, stops in ambiguous:
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
            if brightness is not None and stops is not None:
                brightness[row, c] = stops if best == 0 else stops[::-1]
            settled.append(camera)
    return WandObservations(observations.frames, names, uv, stamps, saturated_of(brightness), brightness), settled


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
    from wand_calib_ros.core.pipeline import CalibrationOptions, calibrate

    observations, settled = detections.observations, Settled()
    if len(rig.cameras) < 2 or rig.wand.n_points != 3:
        return observations, settled
    try:
        result = calibrate(rig, observations, CalibrationOptions(clocks=detections.clocks))
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
