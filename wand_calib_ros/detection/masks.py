"""Masks: the pixels a camera's detector ignores, given by the user or learned from lights that do not move.

A mask is an (H, W) uint8 image, 255 where pixels are ignored. The user gives one per
camera in the rig file (circles, rectangles or a PNG, :func:`mask_from_shapes`,
:func:`read_mask`) or takes one from the current view with the wand out of sight
(:class:`MaskTaker`). The detector also learns one (:class:`StaticSources`): a blob that
stays where it is for STATIC_LEARN_S, in most images, without belonging to the wand's
track, is a lamp, a reflection or a bright spot of a window, and its footprint is masked
from then on. A source that is no longer there (its centre no longer stands out) for
STATIC_FORGET_S is unmasked again: a wand left lying, a lamp switched off.

A learned light's halo (a lamp's glare reaches tens of pixels) is then learned too, as the mean
light it adds around it (:class:`LightPatch`), from images with nothing else near it (or away
from what lingers there); once
known, it is subtracted from every image (:meth:`StaticSources.clean`) and only the light's
saturated core stays masked (the halo is scaled to each image's brightness of the light: lamps
flicker): an LED passing close to a lamp is found and measured on a clean background instead of
being cut by a wide mask.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.detection.background import BOX, saturation_of
from wand_calib_ros.detection.blobs import Blobs, distances
from wand_calib_ros.detection.errors import MaskError
from wand_calib_ros.io.outputs import write_text
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
#: A learned light's halo is learned this far (px) beyond its mask.
PATCH_MARGIN_PX = 30
#: A halo is subtracted once learned from this many images; its mean follows the newest this many.
PATCH_IMAGES = 8
#: Pixels of a learned light this close to the image's full scale (a fraction) stay masked: nothing shows there ...
SATURATED_FRACTION = 0.98
#: Lamps flicker from image to image (mains-powered ones by 10 % and more): a halo is subtracted scaled by how
#: bright it is in this image, measured where it adds this many grey levels or more (of an 8-bit image) ...
REFERENCE_LEVELS = 20.0
#: ... on at least this many pixels (else as learned; a sample of this many is enough).
REFERENCE_PIXELS = 12
REFERENCE_SAMPLE = 64
#: A halo is learned from images with nothing else near it; after this many in a row with something near (an LED
#: lingering), from the next, away from (this far, px, beyond) the other blobs.
PATCH_PATIENCE = 30
OTHER_MARGIN_PX = 6.0
#: A blob on a subtracted halo with a peak below this fraction of the halo there may be the light's flicker.
RESIDUE_FRACTION = 0.3
#: A halo is subtracted where it adds this many grey levels (of an 8-bit image) or more.
HALO_LEVELS = 0.5
#: A known halo keeps learning from every this-many-th image.
PATCH_EVERY = 8
#: A light's surroundings are one wall when the quartiles of its patch's border are within this many grey levels
#: (of an 8-bit image).
UNEVEN_LEVELS = 8.0


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
    """Write a mask as a PNG (white where ignored; as every output is written, :mod:`wand_calib_ros.io.outputs`).

    Raises:
        MaskError: it could not be encoded; OutputError: not written.
    """
    encoded, png = cv2.imencode(".png", mask)
    if not encoded:
        raise MaskError(f"{path}: the mask could not be encoded as a PNG")
    write_text(path, png.tobytes())


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


class LightPatch:
    """The light a static source adds around it: the mean, over the images where nothing else was near it,
    of the image above its wall (the median of the patch's border). Where it is saturated it stays masked
    (nothing shows there); elsewhere it is subtracted, scaled to this image's brightness of the light
    (:meth:`subtract`). A light whose patch's border is not one wall (it straddles a window's edge) is not
    learned: it stays masked as a disc (:attr:`usable`)."""

    def __init__(self, source: Source, size: tuple[int, int]) -> None:
        reach = int(np.ceil(source.radius_px)) + PATCH_MARGIN_PX
        u, v = round(source.centre[0]), round(source.centre[1])
        self.u0, self.v0 = max(u - reach, 0), max(v - reach, 0)
        self.u1, self.v1 = min(u + reach + 1, size[0]), min(v + reach + 1, size[1])
        self.excess = np.zeros((self.v1 - self.v0, self.u1 - self.u0), np.float32)
        self.counts = np.zeros(self.excess.shape, np.int32)  # images each pixel was learned from
        self.waited = 0  # images passed over since the last it was learned from (something else was near)
        self.images = 0
        self.seen = 0
        self.uneven = 0  # images whose border was not one wall
        self.saturated = np.zeros(self.excess.shape, dtype=bool)
        self.reference = np.zeros(0, dtype=np.int64)  # flat indices where the halo is bright, not saturated
        self.reach = (0, 0, 0, 0)  # (u0, v0, u1, v1) in the patch where the halo matters
        self._halo = np.zeros((0, 0), np.float32)  # the excess there
        self._reference_excess = np.zeros(0, np.float32)  # the excess at the reference pixels

    @property
    def usable(self) -> bool:
        """Its border is one wall (in most images): its halo can be learned."""
        return self.uneven <= self.images

    @property
    def known(self) -> bool:
        """Its halo is learned (and usable)."""
        return self.images >= PATCH_IMAGES and self.usable

    def residue(self, centres: FloatArray, peaks: FloatArray) -> NDArray[np.bool_]:
        """(N,) blobs that may be what is left of the halo once subtracted (the light flickers): in the patch,
        with a peak below RESIDUE_FRACTION of the halo learned at their centre."""
        inside = self.contains(centres)
        if not inside.any():
            return inside
        u = np.clip(np.round(centres[:, 0]).astype(int) - self.u0, 0, self.excess.shape[1] - 1)
        v = np.clip(np.round(centres[:, 1]).astype(int) - self.v0, 0, self.excess.shape[0] - 1)
        return np.asarray(inside & (peaks < RESIDUE_FRACTION * self.excess[v, u]))

    def contains(self, points: FloatArray) -> NDArray[np.bool_]:
        """(N,) which points lie in the patch."""
        u, v = points[:, 0], points[:, 1]
        return np.asarray((u >= self.u0) & (u < self.u1) & (v >= self.v0) & (v < self.v1))

    @staticmethod
    def _wall(patch: NDArray[Any], full: float) -> tuple[float, bool]:
        """The wall behind a patch of the image (the median of its border), and whether the border is one wall:
        its quartiles within UNEVEN_LEVELS (of an 8-bit image) of each other."""
        border = np.concatenate([patch[0], patch[-1], patch[:, 0], patch[:, -1]])
        if border.dtype.kind == "f":
            border = border[np.isfinite(border)]
        n = border.size
        if n < 8:  # (another light covers its border)
            return 0.0, False
        low, wall, high = np.partition(border, [n // 4, n // 2, 3 * n // 4])[[n // 4, n // 2, 3 * n // 4]]
        return float(wall), bool(high - low <= UNEVEN_LEVELS * full / 255.0)

    def due(self) -> bool:
        """Whether this image is one to learn from: every image until known, then every PATCH_EVERY-th; none once
        its surroundings proved not to be one wall."""
        self.seen += 1
        if self.uneven > PATCH_IMAGES and not self.usable:
            return False
        return not self.known or self.seen % PATCH_EVERY == 0

    def add(self, gray: NDArray[Any], full: float, others: list[tuple[float, float, float]]) -> None:
        """One image's light around the source, away from ``others`` ((u, v, radius px) of other blobs in the patch:
        the pixels within OTHER_MARGIN_PX of them are left as they were)."""
        patch = gray[self.v0 : self.v1, self.u0 : self.u1]
        free = np.ones(self.excess.shape, np.uint8)
        for u, v, radius in others:
            cv2.circle(free, (round(u - self.u0), round(v - self.v0)), round(radius + OTHER_MARGIN_PX), 0, -1)
        wall, even = self._wall(np.where(free > 0, patch, np.nan) if others else patch, full)  # (their light aside)
        if not even:
            self.uneven += 1
            return
        self.images += 1
        self.counts += free.astype(np.int32)
        weight = free / np.minimum(np.maximum(self.counts, 1), PATCH_IMAGES).astype(np.float32)
        self.excess += weight * (np.maximum(patch.astype(np.float32) - wall, 0.0) - self.excess)
        self.saturated = np.asarray(patch >= SATURATED_FRACTION * full) | (self.saturated & (self.images > 1))
        reference = np.flatnonzero((self.excess >= REFERENCE_LEVELS * full / 255.0) & ~self.saturated)
        self.reference = reference[:: max(reference.size // REFERENCE_SAMPLE, 1)]  # (a sample is enough)
        rows, cols = np.nonzero(self.excess >= HALO_LEVELS * full / 255.0)  # where subtracting it matters
        self.reach = (0, 0, 0, 0) if not rows.size else (cols.min(), rows.min(), cols.max() + 1, rows.max() + 1)
        u0, v0, u1, v1 = self.reach
        self._halo = np.ascontiguousarray(self.excess[v0:v1, u0:u1])
        self._reference_excess = self.excess.reshape(-1)[self.reference]

    def subtract(self, window: NDArray[Any], full: float) -> None:
        """Take the halo out of ``window`` (this patch of the image, in place), scaled to the light's brightness
        in it (the median ratio of its light to the learned light where that is bright and not saturated), where
        it adds HALO_LEVELS or more."""
        scale = 1.0
        n = self.reference.size
        if n >= REFERENCE_PIXELS:
            wall, _ = self._wall(window, full)
            ratios = (window.reshape(-1)[self.reference].astype(np.float32) - wall) / self._reference_excess
            scale = max(float(np.partition(ratios, n // 2)[n // 2]), 0.0)
        u0, v0, u1, v1 = self.reach
        part = window[v0:v1, u0:u1]
        cv2.subtract(part, np.minimum(scale * self._halo + 0.5, full).astype(window.dtype), dst=part)  # (clips at 0)


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
        self._seen = 0  # images observed (to measure presence)
        self._newest: int | None = None  # the newest image's stamp
        self._born = np.zeros(0, dtype=np.int64)  # the image (count) each candidate was first seen in
        self._start: int | None = None  # the first image's stamp
        self._mask: Mask | None = None
        self.patches: list[LightPatch] = []  # each source's halo, in the order of ``sources``

    @property
    def mask(self) -> Mask:
        """The learned sources' footprints (255), for :func:`~wand_calib_ros.detection.blobs.find_blobs`: a disc
        until the source's halo is known, then its saturated core (and a pixel around it)."""
        if self._mask is None:
            pairs = zip(self.sources, self.patches, strict=True)
            discs = [(s.centre[0], s.centre[1], s.radius_px) for s, p in pairs if not p.known]
            mask = mask_from_shapes(self.size, discs)
            for patch in self.patches:
                if patch.known and patch.saturated.any():
                    core = cv2.dilate(patch.saturated.astype(np.uint8) * 255, np.ones((3, 3), np.uint8))
                    window = mask[patch.v0 : patch.v1, patch.u0 : patch.u1]
                    np.maximum(window, core, out=window)
            self._mask = mask
        return self._mask

    def clean(self, gray: NDArray[Any]) -> NDArray[Any]:
        """The image without the known halos of the learned lights (the same array when none is known)."""
        known = [p for p in self.patches if p.known]
        if not known:
            return gray
        out = gray.copy()
        full = saturation_of(gray)
        for patch in known:
            patch.subtract(out[patch.v0 : patch.v1, patch.u0 : patch.u1], full)
        return out

    def still(self, blobs: Blobs) -> NDArray[np.bool_]:
        """(N,) blobs at a place where a blob has been, in most images, for STILL_S or more, or since the stream's
        first image in STILL_IMAGES images (what was there from the start and has not moved is no wand)."""
        if not blobs.centres.size or self._newest is None:
            return np.zeros(blobs.centres.shape[0], dtype=bool)
        on_source = np.zeros(blobs.centres.shape[0], dtype=bool)
        if self.sources:  # what is left of a learned light: its flicker's residue (dim against the halo it stands
            # on) once its halo is known, its halo flickering beyond its disc before
            pairs = list(zip(self.sources, self.patches, strict=True))
            where = np.array([source.centre for source, _ in pairs])
            reach = [MATCH_PX + 2.0 if p.known else s.radius_px + MASK_MARGIN_PX + 2.0 for s, p in pairs]
            on_source = np.asarray((distances(blobs.centres, where) <= np.array(reach)).any(axis=1))
            for _, patch in pairs:
                if patch.known:
                    on_source |= patch.residue(blobs.centres, blobs.peaks)
        if not self._centres.size:
            return on_source
        nearest, index = self._nearest(blobs)
        age = (self._newest - self._first[index]) / 1e9
        presence = self._count[index] / (self._seen - self._born[index] + 1)
        from_start = (self._first[index] == self._start) & (self._count[index] >= STILL_IMAGES)
        return on_source | (nearest & ((age >= STILL_S) | from_start) & (presence >= STATIC_PRESENCE))

    def observe(
        self,
        stamp_ns: int,
        blobs: Blobs,
        claimed: NDArray[np.bool_],
        standing_out: NDArray[np.bool_] | None = None,
        track_since_ns: int | None = None,
        gray: NDArray[Any] | None = None,
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
            gray: the image as it came (its lights' halos learned from it), or None.

        Returns:
            Whether the mask changed.
        """
        self._seen, self._newest = self._seen + 1, stamp_ns
        self._start = stamp_ns if self._start is None else self._start
        changed = self._forget(stamp_ns, standing_out)
        if blobs.centres.size:
            self._match(stamp_ns, blobs, claimed, track_since_ns)
        if self._centres.size:  # (no candidate light: nothing to learn or forget, the common case)
            keep = (stamp_ns - self._last) <= CANDIDATE_GAP_S * 1e9
            age = (stamp_ns - self._first) / 1e9
            presence = self._count / (self._seen - self._born + 1)
            learned = keep & (age >= STATIC_LEARN_S) & (presence >= STATIC_PRESENCE)
            for i in np.flatnonzero(learned):
                centre = (float(self._centres[i, 0]), float(self._centres[i, 1]))
                source = Source(centre, float(self._radii[i]) + MASK_MARGIN_PX, int(self._first[i]), stamp_ns)
                self.sources.append(source)
                self.patches.append(LightPatch(source, self.size))
                changed = True
            self._keep(keep & ~learned)
        if gray is not None and self.sources:
            changed |= self._learn_halos(gray, blobs)
        if changed:
            self._mask = None
        return changed

    def _nearest(self, blobs: Blobs) -> tuple[NDArray[np.bool_], NDArray[np.int64]]:
        """(N,) whether each blob matches a candidate, and the nearest candidate's index."""
        distance = distances(blobs.centres, self._centres)
        index = np.argmin(distance, axis=1)
        reach = MATCH_PX + 0.25 * np.maximum(blobs.radii(), self._radii[index])
        return distance[np.arange(index.size), index] <= reach, index

    def _match(self, stamp_ns: int, blobs: Blobs, claimed: NDArray[np.bool_], since_ns: int | None) -> None:
        """Count the blobs on the candidates they match (a claimed blob only on a candidate older than the track);
        the unclaimed others are new candidates."""
        new = ~claimed
        if not self._centres.size and not new.any():  # (no candidate, and every blob the wand's: the common case)
            return
        radii = blobs.radii()
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
            self._born = np.concatenate([self._born, np.full(n, self._seen, dtype=np.int64)])

    def _keep(self, keep: NDArray[np.bool_]) -> None:
        if keep.all():
            return
        self._centres, self._radii = self._centres[keep], self._radii[keep]
        self._first, self._last, self._count = self._first[keep], self._last[keep], self._count[keep]
        self._born = self._born[keep]

    def _learn_halos(self, gray: NDArray[Any], blobs: Blobs) -> bool:
        """Each learned light's halo from this image, away from the other blobs near it; whether a mask changed (a
        halo became known)."""
        full = saturation_of(gray)
        changed = False
        radii = blobs.radii()
        for source, patch in zip(self.sources, self.patches, strict=True):
            if not patch.due():
                continue
            inside = np.flatnonzero(patch.contains(blobs.centres)) if blobs.centres.size else np.zeros(0, np.int64)
            distance = distances(blobs.centres[inside], np.array([source.centre]))[:, 0]
            others = [(*blobs.centres[i], radii[i]) for i, d in zip(inside, distance, strict=True) if d > MATCH_PX + 2]
            if others and patch.waited < PATCH_PATIENCE:  # rather an image with nothing else near
                patch.waited += 1
                continue
            patch.waited = 0
            was = patch.known
            patch.add(gray, full, others)
            changed |= patch.known and not was
        return changed

    def _forget(self, stamp_ns: int, standing_out: NDArray[np.bool_] | None) -> bool:
        if standing_out is None or not self.sources:
            return False
        kept, patches = [], []
        for source, patch, there in zip(self.sources, self.patches, standing_out, strict=True):
            if there:
                kept.append(Source(source.centre, source.radius_px, source.since_ns, stamp_ns))
                patches.append(patch)
            elif stamp_ns - source.seen_ns <= STATIC_FORGET_S * 1e9:
                kept.append(source)
                patches.append(patch)
        changed = len(kept) != len(self.sources)
        self.sources, self.patches = kept, patches
        return changed

    def centres_standing_out(self, gray: NDArray[np.generic], threshold: NDArray[np.generic]) -> NDArray[np.bool_]:
        """(S,) whether each source's centre still stands out: the BOX x BOX sum of the grey image there above the
        box sums' threshold (:func:`~wand_calib_ros.detection.background.box_sums`)."""
        if not self.sources:
            return np.zeros(0, dtype=bool)
        half = BOX // 2
        out = []
        for source in self.sources:
            u = min(max(round(source.centre[0]), half), self.size[0] - 1 - half)
            v = min(max(round(source.centre[1]), half), self.size[1] - 1 - half)
            total = float(gray[v - half : v + half + 1, u - half : u + half + 1].astype(np.float64).sum())
            out.append(total > float(threshold[v, u]))
        return np.array(out, dtype=bool)


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
        radii = blobs.radii() + MASK_MARGIN_PX
        self.circles += [(float(u), float(v), float(r)) for (u, v), r in zip(blobs.centres, radii, strict=True)]

    @property
    def mask(self) -> Mask:
        return mask_from_shapes(self.size, self.circles)
