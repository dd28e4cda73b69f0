"""What each camera sees: how many images gave a view and why the others did not, the lights it
masks, and whether its LEDs are exposed well (saturating, too dim, streaking), with what to do.

A :class:`CameraHealth` collects, view by view, how the wand's LEDs looked (:class:`ViewLight`);
:func:`health_report` turns it, with the camera's counts and masks, into a :class:`HealthReport`
whose :meth:`HealthReport.messages` are the sentences a user reads (the collector's status and
warnings, ``wand-calib detect``'s summary, the report).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.detection.blobs import Blobs, distances
from wand_calib_ros.detection.masks import Mask, write_mask
from wand_calib_ros.io.detection_summary import REASON_TEXT, masks_folder, write_summary

FloatArray = NDArray[np.float64]

#: The views a camera's light statistics are taken over (the newest; a live session runs long).
HEALTH_VIEWS = 2000
#: Say the LEDs saturate when at least this fraction of the views' LEDs reach the image's maximum value.
SATURATED_WARN = 0.5
#: An LED is dim when its peak is within this factor of the contrast that finds it ...
DIM_FACTOR = 2.0
#: ... and say so when the dimmest LED of at least this fraction of the views is.
DIM_WARN = 0.2
#: Say the LEDs streak when the median streak is at least this long, px.
STREAK_WARN_PX = 6.0
#: Fewest views before the exposure is judged.
MIN_VIEWS_JUDGED = 20


@dataclass(frozen=True)
class ViewLight:
    """How the LEDs of one view looked, per LED (K,).

    Attributes:
        peaks: brightest value above the LED's background, grey levels.
        saturated: a pixel reached the image's maximum value.
        lengths: motion streak length, px.
        contrast: how far above its background a pixel had to be to count there, grey levels.
        brightness: how bright it was, stops over full scale (:func:`~wand_calib_ros.detection.blobs.brightness_stops`;
            NaN: not measured).
    """

    peaks: FloatArray
    saturated: NDArray[np.bool_]
    lengths: FloatArray
    contrast: FloatArray
    brightness: FloatArray


def view_light(blobs: Blobs, points: FloatArray) -> ViewLight | None:
    """The light of a view's LEDs: the blobs nearest its (K, 2) points (None: the blobs were not measured)."""
    if blobs.lengths is None or blobs.contrast is None or not blobs.centres.size:
        return None
    finite = np.isfinite(points).all(axis=1)
    nearest = distances(points if finite.all() else points[finite], blobs.centres).argmin(axis=1)
    brightness = np.full(nearest.size, np.nan) if blobs.brightness is None else blobs.brightness[nearest]
    return ViewLight(
        blobs.peaks[nearest], blobs.saturated[nearest], blobs.lengths[nearest], blobs.contrast[nearest], brightness
    )


class CameraHealth:
    """One camera's views' light, the newest HEALTH_VIEWS of them."""

    def __init__(self) -> None:
        self._views: deque[ViewLight] = deque(maxlen=HEALTH_VIEWS)

    def add(self, light: ViewLight | None) -> None:
        """One view's light (None: not measured)."""
        if light is not None and light.peaks.size:
            self._views.append(light)

    def __len__(self) -> int:
        return len(self._views)

    def figures(self) -> dict[str, float]:
        """saturated (fraction of the LEDs), dim (fraction of the views whose dimmest LED is dim), peak_median,
        streak_median_px and streak_p95_px over the collected views (empty: none)."""
        if not self._views:
            return {}
        peaks = np.concatenate([v.peaks for v in self._views])
        lengths = np.concatenate([v.lengths for v in self._views])
        saturated = np.concatenate([v.saturated for v in self._views])
        dim = [bool(np.any(v.peaks < DIM_FACTOR * v.contrast)) for v in self._views]
        return {
            "saturated": float(saturated.mean()),
            "dim": float(np.mean(dim)),
            "peak_median": float(np.median(peaks)),
            "streak_median_px": float(np.median(lengths)),
            "streak_p95_px": float(np.percentile(lengths, 95)),
        }


@dataclass(frozen=True)
class HealthReport:
    """What one camera saw.

    Attributes:
        camera: its name.
        images: images received.
        views: views of the wand labelled.
        no_view: images without a view, by reason (:data:`REASON_TEXT`).
        sources: (u, v, radius) px of the static lights it learned and masks.
        masked_fraction: the fraction of its image masked (learned, given and taken masks).
        light: :meth:`CameraHealth.figures` of its views (empty before any view).
        judged: views enough (MIN_VIEWS_JUDGED) to judge the exposure.
    """

    camera: str
    images: int
    views: int
    no_view: Mapping[str, int]
    sources: tuple[tuple[float, float, float], ...]
    masked_fraction: float
    light: Mapping[str, float]
    judged: bool

    def warnings(self) -> dict[str, str]:
        """The exposure's problems, by cause ("saturated", "dim", "streak"), each with what to do."""
        out: dict[str, str] = {}
        light = self.light
        if not self.judged:
            return out
        if light.get("saturated", 0.0) >= SATURATED_WARN:
            out["saturated"] = (
                f"{self.camera}: its LEDs saturate in {100 * light['saturated']:.0f} % of its views (flat tops, less "
                "precise centres): shorten the exposure or dim the LEDs"
            )
        if light.get("dim", 0.0) >= DIM_WARN:
            out["dim"] = (
                f"{self.camera}: the dimmest LED of {100 * light['dim']:.0f} % of its views is within "
                f"{DIM_FACTOR:g}x of what can be found (far or turned away): lengthen the exposure, raise the gain "
                "or brighten the LEDs"
            )
        if light.get("streak_median_px", 0.0) >= STREAK_WARN_PX:
            out["streak"] = (
                f"{self.camera}: its LEDs streak {light['streak_median_px']:.0f} px over the exposure (median; "
                f"{light['streak_p95_px']:.0f} px at the 95th percentile): shorten the exposure or wave slower"
            )
        return out

    def messages(self) -> list[str]:
        """What a user reads: the warnings with what to do first, then what was masked and why images gave no view."""
        out = list(self.warnings().values())
        if self.sources or self.masked_fraction > 0:
            out.append(
                f"{self.camera}: {len(self.sources)} static light{'s' if len(self.sources) != 1 else ''} learned and "
                f"masked; {100 * self.masked_fraction:.1f} % of the image ignored"
            )
        missing = sum(self.no_view.values())
        if self.images and missing:
            reasons = sorted(self.no_view.items(), key=lambda kv: -kv[1])[:3]
            said = ", ".join(f"{REASON_TEXT.get(reason, reason)} {count}" for reason, count in reasons if count > 0)
            out.append(f"{self.camera}: {missing} of {self.images} images gave no view ({said})")
        return out

    def as_dict(self) -> dict[str, Any]:
        """The report as plain values (YAML, diagnostics)."""
        return {
            "images": self.images,
            "views": self.views,
            "no_view": {k: int(v) for k, v in sorted(self.no_view.items()) if v},
            "static_lights": [[round(u, 1), round(v, 1), round(r, 1)] for u, v, r in self.sources],
            "masked_fraction": round(self.masked_fraction, 5),
            **{k: round(v, 4) for k, v in self.light.items()},
            "messages": self.messages(),
        }


def health_report(
    camera: str,
    images: int,
    views: int,
    no_view: Mapping[str, int],
    health: CameraHealth,
    sources: tuple[tuple[float, float, float], ...],
    masked_fraction: float,
) -> HealthReport:
    """A camera's :class:`HealthReport` from its counts, its views' light and its masks."""
    return HealthReport(
        camera,
        images,
        views,
        dict(no_view),
        sources,
        masked_fraction,
        health.figures(),
        len(health) >= MIN_VIEWS_JUDGED,
    )


def save_what_cameras_saw(
    observations: Path, reports: Mapping[str, HealthReport], masks: Mapping[str, Mask | None]
) -> Path:
    """Write, beside an observations CSV, each camera's report (``<stem>.detection.yaml``) and the mask its
    detector ended with (``<stem>.masks/<camera>.png``, :mod:`wand_calib_ros.io.detection_summary`); returns
    the summary's path."""
    folder = masks_folder(observations)
    cameras = {}
    for name, report in reports.items():
        entry = report.as_dict()
        mask = masks.get(name)
        if mask is not None and mask.any():
            write_mask(folder / f"{name}.png", mask)
            entry["mask"] = f"{folder.name}/{name}.png"
        cameras[name] = entry
    return write_summary(observations, cameras)
