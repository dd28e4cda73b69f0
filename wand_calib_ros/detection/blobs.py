"""Bright blobs: the spots that stand out of their local background, with sub-pixel centres.

A pixel belongs to a blob when it is above its threshold (the camera's static structure plus a few times
its noise over time, :mod:`wand_calib_ros.detection.structure`; before one is learned, the local background
plus a few times its noise, :mod:`wand_calib_ros.detection.background`), and is not masked (a mask the user
gave, a light the camera learned). Connected pixels are one blob; size gates reject single hot pixels and
large bright areas. Each blob is measured in a window around it, the static structure taken away
(:mod:`wand_calib_ros.detection.centres`): its centre (a saturated spot's by its outline), its peak above its
own background, the length of its motion streak, and whether it is cut (by the image border, a mask, a
saturated light, or a brighter region that hid part of it: its centre is not trusted). A small blob that
touches a much larger one, or a faint fleck in its halo, is a fringe of it (JPEG ringing, demosaicing, a
blooming LED's halo) and is dropped.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.detection.background import (
    BOX,
    Background,
    BackgroundOptions,
    box_sums,
    box_sums_above,
    estimate_background,
    saturation_of,
    sums_dtype,
)
from wand_calib_ros.detection.centres import (
    SATURATED_FLOOR,
    SpotCentre,
    saturated_centre,
    side_medians,
    spot_centre,
)
from wand_calib_ros.detection.errors import ImageError
from wand_calib_ros.detection.structure import SATURATED_STATIC

FloatArray = NDArray[np.float64]

#: Encodings accepted by :func:`to_gray` (sensor_msgs/Image names).
ENCODINGS = (
    "mono8",
    "mono16",
    "bgr8",
    "rgb8",
    "bgra8",
    "rgba8",
    "bayer_rggb8",
    "bayer_bggr8",
    "bayer_gbrg8",
    "bayer_grbg8",
)

#: OpenCV's conversions by the sensor's pattern (its older names, e.g. BayerRG, call the same patterns by
#: other letters: BayerRGGB2GRAY is BayerBG2GRAY).
_BAYER = {
    "bayer_rggb8": cv2.COLOR_BayerRGGB2GRAY,
    "bayer_bggr8": cv2.COLOR_BayerBGGR2GRAY,
    "bayer_gbrg8": cv2.COLOR_BayerGBRG2GRAY,
    "bayer_grbg8": cv2.COLOR_BayerGRBG2GRAY,
}


@dataclass(frozen=True)
class BlobOptions:
    """Blob extraction settings.

    Attributes:
        background: how far above its local background a pixel must be.
        min_area: smallest blob (px) that counts as an LED.
        max_area: largest blob (px); larger ones are no LED (a person walking by, a lamp switched on; an LED 30x
            over full scale 0.4 m from a fisheye blooms over about 2,500 px with its streak).
        window: margin (px) around a blob's pixels in which it is measured.
    """

    background: BackgroundOptions = field(default_factory=BackgroundOptions)
    min_area: int = 2
    max_area: int = 8000
    window: int = 3


@dataclass(frozen=True, eq=False)
class Blobs:
    """Blobs of one image.

    Attributes:
        centres: (N, 2) sub-pixel centres, OpenCV pixel convention.
        areas: (N,) pixels above the threshold.
        peaks: (N,) brightest value above the blob's own background.
        saturated: (N,) True where a pixel reached the image's maximum value.
        at_border: (N,) True where the blob touches the image border (cut: its centre is pulled
            inwards); None: none does.
        masked: (N,) True where the blob is cut by what cannot be seen: masked pixels, a saturated static light, a
            brighter region that hid part of it (see :func:`find_blobs`); None: none is.
        lengths: (N,) length of the blob's motion streak, px; None: not measured.
        backgrounds: (N,) the background under the blob, grey levels; None: not measured.
        contrast: (N,) how far above that background the image's threshold is there; None: not measured.
        brightness: (N,) how bright the spot was, stops over full scale (:func:`brightness_stops`); None: not
            measured.
    """

    centres: FloatArray
    areas: NDArray[np.int64]
    peaks: FloatArray
    saturated: NDArray[np.bool_]
    at_border: NDArray[np.bool_] | None = None
    masked: NDArray[np.bool_] | None = None
    lengths: FloatArray | None = None
    backgrounds: FloatArray | None = None
    contrast: FloatArray | None = None
    brightness: FloatArray | None = None

    def cut(self, index: list[int]) -> bool:
        """Whether any of the blobs ``index`` is cut: by the image border, a mask or a saturated light."""
        border = self.at_border is not None and bool(self.at_border[index].any())
        return border or (self.masked is not None and bool(self.masked[index].any()))

    def radii(self) -> FloatArray:
        """(N,) each blob's extent as a radius, px: from its area, and its streak's length."""
        lengths = self.lengths if self.lengths is not None else np.zeros(self.areas.shape)
        return np.asarray(np.sqrt(self.areas / np.pi) + 0.5 * lengths)

    def subset(self, keep: NDArray[np.bool_]) -> Blobs:
        """The blobs where ``keep``."""

        def pick(values: NDArray[Any] | None) -> NDArray[Any] | None:
            return None if values is None else values[keep]

        return Blobs(
            self.centres[keep],
            self.areas[keep],
            self.peaks[keep],
            self.saturated[keep],
            pick(self.at_border),
            pick(self.masked),
            pick(self.lengths),
            pick(self.backgrounds),
            pick(self.contrast),
            pick(self.brightness),
        )


#: A spot's centre weighs the pixels above its background by how far they are above this many noise sigmas ...
CENTRE_FLOOR_SIGMAS = 2.0
#: A region's core is where it stands above its background by this fraction of its peak ...
CORE_FRACTION = 0.25
#: ... (and a third of this many noise sigmas); a region whose peak is this many noise sigmas is split where it
#: has two cores each as bright as 0.3 of its peak.
CORE_SPLIT = 10.0
#: A blob of at most this fraction of the area of a blob it touches is a fringe of that blob.
FRINGE_AREA = 0.1
#: ... or, in the halo of a blob (within its radius beyond touching it), of at most this fraction of its peak.
FRINGE_PEAK = 0.2
#: Blobs touch when they are closer than their radii (from their areas) plus this, px.
TOUCH_PX = 2.0


def distances(points: FloatArray, others: FloatArray) -> FloatArray:
    """(N, M) the distances between (N, 2) and (M, 2) points, px (cheaper than numpy.linalg.norm for the
    handful of blobs an image has)."""
    return np.hypot(points[:, None, 0] - others[None, :, 0], points[:, None, 1] - others[None, :, 1])


def touching(
    centres: FloatArray, areas: NDArray[np.int64], margin_px: float | FloatArray = TOUCH_PX
) -> NDArray[np.bool_]:
    """(N, N) which blobs touch or overlap: closer than their radii (from their areas) plus ``margin_px`` (a number,
    or (1, N) per blob of the second axis; the diagonal True)."""
    return np.asarray(clearances(centres, areas) < margin_px)


def clearances(centres: FloatArray, areas: NDArray[np.int64]) -> FloatArray:
    """(N, N) how far apart blobs are beyond their radii (from their areas), px (negative: they overlap)."""
    radii = np.sqrt(areas / np.pi)
    return np.asarray(distances(centres, centres) - (radii[:, None] + radii[None, :]))


def fringes(centres: FloatArray, areas: NDArray[np.int64], peaks: FloatArray) -> NDArray[np.bool_]:
    """(N,) blobs that are fringes of a larger blob: touching it and at most FRINGE_AREA of its area (JPEG ringing,
    demosaicing, a flare), or in its halo (within its radius beyond touching) and also at most FRINGE_PEAK of its
    peak (the noise on a blooming LED's halo breaks into faint flecks around it)."""
    if areas.min() > FRINGE_AREA * areas.max():  # (the common case: LEDs of like size, nothing to compare)
        return np.zeros(areas.shape, dtype=bool)
    smaller = areas[:, None] <= FRINGE_AREA * areas[None, :]
    beyond = clearances(centres, areas) - TOUCH_PX  # (< 0: touching)
    halo = (beyond < np.sqrt(areas / np.pi)[None, :]) & (peaks[:, None] <= FRINGE_PEAK * peaks[None, :])
    return np.asarray((smaller & ((beyond < 0.0) | halo)).any(axis=1))


NO_BLOBS = Blobs(np.zeros((0, 2)), np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0, dtype=bool))


def to_gray(image: NDArray[Any], encoding: str) -> NDArray[Any]:
    """A single-channel image (uint8, or uint16 for mono16) from a decoded sensor_msgs/Image array.

    Raises:
        ImageError: unknown encoding or an array that does not match it.
    """
    if encoding not in ENCODINGS:
        raise ImageError(f"unsupported image encoding '{encoding}' (supported: {', '.join(ENCODINGS)})")
    array = np.asarray(image)
    colour = encoding in ("bgr8", "rgb8", "bgra8", "rgba8")
    if array.ndim != (3 if colour else 2) or (colour and array.shape[2] != len(encoding) - 1):
        raise ImageError(f"image of shape {array.shape} does not match encoding '{encoding}'")
    if array.size == 0:
        raise ImageError("empty image")
    if encoding in _BAYER:
        array = cv2.cvtColor(array.astype(np.uint8), _BAYER[encoding])
    elif colour:
        code = {
            "bgr8": cv2.COLOR_BGR2GRAY,
            "rgb8": cv2.COLOR_RGB2GRAY,
            "bgra8": cv2.COLOR_BGRA2GRAY,
            "rgba8": cv2.COLOR_RGBA2GRAY,
        }[encoding]
        array = cv2.cvtColor(array.astype(np.uint8), code)
    return array if array.dtype in (np.uint8, np.uint16) else array.astype(np.float32)


def _local(background: Background, row: int, col: int) -> tuple[float, float, float, float]:
    """(level, noise, static, contrast) where a spot is measured (grey levels of a pixel): the level its window
    stands on once the static structure (``static`` there, 0 without) is taken away, the noise of a pixel there, and
    how far above its background the search threshold is."""
    threshold = float(background.searched[row, col])
    if background.static is not None:  # the structure taken away: a flat field of the noise over time
        static = float(background.static[row, col])
        a, b = background.static_noise
        noise = math.sqrt(max(a + b * static, 0.0))
        return 0.0, noise, static, max(threshold - BOX**2 * static, 1.0) / BOX**2
    step, levels = background.step, background.level
    sample = (min(round(row / step), levels.shape[0] - 1), min(round(col / step), levels.shape[1] - 1))
    level = float(levels[sample])
    contrast = max(float(background.threshold[row, col]) - level, 1.0) / BOX**2
    return level / BOX**2, float(background.noise[sample]) / BOX, 0.0, contrast


def _measure(
    gray: NDArray[Any],
    box: tuple[int, int, int, int],
    area: int,
    background: Background,
    options: BlobOptions,
    full: float,
    hidden: bool,
    above: NDArray[Any],
) -> list[tuple[float, ...]]:
    """The blob (or blobs) of one connected region above the threshold: (u, v, area, peak, saturated, at border,
    cut, streak length, background, contrast, brightness) each.

    The static structure (where learned) is taken away from the window first. A bright region is looked at again
    at CORE_FRACTION of its own peak: two cores there are two spots that touch at the low threshold (two LEDs close
    together), each measured on its own core; the core, not the faint halo, tells whether the spot is cut by the
    image border. A saturated spot is measured by its outline (:func:`~wand_calib_ros.detection.centres.
    saturated_centre`). ``hidden``: the spot touches a mask or continues where a brighter region hides it (it is
    cut). ``above``: the image's pixels above the search threshold (the spot's own, and what is near it)."""
    height, width = gray.shape
    x, y, bw, bh = box
    w = options.window
    x0, y0 = max(x - w, 0), max(y - w, 0)
    x1, y1 = min(x + bw + w, width), min(y + bh + w, height)
    raw = gray[y0:y1, x0:x1]  # (its pixels as the camera gave them: 8- or 16-bit)
    row, col = min(y + bh // 2, height - 1), min(x + bw // 2, width - 1)
    unit = 1.0 if gray.itemsize == 1 else 257.0  # (8- or 16-bit pixels; itemsize: a dtype comparison costs more)
    level, noise, static, contrast = _local(background, row, col)
    under: NDArray[Any] | float = 0.0 if background.static is None else background.static[y0:y1, x0:x1]
    window = (  # (float32: exact for 8- and 16-bit pixels and their differences)
        raw.astype(np.float32) if isinstance(under, float) else np.subtract(raw, under, dtype=np.float32)
    )
    floor = max(CENTRE_FLOOR_SIGMAS * noise, 0.5 * options.background.min_contrast * unit)
    peak = float(window.max()) - level
    bright = peak >= CORE_SPLIT * noise
    near_border = x <= w or y <= w or x + bw >= width - w or y + bh >= height - w
    parts: list[tuple[NDArray[np.bool_] | None, tuple[int, int, int, int]]] = [(None, (x - x0, y - y0, bw, bh))]
    cores: Sequence[NDArray[Any]] = ()
    if bright or near_border:  # its core: where it splits, and whether the border cuts it
        core = (window > level + max(CORE_FRACTION * peak, CORE_SPLIT / 3 * noise)).astype(np.uint8)
        cores, _ = cv2.findContours(core, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        if near_border:  # (only there can the core reach the border: a spot's window lies inside the image)
            parts = [(None, tuple(cv2.boundingRect(core)))]  # type: ignore[list-item]
    if bright and len(cores) >= 2:
        split: list[tuple[NDArray[np.bool_] | None, tuple[int, int, int, int]]] = []
        for outline in cores:
            drawn = np.zeros(window.shape, np.uint8)
            cv2.drawContours(drawn, [outline], -1, 1, -1)
            # a spot of its own: as bright as half the region's peak, and more than a fleck (noise on a streak)
            if drawn.sum() < options.min_area or float(window[drawn > 0].max()) - level < 0.3 * peak:
                continue
            region = np.asarray(cv2.dilate(drawn, np.ones((3, 3), np.uint8)) > 0)
            split.append((region, tuple(cv2.boundingRect(outline))))  # type: ignore[arg-type]
        parts = split if len(split) >= 2 else parts
    own = cv2.dilate(above[y0:y1, x0:x1], _SQUARE5) > 0  # its pixels (not a lamp beside it) ...
    visible: NDArray[np.bool_] | None = None  # (None: all of the window, no saturated light under it)
    if isinstance(under, np.ndarray) and float(under.max()) >= SATURATED_STATIC * full:
        visible = np.asarray(under < SATURATED_STATIC * full)  # (... nor a lamp's or a window's saturated pixels
        # under it: nothing of it can be seen there)
    seen = own if visible is None else own & visible
    if visible is not None and not seen.any():  # (its own pixels are in ``own``: seen unless hidden)
        return []
    sides = side_medians(window)
    base = 0.25 * sum(sides)
    least, ceiling = 0.0, 0.0
    clipping = float(raw.max()) >= full  # (a pixel of the window at full scale: only then can one of its own be)
    clipped = clipping and float(raw[seen].max()) >= full
    if clipped:  # saturated: measured by its outline, cut if that touches a saturated light
        # (its clipped pixels show the least of its light that any of them can), or if so little of its light shows
        # above a bright region that the noise there would shape it
        brightest = float(np.max(under[seen])) if isinstance(under, np.ndarray) else under
        least = OUTLINE_SIGMAS * _noise_at(background, brightest, noise)
        ceiling = _ceiling(raw, under, seen, full) - base
        least, touches = _clear_outline(window - base, ceiling, least, seen, visible)
        hidden |= ceiling < 2.0 * least or touches
    else:  # unsaturated: cut if its pixels touch a saturated light, or its window does not hold it (its sides on
        # the flat field)
        hidden |= visible is not None and not bool(visible[own].all())
        if background.static is not None and not hidden:
            hidden = max(sides) > max(floor, SIDE_FRACTION * peak)
    own = seen
    measured: list[tuple[float, ...]] = []
    for part, (cx, cy, cw, ch) in parts:
        mine = own if part is None else own & part
        if part is not None and not mine.any():  # (a core of something else in the window)
            continue
        saturated = clipped if part is None else clipping and float(raw[mine].max()) >= full
        if saturated:
            top = ceiling if part is None else _ceiling(raw, under, mine, full) - base
            spot: SpotCentre | None = saturated_centre(window, base, top, mine, least)
            low = min(max(SATURATED_FLOOR * top, least), 0.5 * top)  # (the outline's floor, as saturated_centre's)
            at_full = int(np.count_nonzero(mine & (raw >= full)))
            outlined = int(np.count_nonzero(mine & (window - base >= low)))
            stops = brightness_stops(at_full, outlined, top / low) if low > 0.0 else 0.0  # (no outline: just full)
        else:
            spot = spot_centre(window, floor if part is None else CORE_FRACTION * peak, mine, sides)
            if spot is not None:
                stops = math.log2(max(spot.peak, 1e-3) / max(full - static - spot.background, 1.0))
        if spot is None:
            continue
        cut = x0 + cx == 0 or y0 + cy == 0 or x0 + cx + cw == width or y0 + cy + ch == height
        size = area if part is None else int(part.sum())
        measured.append(
            (x0 + spot.u, y0 + spot.v, size, spot.peak, float(saturated), float(cut), float(hidden), spot.length_px,
             static + spot.background, contrast, min(stops, 0.0) if not saturated else stops)
        )  # fmt: skip
    return measured


def brightness_stops(clipped: int, outlined: int, ratio: float) -> float:
    """How far over full scale a saturated spot's peak was, stops (log2 of its multiple of full scale), from its
    clipped pixels and those of its outline (above ``1 / ratio`` of full scale over its background).

    A spot of Gaussian profile and peak P clips within ``2 pi s^2 ln(P / F)`` pixels of full scale F and rises
    above F / ratio within ``2 pi s^2 (ln(P / F) + ln(ratio))``: the two areas give ``log2(P / F) = log2(ratio)
    clipped / (outlined - clipped)`` whatever its size s, as near the camera as far. Other profiles (a disc, a
    streak) give a measure that still grows with the peak.
    """
    return math.log2(ratio) * clipped / max(outlined - clipped, 1)


#: An unsaturated spot continues beyond its window (a brighter region's threshold hid part of it) when a side of the
#: window, the static structure taken away, stands above the centre's floor and this fraction of its peak.
SIDE_FRACTION = 0.2


_SQUARE3, _SQUARE5 = np.ones((3, 3), np.uint8), np.ones((5, 5), np.uint8)


def _ceiling(raw: NDArray[Any], under: NDArray[Any] | float, region: NDArray[np.bool_], full: float) -> float:
    """The least light any clipped pixel of ``region`` shows above the static light ``under`` it (full scale less
    that light)."""
    clipped = region & (raw >= full)
    return float(full - (np.max(under[clipped]) if isinstance(under, np.ndarray) else under))


#: A saturated spot's outline is drawn at the lowest of these fractions of its headroom whose outline (and a pixel
#: around it) stays clear of saturated static light: a bright LED whose faint halo reaches a window's edge is
#: measured on its brighter part, which is whole (a lower outline there would be cut, and its centre pulled away).
OUTLINE_FRACTIONS = (SATURATED_FLOOR, 0.25, 0.5)


def _clear_outline(
    light: NDArray[Any], ceiling: float, least: float, seen: NDArray[np.bool_], visible: NDArray[np.bool_] | None
) -> tuple[float, bool]:
    """(the least height of a saturated spot's outline above its background, whether even the highest of
    OUTLINE_FRACTIONS touches saturated static light: it is cut); ``light``: (h, w) its window above its background,
    ``ceiling``: its headroom, ``least``: the noise's floor, ``visible``: where no saturated static light is (None:
    everywhere)."""
    if visible is None:
        return least, False
    for fraction in OUTLINE_FRACTIONS:
        outline = ((light >= max(fraction * ceiling, least)) & seen).astype(np.uint8)
        if bool(visible[cv2.dilate(outline, _SQUARE3) > 0].all()):
            return (least if fraction == SATURATED_FLOOR else max(fraction * ceiling, least)), False
    return least, True


#: A saturated spot's outline stands at least this many noise sigmas (where the noise under it is highest) above
#: its background.
OUTLINE_SIGMAS = 4.0


def _noise_at(background: Background, level: float, noise: float) -> float:
    """A pixel's noise over time at a static ``level`` (grey levels), or ``noise`` where no structure is learned."""
    if background.static is None:
        return noise
    a, b = background.static_noise
    return math.sqrt(max(a + b * level, 0.0))


def hidden_continuation(
    sums: NDArray[Any],
    above: NDArray[Any],
    threshold: NDArray[Any],
    box: tuple[int, int, int, int],
    background: Background,
) -> bool:
    """Whether a blob (its bounding ``box`` in ``above``, the search's result) may continue where it cannot be seen,
    before a static structure is learned: next to it the search threshold rises by more than the blob's own contrast
    and the light there is above the blob's own threshold (a bright region's edge: the spot may go on under it).
    Its centre would be cut. (With the structure learned, :func:`_measure` takes it away, cuts a spot next to
    saturated structure, and checks that a spot's window holds it.)"""
    height, width = above.shape
    x, y, bw, bh = box
    x0, y0, x1, y1 = max(x - 1, 0), max(y - 1, 0), min(x + bw + 1, width), min(y + bh + 1, height)
    region = above[y0:y1, x0:x1] > 0
    ring = cv2.dilate(region.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    ring &= ~region
    if not ring.any():
        return False
    limits = threshold[y0:y1, x0:x1].astype(np.float32)
    own = float(np.median(limits[region]))
    margin = max(own - _level_sum(background, y + bh // 2, x + bw // 2), 1.0)
    light = sums[y0:y1, x0:x1][ring].astype(np.float32)
    return bool(((limits[ring] > own + margin) & (light > own)).any())


def _level_sum(background: Background, row: int, col: int) -> float:
    """The spatial background's level (box sums) at a pixel."""
    step, levels = background.step, background.level
    return float(levels[min(round(row / step), levels.shape[0] - 1), min(round(col / step), levels.shape[1] - 1)])


def external_contours(binary: NDArray[Any]) -> list[NDArray[np.int32]]:
    """The external contours of a sparse (H, W) binary image, as ``cv2.findContours`` (RETR_EXTERNAL,
    CHAIN_APPROX_SIMPLE) gives them and in its order, found in the runs of rows that hold any pixel: nothing connects
    across an empty row, and the rows' maxima cost a fraction of a scan for contours (in a stream at 640x480 0.027 ms
    instead of 0.035, at 1280x1024 0.11 instead of 0.20). An image with pixels in most of its rows is scanned whole.
    External contours are in turn much cheaper than labelling the whole image."""
    occupied = np.flatnonzero(cv2.reduce(binary, 1, cv2.REDUCE_MAX)).tolist()
    if 2 * len(occupied) > binary.shape[0]:
        return list(cv2.findContours(binary, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)[0])  # type: ignore[arg-type]
    runs: list[list[int]] = []  # [first row, row after the last] of each run
    for row in occupied:
        if runs and row == runs[-1][1]:
            runs[-1][1] = row + 1
        else:
            runs.append([row, row + 1])
    contours: list[NDArray[np.int32]] = []
    for top, bottom in reversed(runs):  # (findContours lists the lowest first)
        found, _ = cv2.findContours(binary[top:bottom], cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE, offset=(0, top))
        contours.extend(found)  # type: ignore[arg-type]
    return contours


def find_blobs(
    gray: NDArray[Any],
    options: BlobOptions = BlobOptions(),
    *,
    saturation: float | None = None,
    mask: NDArray[np.uint8] | None = None,
    background: Background | None = None,
) -> Blobs:
    """Bright blobs of a grey image (see the module docstring).

    Args:
        gray: (H, W) uint8 or uint16 image.
        options: thresholds and gates.
        saturation: the value of a saturated pixel (default: the dtype's maximum; 65535 for a 12-bit camera's
            mono16 scaled to 16 bits).
        mask: (H, W) uint8, non-zero where pixels are ignored (lamps, windows), or None.
        background: the background of the image's box sums (:func:`~wand_calib_ros.detection.background.box_sums`,
            :func:`~wand_calib_ros.detection.background.estimate_background`; a recent image's will do: it changes
            slowly), or None: estimated here. Its ``search`` threshold, when set, must hold ``mask``
            (:func:`~wand_calib_ros.detection.background.masked`).
    """
    if gray.dtype not in (np.uint8, np.uint16):
        gray = np.clip(np.round(gray), 0, 65535).astype(np.uint16)
    full = saturation_of(gray) if saturation is None else saturation
    depth = sums_dtype(gray)
    above: NDArray[Any]
    if (
        background is not None
        and background.sums is None
        and background.static is not None  # (the sums are then needed for the search alone)
        and background.threshold.shape == gray.shape
        and background.threshold.dtype == depth
    ):
        sums, threshold = None, background.searched
        above = box_sums_above(gray, threshold)
    else:
        sums, unit = (
            box_sums(gray) if background is None or background.sums is None else (background.sums, background.unit)
        )
        if background is None or background.threshold.shape != sums.shape or background.threshold.dtype != sums.dtype:
            background = estimate_background(sums, options.background, unit=unit)
        threshold = background.searched
        above = cv2.compare(sums, threshold, cv2.CMP_GT)
    if background.search is None and mask is not None:  # (else the mask is in the threshold)
        above = cv2.subtract(above, mask)
    contours = external_contours(above)
    rows: list[tuple[float, ...]] = []
    for contour in contours:
        x, y, bw, bh = cv2.boundingRect(contour)
        box = (x, y, bw, bh)
        if bw * bh < options.min_area:
            continue
        area = cv2.countNonZero(above[y : y + bh, x : x + bw])
        if options.min_area <= area <= options.max_area:
            near = mask[max(y - 1, 0) : y + bh + 1, max(x - 1, 0) : x + bw + 1] if mask is not None else None
            touches = near is not None and cv2.countNonZero(near) > 0
            hidden = touches or (
                sums is not None
                and background.static is None
                and hidden_continuation(sums, above, threshold, box, background)
            )
            rows += _measure(gray, box, area, background, options, full, hidden, above)
    if not rows:
        return NO_BLOBS
    table = np.array(rows, dtype=np.float64)
    areas = table[:, 2].astype(np.int64)
    fringe = fringes(table[:, :2], areas, table[:, 3])
    if fringe.any():
        table, areas = table[~fringe], areas[~fringe]
    centres, columns = table[:, :2].copy(), table.T.copy()  # (each column contiguous, from one copy)
    return Blobs(
        centres,
        areas,
        columns[3],
        columns[4] > 0,
        columns[5] > 0,
        columns[6] > 0,
        columns[7],
        columns[8],
        columns[9],
        columns[10],
    )
