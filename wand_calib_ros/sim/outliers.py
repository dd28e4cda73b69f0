"""Corrupted detections of the kinds a real LED detector produces."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.model.rig import WandObservations

#: The corruptions: A and C swapped, one point replaced by a spurious blob, one point off by 20 px.
KINDS = ("swap", "blob", "gross")


@dataclass(frozen=True, eq=False)
class Corruption:
    """Observations with some camera views corrupted.

    Attributes:
        observations: the corrupted observations.
        corrupted: (F, C) True for the corrupted views.
        kind: (F, C) index into :data:`KINDS` (-1 where clean).
    """

    observations: WandObservations
    corrupted: NDArray[np.bool_]
    kind: NDArray[np.int64]


def corrupt(
    observations: WandObservations,
    fraction: float,
    image_sizes: tuple[tuple[int, int], ...],
    rng: np.random.Generator,
    *,
    gross_px: float = 20.0,
) -> Corruption:
    """Corrupt ``fraction`` of the complete camera views, each with a random kind.

    Args:
        observations: clean observations.
        fraction: share of complete (frame, camera) views to corrupt.
        image_sizes: (width, height) per camera, for spurious blobs.
        rng: seeded generator.
        gross_px: displacement of a gross error, px.
    """
    uv = observations.uv.copy()
    frames, cameras = np.nonzero(observations.complete)
    count = round(fraction * frames.size)
    chosen = rng.choice(frames.size, count, replace=False)
    kind = np.full(observations.complete.shape, -1, dtype=np.int64)
    for index in chosen:
        f, c = frames[index], cameras[index]
        k = int(rng.integers(len(KINDS)))
        kind[f, c] = k
        point = int(rng.integers(3))
        if KINDS[k] == "swap":
            uv[f, c] = uv[f, c, ::-1]
        elif KINDS[k] == "blob":
            width, height = image_sizes[c]
            uv[f, c, point] = rng.uniform([0.0, 0.0], [width - 1.0, height - 1.0])
        else:
            angle = rng.uniform(0, 2 * np.pi)
            uv[f, c, point] += gross_px * np.array([np.cos(angle), np.sin(angle)])
    corrupted = observations.with_uv(uv)
    return Corruption(corrupted, kind >= 0, kind)
