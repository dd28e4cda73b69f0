"""Which marker is which on a two-marker wand (easyWand's and Argus's).

A two-marker wand has no A/C asymmetry: each camera labels its two blobs as it likes, per image.
The calibration needs the same label for the same marker in every view of a placement, and (for the
motion models of free-running cameras) over time. Three steps settle it:

- per camera through the take (:func:`continuous_in_image`): each marker moves the shorter way from
  one view to the next;
- for a camera pair before its initialisation (:func:`match_pair`): the midpoint of the two bearings
  does not depend on the labels and is close to the bearing of the wand's middle, so an essential
  matrix from the midpoints (RANSAC) tells, per placement, which of the two pairings the epipolar
  geometry prefers;
- for the whole rig once the cameras have a start (:func:`consistent_labels`): per placement, every view is
  paired to a reference view by the smaller epipolar error, then consecutive placements are oriented
  alike (the wand's ends move little from one frame to the next).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.placements import triangulate_placements
from wand_calib_ros.core.initialise.essential import epipolar_angles, ransac_essential
from wand_calib_ros.core.model.camera_model import CameraModel, unproject
from wand_calib_ros.core.model.geometry import Pose, skew

FloatArray = NDArray[np.float64]

#: The midpoints' RANSAC threshold over the pair's: the midpoint bearing is off the middle's bearing by
#: a second-order amount that grows with the wand's angular size.
MIDPOINT_SLACK = 3.0
#: Rounds of re-estimating the pair's geometry from the markers as the previous round paired them.
REFINEMENTS = 2


def swapped(uv: FloatArray, swap: NDArray[np.bool_]) -> FloatArray:
    """(N, 2, D) views with the two markers exchanged where ``swap`` (N,)."""
    out = uv.copy()
    out[swap] = uv[swap, ::-1]
    return out


def _pairing_errors(essential: FloatArray, b0: FloatArray, b1: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(N,) summed epipolar angles of the markers paired as labelled and crosswise."""
    straight = epipolar_angles(essential, b0[:, 0], b1[:, 0]) + epipolar_angles(essential, b0[:, 1], b1[:, 1])
    crossed = epipolar_angles(essential, b0[:, 0], b1[:, 1]) + epipolar_angles(essential, b0[:, 1], b1[:, 0])
    return straight, crossed


def affine_epipolar(x0: FloatArray, x1: FloatArray) -> FloatArray:
    """(5,) the affine epipolar constraint ``a . (u1, v1, u0, v0, 1) = 0`` of two narrow cameras, fitted by
    total least squares to the (N, 2) pixels ``x0``, ``x1`` of the same points (at a few degrees across a
    camera is affine to a fraction of a pixel: its epipolar lines are parallel). Scaled so that
    ``hypot(a0, a1) = 1``: the constraint is then camera 1's pixel distance from the epipolar line."""
    design = np.concatenate([x1, x0], axis=1)
    design = design[np.all(np.isfinite(design), axis=1)]
    centre = design.mean(axis=0)
    normal = np.linalg.svd(design - centre, full_matrices=False)[2][-1]
    line = np.r_[normal, -normal @ centre]
    return np.asarray(line / np.hypot(line[0], line[1]), dtype=np.float64)


def _affine_pairing_errors(line: FloatArray, p0: FloatArray, p1: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(N,) summed distances (px) from the affine epipolar lines of (N, 2, 2) pixels paired as labelled and
    crosswise."""

    def distance(a: FloatArray, b: FloatArray) -> FloatArray:
        return np.asarray(np.abs(b @ line[:2] + a @ line[2:4] + line[4]), dtype=np.float64)

    straight = distance(p0[:, 0], p1[:, 0]) + distance(p0[:, 1], p1[:, 1])
    crossed = distance(p0[:, 0], p1[:, 1]) + distance(p0[:, 1], p1[:, 0])
    return straight, crossed


def continuous_in_image(uv: FloatArray) -> FloatArray:
    """(F, C, 2, 2) views relabelled so that, per camera, each marker moves the shorter way from one
    whole view to the camera's next (frames in time order; harmless for independent placements):
    the image tracks of free-running cameras then follow one marker each."""
    out = uv.copy()
    for c in range(uv.shape[1]):
        rows = np.flatnonzero(np.all(np.isfinite(uv[:, c]), axis=(1, 2)))
        flip = rows[_flips(uv[rows, c])]
        out[flip, c] = uv[flip, c, ::-1]
    return out


def _flips(track: FloatArray) -> NDArray[np.bool_]:
    """(N,) which entries of an (N, 2, D) sequence of marker pairs to exchange so that each marker moves
    the shorter way from one entry to the next: a crossing between neighbours flips the parity of
    every later entry."""
    if len(track) == 0:
        return np.zeros(0, dtype=bool)
    straight = np.linalg.norm(track[1:] - track[:-1], axis=-1).sum(axis=1)
    crossed = np.linalg.norm(track[1:, ::-1] - track[:-1], axis=-1).sum(axis=1)
    return np.concatenate([[False], np.cumsum(crossed < straight) % 2 == 1])


def match_pair(
    models: tuple[CameraModel, CameraModel],
    uv0: FloatArray,
    uv1: FloatArray,
    *,
    threshold_rad: float,
    rng: np.random.Generator,
) -> FloatArray:
    """Camera 1's (N, 2, 2) views relabelled to match camera 0's (placements both see completely).

    Args:
        models: the two cameras' start intrinsics.
        uv0, uv1: (N, 2, 2) pixels of the two markers, each camera's own labels.
        threshold_rad: the pair's RANSAC threshold (the midpoints get MIDPOINT_SLACK times it).
        rng: seeded generator.
    """
    b0, b1 = unproject(models[0], uv0), unproject(models[1], uv1)  # (N, 2, 3)
    mid0, mid1 = b0.sum(axis=1), b1.sum(axis=1)
    mid0 /= np.linalg.norm(mid0, axis=1, keepdims=True)
    mid1 /= np.linalg.norm(mid1, axis=1, keepdims=True)
    usable = np.all(np.isfinite(mid0), axis=1) & np.all(np.isfinite(mid1), axis=1)
    essential, _ = ransac_essential(mid0[usable], mid1[usable], threshold_rad=MIDPOINT_SLACK * threshold_rad, rng=rng)
    for _ in range(REFINEMENTS):  # the markers themselves, paired by the current geometry, refine it
        straight, crossed = _pairing_errors(essential, b0, b1)
        paired = np.where((crossed < straight)[:, None, None], b1[:, ::-1], b1)
        m0, m1 = b0[usable].reshape(-1, 3), paired[usable].reshape(-1, 3)
        essential, _ = ransac_essential(m0, m1, threshold_rad=threshold_rad, rng=rng)
    straight, crossed = _pairing_errors(essential, b0, b1)
    return swapped(uv1, crossed < straight)


def consistent_labels(
    models: tuple[CameraModel, ...],
    poses: tuple[Pose, ...],
    uv: FloatArray,
    narrow: NDArray[np.bool_] | None = None,
) -> FloatArray:
    """(P, C, 2, 2) views relabelled so that a marker has one label in every view of a placement and
    from one placement to the next.

    Args:
        models, poses: the cameras' starts (poses X_cam = R X_ref + T).
        uv: (P, C, 2, 2) pixels, each view labelled as its camera liked; NaN where not seen.
        narrow: (C,) cameras with a narrow field of view: a pair of them is paired by the affine epipolar
            geometry of its pixels (:func:`affine_epipolar`), which a start's poses hardly fix there.
    """
    out = uv.copy()
    complete = np.all(np.isfinite(uv), axis=(2, 3))  # (P, C)
    reference = np.argmax(complete, axis=1)  # per placement the first camera with a whole view
    bearings = [unproject(models[c], uv[:, c]) for c in range(len(models))]
    affine = np.zeros(len(models), dtype=bool) if narrow is None else narrow
    for r in range(len(models)):
        for c in range(len(models)):
            rows = np.flatnonzero((reference == r) & complete[:, c] & complete[:, r])
            if c == r or rows.size == 0:
                continue
            if affine[r] and affine[c]:
                both = np.flatnonzero(complete[:, c] & complete[:, r])
                line = affine_epipolar(uv[both, r].mean(axis=1), uv[both, c].mean(axis=1))
                straight, crossed = _affine_pairing_errors(line, uv[rows, r], uv[rows, c])
            else:
                relative = poses[c].compose(poses[r].inverse())  # camera r's frame to camera c's
                essential = skew(relative.translation) @ relative.rotation
                straight, crossed = _pairing_errors(essential, bearings[r][rows], bearings[c][rows])
            out[rows, c] = swapped(uv[rows, c], crossed < straight)
    points = triangulate_placements(models, poses, np.where(complete[..., None, None], out, np.nan))  # (P, 2, 3)
    _label_single_markers(models, poses, out, points)
    placed = np.flatnonzero(np.all(np.isfinite(points), axis=(1, 2)))
    flip = placed[_flips(points[placed])]
    out[flip] = out[flip][:, :, ::-1]
    return out


def _label_single_markers(
    models: tuple[CameraModel, ...], poses: tuple[Pose, ...], uv: FloatArray, points: FloatArray
) -> None:
    """Views of one marker only (the other unseen) labelled in place as the placement's marker (``points``
    (P, 2, 3), triangulated from whole views) nearer their ray; views of placements not triangulated are
    left as they are."""
    seen = np.all(np.isfinite(uv), axis=-1)  # (P, C, 2)
    known = np.all(np.isfinite(points), axis=(1, 2))
    for c, (model, pose) in enumerate(zip(models, poses, strict=True)):
        rows = np.flatnonzero((seen[:, c].sum(axis=1) == 1) & known)
        if rows.size == 0:
            continue
        which = np.argmax(seen[rows, c], axis=1)  # the label it came with
        pixel = uv[rows, c, which]
        bearing = unproject(model, pixel)
        toward = pose.apply(points[rows])  # (N, 2, 3) the two markers in the camera's frame
        toward /= np.linalg.norm(toward, axis=-1, keepdims=True)
        nearer = np.argmax(np.einsum("nj,nkj->nk", bearing, toward), axis=1)
        moved = np.flatnonzero(np.isfinite(bearing[:, 0]) & (nearer != which))
        uv[rows[moved], c, nearer[moved]] = pixel[moved]
        uv[rows[moved], c, which[moved]] = np.nan
