"""A world frame from the wand laid on the floor: z up, the origin and x where the user put the wand.

The user lays the wand on the floor and holds it still, in at least two directions (e.g. along the
room's x, then along y). Triangulated with the calibrated cameras, those placements' points fit
the floor plane; its normal, turned towards the cameras, is z; the first placement's A (or its
centre) is the origin; its A->C projected onto the floor is x. Poses in the result stay relative
to the reference camera (X_cam = R X_ref + T); the world frame is one more transform:
X_world = R_w X_ref + T_w.

The plane fit (:func:`fit_floor`, or :func:`fit_tool` for a floor tool's markers) checks the floor frames
and starts :func:`floor_of`, which adjusts the floor with the cameras
(:mod:`~wand_calib_ros.core.after.floor_adjustment`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.after.floor_adjustment import adjust_floor
from wand_calib_ros.core.after.floor_tool import label_tool_views, rigid_fit
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
    lay = lays_of(usable) == 0  # the first lay of the wand: every still placement of it, averaged
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


def lays_of(points: FloatArray) -> NDArray[np.intp]:
    """(P,) the lay of each placement: placements whose A lies within LAY_RADIUS_MM of a lay's first one's,
    pointing the same way, are that lay held still (0: the first placement's).

    Args:
        points: (P, K, 3) the placements' markers (A first, C last), mm.
    """
    direction = points[:, -1] - points[:, 0]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    first: list[int] = []
    lay = np.empty(len(points), dtype=np.intp)
    for i in range(len(points)):
        for j, f in enumerate(first):
            if np.linalg.norm(points[i, 0] - points[f, 0]) < LAY_RADIUS_MM and direction[i] @ direction[f] > 0.99:
                lay[i] = j
                break
        else:
            lay[i] = len(first)
            first.append(i)
    return lay


@dataclass(frozen=True, eq=False)
class Floor:
    """The world frame of the floor frames and the cameras adjusted with it.

    Attributes:
        world: the world frame (its standard deviations include the calibration's).
        models, poses: the cameras of the joint adjustment (poses relative to the reference camera).
    """

    world: WorldFrame
    models: tuple[CameraModel, ...]
    poses: tuple[Pose, ...]


def floor_of(
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    uv: FloatArray,
    covariance: FloatArray,
    sigma_px: float,
    *,
    positions_mm: tuple[float, ...],
    origin: str = "A",
    tool_mm: FloatArray | None = None,
) -> Floor:
    """The world frame of (F, C, K, 2) views of the wand laid still on the floor, or of a floor tool.

    The placements are triangulated with the calibrated cameras (``poses`` relative to the reference
    camera). For the wand laid on the floor, a plane is fitted to them (:func:`fit_floor`: the checks and
    the start); a tool's markers are aligned with their known positions (:func:`fit_tool`). The floor frame
    is then adjusted with the cameras (:func:`~wand_calib_ros.core.after.floor_adjustment.adjust_floor`):
    the floor's views are weighted like every other view, with the calibration's ``covariance`` and pixel
    noise as the cameras' prior.

    Args:
        models, poses: the calibrated cameras.
        uv: the floor frames' views: the wand's markers, or the tool's in any order per view (labelled here).
        covariance: (C*N_CAMERA_PARAMS, C*N_CAMERA_PARAMS) the calibration's camera covariance
            (CalibrationResult.camera_covariance).
        sigma_px: the calibration's pixel noise.
        positions_mm: the wand's marker positions from A.
        origin: for the wand: the first lay's "A" or its "centre".
        tool_mm: (K, 3) a floor tool's markers in the world frame (None: the wand lies on the floor).
    """
    centres = np.array([pose.center for pose in poses])
    if tool_mm is not None:
        views = label_tool_views(models, poses, uv[:, :, : len(tool_mm)], tool_mm)
        fitted = fit_tool(triangulate_placements(models, poses, views), tool_mm, centres)
        solution = adjust_floor(
            models, poses, covariance, sigma_px, views, fitted.world_from_reference.inverse(), tool_mm=tool_mm
        )
    else:
        points = triangulate_placements(models, poses, uv)
        fitted = fit_floor(points, centres, origin=origin)
        usable = np.all(np.isfinite(points), axis=(1, 2))
        lay = lays_of(points[usable])
        positions = np.asarray(positions_mm, dtype=float)
        if origin != "A":
            positions = positions - positions[-1] / 2.0
        starts = np.zeros((int(lay.max()) + 1, 3))
        for j in range(1, len(starts)):
            mean = fitted.world_from_reference.apply(points[usable][lay == j].mean(axis=0))
            along = mean[-1] - mean[0]
            psi = float(np.arctan2(along[1], along[0]))
            anchor = mean[0] - positions[0] * np.array([np.cos(psi), np.sin(psi), 0.0])
            starts[j] = anchor[0], anchor[1], psi
        solution = adjust_floor(
            models, poses, covariance, sigma_px, uv[usable], fitted.world_from_reference.inverse(),
            lay_of_frame=lay, positions_mm=positions, lay_starts=starts,
        )  # fmt: skip
    world = WorldFrame(
        solution.reference_from_world.inverse(),
        fitted.residual_mm,
        solution.normal_std_deg,
        solution.origin_std_mm,
        fitted.placements,
    )
    return Floor(world, solution.models, solution.poses)


def fit_tool(points: FloatArray, tool_mm: FloatArray, camera_centres: FloatArray) -> WorldFrame:
    """The world frame of a floor tool's triangulated markers: the rotation and translation that carry its
    known positions onto them (least squares over the frames' mean; a still tool).

    Args:
        points: (F, K, 3) the tool's markers triangulated per frame, reference frame, mm (NaN: not seen).
        tool_mm: (K, 3) their positions in the world frame, mm.
        camera_centres: (C, 3) the cameras' centres (the tool's z must point towards them).

    Raises:
        InsufficientDataError: fewer than three of its markers were seen by two cameras.
        DegenerateDataError: the markers are not where ``tool_mm`` puts them, or the cameras are under it.
    """
    seen: NDArray[np.bool_] = np.all(np.isfinite(points), axis=2)  # (F, K)
    counts = seen.sum(axis=0)
    known = counts > 0
    if known.sum() < 3:
        raise InsufficientDataError(
            f"the floor tool needs three of its markers seen by two cameras in the floor frames; got {int(known.sum())}"
        )
    mean = np.where(seen[..., None], points, 0.0).sum(axis=0)[known] / counts[known, None]
    model = tool_mm[known]
    rotation, translation = rigid_fit(model, mean)
    residual = float(np.sqrt(np.mean(np.sum((model @ rotation.T + translation - mean) ** 2, axis=1))))
    if residual > MAX_FLOOR_RESIDUAL_MM:
        raise DegenerateDataError(
            f"the floor frames' markers lie {residual:.0f} mm RMS from where floor points_mm puts them (at most "
            f"{MAX_FLOOR_RESIDUAL_MM:g}): check the tool's dimensions and that its markers are points A, B, C, ... "
            "in the order of points_mm"
        )
    up = rotation[:, 2]
    if float(np.median((camera_centres - translation) @ up)) <= 0:
        raise DegenerateDataError(
            "the floor tool's z (the cross product of its x and y markers) points away from the cameras: "
            "list points_mm so that x, y and up form a right-handed frame"
        )
    reference_from_world = Pose(rotation, translation)
    return WorldFrame(reference_from_world.inverse(), residual, 0.0, 0.0, int(seen.any(axis=1).sum()))
