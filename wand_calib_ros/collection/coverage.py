"""Is the wand data good enough to calibrate? Coverage per camera and connectivity of the rig.

Per camera: placements seen completely, the share of an 8 x 8 image grid the
wand's points reached, which of the nine image regions (corners, edges,
centre) are still empty, and the widest off-axis angle reached (under the
nominal lens model) against what the image offers, the directions the wand
was held in (image sectors) and how much nearer and farther it went (spread of
its image length). For the rig: placements each camera pair shares and whether
those pairs connect every camera.
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.initialise.intrinsics_init import nominal_bearings
from wand_calib_ros.core.model.rig import RigSpec

FloatArray = NDArray[np.float64]

GRID = 8
#: Sectors of the wand's direction in the image (over 180 degrees).
DIRECTIONS = 6
#: Histogram of log2 |AC| in pixels: LENGTH_BINS bins from 2^0 to 2^LENGTH_OCTAVES.
LENGTH_OCTAVES, LENGTH_BINS = 13, 260
_REGIONS = {
    (0, 0): "top-left", (0, 1): "top", (0, 2): "top-right",
    (1, 0): "left", (1, 1): "centre", (1, 2): "right",
    (2, 0): "bottom-left", (2, 1): "bottom", (2, 2): "bottom-right",
}  # fmt: skip


def _share(value: float, need: float) -> float:
    """How much of a threshold is reached (inf where it asks for nothing)."""
    return float(value) / need if need > 0 else np.inf


def _empty_side(occupied: NDArray[np.bool_]) -> str:
    """Where an image is emptiest, in words: the side (or corner, or centre) with the fewest covered cells."""
    third = GRID // 3
    regions = {
        "left side empty": occupied[:, :third],
        "right side empty": occupied[:, -third:],
        "top empty": occupied[:third],
        "bottom empty": occupied[-third:],
    }
    emptiest = min(regions, key=lambda name: float(regions[name].mean()))
    return emptiest if not regions[emptiest].any() else emptiest.replace(" empty", " nearly empty")


@dataclass(frozen=True)
class CoverageThresholds:
    """What "ready" means. The defaults are what a minute of waving through the volume the cameras
    share reaches on every simulated rig (paper, mixed, paper3, mixed3, ring6; the lowest there: 28 %
    of the image grid, 0.43 of the image's widest angle, 5 directions, depth ratio 1.37;
    ``benchmarks/coverage_defaults.py``); the paper and mixed rigs reach them within 20 s.

    Attributes:
        min_placements: complete views per camera.
        min_image_fraction: share of the 8 x 8 grid cells with wand points.
        min_theta_fraction: widest observed angle over the widest angle the image offers.
        min_pair_placements: placements a camera pair must share to link them.
        min_directions: of DIRECTIONS 30-degree sectors of the wand's direction in the image,
            how many it must have been held in (orientation diversity).
        min_depth_ratio: 90th over 10th percentile of the wand's image length |AC| (it was seen
            near and far: depth diversity).
    """

    min_placements: int = 100
    min_image_fraction: float = 0.25
    min_theta_fraction: float = 0.4
    min_pair_placements: int = 15
    min_directions: int = 4
    min_depth_ratio: float = 1.2


@dataclass(frozen=True)
class CameraCoverage:
    """One camera's coverage and what is missing (plain words).

    Attributes:
        name: the camera.
        placements: its complete views.
        image_fraction: the share of the image grid's cells with wand points.
        max_theta_deg: the widest angle off its axis the wand was seen at.
        reach_theta_deg: the widest angle its image offers.
        missing: every threshold not met, one phrase each.
        gap: the one furthest from being met, in a few words ("18 % of the image covered, left side empty";
            empty when nothing is missing).
    """

    name: str
    placements: int
    image_fraction: float
    max_theta_deg: float
    reach_theta_deg: float
    missing: tuple[str, ...]
    gap: str = ""

    @property
    def ok(self) -> bool:
        return not self.missing


@dataclass(frozen=True)
class CoverageStatus:
    """The rig's coverage: per camera, per pair, connectivity and readiness."""

    cameras: tuple[CameraCoverage, ...]
    shared: NDArray[np.int64]
    connected: bool
    groups: tuple[tuple[str, ...], ...]

    @property
    def ready(self) -> bool:
        return self.connected and all(c.ok for c in self.cameras)

    def progress(self) -> list[str]:
        """One short line per camera still missing something, naming its worst gap, and the cameras not linked."""
        lines = [f"{c.name}: {c.gap}" for c in self.cameras if c.missing]
        if not self.connected:
            lines.append("not linked by shared placements: " + " | ".join(", ".join(g) for g in self.groups))
        return lines

    def messages(self) -> list[str]:
        """One line per problem, e.g. "cam2: corners top-left, bottom-right uncovered"."""
        lines = [f"{c.name}: {'; '.join(c.missing)}" for c in self.cameras if c.missing]
        if not self.connected:
            lines.append("cameras not linked by shared placements: " + " | ".join(", ".join(g) for g in self.groups))
        return lines


class CoverageTracker:
    """Accumulates synchronised frames and reports :class:`CoverageStatus`."""

    def __init__(self, rig: RigSpec, thresholds: CoverageThresholds = CoverageThresholds()) -> None:
        self.rig = rig
        self.thresholds = thresholds
        n = len(rig.cameras)
        self.cells = np.zeros((n, GRID, GRID), dtype=np.int64)
        self.placements = np.zeros(n, dtype=np.int64)
        self.shared = np.zeros((n, n), dtype=np.int64)
        self.max_theta = np.zeros(n)
        self.directions = np.zeros((n, DIRECTIONS), dtype=np.int64)
        self.lengths = np.zeros((n, LENGTH_BINS), dtype=np.int64)
        self._bearings = [nominal_bearings(spec) for spec in rig.cameras]
        self.reach = np.array([self._reach(c) for c in range(n)])

    def _reach(self, c: int) -> float:
        """Widest angle the image offers (the corners, or theta_max if smaller), rad."""
        spec, table = self.rig.cameras[c], self._bearings[c]
        if table is None:
            return spec.max_view_angle
        width, height = spec.image_size
        corners = np.array([[0, 0], [width - 1, 0], [0, height - 1], [width - 1, height - 1]], dtype=float)
        theta = np.arccos(np.clip(table(corners)[:, 2], -1, 1))
        return float(min(theta.max(), spec.max_view_angle))

    def add(self, uv: FloatArray) -> None:
        """Frames: (C, 3, 2) pixels of one, or (F, C, 3, 2) of several; NaN where a camera did not see the point."""
        frames = uv.reshape(-1, *uv.shape[-3:])
        complete = np.all(np.isfinite(frames), axis=(2, 3))  # (F, C)
        counts = complete.astype(np.int64)
        self.placements += counts.sum(axis=0)
        self.shared += counts.T @ counts
        for c in np.flatnonzero(complete.any(axis=0)):
            seen = frames[complete[:, c], c]  # (f, 3, 2)
            width, height = self.rig.cameras[c].image_size
            cells = np.clip((seen / [width, height] * GRID).astype(np.int64), 0, GRID - 1).reshape(-1, 2)
            np.add.at(self.cells[c], (cells[:, 1], cells[:, 0]), 1)
            du, dv = (seen[:, -1] - seen[:, 0]).T
            direction = (np.arctan2(dv, du) % np.pi / np.pi * DIRECTIONS).astype(np.int64) % DIRECTIONS
            self.directions[c] += np.bincount(direction, minlength=DIRECTIONS)
            octave = np.log2(np.maximum(np.hypot(du, dv), 1.0)) / LENGTH_OCTAVES
            length = np.minimum((octave * LENGTH_BINS).astype(np.int64), LENGTH_BINS - 1)
            self.lengths[c] += np.bincount(length, minlength=LENGTH_BINS)
            table = self._bearings[c]
            if table is not None:
                theta = np.arccos(np.clip(table(seen.reshape(-1, 2))[:, 2], -1, 1))
                self.max_theta[c] = max(self.max_theta[c], float(theta.max()))

    def _worst_gap(self, c: int, occupied: NDArray[np.bool_], sectors: int, depth: float) -> str:
        """Camera ``c``'s threshold furthest from being met (the smallest share of it reached), in a few words."""
        t, seen = self.thresholds, bool(self.placements[c])
        shares = {
            f"{self.placements[c]} of {t.min_placements} views of the whole wand": _share(
                self.placements[c], t.min_placements
            ),
            f"{100 * occupied.mean():.0f} % of the image covered, {_empty_side(occupied)}": _share(
                occupied.mean(), t.min_image_fraction
            ),
            f"seen up to {np.degrees(self.max_theta[c]):.0f} deg off-axis, move it towards the border": _share(
                self.max_theta[c], t.min_theta_fraction * self.reach[c]
            ),
            f"held in {sectors} directions, turn it": _share(sectors, t.min_directions) if seen else np.inf,
            "always about as far, move it nearer and farther": (
                _share(depth - 1.0, t.min_depth_ratio - 1.0) if seen else np.inf
            ),
        }
        return min(shares, key=lambda line: shares[line])

    def _depth_ratio(self, c: int) -> float:
        """90th over 10th percentile of the camera's |AC| image lengths (1.0 without data)."""
        cumulative = np.cumsum(self.lengths[c])
        if cumulative[-1] == 0:
            return 1.0
        low, high = np.searchsorted(cumulative, [0.1 * cumulative[-1], 0.9 * cumulative[-1]])
        return float(2.0 ** ((high - low) * LENGTH_OCTAVES / LENGTH_BINS))

    def status(self) -> CoverageStatus:
        """Current coverage against the thresholds."""
        t = self.thresholds
        cameras = []
        for c, spec in enumerate(self.rig.cameras):
            missing = []
            if self.placements[c] < t.min_placements:
                missing.append(f"{self.placements[c]} of {t.min_placements} placements")
            occupied = self.cells[c] > 0
            fraction = float(occupied.mean())
            if fraction < t.min_image_fraction:
                empty = [
                    name for (row, col), name in _REGIONS.items()
                    if not occupied[row * GRID // 3 : (row + 1) * GRID // 3 + (row == 2),
                                    col * GRID // 3 : (col + 1) * GRID // 3 + (col == 2)].any()
                ]  # fmt: skip
                where = f"; {', '.join(empty)} uncovered" if empty else ""
                missing.append(
                    f"{100 * fraction:.0f} % of the image covered (need {100 * t.min_image_fraction:.0f} %){where}"
                )
            if self.max_theta[c] < t.min_theta_fraction * self.reach[c]:
                missing.append(
                    f"wand seen up to {np.degrees(self.max_theta[c]):.0f} deg off-axis of "
                    f"{np.degrees(self.reach[c]):.0f} (need {np.degrees(t.min_theta_fraction * self.reach[c]):.0f}): "
                    "move it towards the image border"
                )
            sectors = int((self.directions[c] > 0).sum())
            if self.placements[c] and sectors < t.min_directions:
                missing.append(
                    f"wand held in {sectors} of {DIRECTIONS} directions in the image (need {t.min_directions}): turn it"
                )
            depth = self._depth_ratio(c)
            if self.placements[c] and depth < t.min_depth_ratio:
                missing.append(
                    f"wand always about as far (image length ratio {depth:.2f}, need {t.min_depth_ratio:g}): "
                    "move it nearer and farther"
                )
            cameras.append(
                CameraCoverage(
                    spec.name,
                    int(self.placements[c]),
                    fraction,
                    float(np.degrees(self.max_theta[c])),
                    float(np.degrees(self.reach[c])),
                    tuple(missing),
                    self._worst_gap(c, occupied, sectors, depth) if missing else "",
                )
            )
        graph = nx.Graph()
        graph.add_nodes_from(range(len(self.rig.cameras)))
        n = len(self.rig.cameras)
        graph.add_edges_from(
            (i, j) for i in range(n) for j in range(i + 1, n) if self.shared[i, j] >= t.min_pair_placements
        )
        groups = tuple(
            tuple(self.rig.cameras[i].name for i in sorted(g)) for g in sorted(nx.connected_components(graph), key=min)
        )
        return CoverageStatus(tuple(cameras), self.shared.copy(), len(groups) == 1, groups)
