"""Whether a rig description, its views and a calibration can be physically right.

A calibration can converge on a self-consistent but wrong description: wand lengths in metres
(the whole scene shrinks a thousandfold), the wand's two segments swapped or declared equal, a
nominal focal off by orders of magnitude. Each check here compares what the user declared with
what the images or the result show, and names the parameter that is most likely wrong.

Checks before the solve (:func:`check_rig`, :func:`check_views`) and after it
(:func:`check_result`) raise :class:`PlausibilityError` with one line a user can act on.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult
from wand_calib_ros.core.adjust.bundle_problem import N_CAMERA_PARAMS
from wand_calib_ros.core.adjust.narrow_field import NARROW_FIELD_DEG, field_of_view_deg
from wand_calib_ros.core.errors import PlausibilityError
from wand_calib_ros.core.judge.degeneracy import MAX_FOCAL_STD
from wand_calib_ros.core.model.camera_model import CameraModel, to_opencv
from wand_calib_ros.core.model.result import CalibrationResult
from wand_calib_ros.core.model.rig import CameraSpec, RigSpec, WandObservations, WandSpec

FloatArray = NDArray[np.float64]

#: The widest ray's image radius (nominal focal x theta_max) over the image's half diagonal must
#: lie within these factors (circular fisheyes reach about 0.6, full-frame ones about 1.3).
IMAGE_RADIUS_RANGE = (0.25, 4.0)
#: The median image ratio |AB|/|BC| over at least WAND_RATIO_VIEWS views may differ from L1/L2 by
#: this factor at most (perspective and distortion move single views: the median of 300 stays
#: within 3 % on simulated rigs, of 20 fisheye views within 30 %); equal or swapped segments of a
#: 2:1 wand are 2x and 4x off.
WAND_RATIO_TOLERANCE = 1.5
WAND_RATIO_VIEWS = 30
#: Views whose B falls in the same cell of this size (px) count once (a wand held still).
VIEW_CELL_PX = 20.0
#: The wand's median distance from a camera, in nominal focal lengths, below which no lens can
#: have imaged it (the lengths are in another unit): twice the focal is life size, and a long lens's nominal
#: focal may be 3x below its true one; and the distance (mm) beyond which no wand calibration happens.
MIN_DISTANCE_FOCALS = 2.0
MAX_DISTANCE_MM = 1e6
#: Estimated focal over the nominal one: outside these factors the nominal focal or the solution is wrong.
FOCAL_RANGE = (0.5, 2.0)
#: A camera whose reprojection RMS exceeds this multiple of the other cameras' median RMS (and
#: MIN_BAD_RMS_PX) was not calibrated: its model or its views are wrong.
RMS_FACTOR = 4.0
MIN_BAD_RMS_PX = 1.0
#: The wand's length error (RMS of the first-to-last marker distance) is refused as a scene that is not rigid
#: only beyond this fraction of its length and WAND_NOISE_FACTOR times what the pixel noise alone causes on the
#: same placements (:func:`~wand_calib_ros.core.judge.quality.noise_wand_error`): a wand a few tens of pixels long
#: measures its length to a few percent, however rigid the scene.
WAND_ERROR_FRACTION = 0.05
WAND_NOISE_FACTOR = 3.0
#: A marker between the ends must sit where the rig description puts it: the median of its position along the
#: freely triangulated wand (a fraction of the wand's length) may differ from the description's by
#: SEGMENT_SIGMAS of its standard error and SEGMENT_TOLERANCE at most (a segment 3 % off moves it 1-2 % of the
#: wand's length, 100 standard errors on a simulated take); judged over SEGMENT_PLACEMENTS placements at least.
SEGMENT_SIGMAS = 6.0
SEGMENT_TOLERANCE = 0.005
SEGMENT_PLACEMENTS = 20
#: A calibration from fewer placements than this that fails the wand check may have started badly (said).
SHORT_TAKE = 100
#: Given intrinsics held fixed are the user's knowledge. The views lean away from them when freeing the focal
#: length and principal point lowers the camera's residuals significantly (chi-square, 3 degrees of freedom, at
#: 0.1 %: GIVEN_CHI2) and moves them by more than GIVEN_FOCAL_FRACTION of the focal or GIVEN_CENTRE_FRACTION of
#: the image width: a warning. They are refused only on strong evidence that they cannot fit: that move is also
#: GIVEN_SIGMAS of the views' own standard deviations, and what the views say is a camera (its principal point
#: inside the image, its focal within FOCAL_RANGE of the nominal one), not a weak problem's wandering.
GIVEN_CHI2 = 16.27
GIVEN_FOCAL_FRACTION = 0.02
GIVEN_CENTRE_FRACTION = 0.02
GIVEN_SIGMAS = 5.0
#: Two cameras' freed intrinsics that remove within this fraction of each other's squared residuals explain the
#: views alike: both are named.
ALIKE = 0.8


def image_radius_ratio(spec: CameraSpec) -> float:
    """Where an equidistant lens of the nominal focal images theta_max, over the image's half diagonal."""
    radius_px = spec.nominal_focal_mm * spec.max_view_angle * float(np.mean(spec.m))
    return radius_px / (float(np.hypot(*spec.image_size)) / 2.0)


def check_rig(rig: RigSpec) -> None:
    """Each camera's nominal focal, view angle, pixel size and image size must describe one lens.

    Raises:
        PlausibilityError: naming the camera and the focal these would need.
    """
    for spec in rig.cameras:
        ratio = image_radius_ratio(spec)
        if not IMAGE_RADIUS_RANGE[0] <= ratio <= IMAGE_RADIUS_RANGE[1]:
            fitting = spec.nominal_focal_mm / ratio
            raise PlausibilityError(
                f"camera '{spec.name}': nominal_focal_mm {spec.nominal_focal_mm:g} with max_view_angle_deg "
                f"{spec.max_view_angle_deg:g} and pixel_size_um {spec.pixel_size_um[0]:g} would image the widest "
                f"ray {ratio:.3g}x as far from the centre as the image's corner; one of them is wrong "
                f"(for this view angle and pixel size, a focal near {fitting:.3g} mm)"
            )
        given = spec.intrinsics
        narrow = field_of_view_deg(spec, spec.nominal_focal_mm) < NARROW_FIELD_DEG  # a long lens: said later
        far = given is not None and not FOCAL_RANGE[0] <= float(given.k[0]) / spec.nominal_focal_mm <= FOCAL_RANGE[1]
        if given is not None and far and not narrow:
            raise PlausibilityError(
                f"camera '{spec.name}': its given intrinsics (fx {float(given.focal_px[0]):.0f} px) mean a focal of "
                f"{float(given.k[0]):.3g} mm with pixel_size_um {spec.pixel_size_um[0]:g}, against the nominal "
                f"{spec.nominal_focal_mm:g} mm: check pixel_size_um, nominal_focal_mm, or that K is this camera's"
            )


def end_to_end_px(uv: FloatArray) -> FloatArray:
    """(F, C) the first-to-last image length (px) of (F, C, K, 2) views (NaN where an end is missing)."""
    return _distance(uv[:, :, 0], uv[:, :, -1])


def image_lengths(uv: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(|AB|, |BC|) image lengths (px) of (..., 3, 2) views (NaN where a point is missing)."""
    return _distance(uv[..., 0, :], uv[..., 1, :]), _distance(uv[..., 1, :], uv[..., 2, :])


def _distance(first: FloatArray, second: FloatArray) -> FloatArray:
    """(...) the distance of (..., 2) points (component by component: the dense views of a large rig are mostly
    NaN, and their differences as whole arrays cost as much as the rest of the checks)."""
    return np.asarray(np.hypot(second[..., 0] - first[..., 0], second[..., 1] - first[..., 1]), dtype=np.float64)


def check_views(rig: RigSpec, observations: WandObservations) -> None:
    """The views must show the declared wand: its segments' ratio, and a scale a lens can image.

    Raises:
        PlausibilityError: L1/L2 disagree with the images (equal, swapped or wrong), or the
            wand would have to be closer to a camera than a lens images (lengths in metres?) or
            farther than any calibration volume (micrometres?).
    """
    wand = rig.wand
    if wand.n_points == 3:
        _check_segment_ratio(wand, observations.uv)
    ends = end_to_end_px(observations.uv)
    names = "L1 and L2" if wand.n_points == 3 else "the marker positions"
    lengths = (wand.L1, wand.L2) if wand.n_points == 3 else wand.positions_mm
    metres = " and ".join(f"{1000 * v:g}" for v in lengths)
    for c, spec in enumerate(rig.cameras):
        length = ends[:, c]
        length = length[np.isfinite(length) & (length > 0)]
        if length.size == 0:
            continue
        focal_px = spec.nominal_focal_mm * float(np.mean(spec.m))
        distance = float(np.median(focal_px * wand.L / length))  # mm, for a wand seen side-on
        if distance < MIN_DISTANCE_FOCALS * spec.nominal_focal_mm:
            raise PlausibilityError(
                f"camera '{spec.name}': with {wand.ends} = {wand.L:g} mm the wand would be about {distance:.3g} mm "
                f"from the lens (its nominal focal is {spec.nominal_focal_mm:g} mm): no lens images that; are {names} "
                f"in metres or cm? write them in mm (e.g. {metres} for metres)"
            )
        if distance > MAX_DISTANCE_MM:
            raise PlausibilityError(
                f"camera '{spec.name}': with {wand.ends} = {wand.L:g} mm the wand would be about "
                f"{distance / 1e6:.3g} km from the lens: are {names} in micrometres? write them in mm"
            )


def _check_segment_ratio(wand: WandSpec, uv: FloatArray) -> None:
    """The three-LED wand's L1/L2 against the median image ratio |AB|/|BC| of (F, C, 3, 2) views."""
    ab, bc = image_lengths(uv)  # (F, C)
    measured = np.isfinite(ab) & np.isfinite(bc) & (bc > 0)
    ratios = (ab / bc)[measured]
    declared = wand.L1 / wand.L2
    if _distinct_views(uv, measured) >= WAND_RATIO_VIEWS:  # a wand held still is one view
        seen = float(np.median(ratios))
        if not 1.0 / WAND_RATIO_TOLERANCE <= seen / declared <= WAND_RATIO_TOLERANCE:
            swapped = 1.0 / WAND_RATIO_TOLERANCE <= seen * declared <= WAND_RATIO_TOLERANCE
            hint = (
                f"L1 and L2 are swapped (|AB| = L1 is the segment at A; write L1: {wand.L2:g}, L2: {wand.L1:g})"
                if swapped
                else f"the wand's L1 and L2 should be in about that ratio (e.g. L1: {wand.L * seen / (1 + seen):.0f}, "
                f"L2: {wand.L / (1 + seen):.0f} for |AC| = {wand.L:g} mm)"
            )
            raise PlausibilityError(
                f"wand: the views' median image ratio |AB|/|BC| is {seen:.2f} ({ratios.size} views) but "
                f"L1/L2 = {wand.L1:g}/{wand.L2:g} = {declared:.2f}: {hint}"
            )


def _distinct_views(uv: FloatArray, measured: NDArray[np.bool_]) -> int:
    """How many of the (F, C) ``measured`` views put the wand's B in different VIEW_CELL_PX cells."""
    frames, cameras = np.nonzero(measured)
    cells = np.floor(uv[frames, cameras, 1] / VIEW_CELL_PX).astype(np.int64)  # (N, 2): B's cell in u and v
    n_cameras = uv.shape[1]
    span = int(np.max(np.abs(cells), initial=0)) + 1  # one integer per (camera, cell u, cell v)
    keys = (cells[:, 0] * (2 * span + 1) + cells[:, 1]) * n_cameras + cameras
    return int(np.unique(keys).size)


def check_result(
    rig: RigSpec, result: CalibrationResult, views: FloatArray, points: FloatArray | None = None
) -> list[str]:
    """A calibration's focal lengths, image errors and wand lengths must be those of a real rig.

    Its wand too, from ``views`` ((F, C, K, 2) the views it used, the rig's camera order) or, where given, ``points``
    (their markers triangulated freely with its cameras, as the calibration returns them): the markers between
    the ends where the description puts them (:func:`check_segments`) and the wand's length error within what
    the pixel noise causes on a wand of that image length (:data:`WAND_NOISE_FACTOR`).

    A narrow camera's focal (a field under NARROW_FIELD_DEG) beyond FOCAL_RANGE of its nominal one is
    said, not refused, where the views determine it (to MAX_FOCAL_STD): long lenses are often used with
    extenders and zooms their data sheet does not name.

    Returns:
        Warnings (a narrow camera's focal far from its nominal one; a wand whose image length limits the accuracy).

    Raises:
        PlausibilityError: naming the camera (or the wand) and the likely cause.
    """
    warnings = []
    rms = {camera.name: camera.rms_reprojection_px for camera in result.cameras}
    for spec in rig.cameras:
        camera = result.camera(spec.name)
        focal = float(camera.model.k[0])
        narrow = field_of_view_deg(spec, spec.nominal_focal_mm) < NARROW_FIELD_DEG
        off = not FOCAL_RANGE[0] <= focal / spec.nominal_focal_mm <= FOCAL_RANGE[1]
        if off and (narrow or not spec.holds_intrinsics):
            # (given intrinsics held fixed were checked with the rig, a narrow camera's are said here)
            std = 0.0 if spec.holds_intrinsics else camera.parameter_std.get("k1", np.inf) / focal
            if narrow and std <= MAX_FOCAL_STD:
                how = "as given" if spec.holds_intrinsics else f"+-{100 * std:.2g} %"
                warnings.append(
                    f"{spec.name}: its focal is {focal:.4g} mm (fx {focal * float(camera.model.m[0]):.0f} px {how}), "
                    f"{focal / spec.nominal_focal_mm:.2g}x the nominal {spec.nominal_focal_mm:g} mm: check "
                    "nominal_focal_mm and pixel_size_um (an extender or a zoom?)"
                )
                continue
            raise PlausibilityError(
                f"camera '{spec.name}': the calibration puts its focal at {focal:.3g} mm "
                f"(fx {focal * float(camera.model.m[0]):.0f} px) against the nominal {spec.nominal_focal_mm:g} mm: "
                "check nominal_focal_mm and pixel_size_um, or the camera's views (another camera's images?)"
            )
        others = float(np.median([value for name, value in rms.items() if name != spec.name]))
        if camera.rms_reprojection_px > max(RMS_FACTOR * others, MIN_BAD_RMS_PX):
            raise PlausibilityError(
                f"camera '{spec.name}': its reprojection RMS is {camera.rms_reprojection_px:.2f} px where the other "
                f"cameras' median is {others:.2f} px: its model or its views are wrong (check its entry in the rig "
                "description and which images its views come from)"
            )
    check_segments(rig, result, views, points)
    return warnings + _wand_length(rig, result, views)


def _wand_length(rig: RigSpec, result: CalibrationResult, views: FloatArray) -> list[str]:
    """The wand-length gate (:data:`WAND_ERROR_FRACTION`, :data:`WAND_NOISE_FACTOR`), and a warning where the
    wand's image length is what limits the accuracy.

    Raises:
        PlausibilityError: the length error is beyond both.
    """
    from wand_calib_ros.core.judge.quality import noise_wand_error

    L, error = rig.wand.L, result.wand_length_rms_mm
    if error <= WAND_ERROR_FRACTION * L:
        return []
    noise = noise_wand_error(result, rig.camera_names, views)
    first_last = end_to_end_px(views)
    seen = np.isfinite(first_last).any(axis=0)
    lengths = np.full(len(rig.cameras), np.nan)
    lengths[seen] = np.nanmedian(first_last[:, seen], axis=0)
    shortest = int(np.nanargmin(lengths))
    size = f"{rig.wand.ends} is {lengths[shortest]:.0f} px long in {rig.camera_names[shortest]}'s images (median)"
    if np.isfinite(noise) and not error > WAND_NOISE_FACTOR * noise:
        return [
            f"wand: {rig.wand.ends} comes out {error:.3g} mm RMS away from {L:g} mm ({100 * error / L:.1f} %), "
            f"what {result.sigma_px:.2g} px of pixel noise gives ({noise:.3g} mm): {size}, which limits the "
            "accuracy; a longer wand or one waved closer to the cameras measures better"
        ]
    held = [spec.name for spec in rig.cameras if spec.holds_intrinsics]
    given = (
        f", or the intrinsics given fixed for {', '.join(held)} (give them as a start: fixed: false)" if held else ""
    )
    short = (
        f"; or the take is too short to hold a start ({result.placements_used} placements used): wave longer"
        if result.placements_used < SHORT_TAKE
        else ""
    )
    beyond = f", {error / noise:.0f}x what the pixel noise causes" if np.isfinite(noise) and noise > 0 else ""
    raise PlausibilityError(
        f"wand: {rig.wand.ends} comes out {error:.3g} mm RMS away from {L:g} mm ({100 * error / L:.0f} %{beyond}): "
        "the scene is not rigid; check the wand's lengths and "
        f"that each camera's views are of the same wand at the same time{given}{short}"
    )


def check_segments(
    rig: RigSpec, result: CalibrationResult, views: FloatArray, points: FloatArray | None = None
) -> None:
    """Each marker between the wand's ends must sit where the rig description puts it.

    The placements seen whole are triangulated freely with the calibration (no wand constraint), and each
    inner marker's position along its wand (the projection of its distance from the first marker on the
    first-to-last direction) compared with the description's (:data:`SEGMENT_SIGMAS`,
    :data:`SEGMENT_TOLERANCE`). A segment length given wrong is held by the adjustment, which bends the
    cameras and inflates the residuals to fit it; the images still place the marker where it is.

    Args:
        views: (F, C, K, 2) the views the calibration used, cameras in the rig's order.
        points: (F', K, 3) their markers so triangulated already (the calibration's), or None.

    Raises:
        PlausibilityError: naming the marker, where the images put it and where the description does.
    """
    from wand_calib_ros.core.adjust.placements import triangulate_placements

    wand = rig.wand
    if wand.n_points < 3:
        return
    if points is None:
        names = rig.camera_names
        models = tuple(result.camera(name).model for name in names)
        poses = tuple(result.camera(name).pose for name in names)
        points = triangulate_placements(models, poses, views)
    points = points[np.all(np.isfinite(points), axis=(1, 2))]
    if len(points) < SEGMENT_PLACEMENTS:
        return
    axis = points[:, -1] - points[:, 0]
    along = np.einsum("pkd,pd->pk", points[:, 1:-1] - points[:, :1], axis) / np.sum(axis * axis, axis=1)[:, None]
    median = np.median(along, axis=0)
    spread = 1.4826 * np.median(np.abs(along - median), axis=0)
    standard_error = 1.2533 * spread / np.sqrt(len(points))
    expected = np.asarray(wand.positions_mm[1:-1]) / wand.L
    off = np.abs(median - expected)
    bad = off > np.maximum(SEGMENT_SIGMAS * standard_error, SEGMENT_TOLERANCE)
    if not bad.any():
        return
    k = int(np.argmax(np.where(bad, off / np.maximum(standard_error, 1e-12), -np.inf)))
    label, first = wand.labels[k + 1], wand.labels[0]
    raise PlausibilityError(
        f"wand: the images put {label} {median[k] * wand.L:.1f} mm from {first} (+-{standard_error[k] * wand.L:.1f}, "
        f"{len(points)} placements), the rig description {expected[k] * wand.L:g} mm: a segment length is wrong "
        f"(the calibration bent to hold it: pixel noise {result.sigma_px:.2g} px); measure the wand's segments again"
    )


def check_given_intrinsics(
    rig: RigSpec, result: BundleResult, free: NDArray[np.bool_], points: NDArray[np.int64]
) -> list[str]:
    """Given intrinsics held fixed against the views: for each such camera, the linearised estimate with
    its focal length and principal point freed (the adjustment's own normal equations,
    :meth:`~wand_calib_ros.core.adjust.bundle_adjustment.CameraSystem.step`) and how much of its squared
    residuals that would remove (see GIVEN_CHI2, GIVEN_SHARE).

    Args:
        result: the final adjustment, of the (C, N_CAMERA_PARAMS) parameters ``free``.
        points: (C,) image points of each camera in it.

    Returns:
        A warning per camera whose views lean away from its given intrinsics, weakly (they are kept).

    Raises:
        PlausibilityError: a camera whose given intrinsics cannot fit its views, naming its given values and
            what the views say.
    """
    system = result.system
    if system is None:
        return []
    n_cameras = len(rig.cameras)
    refusals: list[tuple[float, str, str]] = []  # (squared residuals freeing it removes, the camera, the refusal)
    leaning: list[tuple[float, str]] = []  # (the same, the camera) of every camera the views lean away from
    warnings = []
    for c, spec in enumerate(rig.cameras):
        if not spec.holds_intrinsics:
            continue
        released = free.copy()
        released[c, [0, 5, 6]] = True  # k1, u0, v0
        delta = system.step(released)
        removed = max(float(delta[:, system.columns].reshape(-1) @ system.rhs), 0.0)  # of the squared residuals
        step = delta[c]
        std = np.sqrt(np.clip(np.diag(system.covariance(released, result.sigma)), 0, None))
        std = std.reshape(n_cameras, N_CAMERA_PARAMS)[c]
        model = result.state.models[c]
        focal = float(step[0] / model.k[0])
        centre = float(np.hypot(step[5], step[6]))
        moved = abs(focal) > GIVEN_FOCAL_FRACTION or centre > GIVEN_CENTRE_FRACTION * spec.image_size[0]
        if not (moved and removed / result.sigma**2 > GIVEN_CHI2):
            continue
        fx = float(model.focal_px[0])
        seen = model.principal_point + step[5:7]
        figures = (
            f"they put its focal length at fx {fx * (1 + focal):.0f} +- {fx * std[0] / model.k[0]:.0f} px against the "
            f"given {fx:.0f} ({100 * focal:+.0f} %) and its principal point at ({seen[0]:.0f}, {seen[1]:.0f}) "
            f"+- {np.hypot(std[5], std[6]):.0f} px against ({model.principal_point[0]:.0f}, "
            f"{model.principal_point[1]:.0f})"
        )
        share = removed / max(float(points[c]) * 2 * result.sigma**2, 1e-12)
        leaning.append((removed, spec.name))
        strong = abs(step[0]) > GIVEN_SIGMAS * std[0] or centre > GIVEN_SIGMAS * float(np.hypot(std[5], std[6]))
        inside = bool(np.all((seen >= 0) & (seen <= np.asarray(spec.image_size))))
        camera_like = FOCAL_RANGE[0] <= (1 + focal) * float(model.k[0]) / spec.nominal_focal_mm <= FOCAL_RANGE[1]
        if strong and inside and camera_like:
            refusals.append(
                (
                    removed,
                    spec.name,
                    f"camera '{spec.name}': the views disagree with its given intrinsics: {figures}: "
                    + (_tangential_hint(model) or "check that K is this camera's and for this image size")
                    + ", or give them as a start (fixed: false)",
                )
            )
        warnings.append(
            f"{spec.name}: its views lean away from its given intrinsics ({figures}; freed they would fit "
            f"{100 * min(share, 1.0):.0f} % of its squared residuals better) but not strongly enough to overrule "
            "them: the given intrinsics are kept"
        )
    if refusals:  # the camera whose freed intrinsics explain the most (one wrong camera pulls the others too) ...
        first, named, line = max(refusals)
        alike = [name for removed, name in leaning if name != named and removed >= ALIKE * first]
        if alike:  # ... or another that explains them alike (the views fix the cameras' focal ratio, say)
            line += f" (or {' or '.join(alike)}'s: freeing either explains the views alike)"
        raise PlausibilityError(line)
    return warnings


#: OpenCV tangential terms (p1, p2) of real lenses stay below this (a few thousandths); larger ones shift the image as
#: a displaced principal point would.
TANGENTIAL_LIMIT = 0.005


def _tangential_hint(model: CameraModel) -> str | None:
    """What to check when a given pinhole model's tangential terms are larger than a lens's, else None."""
    if not model.is_pinhole:
        return None
    p1, p2 = (float(v) for v in to_opencv(model).distortion[2:4])
    if max(abs(p1), abs(p2)) <= TANGENTIAL_LIMIT:
        return None
    return (
        f"its given tangential terms p1 {p1:g}, p2 {p2:g} are larger than a lens's (a few thousandths) and move "
        "the image as the principal point would: check D's order (k1, k2, p1, p2, k3)"
    )
