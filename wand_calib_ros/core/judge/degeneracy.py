"""Data that cannot determine a calibration, refused with what to do: wand motion on a line or in a plane,
a camera left with too few views, intrinsics the data leave undetermined."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.adjust.bundle_adjustment import BundleResult
from wand_calib_ros.core.adjust.gating import MIN_CAMERA_VIEWS
from wand_calib_ros.core.adjust.narrow_field import NARROW_FIELD_DEG, field_of_view_deg
from wand_calib_ros.core.errors import DegenerateDataError, InsufficientDataError
from wand_calib_ros.core.model.rig import RigSpec
from wand_calib_ros.core.model.views import whole_views

FloatArray = NDArray[np.float64]

#: Wand points whose second (third) principal spread is below this fraction of the first lie on a line (plane).
DEGENERATE_SPREAD = 0.03
#: Relative focal-length and principal-point (fraction of the image width) standard deviations that make
#: a calibration meaningless.
MAX_FOCAL_STD = 0.05


MAX_CENTRE_STD = 0.1


def require(count: int, needed: int, what: str) -> None:
    if count < needed:
        raise InsufficientDataError(f"only {count} placements {what}; need at least {needed}")


def check_geometry(points: FloatArray) -> None:
    """Refuse wand motion that cannot determine a calibration.

    Args:
        points: (P, 3, 3) wand points A, B, C of the adjusted placements, mm.

    Raises:
        DegenerateDataError: every wand point lies on (nearly) one line or one plane.
    """
    flat = points.reshape(-1, 3)
    spread = np.linalg.svd(flat - flat.mean(axis=0), compute_uv=False) / np.sqrt(flat.shape[0])
    if spread[1] < DEGENERATE_SPREAD * spread[0]:
        raise DegenerateDataError(
            f"the wand moved along a single line (spread {spread[0]:.0f} mm along it, {spread[1]:.0f} mm across): "
            "move and turn it through the whole volume"
        )
    if spread[2] < DEGENERATE_SPREAD * spread[0]:
        raise DegenerateDataError(
            f"the wand moved only in a plane ({spread[2]:.0f} mm thick over {spread[0]:.0f} mm): the calibration "
            "is not determined; move it towards and away from the cameras too"
        )


def check_camera_views(rig: RigSpec, uv_seen: FloatArray, uv_used: FloatArray) -> None:
    """Refuse a solution in which a camera kept fewer than MIN_CAMERA_VIEWS views.

    Args:
        rig: the rig description.
        uv_seen: (P, C, 3, 2) every placement as observed.
        uv_used: (P', C, 3, 2) the placements and views the solution uses (rejected views NaN).

    Raises:
        InsufficientDataError: naming the camera and how many of its views were left.
    """
    views = whole_views(uv_used).sum(axis=0)
    seen = whole_views(uv_seen).sum(axis=0)
    for c, spec in enumerate(rig.cameras):
        if views[c] < MIN_CAMERA_VIEWS:
            raise InsufficientDataError(
                f"camera '{spec.name}': only {views[c]} of its {seen[c]} views fit the solution "
                f"(need {MIN_CAMERA_VIEWS}); "
                "the others failed the wand-length gate or were outliers. Wave the wand where it and the "
                "other cameras see it together, through more of its view"
            )


def check_uncertainty(rig: RigSpec, result: BundleResult) -> None:
    """Refuse a solution whose focal lengths or principal points the data do not determine.

    Raises:
        DegenerateDataError: naming the camera and its uncertainties.
    """
    for c, (spec, model) in enumerate(zip(rig.cameras, result.state.models, strict=True)):
        focal = result.camera_std[c, 0] / model.k[0]
        centre = float(np.max(result.camera_std[c, 5:7]))
        if not (focal <= MAX_FOCAL_STD and centre <= MAX_CENTRE_STD * spec.image_size[0]):  # NaN: undetermined
            field = field_of_view_deg(spec)  # a wand's views hardly fix a long lens's focal
            narrow = field < NARROW_FIELD_DEG
            raise DegenerateDataError(
                f"camera '{spec.name}': the data do not determine its intrinsics (focal length +-{100 * focal:.0f} %, "
                f"principal point +-{centre:.0f} px); "
                + (
                    f"its field of view is narrow ({field:.1f} deg across): give its focal "
                    f"(intrinsics: K, as a start with fixed: false, or check nominal_focal_mm "
                    f"{spec.nominal_focal_mm:g}), a wand alone hardly fixes it there"
                    if narrow
                    else f"wave the wand through more of its view, nearer and farther, or give {spec.name}'s focal "
                    "(intrinsics: K, fixed: false as a start)"
                )
            )
