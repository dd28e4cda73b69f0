"""Wand identification: which three blobs are A, B and C.

A, B, C are collinear with B between them and |AB| = L1 > L2 = |BC|. Among
the candidate blobs every triple is scored by how far its middle point lies
from the line through its ends (relative to its length, so fisheye curvature
within the tolerance is accepted) and by how far its image ratio |AB|/|BC| is
from the wand's; perspective changes that ratio, so it only breaks ties. The
end farther from B is A. When the image ratio is close to 1 (the wand points
steeply towards the camera) the labels are ambiguous: the detection says so
and a tracker or another camera has to decide (:mod:`wand_calib_ros.detection.tracking`).

With a track's prediction (where the wand was heading in this camera), the triples near it
are preferred: a lamp that lines up with two LEDs, or another wand-like triple elsewhere,
does not compete with the one that continues the track. Blobs that may not be part of a
wand (still lights, learned or not yet) are left out by the caller (``usable``).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.bearings import BearingTable
from wand_calib_ros.core.model.camera_model import CameraModel, unproject
from wand_calib_ros.core.model.rig import RigSpec, WandSpec
from wand_calib_ros.detection.blobs import Blobs, touching
from wand_calib_ros.detection.errors import UnsupportedWandError

FloatArray = NDArray[np.float64]

#: Reasons a frame gives no wand (counted per camera by ``wand-calib detect``).
REASONS = ("no_blobs", "too_few_blobs", "not_collinear", "competing_triples", "at_border")


def distance_to(points: FloatArray, prediction: FloatArray) -> float:
    """The largest distance (px) of a view's points from a prediction's, in the nearer of the two orders."""
    mine, theirs = points.tolist(), prediction.tolist()  # (scalar arithmetic: cheaper than numpy's calls here)
    straight = max(math.dist(a, b) for a, b in zip(mine, theirs, strict=True))
    swapped = max(math.dist(a, b) for a, b in zip(mine[::-1], theirs, strict=True))
    return min(straight, swapped)


@dataclass(frozen=True)
class WandOptions:
    """Wand identification settings.

    Attributes:
        ratio: the wand's |AB| / |BC| = L1 / L2.
        collinearity: largest distance of B from the line AC, as a fraction of |AC|.
        min_length_px: smallest |AC| in the image.
        ambiguous_ratio: image ratios within [1/x, x] of 1 leave A and C ambiguous.
        competing_margin: a second triple scoring within this factor of the best makes the frame ambiguous.
        n_points: the wand's markers: 3 (the paper's wand), 2 (a two-marker wand: the image's two
            blobs, labelled as found; the calibration matches them up) or more (collinear markers
            whose spacing pattern tells their order).
        positions: the markers' positions along the wand over its length (0 ... 1; wands of four or
            more markers).
        max_pattern_error: largest mean difference between the image's and the wand's normalised
            marker positions once the perspective foreshortening is fitted (four or more markers).
        tool_markers: a floor tool's markers (0: the rig has none). An image of exactly that many blobs
            that hold no wand is the tool's view, its blobs as found: the calibration labels them
            (:mod:`wand_calib_ros.core.after.floor_tool`).
    """

    ratio: float = 2.0
    collinearity: float = 0.03
    min_length_px: float = 6.0
    ambiguous_ratio: float = 1.25
    competing_margin: float = 2.0
    n_points: int = 3
    positions: tuple[float, ...] = ()
    max_pattern_error: float = 0.02
    tool_markers: int = 0

    @classmethod
    def for_rig(cls, rig: RigSpec) -> WandOptions:
        """The settings of a rig's wand (:meth:`for_wand`) and its floor tool."""
        options = cls.for_wand(rig.wand)
        return options if rig.floor_tool is None else replace(options, tool_markers=len(rig.floor_tool))

    @classmethod
    def for_wand(cls, wand: WandSpec) -> WandOptions:
        """The settings of a rig's wand.

        Raises:
            UnsupportedWandError: a wand of other than three markers (calibrate it from an observations
                CSV of its markers instead).
        """
        if wand.n_points == 2:
            return cls(n_points=2)
        if wand.n_points > 3:
            normalised = tuple(float(p) / wand.L for p in wand.positions_mm)
            if np.allclose(normalised, [1.0 - p for p in normalised[::-1]], atol=0.05):
                raise UnsupportedWandError(
                    f"the wand's markers {list(wand.positions_mm)} are spaced symmetrically: nothing in an image "
                    "tells its ends apart; space them unevenly, or detect them with your own tool"
                )
            return cls(n_points=wand.n_points, positions=normalised)
        return cls(ratio=wand.L1 / wand.L2)


@dataclass(frozen=True, eq=False)
class WandDetection:
    """The wand in one image, or why not.

    Attributes:
        points: (3, 2) pixels of A, B, C, or None.
        quality: 0..1, higher is better (collinearity and ratio agreement).
        reason: None when found, else one of :data:`REASONS`.
        ambiguous: A and C could be swapped (image ratio near 1).
        image_ratio: |AB| / |BC| in the image.
        tool: the points are a floor tool's markers in the order found (rows beyond them NaN), not the wand's.
    """

    points: FloatArray | None
    quality: float
    reason: str | None
    ambiguous: bool = False
    image_ratio: float = float("nan")
    tool: bool = False


#: The far end of a wand is at most this many times as far from the camera as its near end (a 600 mm wand 0.3 m
#: away): a triple whose segments' ratio needs more is no wand.
MAX_DEPTH_RATIO = 3.0


def _depth_ratio(ab: float, bc: float, ratio: float, bearings: list[list[float]] | None) -> float:
    """How many times as far from the camera one end of a triple must be as the other for its segments to look as
    they do (under the better of its two labellings): a line's image (a pinhole's, or the bearings' on a plane
    across their mean) scales each segment by the inverse of its ends' depths, so |ab| / |bc| = (|AB| / |BC|)
    z_C / z_A; ``bearings`` (3 x 3 numbers) of one end, the middle and the other end, or None: the pixels' ``ab``
    and ``bc``."""
    if bearings is not None:
        (a0, a1, a2), (b0, b1, b2), (c0, c1, c2) = bearings
        n0, n1, n2 = a0 + b0 + c0, a1 + b1 + c1, a2 + b2 + c2  # (their mean direction, unnormalised)
        da, db, dc = a0 * n0 + a1 * n1 + a2 * n2, b0 * n0 + b1 * n1 + b2 * n2, c0 * n0 + c1 * n1 + c2 * n2
        if min(da, db, dc) <= 0:  # (more than a hemisphere apart: no plane shows them all)
            return 1.0
        pa, pb, pc = [(x / d, y / d, z / d) for (x, y, z), d in zip(bearings, (da, db, dc), strict=True)]
        ab, bc = math.dist(pa, pb), math.dist(pb, pc)
    if min(ab, bc) <= 0:
        return math.inf
    seen = ab / bc  # (either end may be A: the smaller of what the two labellings need)
    return min(max(seen / ratio, ratio / seen), max(1.0 / (seen * ratio), seen * ratio))


def _score(
    triple: FloatArray, options: WandOptions, bearings: FloatArray | None = None
) -> tuple[float, FloatArray, float] | None:
    """(score, A-B-C ordered points, image ratio) of a triple, or None when it is not a wand.

    Args:
        triple: (3, 2) pixels.
        options: tolerances.
        bearings: (3, 3) their unit bearings under a (nominal) camera model, or None: then
            collinearity is judged in the image, else on the sphere (the wand's points lie on
            a great circle, however strongly a fisheye bends its image).
    """
    # The ends of the longest side are A and C; the third point is B. (Scalar arithmetic: numpy's calls cost more
    # than the sums on three points.)
    corners = triple.tolist()
    (x0, y0), (x1, y1), (x2, y2) = corners
    d01, d02, d12 = math.hypot(x1 - x0, y1 - y0), math.hypot(x2 - x0, y2 - y0), math.hypot(x2 - x1, y2 - y1)
    i, j, m, length = max(((0, 1, 2, d01), (0, 2, 1, d02), (1, 2, 0, d12)), key=lambda t: t[3])
    if length < options.min_length_px:
        return None
    a, c, b = corners[i], corners[j], corners[m]
    rays = None if bearings is None else bearings.tolist()
    if rays is None:
        ax, ay = (c[0] - a[0]) / length, (c[1] - a[1]) / length
        off_line = abs(ax * (b[1] - a[1]) - ay * (b[0] - a[0])) / length
    else:
        (p0, p1, p2), (q0, q1, q2), (r0, r1, r2) = rays[i], rays[j], rays[m]
        n0, n1, n2 = p1 * q2 - p2 * q1, p2 * q0 - p0 * q2, p0 * q1 - p1 * q0  # normal of the ends' great circle
        span = n0 * n0 + n1 * n1 + n2 * n2  # sin^2 of the angle between the ends' rays
        off_line = abs(n0 * r0 + n1 * r1 + n2 * r2) / max(span, 1e-12) if span > 0 else math.inf
    if off_line > options.collinearity:
        return None
    ab, bc = math.hypot(b[0] - a[0], b[1] - a[1]), math.hypot(c[0] - b[0], c[1] - b[1])
    if min(ab, bc) <= 0:
        return None
    if _depth_ratio(ab, bc, options.ratio, None if rays is None else [rays[i], rays[m], rays[j]]) > MAX_DEPTH_RATIO:
        return None
    order = [i, m, j]
    if ab < bc:  # A is the end farther from B
        order, ab, bc = [j, m, i], bc, ab
    ratio = ab / bc
    ratio_error = abs(math.log(ratio / options.ratio))
    score = off_line / options.collinearity + 0.25 * ratio_error
    return score, triple[order], ratio


def identify_wand(
    blobs: Blobs,
    options: WandOptions = WandOptions(),
    model: CameraModel | BearingTable | None = None,
    *,
    usable: NDArray[np.bool_] | None = None,
    near: tuple[FloatArray, float] | None = None,
) -> WandDetection:
    """The most wand-like collinear triple among the blobs (see the module docstring), else a floor
    tool's view when ``options.tool_markers`` says the rig has one and the image holds that many blobs.

    Args:
        blobs: the image's blobs.
        options: tolerances.
        model: the camera's (nominal or calibrated) model, or its BearingTable: collinearity is
            then tested on the unit sphere, which keeps fisheye images of the wand straight.
        usable: (N,) the blobs that may be part of the wand (None: all; a blob a mask or a saturated light cuts,
            ``blobs.masked``, never is).
        near: (points (3, 2), gate px) a track's prediction: a triple within the gate of it wins over
            the others; two within it make the image ambiguous.
    """
    cut = blobs.masked if blobs.masked is not None else np.zeros(blobs.centres.shape[0], dtype=bool)
    if cut.any():  # a spot a mask or a saturated light cuts is no LED's centre: never part of a wand
        usable = ~cut if usable is None else usable & ~cut
    usable = _searched(blobs, usable, near)
    if usable is not None and not usable.all():
        found = _find_wand(blobs.subset(usable), options, model, near)
        if found.points is None and found.reason in ("no_blobs", "too_few_blobs"):  # the lights left out were still
            # (or cut)
            still = ~usable & ~cut
            return WandDetection(None, 0.0, "still" if still.any() or not cut.any() else "at_border")
    else:
        found = _find_wand(blobs, options, model, near)
    n = blobs.centres.shape[0]
    if found.points is not None or not options.tool_markers or n != options.tool_markers:
        return found
    if blobs.cut(list(range(n))):
        return WandDetection(None, 0.0, "at_border")
    points = np.full((max(options.n_points, n), 2), np.nan)
    points[:n] = blobs.centres
    return WandDetection(points, 1.0, None, tool=True)


#: At most this many blobs are searched for the wand (the triples grow as their cube): those nearest the track's
#: prediction, then the brightest.
MAX_WAND_BLOBS = 24


def _searched(
    blobs: Blobs, usable: NDArray[np.bool_] | None, near: tuple[FloatArray, float] | None
) -> NDArray[np.bool_] | None:
    """The usable blobs, at most MAX_WAND_BLOBS of them (None: all)."""
    count = blobs.centres.shape[0] if usable is None else int(usable.sum())
    if count <= MAX_WAND_BLOBS:
        return usable
    keep = np.ones(blobs.centres.shape[0], dtype=bool) if usable is None else usable.copy()
    rank = -blobs.peaks * np.sqrt(blobs.areas)  # the brightest first ...
    if near is not None:  # ... after those within the track's gate
        gaps = np.hypot(*(blobs.centres[:, None, :] - near[0][None, :, :]).transpose(2, 0, 1)).min(axis=1)
        rank = np.where(gaps <= near[1], rank - 1e18, rank)
    order = np.argsort(np.where(keep, rank, np.inf), kind="stable")
    chosen = np.zeros_like(keep)
    chosen[order[:MAX_WAND_BLOBS]] = True
    return chosen & keep


def _find_wand(
    blobs: Blobs,
    options: WandOptions,
    model: CameraModel | BearingTable | None,
    near: tuple[FloatArray, float] | None = None,
) -> WandDetection:
    """The most wand-like collinear triple among the blobs (see the module docstring)."""
    n = blobs.centres.shape[0]
    if n == 0:
        return WandDetection(None, 0.0, "no_blobs")
    if options.n_points == 2:
        return _two_markers(blobs, options)
    if options.n_points > 3:
        return _marker_pattern(blobs, options, None if model is None else _bearings(model, blobs.centres))
    if n < 3:
        return WandDetection(None, 0.0, "too_few_blobs")
    scored = []
    if model is None:
        bearings = None
    elif isinstance(model, BearingTable):
        bearings = model(blobs.centres)
    else:
        bearings = unproject(model, blobs.centres)
    merged = touching(blobs.centres, blobs.areas, 0.0)  # overlapping blobs: parts of one spot, never two LEDs
    for i, j, k in itertools.combinations(range(n), 3):
        if merged[i, j] or merged[i, k] or merged[j, k]:
            continue
        index = [i, j, k]
        outcome = _score(blobs.centres[index], options, None if bearings is None else bearings[index])
        if outcome is not None:
            scored.append((*outcome, index))
    if not scored:
        return WandDetection(None, 0.0, "not_collinear")
    if near is not None:  # the triples that continue the track, if any, compete only among themselves
        continuing = [s for s in scored if distance_to(s[1], near[0]) <= near[1]]
        scored = continuing or scored
    scored.sort(key=lambda s: float(s[0]))
    best = scored[0]
    if len(scored) > 1 and scored[1][0] < options.competing_margin * best[0] + 0.05:
        return WandDetection(None, 0.0, "competing_triples")
    score, points, ratio, index = best
    if blobs.cut(index):  # an LED cut by the image border: its centre is biased, the view is not written
        return WandDetection(None, 0.0, "at_border")
    ambiguous = 1 / options.ambiguous_ratio <= ratio <= options.ambiguous_ratio
    return WandDetection(points, float(1.0 / (1.0 + score)), None, bool(ambiguous), float(ratio))


def _two_markers(blobs: Blobs, options: WandOptions) -> WandDetection:
    """A two-marker wand: the image's two blobs, as found (nothing tells its ends apart). A third blob
    (a reflection, another light) makes the image ambiguous: the view is rejected rather than guessed."""
    n = blobs.centres.shape[0]
    if n != 2:
        return WandDetection(None, 0.0, "too_few_blobs" if n < 2 else "competing_triples")
    if float(np.linalg.norm(blobs.centres[1] - blobs.centres[0])) < options.min_length_px:
        return WandDetection(None, 0.0, "not_collinear")
    if blobs.cut([0, 1]):
        return WandDetection(None, 0.0, "at_border")
    return WandDetection(blobs.centres.copy(), 1.0, None)


#: Most blobs an image may hold for a wand of four or more markers (the combinations grow fast).
MAX_PATTERN_BLOBS = 10


def _bearings(model: CameraModel | BearingTable, centres: FloatArray) -> FloatArray:
    return model(centres) if isinstance(model, BearingTable) else unproject(model, centres)


def _gnomonic(bearings: FloatArray) -> FloatArray:
    """(K, 2) the bearings as a pinhole camera looking at their mean direction would image them: lines
    stay lines (a fisheye's curved image of the wand is straightened), distances keep their ratios
    up to the usual perspective."""
    axis = bearings.mean(axis=0)
    axis /= np.linalg.norm(axis)
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    plane = bearings / (bearings @ axis)[:, None]
    return np.column_stack([plane @ u, plane @ v])


def _pattern_error(t: FloatArray, wanted: FloatArray) -> float:
    """How far (mean, in wand lengths) normalised image positions ``t`` of the markers are from the wand's
    ``wanted`` ones seen in perspective: a line's points map by t = (1 + c) w / (1 + c w) with the ends
    fixed; c (the foreshortening) is fitted to the inner markers."""
    w, inner = wanted[1:-1], t[1:-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        c = float(np.nanmedian((inner - w) / (w * (1.0 - inner))))
    if not np.isfinite(c) or c <= -0.9:  # no camera in front of the wand sees it so
        return float("inf")
    return float(np.mean(np.abs(inner - (1.0 + c) * w / (1.0 + c * w))))


def _marker_pattern(blobs: Blobs, options: WandOptions, bearings: FloatArray | None = None) -> WandDetection:
    """A wand of four or more collinear markers: the K blobs that lie on one line and whose spacing
    matches the wand's (normalised positions along the line, in the order that fits better); an
    image where two sets fit, or where both orders fit alike, is rejected. With the camera's
    (nominal) model the test is made on the view a pinhole camera would have (fisheyes bend lines)."""
    n, k = blobs.centres.shape[0], options.n_points
    if n < k:
        return WandDetection(None, 0.0, "too_few_blobs")
    if n > MAX_PATTERN_BLOBS:
        return WandDetection(None, 0.0, "competing_triples")
    wanted = np.array(options.positions)
    found = []
    for index in itertools.combinations(range(n), k):
        pixels = blobs.centres[list(index)]
        if float(np.max(np.linalg.norm(pixels[:, None] - pixels[None], axis=-1))) < options.min_length_px:
            continue
        points = pixels if bearings is None else _gnomonic(bearings[list(index)])
        if not np.all(np.isfinite(points)):
            continue
        distances = np.linalg.norm(points[:, None] - points[None], axis=-1)
        i, j = np.unravel_index(int(np.argmax(distances)), distances.shape)
        length = float(distances[i, j])
        axis = (points[j] - points[i]) / length
        along = (points - points[i]) @ axis / length
        across = np.abs((points - points[i]) @ np.array([-axis[1], axis[0]])) / length
        if across.max() > options.collinearity:
            continue
        order = np.argsort(along)
        t = along[order]
        forward, backward = _pattern_error(t, wanted), _pattern_error(1.0 - t[::-1], wanted)
        error = min(forward, backward)
        if error <= options.max_pattern_error:
            ordered = pixels[order] if forward <= backward else pixels[order][::-1]
            found.append((error + across.max() / options.collinearity * 0.01, ordered, abs(forward - backward), index))
    if not found:
        return WandDetection(None, 0.0, "not_collinear")
    found.sort(key=lambda f: f[0])
    if len(found) > 1 and found[1][0] < options.competing_margin * found[0][0]:
        return WandDetection(None, 0.0, "competing_triples")
    error, points, separation, index = found[0]
    if separation < 2 * error:  # both orders fit about alike: the ends cannot be told apart here
        return WandDetection(None, 0.0, "ambiguous")
    if blobs.cut(list(index)):
        return WandDetection(None, 0.0, "at_border")
    return WandDetection(points, float(1.0 / (1.0 + error)), None)
