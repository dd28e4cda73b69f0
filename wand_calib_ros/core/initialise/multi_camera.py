"""Step 1 of Section III-B: initial intrinsics and poses of every camera from chained pairs.

Only the pairs on the shortest paths of the vision graph are calibrated (Steps
1-3 of the two-camera method). Poses are chained along each path with
R_ik = R_jk R_ij, T_ik = R_jk T_ij + T_jk (paper eq. transfer). A camera's
intrinsics come from the calibrated pair in which it shares the most
placements; a camera already calibrated in an earlier pair starts its later
pairs from those intrinsics instead of re-trying every lens projection, and a
camera with the same data sheet as a calibrated one starts from that one's lens
(:func:`_twin_start`); a pair whose cameras both have a start skips Step 3
(:func:`~wand_calib_ros.core.initialise.pairwise.initialise_pair`).

A pair that moves such a camera's focal length by more than JUMP of its start has
gone astray (narrow lenses far from the wand leave focal length and distance
nearly interchangeable): it is calibrated again from every lens start, and a
camera's start is only ever replaced by a pair's estimate that agrees with it.
Without this, one pair gone astray at the reference camera corrupted every
later pair started from it (a 64-camera stage at 12,500 placements).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import DegenerateDataError
from wand_calib_ros.core.initialise.pairwise import PairOptions, Start, initialise_pair
from wand_calib_ros.core.initialise.vision_graph import VisionGraph
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.result import LensTrial
from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.core.model.views import whole_views

FloatArray = NDArray[np.float64]
log = logging.getLogger(__name__)

#: A pair's focal length for a camera that had a start, relative to that start's: beyond this change
#: the pair is redone from every lens start, and it never replaces the start.
JUMP = 0.1


def _jump(model: CameraModel, start: tuple[str, CameraModel] | None) -> float:
    """Relative change of the focal length from a camera's start (0 without one)."""
    return 0.0 if start is None else abs(float(model.k[0] / start[1].k[0]) - 1.0)


@dataclass(frozen=True, eq=False)
class RigInitialisation:
    """Initial values for the global bundle adjustment.

    Attributes:
        models: per camera intrinsics (rig order).
        poses: per camera pose in the reference camera's frame.
        projections: per camera, the Step 1 projection its start came from.
        trials: the lens starts tried on every calibrated pair.
    """

    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]
    projections: tuple[str, ...]
    trials: tuple[LensTrial, ...]


def _twin_start(rig: RigSpec, camera: int, starts: list[Start | None]) -> Start | None:
    """The start of a camera with the same data sheet (image size, pixel size, nominal focal length, field
    of view, lens hint) as ``camera`` that is calibrated already, if any: its projection and lens curve
    (the same kind of lens, made alike), the principal point at the image centre.

    Not the other camera's principal point: that is its own lens's mounting. (Started from it, a short sparse
    take of four cameras, sparse4 at 200 frames, settled with principal points 120-190 px off where its data do
    not determine them, and was no longer refused for it.)
    """
    spec = rig.cameras[camera]
    for other, start in zip(rig.cameras, starts, strict=True):
        if start is not None and replace(other, name=spec.name) == spec:
            projection, model = start
            return projection, replace(model, principal_point=spec.image_center)
    return None


def initialise_rig(
    rig: RigSpec, uv: FloatArray, graph: VisionGraph, options: PairOptions = PairOptions()
) -> RigInitialisation:
    """Calibrate the vision graph's tree edges pairwise and chain them from the reference.

    Args:
        rig: the rig description (cameras in the order of ``uv``'s axis 1).
        uv: (P, C, 3, 2) pixels, NaN where not seen.
        graph: the vision graph with the pairs to calibrate.
        options: settings of the pairwise calibrations.
    """
    complete = whole_views(uv)
    n_cameras = len(rig.cameras)
    poses: list[Pose | None] = [None] * n_cameras
    poses[graph.reference] = Pose.identity()
    starts: list[tuple[str, CameraModel] | None] = [None] * n_cameras
    support = np.zeros(n_cameras, dtype=np.int64)  # placements behind each camera's current intrinsics
    trials: list[LensTrial] = []
    for parent, child in graph.edges:
        both = complete[:, parent] & complete[:, child]
        log.info("pair %s-%s: %d common placements", rig.cameras[parent].name, rig.cameras[child].name, both.sum())
        known = (starts[parent], starts[child] or _twin_start(rig, child, starts))
        try:
            init = initialise_pair(
                (rig.cameras[parent], rig.cameras[child]), uv[both, parent], uv[both, child], rig.wand, options,
                known=known,
            )  # fmt: skip
            jump = max(_jump(model, start) for model, start in zip(init.models, known, strict=True))
            if jump > JUMP:
                raise DegenerateDataError(f"it moved a started camera's focal length by {100 * jump:.0f} %")
        except DegenerateDataError as error:  # the starts carried over from earlier pairs do not fit this one
            log.info("pair %s-%s from the earlier starts failed (%s): every lens start instead",
                     rig.cameras[parent].name, rig.cameras[child].name, error)  # fmt: skip
            init = initialise_pair(
                (rig.cameras[parent], rig.cameras[child]), uv[both, parent], uv[both, child], rig.wand, options
            )
        trials.extend(init.trials)
        parent_pose = poses[parent]
        assert parent_pose is not None  # edges are ordered parents first
        poses[child] = init.pose.compose(parent_pose)
        for camera, model, projection in zip((parent, child), init.models, init.projections, strict=True):
            if int(both.sum()) > support[camera] and _jump(model, starts[camera]) <= JUMP:
                starts[camera] = (projection, model)
                support[camera] = int(both.sum())
    models = tuple(s[1] for s in starts if s is not None)
    projections = tuple(s[0] for s in starts if s is not None)
    assert len(models) == n_cameras and all(p is not None for p in poses)
    return RigInitialisation(models, tuple(p for p in poses if p is not None), projections, tuple(trials))
