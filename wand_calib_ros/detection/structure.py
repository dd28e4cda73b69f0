"""Static structure: what a camera sees that never moves, learned from its own images, so that only what moves
stands out.

A room is not a smooth wall: a lab floor has painted lines and grain, a glossy floor broad reflections of the
ceiling lamps, a room chair legs and glints, a window its bars. A threshold from a spatial median (the local
background of :mod:`~wand_calib_ros.detection.background`, about 20 px across) does not follow a 5 px stripe, so
the stripe's pieces are blobs, collinear ones wand-like; and it is widened over a bright region's neighbourhood,
so an LED 30 grey levels above a reflection's slope stays below it. Over time, though, the wand moves and the
room does not:

- every SNAPSHOT_NS (the first few EARLY_NS apart) the image's box sums are kept, the newest SNAPSHOTS of them
  (three seconds); the structure is their per-pixel median: a moving LED is at a pixel in one or two
  of them, so it is not part of it (an LED at rest for longer is: it is still, not the wand). Once QUIET_SNAPSHOTS
  snapshots in a row changed nothing, the room is still: a snapshot due is only compared with the structure and
  kept when it differs, or every QUIET_NS;
- the structure's threshold is made again when a snapshot changes it: where the snapshot stands above the
  threshold or below the structure by as much (a lamp switched on or off, a chair moved) on more than
  CHANGED_PIXELS pixels, or when the noise changed by NOISE_CHANGE; and at least every SNAPSHOTS snapshots, so
  that it is never older than its window. A still room's snapshots change no threshold: it is made once in a
  window, and only the structure's pixels (the median spots are measured on) follow every snapshot;
- the threshold that follows it is the structure plus the noise's contrast at its level. The noise is measured
  over time, from two snapshots' differences (tiles' lower halves, as the background measures it in space): a
  floor's grain or a window's bars are structure, not noise;
- light that flickers (a mains lamp's glare varies by 10 % and more from image to image, JPEG blocks shift with
  the noise) spreads its snapshots: FLICKER_SPREAD times the spread between their median and their second largest
  beyond what the noise spreads (SPREAD_NOISE of its standard deviation) is added where it shows. A painted stripe
  does not flicker and keeps the noise's threshold; the wand is kept out of the snapshots where its track is
  known, and an LED passing a pixel in one snapshot moves neither the median nor the second largest. Only light
  that stands above its surroundings (the spatial background) flickers, by at most FLICKER_MAX of what it stands
  above them: a wand passing twice over a dark wall does not raise its threshold. Until there are SNAPSHOTS of
  them, such light is assumed to flicker by that much and any light by EARLY_FLICKER, and the threshold is never
  below the spatial one.

An LED in front of a stripe or a reflection is found where it stands out of that: the threshold follows the
structure pixel by pixel.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.detection.background import (
    STEP,
    Background,
    BackgroundOptions,
    noise_model,
    tile_noise,
)

#: A snapshot of the box sums is kept this often (ns) ...
SNAPSHOT_NS = 600_000_000
#: ... the first EARLY_SNAPSHOTS of them this often (a structure within a tenth of a second of the start, whole in
#: a fifth).
EARLY_NS = 50_000_000
EARLY_SNAPSHOTS = 5
#: The structure is the median of the newest this many snapshots (odd), once there are MIN_SNAPSHOTS.
SNAPSHOTS = 5
MIN_SNAPSHOTS = 3
#: Flickering light's threshold: this many times the spread of its snapshots (second largest minus median) beyond
#: what the noise spreads them (SPREAD_NOISE noise sigmas: the spread's mean for five draws of pure noise is 0.5).
#: A lamp flickering uniformly by +-f spreads five snapshots by f / 3 on average.
FLICKER_SPREAD = 4.0
SPREAD_NOISE = 0.8

#: Static light that stands above its surroundings (the spatial background) flickers by at most this fraction of
#: what it stands above them (mains lamps: 10-20 %); until there are SNAPSHOTS snapshots, it is assumed to.
FLICKER_MAX = 0.3
#: ... and until there are SNAPSHOTS snapshots, any static light may flicker by this fraction of it.
EARLY_FLICKER = 0.15

#: A static pixel this close to full scale (a fraction) is saturated: nothing of a spot can be seen there.
SATURATED_STATIC = 0.98
#: Saturated static pixels this many apart belong to one static light ...
LIGHT_GAP_PX = 4
#: ... and a light has at least this many of them (a lone saturated pixel is a speck of a bright region's edge).
MIN_LIGHT_PX = 4

#: A snapshot changes the structure when more than this many of its box sums stand above the search threshold or
#: below the structure by as much (noise alone: about one pixel in a million beyond five sigmas) ...
CHANGED_PIXELS = 16
#: ... or when the noise's variance at a typical level changed by more than this factor (a gain or exposure
#: changed; one estimate's scatter is a few percent).
NOISE_CHANGE = 1.5

#: Once this many snapshots in a row changed nothing, the room is still: a snapshot due is only compared with the
#: structure (its box sums beyond the threshold or below the floor, the wand's discs left out: no noise, no median)
#: and kept only when that finds a change, or when the newest kept one is QUIET_NS old. A lamp switched on is seen
#: as soon as before; a still room's snapshots span four times as long, at about a third of the cost.
QUIET_SNAPSHOTS = 5
QUIET_NS = 4 * SNAPSHOT_NS

#: Comparators (i, j) that sort 2-5 values (optimal networks): after them value i <= value j for every pair.
_NETWORKS = {
    2: ((0, 1),),
    3: ((0, 1), (1, 2), (0, 1)),
    4: ((0, 1), (2, 3), (0, 2), (1, 3), (1, 2)),
    5: ((0, 1), (3, 4), (2, 4), (2, 3), (0, 3), (0, 2), (1, 4), (1, 3), (1, 2)),
}


def sorted_pixels(snapshots: list[NDArray[Any]]) -> list[NDArray[Any]]:
    """The images' values sorted pixel by pixel (1-5 images of one size and dtype): item k holds every pixel's k-th
    smallest, by a sorting network of minima and maxima (a fraction of numpy's sort's cost)."""
    n = len(snapshots)
    if not 1 <= n <= 5:
        raise ValueError(f"1-5 snapshots, not {n}")
    values = list(snapshots)
    for i, j in _NETWORKS.get(n, ()):
        values[i], values[j] = cv2.min(values[i], values[j]), cv2.max(values[i], values[j])
    return values


#: The medians run over this many rows at a time: a band's arrays stay in the cache from one step to the next (at
#: 1280x1024, 1.7 times as fast as whole images).
BAND_ROWS = 32


def _bands(height: int) -> Iterator[slice]:
    """The rows of an image ``height`` rows high, BAND_ROWS at a time (the last band shorter)."""
    return (slice(top, top + BAND_ROWS) for top in range(0, height, BAND_ROWS))


def median_and_upper(snapshots: list[NDArray[Any]]) -> tuple[NDArray[Any], NDArray[Any]]:
    """The per-pixel median and second largest of 3-5 images (the lower median and the second largest of four): of
    five by thirteen minima and maxima instead of a sort's eighteen, band by band (BAND_ROWS)."""
    if len(snapshots) != 5:
        ordered = sorted_pixels(snapshots)
        return ordered[(len(ordered) - 1) // 2], ordered[-2]
    first = snapshots[0]
    median, upper = np.empty_like(first), np.empty_like(first)
    small, large = np.empty_like(first[:BAND_ROWS]), np.empty_like(first[:BAND_ROWS])
    for rows in _bands(first.shape[0]):
        a, b, c, d, e = (snapshot[rows] for snapshot in snapshots)
        low, high, less, more = median[rows], upper[rows], small[: len(a)], large[: len(a)]
        np.minimum(a, b, out=low), np.maximum(a, b, out=high), np.minimum(c, d, out=less), np.maximum(c, d, out=more)
        np.maximum(low, less, out=low)  # the middle two of four: low, less; the largest: high
        np.minimum(high, more, out=less)
        np.maximum(high, more, out=high)
        np.minimum(low, less, out=more)  # the middle two ordered: more <= low
        np.maximum(low, less, out=low)
        np.minimum(high, e, out=high)  # the second largest of five
        np.maximum(low, high, out=high)
        np.minimum(low, e, out=low)  # the median of five
        np.maximum(more, low, out=low)
    return median, upper


def median_of(snapshots: list[NDArray[Any]]) -> NDArray[Any]:
    """The per-pixel median of 1-5 images (the lower median of an even count); of five by seven minima and maxima
    (the median of 5 is the median of the fifth and the middle two of the other four's pairs), band by band
    (BAND_ROWS)."""
    if len(snapshots) != 5:
        return sorted_pixels(snapshots)[(len(snapshots) - 1) // 2]
    first = snapshots[0]
    median = np.empty_like(first)
    spares = [np.empty_like(first[:BAND_ROWS]) for _ in range(3)]
    for rows in _bands(first.shape[0]):
        a, b, c, d, e = (snapshot[rows] for snapshot in snapshots)
        low, high, spare = (array[: len(a)] for array in spares)
        np.minimum(a, b, out=low), np.minimum(c, d, out=high)
        np.maximum(low, high, out=low)  # the larger of the pairs' minima
        np.maximum(a, b, out=high), np.maximum(c, d, out=spare)
        np.minimum(high, spare, out=high)  # the smaller of their maxima
        np.minimum(low, high, out=median[rows])
        np.maximum(low, high, out=low)
        np.minimum(low, e, out=low)
        np.maximum(median[rows], low, out=median[rows])
    return median


class StaticStructure:
    """One camera's static structure over time (see the module docstring): feed the images (and their box sums) a
    background is estimated from (:meth:`add`, when :meth:`due`), then let :meth:`apply` put the structure into
    each new background: its threshold for the search, its pixels and their noise for the centres."""

    def __init__(self, options: BackgroundOptions | None = None) -> None:
        self.options = options or BackgroundOptions()
        self._images: deque[NDArray[Any]] = deque(maxlen=SNAPSHOTS)
        self._sums: deque[NDArray[Any]] = deque(maxlen=SNAPSHOTS)
        self._taken = 0
        self._last_ns: int | None = None
        self._noise: tuple[float, float] | None = None  # (a, b) of the sums' variance over time
        self._pairs: deque[tuple[tuple[float, float], tuple[float, float]]] = deque(maxlen=NOISE_PAIRS)
        self._last: tuple[NDArray[Any], NDArray[Any]] | None = None  # the newest snapshot's image and sums as they came
        self._pixel_noise: tuple[float, float] = (0.0, 0.0)  # (a, b) of a pixel's
        self._made: tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]] | None = None  # (see _make)
        self._made_noise: tuple[float, float] | None = None  # the noise it was made with
        self._kept = 0  # snapshots since it was made
        self._still = 0  # snapshots in a row that changed nothing
        self._kept_ns: int | None = None  # the newest kept snapshot's stamp
        self._made_from = 0  # of how many snapshots
        self._threshold: NDArray[Any] | None = None  # made from it (see apply)
        self._floor: NDArray[Any] | None = None  # the structure less as much as the threshold stands above it

    def due(self, stamp_ns: int) -> bool:
        """Whether an image at ``stamp_ns`` should give a snapshot (:meth:`add`)."""
        if self._last_ns is None:
            return True
        every = EARLY_NS if self._taken < EARLY_SNAPSHOTS else SNAPSHOT_NS
        return not 0 <= stamp_ns - self._last_ns < every  # (a stamp going back: start again from it)

    def worth_keeping(
        self, stamp_ns: int, sums: NDArray[Any], keep_out: list[tuple[float, float, float]] | None = None
    ) -> bool:
        """Whether a snapshot due at ``stamp_ns`` (its box sums ``sums``, the wand in ``keep_out`` discs as
        :meth:`add` takes them) should be kept with :meth:`add`: always, but in a still room (QUIET_SNAPSHOTS) only
        when it differs from the structure or the newest kept snapshot is QUIET_NS old. One not kept counts as taken:
        the next is due SNAPSHOT_NS later."""
        kept_ns, threshold = self._kept_ns, self._threshold
        if self._still < QUIET_SNAPSHOTS or kept_ns is None or not 0 <= stamp_ns - kept_ns < QUIET_NS:
            return True
        if threshold is None or sums.shape != threshold.shape or sums.dtype != threshold.dtype:
            return True
        if self._differing(sums, keep_out or []) > CHANGED_PIXELS:
            return True
        self._last_ns = stamp_ns
        return False

    def add(
        self,
        stamp_ns: int,
        gray: NDArray[Any],
        sums: NDArray[Any],
        keep_out: list[tuple[float, float, float]] | None = None,
    ) -> None:
        """Keep an image and its box sums as a snapshot (a new kind of image starts the structure again).

        Args:
            stamp_ns: its stamp.
            gray: (H, W) the image.
            sums: (H, W) its box sums.
            keep_out: (u, v, radius px) discs where the wand is: the structure learned so far stands in for the image
                there (a wand moving slowly at the end of a stroke is not learned as structure).
        """
        if self._images and (self._images[0].shape != gray.shape or self._images[0].dtype != gray.dtype):
            self.reset()
        if self._last is not None and repeated(self._last[1], sums):  # a driver that sent one image twice: no news
            return
        if self._last is not None:  # the noise from the images as they came (not from the structure pasted in)
            # each pair's estimate is a draw: the median of the newest NOISE_PAIRS of them
            self._pairs.append((temporal_noise(self._last[1], sums), temporal_noise(self._last[0], gray)))
            self._noise = _median_model([pair[0] for pair in self._pairs])
            self._pixel_noise = _median_model([pair[1] for pair in self._pairs])
        self._last = (gray, sums)
        made = self._made if self._made is not None else self._make(1.0)
        if keep_out and made is not None:
            gray, sums = gray.copy(), sums.copy()
            for u, v, radius in keep_out:
                disc = _disc_box(gray.shape, u, v, radius)
                if disc is not None:
                    rows, cols, inside = disc
                    gray[rows, cols][inside] = made[0][rows, cols][inside]
                    sums[rows, cols][inside] = made[1][rows, cols][inside]
        self._images.append(gray)
        self._sums.append(sums)
        self._taken += 1
        self._last_ns = self._kept_ns = stamp_ns
        self._kept += 1
        differs = self._differs(sums)
        self._still = 0 if differs else self._still + 1
        if differs or self._made_from < SNAPSHOTS or self._kept >= SNAPSHOTS:  # (made from fewer snapshots, early:
            # made again with each until the window is full; and at least once a window)
            self._made = self._made_noise = self._threshold = self._floor = None
            self._kept = 0
        elif self._made is not None:  # the pixels spots are measured on: the newest snapshots' median still
            self._made = (median_of(list(self._images)), *self._made[1:])

    @property
    def pixels(self) -> NDArray[Any] | None:
        """(H, W) the structure's pixels (the newest snapshots' median), or None: none learned yet."""
        return None if self._made is None else self._made[0]

    @property
    def unchanged(self) -> bool:
        """Whether the newest snapshot left the structure's threshold as it was (its pixels follow every snapshot)."""
        return self._threshold is not None

    def _differs(self, sums: NDArray[Any]) -> bool:
        """Whether a new snapshot's box sums (the wand kept out) differ from the structure: its noise, or more than
        CHANGED_PIXELS of them (see the module docstring); True while there is none to compare with."""
        if self._threshold is None or self._made_noise is None or self._noise is None:
            return True
        if sums.shape != self._threshold.shape or sums.dtype != self._threshold.dtype:
            return True
        level = 100.0 * max(1.0, self._noise[1], self._made_noise[1])
        now, then = (max(a + b * level, 1e-12) for a, b in (self._noise, self._made_noise))
        if not 1.0 / NOISE_CHANGE <= now / then <= NOISE_CHANGE:
            return True
        return self._differing(sums, []) > CHANGED_PIXELS

    def _differing(self, sums: NDArray[Any], keep_out: list[tuple[float, float, float]]) -> int:
        """How many box sums stand above the structure's threshold or below its floor, outside the ``keep_out``
        discs (the structure must be made: its threshold and floor of the sums' shape and dtype)."""
        assert self._threshold is not None and self._floor is not None
        over = cv2.compare(sums, self._threshold, cv2.CMP_GT)
        under = cv2.compare(sums, self._floor, cv2.CMP_LT)
        for u, v, radius in keep_out:
            disc = _disc_box(sums.shape, u, v, radius)
            if disc is not None:
                rows, cols, inside = disc
                over[rows, cols][inside] = 0
                under[rows, cols][inside] = 0
        return int(cv2.countNonZero(over) + cv2.countNonZero(under))

    def reset(self) -> None:
        """Forget what was learned (the view changed)."""
        self._images.clear()
        self._sums.clear()
        self._pairs.clear()
        self._last = None
        self._taken, self._last_ns, self._noise, self._made, self._threshold = 0, None, None, None, None
        self._made_noise, self._floor, self._kept, self._made_from = None, None, 0, 0
        self._still, self._kept_ns = 0, None

    @property
    def noise(self) -> tuple[float, float] | None:
        """(a, b) of the box sums' noise variance a + b x level over time, or None: fewer than two snapshots."""
        return self._noise

    def structure(self) -> NDArray[Any] | None:
        """(H, W) the static structure's box sums, or None: fewer than MIN_SNAPSHOTS yet."""
        made = self._make(1.0)
        return None if made is None else made[1]

    def apply(self, background: Background) -> Background:
        """The background with the structure (:attr:`~wand_calib_ros.detection.background.Background.structure`,
        ``static``, ``static_sums``, ``static_noise``); unchanged while none is learned, or for an image of another
        size or kind. The threshold is made once per snapshot, with the spatial background of the image that asks
        first (it changes slowly)."""
        made = self._make(background.unit)
        if made is None:
            return background
        pixels, structure, above, flicker = made
        if above.shape != background.threshold.shape or above.dtype != background.threshold.dtype:
            return background
        if self._threshold is None:
            self._threshold = _threshold(structure, above, flicker, background, len(self._sums) < SNAPSHOTS)
            self._floor = _floor(structure, above, flicker)
        return replace(background, search=None, structure=self._threshold, static=pixels, static_sums=structure,
                       static_noise=self._pixel_noise)  # fmt: skip

    def saturated(self, full: float) -> NDArray[np.bool_] | None:
        """(H, W) where the structure is saturated (a lamp's core, a window in daylight: nothing can be seen there, a
        spot touching it is cut), or None: none learned yet."""
        made = self._made
        return None if made is None else np.asarray(made[0] >= SATURATED_STATIC * full)

    def lights(self, full: float) -> tuple[tuple[float, float, float], ...]:
        """(u, v, radius px) of each saturated region of the structure: the static lights it learned. Saturated
        pixels a few apart are one light (a window's edge or a pane just at full scale flickers into specks), and a
        region of fewer than MIN_LIGHT_PX pixels is none."""
        where = self.saturated(full)
        if where is None or not where.any():
            return ()
        joined = cv2.morphologyEx(where.astype(np.uint8), cv2.MORPH_CLOSE, np.ones((LIGHT_GAP_PX + 1,) * 2, np.uint8))
        count, _, stats, centres = cv2.connectedComponentsWithStats(joined, connectivity=8)
        return tuple(
            (float(centres[i, 0]), float(centres[i, 1]), float(np.sqrt(stats[i, cv2.CC_STAT_AREA] / np.pi)))
            for i in range(1, count)
            if stats[i, cv2.CC_STAT_AREA] >= MIN_LIGHT_PX
        )

    def _make(self, unit: float) -> tuple[NDArray[Any], NDArray[Any], NDArray[Any], NDArray[Any]] | None:
        """(the structure's pixels, its sums, its sums plus the noise's contrast, the flicker's margin measured over
        the snapshots), made again when a snapshot comes (``unit``: of min_contrast, the first time)."""
        if self._made is None and self._noise is not None and len(self._sums) >= MIN_SNAPSHOTS:
            structure, upper = median_and_upper(list(self._sums))
            a, b = self._noise
            # an image stands out of the median of n snapshots with its own noise and the median's (pi / 2n of it)
            sigmas = np.float32(self.options.noise_sigmas * np.sqrt(1.0 + np.pi / (2 * len(self._sums))))
            least = np.float32(self.options.min_contrast * unit)
            if structure.dtype == np.uint16:  # box sums of 8-bit images: a table of every sum's contrast
                sums = np.arange(int(structure.max()) + 1, dtype=np.float32)
                noise = np.sqrt(np.float32(a) + np.float32(b) * sums)
                table = np.minimum(np.ceil(np.maximum(sigmas * noise, least)), 65535.0).astype(np.uint16)
                contrast = _looked_up(table, structure)
                above = cv2.add(structure, contrast)
                flicker = _flicker(structure, upper, (a, b), contrast, float(sigmas))
            else:
                level = structure.astype(np.float32)
                above = level + np.maximum(sigmas * np.sqrt(np.float32(a) + np.float32(b) * level), least)
                flicker = _flicker(structure, upper, (a, b))
            self._made = (median_of(list(self._images)), structure, above, flicker)
            self._made_noise, self._made_from = self._noise, len(self._sums)
        return self._made


def _looked_up(table: NDArray[Any], indices: NDArray[Any]) -> NDArray[Any]:
    """(H, W) ``table``'s entry at each of ``indices`` (H, W; clipped to its length), in the table's dtype, band by
    band (BAND_ROWS: numpy widens a band's indices, not the whole image's, to 64 bits: twice as fast)."""
    out = np.empty(indices.shape, table.dtype)
    for rows in _bands(indices.shape[0]):
        np.take(table, indices[rows], out=out[rows], mode="clip")
    return out


def _scaled(image: NDArray[Any], factor: float) -> NDArray[Any]:
    """``image`` times ``factor`` in its own dtype (rounded, saturated: cv2's weighted sum, three times as fast as its
    multiply by a scalar on 16-bit images)."""
    scaled: NDArray[Any] = cv2.addWeighted(image, float(factor), image, 0.0, 0.0)
    return scaled


def _threshold(
    structure: NDArray[Any], above: NDArray[Any], flicker: NDArray[Any], background: Background, early: bool
) -> NDArray[Any]:
    """(H, W) the search threshold from the structure's sums, those plus the noise's contrast (``above``) and the
    flicker's margin measured over the snapshots, capped at FLICKER_MAX of the structure's excess over the spatial
    background; ``early`` (too few snapshots to tell flicker): any static light may flicker by EARLY_FLICKER of it,
    and the threshold is never below the spatial one."""
    height, width = above.shape
    if structure.dtype == np.uint16:  # (the level's grid in the sums' dtype: a quarter of a float image's cost)
        grid = np.minimum(np.round(background.level), 65535.0).astype(np.uint16)
        excess = cv2.subtract(structure, cv2.resize(grid, (width, height), interpolation=cv2.INTER_LINEAR))
        cap = _scaled(excess, FLICKER_MAX)  # (saturates at 0)
    else:
        level = cv2.resize(background.level.astype(np.float32), (width, height), interpolation=cv2.INTER_LINEAR)
        cap = np.maximum(structure - level, 0.0) * np.float32(FLICKER_MAX)
    if early:
        light = _scaled(structure, EARLY_FLICKER)
        threshold: NDArray[Any] = cv2.max(cv2.add(above, cv2.max(cap, light)), background.threshold)
        return threshold
    return cv2.add(above, cv2.min(flicker, cap))


def _floor(structure: NDArray[Any], above: NDArray[Any], flicker: NDArray[Any]) -> NDArray[Any]:
    """(H, W) the structure's sums less the noise's contrast (``above`` less the structure) and the flicker's margin:
    a snapshot below it there has lost light the structure holds."""
    if structure.dtype == np.uint16:
        return cv2.subtract(structure, cv2.add(cv2.subtract(above, structure), flicker))  # (saturates at 0)
    return np.asarray(structure - (above - structure) - flicker)


def _flicker(
    structure: NDArray[Any],
    upper: NDArray[Any],
    noise: tuple[float, float],
    contrast: NDArray[Any] | None = None,
    sigmas: float = 1.0,
) -> NDArray[Any]:
    """(H, W) the threshold flickering light needs (the structure's units and dtype): FLICKER_SPREAD times the spread
    between the snapshots' median and second largest beyond SPREAD_NOISE noise sigmas, widened by a pixel (a
    lamp's edge moves with its brightness). ``contrast``: the noise's contrast at the structure (``sigmas`` noise
    sigmas), where it is known (8-bit box sums)."""
    a, b = noise
    if structure.dtype == np.uint16 and contrast is not None:  # box sums of 8-bit images: the allowance from the
        # noise's contrast there
        allowed = _scaled(contrast, SPREAD_NOISE / sigmas)
        excess = cv2.subtract(cv2.subtract(upper, structure), allowed)  # (saturates at 0)
        margin = _scaled(excess, FLICKER_SPREAD)
    else:
        level = structure.astype(np.float32)
        allowed = np.float32(SPREAD_NOISE) * np.sqrt(np.float32(a) + np.float32(b) * level)
        margin = np.float32(FLICKER_SPREAD) * np.maximum(upper - structure - allowed, 0.0)
    widened: NDArray[Any] = cv2.dilate(margin, np.ones((3, 3), np.uint8))
    return widened


def _disc_box(
    shape: tuple[int, ...], u: float, v: float, radius: float
) -> tuple[slice, slice, NDArray[np.bool_]] | None:
    """(rows, columns, the disc's pixels in them) of a disc (u, v, radius px) in an image of ``shape``, or None: off
    the image."""
    height, width = shape[:2]
    u0, u1 = max(int(u - radius), 0), min(int(u + radius) + 2, width)
    v0, v1 = max(int(v - radius), 0), min(int(v + radius) + 2, height)
    if u1 <= u0 or v1 <= v0:
        return None
    cols, rows = np.arange(u0, u1) - u, np.arange(v0, v1)[:, None] - v
    return slice(v0, v1), slice(u0, u1), np.asarray(cols[None, :] ** 2 + rows**2 <= radius**2)


#: The noise is the median of the estimates of the newest this many pairs of snapshots (one pair's is a draw).
NOISE_PAIRS = 3
#: Two images are one image sent twice when more than this fraction of their samples are equal (noise makes a
#: few of them equal: box sums of 8-bit images about 10 % of them at a noise of one grey level).
REPEATED = 0.5


def repeated(first: NDArray[Any], second: NDArray[Any]) -> bool:
    """Whether two images (box sums) are one image sent twice (REPEATED of every STEP-th pixel equal)."""
    return bool(np.mean(first[::STEP, ::STEP] == second[::STEP, ::STEP]) > REPEATED)


def _median_model(models: list[tuple[float, float]]) -> tuple[float, float]:
    """The noise model whose variance at a typical level is the median of the models' (the larger of two)."""
    level = 100.0 * max(1.0, max(b for _, b in models))  # (a level where both terms count)
    ranked = sorted(models, key=lambda model: model[0] + model[1] * level)
    return ranked[len(ranked) // 2]


def temporal_noise(first: NDArray[Any], second: NDArray[Any]) -> tuple[float, float]:
    """(a, b) of the noise variance a + b x level over time of two images of one view (pixels or box sums), from every
    STEP-th pixel's difference between them in tiles (an LED in one of them is in the upper half of its tile)."""
    x = first[::STEP, ::STEP].astype(np.float32)
    y = second[::STEP, ::STEP].astype(np.float32)
    return noise_model(*tile_noise(np.square(y - x), np.minimum(x, y)), from_median=True)
