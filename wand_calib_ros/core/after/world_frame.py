"""A world frame from the wand laid on the floor: z up, the origin and x where the user put the wand.

The user lays the wand on the floor and holds it still, in at least two directions (e.g. along the
room's x, then along y). Triangulated with the calibrated cameras, those placements' points fit
the floor plane; its normal, turned towards the cameras, is z; the first placement's A (or its
centre) is the origin; its A->C projected onto the floor is x. Poses in the result stay relative
to the reference camera (X_cam = R X_ref + T); the world frame is one more transform:
X_world = R_w X_ref + T_w.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.errors import DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.geometry import Pose
from wand_calib_ros.core.model.result import WorldFrame

FloatArray = NDArray[np.float64]

#: Floor placements whose wand directions (on the floor) all lie within this angle of each other
#: (degrees) leave the floor's tilt about that direction undetermined.
MIN_DIRECTION_SPREAD_DEG = 20.0
#: Placements whose A lies within this distance (mm) of the first one's, pointing the same way, are
#: the same lay of the wand held still: the origin and x are their average.
LAY_RADIUS_MM = 50.0
#: The fewest still placements a floor needs.
MIN_FLOOR_PLACEMENTS = 2
#: Floor points further than this RMS (mm) from one plane were not on the floor (the wand was waved).
MAX_FLOOR_RESIDUAL_MM = 20.0
#: At least this fraction of the floor placements must repeat a lay (the wand held still).
MIN_STILL_FRACTION = 0.5


def fit_floor(points: FloatArray, camera_centres: FloatArray, *, origin: str = "A") -> WorldFrame:
    """The world frame of wand placements lying on the floor.

    Args:
        points: (P, K, 3) the floor placements' wand points (A first, C last) in the reference frame,
            mm (NaN rows: placements that could not be triangulated).
        camera_centres: (C, 3) the cameras' centres in the reference frame (z points towards them).
        origin: "A" (the first lay's A) or "centre" (the midpoint of its A and C), projected onto the floor; the
            first lay is the first placement and every still one like it, averaged.

    Raises:
        InsufficientDataError: fewer than MIN_FLOOR_PLACEMENTS placements.
        DegenerateDataError: the placements all point the same way, or the cameras lie in the floor.
    """
    usable = points[np.all(np.isfinite(points), axis=(1, 2))]
    if usable.shape[0] < MIN_FLOOR_PLACEMENTS:
        raise InsufficientDataError(
            f"the floor needs the wand laid still in at least {MIN_FLOOR_PLACEMENTS} placements seen by two "
            f"cameras; got {usable.shape[0]}"
        )
    _require_still(usable)
    flat = usable.reshape(-1, 3)
    centroid = flat.mean(axis=0)
    _, singular, vt = np.linalg.svd(flat - centroid, full_matrices=False)
    normal = vt[2]
    above = float(np.median((camera_centres - centroid) @ normal))
    if abs(above) < 1e-9:
        raise DegenerateDataError("the cameras lie in the fitted floor plane: no side of it is up")
    normal = normal if above > 0 else -normal
    directions = _on_plane(usable[:, -1] - usable[:, 0], normal)
    spread = float(np.degrees(np.max(np.arccos(np.clip(np.abs(directions @ directions.T), 0.0, 1.0)))))
    if spread < MIN_DIRECTION_SPREAD_DEG:
        raise DegenerateDataError(
            f"the wand lay on the floor in one direction only (within {spread:.0f} deg): lay it in a second "
            f"direction, at least {MIN_DIRECTION_SPREAD_DEG:.0f} deg from the first, so the floor's tilt is known"
        )
    # The first lay of the wand: every still placement of it (A within LAY_RADIUS_MM of the first
    # one's, pointing the same way), averaged.
    lay = (np.linalg.norm(usable[:, 0] - usable[0, 0], axis=1) < LAY_RADIUS_MM) & (directions @ directions[0] > 0.99)
    first = usable[lay].mean(axis=0)
    anchor = first[0] if origin == "A" else (first[0] + first[-1]) / 2.0  # A, or the midpoint of A and C
    anchor = anchor - ((anchor - centroid) @ normal) * normal  # onto the floor
    x = _on_plane((first[-1] - first[0])[None], normal)[0]
    rotation = np.stack([x, np.cross(normal, x), normal])  # rows: the world axes in the reference frame
    residual = float(np.sqrt(np.mean(((flat - centroid) @ normal) ** 2)))
    if residual > MAX_FLOOR_RESIDUAL_MM:
        raise DegenerateDataError(
            f"the floor frames' wand points lie {residual:.0f} mm RMS off one plane (at most "
            f"{MAX_FLOOR_RESIDUAL_MM:g}): the wand was not lying still on the floor in them; give the frames where "
            "it does"
        )
    in_plane = float(np.sqrt((singular[0] ** 2 + singular[1] ** 2) / 2.0))  # RMS spread x sqrt(n)
    return WorldFrame(
        Pose(rotation, -rotation @ anchor),
        residual,
        float(np.degrees(residual / max(in_plane, 1e-12))),
        residual * float(np.sqrt(1.0 / lay.sum() + 1.0 / flat.shape[0])),  # the anchor's noise, the plane's offset
        int(usable.shape[0]),
    )


def _require_still(points: FloatArray) -> None:
    """Refuse floor placements most of which repeat no other (within LAY_RADIUS_MM, the same direction):
    the wand moved from frame to frame, it was not laid still.

    Args:
        points: (P, K, 3) the floor placements' markers.
    """
    direction = points[:, -1] - points[:, 0]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    near = np.linalg.norm(points[:, None, 0] - points[None, :, 0], axis=-1) < LAY_RADIUS_MM
    alike = (direction @ direction.T) > 0.99
    repeated = ((near & alike).sum(axis=1) >= 2).sum()  # each counts itself
    if repeated < MIN_STILL_FRACTION * len(points):
        moved = np.linalg.norm(np.diff(points[:, 0], axis=0), axis=1)
        raise DegenerateDataError(
            f"the wand was not lying still in the floor frames: {repeated} of {len(points)} placements repeat "
            f"another within {LAY_RADIUS_MM:g} mm (from one frame to the next it moved by a median "
            f"{float(np.median(moved)):.0f} mm); give the frames where it lies still on the floor"
        )


def _on_plane(vectors: FloatArray, normal: FloatArray) -> FloatArray:
    """(N, 3) unit vectors of ``vectors`` projected onto the plane with unit ``normal``."""
    flat = vectors - (vectors @ normal)[:, None] * normal
    return flat / np.linalg.norm(flat, axis=1, keepdims=True)


def floor_of(
    models: tuple[CameraModel, ...], poses: tuple[Pose, ...], uv: FloatArray, *, origin: str = "A"
) -> WorldFrame:
    """:func:`fit_floor` of (F, C, 3, 2) views of the wand on the floor, triangulated with calibrated cameras
    (``poses`` relative to the reference camera)."""
    points = triangulate_placements(models, poses, uv)
    return fit_floor(points, np.array([pose.center for pose in poses]), origin=origin)
