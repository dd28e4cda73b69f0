"""Masks: the pixels a camera's detector ignores, given by the user or learned from lights that do not move.

A mask is an (H, W) uint8 image, 255 where pixels are ignored. The user gives one per
camera in the rig file (circles, rectangles or a PNG, :func:`mask_from_shapes`,
:func:`read_mask`) or takes one from the current view with the wand out of sight
(:class:`MaskTaker`). The detector also learns one (:class:`StaticSources`): a blob that
stays where it is for STATIC_LEARN_S, in most images, without belonging to the wand's
track, is a lamp, a reflection or a bright spot of a window, and its footprint is masked
from then on. A source that is no longer there (its centre no longer stands out) for
STATIC_FORGET_S is unmasked again: a wand left lying, a lamp switched off.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.detection.blobs import Blobs
from wand_calib_ros.detection.errors import MaskError
from wand_calib_ros.io.rig_yaml import MaskSpec

FloatArray = NDArray[np.float64]
Mask = NDArray[np.uint8]

#: A blob that has stayed put this long (s) is still: it cannot be the wand's (nor can one that has been there
#: since the stream's first image, in STILL_IMAGES images).
STILL_S = 0.5
STILL_IMAGES = 3
#: ... and this long a static source: it is masked.
STATIC_LEARN_S = 2.0
#: ... when it was there in at least this fraction of the images meanwhile.
STATIC_PRESENCE = 0.7
#: Blobs of two images within this distance (px, plus their own sizes' jitter) are the same light.
MATCH_PX = 2.0
#: A candidate source missing for this long (s) is given up; ...
CANDIDATE_GAP_S = 0.3
#: ... a masked source whose centre no longer stands out for this long (s) is unmasked.
STATIC_FORGET_S = 5.0
#: A source's mask reaches this far (px) beyond the largest blob it made.
MASK_MARGIN_PX = 2.0


def empty_mask(size: tuple[int, int]) -> Mask:
    """An (H, W) mask that ignores nothing, for an image of (width, height)."""
    return np.zeros((size[1], size[0]), np.uint8)


def mask_from_shapes(
    size: tuple[int, int],
    circles: list[tuple[float, float, float]] = [],  # noqa: B006 - read only
    rectangles: list[tuple[float, float, float, float]] = [],  # noqa: B006 - read only
) -> Mask:
    """A mask of circles (u, v, radius) and rectangles (u0, v0, u1, v1, inclusive corners), px."""
    mask = empty_mask(size)
    for u, v, radius in circles:
        cv2.circle(mask, (round(u), round(v)), max(round(radius), 0), 255, -1)
    for u0, v0, u1, v1 in rectangles:
        cv2.rectangle(mask, (round(u0), round(v0)), (round(u1), round(v1)), 255, -1)
    return mask


def read_mask(path: Path, size: tuple[int, int]) -> Mask:
    """A mask from an image file: non-zero (white) pixels are ignored.

    Raises:
        MaskError: not an image, or not of the camera's size.
    """
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE) if path.is_file() else None
    if image is None:
        raise MaskError(f"{path}: not an image file (a mask is a PNG, white where pixels are ignored)")
    if (image.shape[1], image.shape[0]) != size:
        raise MaskError(f"{path}: a {image.shape[1]}x{image.shape[0]} mask for a {size[0]}x{size[1]} camera")
    return np.where(image > 0, 255, 0).astype(np.uint8)


def write_mask(path: Path, mask: Mask) -> None:
    """Write a mask as a PNG (white where ignored)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), mask):
        raise MaskError(f"{path}: the mask could not be written")


def mask_of(spec: MaskSpec, size: tuple[int, int]) -> Mask:
    """A camera's mask from the rig file's ``mask`` (its shapes and its PNG together).

    Raises:
        MaskError: its PNG is not an image of the camera's size.
    """
    mask = mask_from_shapes(size, list(spec.circles), list(spec.rectangles))
    if spec.file is not None:
        mask = np.maximum(mask, read_mask(spec.file, size))
    return mask


def mask_fraction(mask: Mask) -> float:
    """The fraction of the image a mask ignores."""
    return float(cv2.countNonZero(mask)) / max(mask.size, 1)


def _radii(blobs: Blobs) -> FloatArray:
    """(N,) a blob's extent as a radius, px: from its area, and its streak's length."""
    lengths = blobs.lengths if blobs.lengths is not None else np.zeros(blobs.areas.shape)
    return np.sqrt(blobs.areas / np.pi) + 0.5 * lengths


@dataclass(frozen=True)
class Source:
    """A light that does not move.

    Attributes:
        centre: (u, v) px.
        radius_px: how far its mask reaches.
        since_ns: when it was first seen.
        seen_ns: when it last stood out.
    """

    centre: tuple[float, float]
    radius_px: float
    since_ns: int
    seen_ns: int


class StaticSources:
    """One camera's learned static lights (see the module docstring).

    Feed every image's blobs (:meth:`observe`) in time order with which of them belong to the wand's
    track; ask which blobs are still (:meth:`still`) and what to mask (:attr:`mask`).
    """

    def __init__(self, size: tuple[int, int]) -> None:
        self.size = size
        self.sources: list[Source] = []
        self._centres = np.zeros((0, 2))  # candidates
        self._radii = np.zeros(0)
        self._first = np.zeros(0, dtype=np.int64)
        self._last = np.zeros(0, dtype=np.int64)
        self._count = np.zeros(0, dtype=np.int64)
        self._images: list[int] = []  # stamps of the images observed (to measure presence)
        self._start: int | None = None  # the first image's stamp
        self._mask: Mask | None = None

    @property
    def mask(self) -> Mask:
        """The learned sources' footprints (255), for :func:`~wand_calib_ros.detection.blobs.find_blobs`."""
        if self._mask is None:
            self._mask = mask_from_shapes(self.size, [(s.centre[0], s.centre[1], s.radius_px) for s in self.sources])
        return self._mask

    def still(self, blobs: Blobs) -> NDArray[np.bool_]:
        """(N,) blobs at a place where a blob has been, in most images, for STILL_S or more, or since the stream's
        first image in STILL_IMAGES images (what was there from the start and has not moved is no wand)."""
        if not self._centres.size or not blobs.centres.size or not self._images:
            return np.zeros(blobs.centres.shape[0], dtype=bool)
        nearest, index = self._nearest(blobs)
        age = (self._images[-1] - self._first[index]) / 1e9
        presence = self._count[index] / np.maximum(self._observed_since(self._first[index]), 1)
        from_start = (self._first[index] == self._start) & (self._count[index] >= STILL_IMAGES)
        return nearest & ((age >= STILL_S) | from_start) & (presence >= STATIC_PRESENCE)

    def observe(
        self,
        stamp_ns: int,
        blobs: Blobs,
        claimed: NDArray[np.bool_],
        standing_out: NDArray[np.bool_] | None = None,
        track_since_ns: int | None = None,
    ) -> bool:
        """Learn from one image.

        Args:
            stamp_ns: its stamp (time order).
            blobs: its blobs (the learned mask already applied).
            claimed: (N,) blobs of the wand's track: never new candidates (a wand at rest is not learned), but
                counted on a candidate older than the track (a lamp the track took for an LED is still a lamp).
            standing_out: (S,) whether each current source's centre still stands out in this image (None:
                not checked; every source stays).
            track_since_ns: when the wand's track began (None: no track).

        Returns:
            Whether the mask changed.
        """
        self._images.append(stamp_ns)
        self._start = stamp_ns if self._start is None else self._start
        horizon = stamp_ns - int(4 * STATIC_LEARN_S * 1e9)
        if self._images[0] < horizon:
            self._images = [s for s in self._images if s >= horizon]
        changed = self._forget(stamp_ns, standing_out)
        if blobs.centres.size:
            self._match(stamp_ns, blobs, claimed, track_since_ns)
        keep = (stamp_ns - self._last) <= CANDIDATE_GAP_S * 1e9
        age = (stamp_ns - self._first) / 1e9
        presence = self._count / np.maximum(self._observed_since(self._first), 1)
        learned = keep & (age >= STATIC_LEARN_S) & (presence >= STATIC_PRESENCE)
        for i in np.flatnonzero(learned):
            centre = (float(self._centres[i, 0]), float(self._centres[i, 1]))
            self.sources.append(Source(centre, float(self._radii[i]) + MASK_MARGIN_PX, int(self._first[i]), stamp_ns))
            changed = True
        self._keep(keep & ~learned)
        if changed:
            self._mask = None
        return changed

    def _observed_since(self, first: NDArray[np.int64]) -> NDArray[np.int64]:
        stamps = np.asarray(self._images, dtype=np.int64)
        return len(stamps) - np.searchsorted(stamps, first)

    def _nearest(self, blobs: Blobs) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
        """(N,) whether each blob matches a candidate, and the nearest candidate's index."""
        distance = np.linalg.norm(blobs.centres[:, None] - self._centres[None], axis=-1)
        index = np.argmin(distance, axis=1)
        reach = MATCH_PX + 0.25 * np.maximum(_radii(blobs), self._radii[index])
        return distance[np.arange(index.size), index] <= reach, index

    def _match(self, stamp_ns: int, blobs: Blobs, claimed: NDArray[np.bool_], since_ns: int | None) -> None:
        """Count the blobs on the candidates they match (a claimed blob only on a candidate older than the track);
        the unclaimed others are new candidates."""
        radii = _radii(blobs)
        new = ~claimed
        if self._centres.size:
            matched, index = self._nearest(blobs)
            for b in np.flatnonzero(matched):
                i = index[b]
                if claimed[b] and (since_ns is None or self._first[i] > since_ns):
                    continue
                if self._last[i] == stamp_ns:  # a second blob on one candidate: counted once
                    new[b] = False
                    continue
                self._last[i], self._count[i] = stamp_ns, self._count[i] + 1
                self._radii[i] = max(self._radii[i], radii[b])
                new[b] = False
        if new.any():
            n = int(new.sum())
            self._centres = np.vstack([self._centres, blobs.centres[new]])
            self._radii = np.concatenate([self._radii, radii[new]])
            self._first = np.concatenate([self._first, np.full(n, stamp_ns, dtype=np.int64)])
            self._last = np.concatenate([self._last, np.full(n, stamp_ns, dtype=np.int64)])
            self._count = np.concatenate([self._count, np.ones(n, dtype=np.int64)])

    def _keep(self, keep: NDArray[np.bool_]) -> None:
        self._centres, self._radii = self._centres[keep], self._radii[keep]
        self._first, self._last, self._count = self._first[keep], self._last[keep], self._count[keep]

    def _forget(self, stamp_ns: int, standing_out: NDArray[np.bool_] | None) -> bool:
        if standing_out is None or not self.sources:
            return False
        kept = []
        for source, there in zip(self.sources, standing_out, strict=True):
            if there:
                kept.append(Source(source.centre, source.radius_px, source.since_ns, stamp_ns))
            elif stamp_ns - source.seen_ns <= STATIC_FORGET_S * 1e9:
                kept.append(source)
        changed = len(kept) != len(self.sources)
        self.sources = kept
        return changed

    def centres_standing_out(self, gray: NDArray[np.generic], threshold: NDArray[np.generic]) -> NDArray[np.bool_]:
        """(S,) whether each source's centre pixel is above the image's threshold there."""
        if not self.sources:
            return np.zeros(0, dtype=bool)
        centres = np.array([s.centre for s in self.sources])
        u = np.clip(np.round(centres[:, 0]).astype(int), 0, self.size[0] - 1)
        v = np.clip(np.round(centres[:, 1]).astype(int), 0, self.size[1] - 1)
        return np.asarray(gray[v, u] > threshold[v, u])


class MaskTaker:
    """A mask taken from the current view with the wand out of sight: every blob of the images it is
    shown, each masked to MASK_MARGIN_PX beyond its extent."""

    def __init__(self, size: tuple[int, int]) -> None:
        self.size = size
        self.circles: list[tuple[float, float, float]] = []
        self.images = 0

    def add(self, blobs: Blobs) -> None:
        """Take one image's blobs."""
        self.images += 1
        radii = _radii(blobs) + MASK_MARGIN_PX
        self.circles += [(float(u), float(v), float(r)) for (u, v), r in zip(blobs.centres, radii, strict=True)]

    @property
    def mask(self) -> Mask:
        return mask_from_shapes(self.size, self.circles)
