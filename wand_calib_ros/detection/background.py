"""The local background of an image and its noise: where a pixel stands out.

A room's images are not a dark field with spots: a wall lit unevenly, a window, the halo of
a lamp. A threshold that follows the brightest pixel (a lamp sets it) loses LEDs that are
10-20 grey levels above a dark wall. Here each region's threshold is its own background
plus a few times its own noise:

- the background is measured on every STEP-th pixel of every STEP-th row, as the median of
  SPOT_SAMPLES x SPOT_SAMPLES samples (spots narrower than about half that, LEDs and lamps, do
  not raise it; a window does), then widened to the largest of its neighbours so that the
  soft edge of a bright area stays below its own threshold;
- the noise grows with the signal (shot noise): its variance is fitted as a + b x level to
  tiles of the samples (the lower half of their squared differences of neighbouring samples,
  so that edges crossing a tile do not count), so a bright window's noise does not make
  blobs while a dark wall's threshold stays low;
- the threshold image is the background plus max(noise_sigmas x noise, min_contrast),
  bilinear between the samples.

The detector thresholds sums of 3 x 3 pixels (:func:`box_sums`): a dim spot stands out of them
about 1.6 times more clearly than its brightest pixel from the image.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Samples are every STEP-th pixel of every STEP-th row.
STEP = 4
#: The background is the median of this many samples square (the largest median filter OpenCV has for 16 bits).
SPOT_SAMPLES = 5
#: Tiles of this many samples square estimate the noise.
TILE_SAMPLES = 8
#: The mean of the lower half of TILE_SAMPLES^2 draws of a chi-square with one degree of freedom (measured over
#: 2e7 tiles): a tile's differences of neighbouring samples, squared, average this times their variance over
#: their lower half, whatever edges (a window's frame, a bar) cross the other half.
LOWER_HALF_MEAN = 0.1509


@dataclass(frozen=True)
class BackgroundOptions:
    """Where a pixel stands out.

    Attributes:
        noise_sigmas: a blob pixel stands this many noise standard deviations above its background ...
        min_contrast: ... and at least this many grey levels (of an 8-bit image; scaled for 16-bit images).
    """

    noise_sigmas: float = 5.0
    min_contrast: float = 5.0


@dataclass(frozen=True, eq=False)
class Background:
    """An image's local background and noise.

    Attributes:
        level: (H / step, W / step) the background at every step-th pixel, grey levels.
        noise: (H / step, W / step) the noise standard deviation there, grey levels.
        threshold: (H, W) the full image's threshold (the image's dtype): a pixel above it stands out.
        step: the samples' spacing, px (STEP; 1 for an image too small to sample).
        sums: the box sums it was estimated from, when they are the image's that is about to be searched (a
            stream's background is used for several images; :func:`~wand_calib_ros.detection.blobs.find_blobs`
            takes them instead of summing again), else None.
        unit: the unit of min_contrast in the image it was estimated from.
        search: (H, W) the threshold blobs are searched against, a mask's pixels out of reach (:func:`masked`);
            None: ``structure`` or ``threshold`` (and a mask is applied to each image).
        structure: (H, W) the threshold that follows the camera's static structure pixel by pixel
            (:mod:`~wand_calib_ros.detection.structure`), or None: none learned yet (``threshold`` applies).
        static: (H, W) the static structure's pixels (the grey image's dtype: what never moves, taken away
            before a spot is measured), or None.
        static_noise: (a, b) of a pixel's noise variance a + b x level over time (grey levels), with ``static``.
        static_sums: (H, W) the static structure's box sums (the threshold's dtype), with ``static``.
    """

    level: FloatArray
    noise: FloatArray
    threshold: NDArray[Any]
    step: int = STEP
    sums: NDArray[Any] | None = None
    unit: float = 1.0
    search: NDArray[Any] | None = None
    structure: NDArray[Any] | None = None
    static: NDArray[Any] | None = None
    static_noise: tuple[float, float] = (0.0, 0.0)
    static_sums: NDArray[Any] | None = None

    @property
    def searched(self) -> NDArray[Any]:
        """What blobs are searched against: the masked threshold, else the structure's, else the threshold."""
        if self.search is not None:
            return self.search
        return self.threshold if self.structure is None else self.structure

    def at(self, uv: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(N,) background level and noise at (N, 2) pixels (their nearest samples')."""
        rows = np.clip(np.round(uv[:, 1] / self.step).astype(int), 0, self.level.shape[0] - 1)
        cols = np.clip(np.round(uv[:, 0] / self.step).astype(int), 0, self.level.shape[1] - 1)
        return self.level[rows, cols], self.noise[rows, cols]


def noise_model(level: FloatArray, variance: FloatArray, *, from_median: bool = False) -> tuple[float, float]:
    """(a, b) of variance = a + b x level fitted to tiles (a, b >= 0), by least squares that drop, three times
    over, the tiles more than three times above the fit (a lamp or an LED in the tile, a textured window).
    ``from_median``: the first fit leaves out the tiles more than three times the median variance too (one bright
    tile far from the others, a lamp that flickered between two images, would otherwise set the slope)."""
    x, y = level.ravel().astype(np.float64), variance.ravel().astype(np.float64)
    keep = y <= 3.0 * float(np.median(y)) + 1e-6 if from_median else np.ones(x.size, dtype=bool)
    a, b = float(np.mean(y)), 0.0
    for _ in range(3):
        n = float(keep.sum())
        if n < 2:
            break
        kept_x, kept_y = x[keep], y[keep]
        sx, sy = float(kept_x.sum()), float(kept_y.sum())
        sxx, sxy = float(kept_x @ kept_x), float(kept_x @ kept_y)
        spread = n * sxx - sx * sx
        b = max((n * sxy - sx * sy) / spread, 0.0) if spread > 1e-9 * max(n * sxx, 1.0) else 0.0
        a = max((sy - b * sx) / n, 0.0)
        keep = y <= 3.0 * (a + b * x) + 1e-6
    return a, b


def tile_noise(squared: NDArray[np.float32], level: NDArray[np.float32]) -> tuple[FloatArray, FloatArray]:
    """(level, noise variance) per tile of TILE_SAMPLES x TILE_SAMPLES of an image of squared differences of
    independent samples (twice the noise's variance: neighbours STEP px apart, or one pixel in two images) and the
    level there; one tile of everything when there are fewer than a tile's worth. A tile's variance is from the
    lower half of its squared differences (LOWER_HALF_MEAN): edges or an LED crossing the other half do not
    count."""
    rows, cols = squared.shape[0] // TILE_SAMPLES, squared.shape[1] // TILE_SAMPLES
    if rows < 1 or cols < 1:
        tiles = squared.reshape(1, -1)
        levels = np.array([[float(np.median(level))]])
    else:
        height, width = rows * TILE_SAMPLES, cols * TILE_SAMPLES
        blocks = squared[:height, :width].reshape(rows, TILE_SAMPLES, cols, TILE_SAMPLES)
        tiles = blocks.transpose(0, 2, 1, 3).reshape(rows * cols, -1)
        levels = cv2.resize(level[:height, :width], (cols, rows), interpolation=cv2.INTER_AREA)
    if tiles.shape[1] < 2:
        return np.zeros((1, 1)), np.zeros((1, 1))
    half = tiles.shape[1] // 2
    lower = np.partition(tiles, half - 1, axis=1)[:, :half].mean(axis=1)
    variance = lower / (2.0 * LOWER_HALF_MEAN)
    return levels.astype(np.float64).reshape(-1), variance.astype(np.float64)


def _spatial_noise(samples: NDArray[np.float32], median: NDArray[np.float32]) -> tuple[FloatArray, FloatArray]:
    """(level, noise variance) of tiles of neighbouring samples' differences, every other row (enough, and half the
    cost)."""
    rows, cols = samples.shape[0] // (2 * TILE_SAMPLES), (samples.shape[1] - 1) // TILE_SAMPLES
    if rows < 1 or cols < 1:
        return tile_noise(np.square(samples[:, 1:] - samples[:, :-1]).reshape(1, -1), median)
    height, width = 2 * rows * TILE_SAMPLES, cols * TILE_SAMPLES
    squared = np.square(samples[:height:2, 1 : width + 1] - samples[:height:2, :width])
    return tile_noise(squared, median[:height:2, :width])


def estimate_background(
    image: NDArray[Any], options: BackgroundOptions = BackgroundOptions(), *, unit: float | None = None
) -> Background:
    """The local background, noise and threshold image of an image (see the module docstring).

    Args:
        image: (H, W) uint8, uint16 or float32 image: grey levels, or sums of them (:func:`box_sums`).
        options: how far above its background a pixel must be.
        unit: how many of the image's units one grey level of an 8-bit image is (min_contrast is in those):
            default 1 for uint8, 257 for uint16 images.
    """
    height, width = image.shape
    full = saturation_of(image) if image.dtype.kind == "u" else np.inf
    unit = (1.0 if image.dtype == np.uint8 else 257.0) if unit is None else unit
    step = STEP if min(height, width) >= 2 * STEP * TILE_SAMPLES else 1  # (a small image: every pixel)
    sampled = cv2.resize(image, (width // step, height // step), interpolation=cv2.INTER_NEAREST)
    samples = sampled.astype(np.float32)
    median = cv2.medianBlur(sampled, SPOT_SAMPLES).astype(np.float32)
    level = cv2.dilate(median, np.ones((5, 5), np.uint8), borderType=cv2.BORDER_REPLICATE)
    a, b = noise_model(*_spatial_noise(samples, median))
    noise = np.sqrt(a + b * level)
    contrast = np.maximum(options.noise_sigmas * noise, options.min_contrast * unit)
    small = np.minimum(np.ceil(level + contrast), full).astype(image.dtype)
    threshold = cv2.resize(small, (width, height), interpolation=cv2.INTER_LINEAR)
    return Background(level.astype(np.float64), noise.astype(np.float64), threshold, step, None, unit)


def masked(background: Background, mask: NDArray[np.uint8] | None) -> Background:
    """The background whose search threshold no sum reaches where ``mask`` (H, W) is non-zero: a stream's
    mask is then applied once per background rather than to each image."""
    if mask is None:
        return replace(background, search=None)
    search = (background.threshold if background.structure is None else background.structure).copy()
    search[mask > 0] = saturation_of(search) if search.dtype.kind == "u" else np.inf
    return replace(background, search=search)


def saturation_of(gray: NDArray[Any]) -> float:
    """The largest value an image of this dtype holds (what a saturated pixel reads; 255 for a float image)."""
    dtype = gray.dtype
    if dtype == np.uint8:  # (the common cases without numpy.iinfo, which costs microseconds a call)
        return 255.0
    if dtype == np.uint16:
        return 65535.0
    return float(np.iinfo(dtype).max) if dtype.kind == "u" else 255.0


#: The sums that detect spots are over this many pixels square.
BOX = 3


def sums_dtype(gray: NDArray[Any]) -> type[np.uint16] | type[np.float32]:
    """The dtype of a grey image's :func:`box_sums`: uint16 for 8-bit pixels (exact), float32 for others."""
    return np.uint16 if gray.dtype == np.uint8 else np.float32


def box_sums(gray: NDArray[Any]) -> tuple[NDArray[Any], float]:
    """(sums, unit) of every BOX x BOX neighbourhood of a grey image, and the unit of min_contrast in them.

    Thresholding the sums rather than the pixels finds a dim spot whose peak is a few noise sigmas: a BOX x BOX
    sum holds about 4.7 times a 1-pixel spot's peak and only BOX times the noise (a spot found at 5 sigmas of
    the sums has a peak of about 3.2 sigmas of the pixels). min_contrast, a floor for images whose noise is
    smoothed away (JPEG), counts BOX grey levels a unit. Sums of 8-bit images are exact in uint16; 16-bit
    images' in float32."""
    depth, unit = (cv2.CV_16U, float(BOX)) if gray.dtype == np.uint8 else (cv2.CV_32F, BOX * 257.0)
    sums = cv2.boxFilter(gray, depth, (BOX, BOX), normalize=False, borderType=cv2.BORDER_REPLICATE)
    return sums, unit


#: Images of at least this many pixels are compared with their threshold band by band (:func:`box_sums_above`) ...
BANDED_PIXELS = 1 << 20
#: ... this many rows at a time.
ABOVE_BAND_ROWS = 64


def box_sums_above(gray: NDArray[Any], threshold: NDArray[Any]) -> NDArray[np.uint8]:
    """(H, W) 255 where the box sums of a grey image (:func:`box_sums`) are above ``threshold`` (H, W, in the sums'
    dtype), 0 elsewhere: the same pixels as comparing :func:`box_sums` with it, band by band (ABOVE_BAND_ROWS, each
    summed with a row of the bands around it) for an image of BANDED_PIXELS or more, whose sums and threshold
    outgrow a core's cache (at 1280x1024 0.53 ms instead of 0.62); a smaller image at once."""
    height = gray.shape[0]
    if gray.size < BANDED_PIXELS:
        return np.asarray(cv2.compare(box_sums(gray)[0], threshold, cv2.CMP_GT), dtype=np.uint8)
    above = np.empty(gray.shape[:2], np.uint8)
    for top in range(0, height, ABOVE_BAND_ROWS):
        bottom = min(top + ABOVE_BAND_ROWS, height)
        first, last = max(top - 1, 0), min(bottom + 1, height)
        sums = box_sums(gray[first:last])[0][top - first : bottom - first]
        cv2.compare(sums, threshold[top:bottom], cv2.CMP_GT, dst=above[top:bottom])
    return above
