"""A point file's pixel origin decided from the data: how well the points calibrate with the cameras' given
intrinsics from each origin.

Where the intrinsics are written in OpenCV's frame (a board calibration's TOML) and the points' origin is not
written, the wrong origin mirrors the points about the image's middle row but not the principal point and the
lens's distortion: the calibration with the intrinsics held is refused, or fits worse (a larger pixel noise
estimated from its residuals). Where the lens is nearly symmetric about the image's middle row, or the wand
stays small in the image, both fit alike and the data do not tell. (Intrinsics written in the points' own frame
turn with them: both origins then fit exactly alike, one the other's mirror image.)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from wand_calib_ros.core.model.camera_model import CameraModel
from wand_calib_ros.core.model.rig import RigSpec, WandObservations
from wand_calib_ros.errors import WandCalibError
from wand_calib_ros.io.imports.pixels import ORIGINS, WrittenPoints

#: How much larger the pixel noise the wrong origin's calibration estimates must be for the data to tell.
CLEAR_RATIO = 1.2


@dataclass(frozen=True)
class OriginFit:
    """How the points calibrate from each origin.

    Attributes:
        sigma_px: origin -> the pixel noise the calibration estimates (NaN where it was refused).
        refusals: origin -> why its calibration was refused (absent where it calibrated).
        chosen: the origin that fits clearly better, or None: the data do not tell.
    """

    sigma_px: dict[str, float]
    refusals: dict[str, str]
    chosen: str | None

    def in_words(self) -> str:
        """Each origin's fit, in words."""
        return "; ".join(
            f"{origin}: {self.refusals[origin]}" if origin in self.refusals else f"{origin}: noise {sigma:.2f} px"
            for origin, sigma in self.sigma_px.items()
        )


def fit_origins(written: WrittenPoints, rig: RigSpec, models: Sequence[CameraModel]) -> OriginFit:
    """The points calibrated from each origin with the given intrinsics (OpenCV's frame) held.

    Args:
        written: the points as written (their origin not known).
        rig: the rig description.
        models: each camera's given intrinsics, the rig's order.
    """
    from wand_calib_ros.core.pipeline import calibrate

    held = replace(
        rig,
        cameras=tuple(
            replace(spec, intrinsics=model, intrinsics_fixed=True)
            for spec, model in zip(rig.cameras, models, strict=True)
        ),
    )
    heights = np.array([spec.image_size[1] for spec in rig.cameras], dtype=np.float64)
    sigma, refusals = {}, {}
    for origin in ORIGINS:
        observations = WandObservations(written.frames, rig.camera_names, written.uv(heights, origin))
        try:
            sigma[origin] = calibrate(held, observations).sigma_px
        except WandCalibError as error:
            sigma[origin], refusals[origin] = float("nan"), f"refused ({error})"
    fits = [origin for origin in ORIGINS if origin not in refusals]
    if len(fits) == 1:
        chosen: str | None = fits[0]
    elif len(fits) == 2:
        low, high = sorted(fits, key=lambda origin: sigma[origin])
        chosen = low if sigma[high] > CLEAR_RATIO * sigma[low] else None
    else:
        chosen = None
    return OriginFit(sigma, refusals, chosen)
