"""The vision graph of Section III-B: which camera pairs to calibrate and how to chain them.

Vertices are cameras; an edge joins two cameras that both see the whole wand in
at least ``min_shared`` placements, with weight 1 / M_ij (M_ij = that count).
Dijkstra's shortest paths from the reference camera give, for every camera, the
chain of pairwise calibrations that places it in the reference frame.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wand_calib_ros.core.errors import InsufficientDataError

IntArray = NDArray[np.int64]


class DisconnectedRigError(InsufficientDataError):
    """Some cameras share no usable placements with the others (directly or through other cameras)."""


@dataclass(frozen=True, eq=False)
class VisionGraph:
    """Shortest-path tree of the vision graph.

    Attributes:
        names: camera names, in the order of the observations.
        shared: (C, C) M_ij, placements seen completely by both cameras (diagonal: by each).
        reference: index of the reference camera.
        paths: for each camera, the camera indices from the reference to it.
        edges: the pairwise calibrations needed, (parent, child), parents before children.
    """

    names: tuple[str, ...]
    shared: IntArray
    reference: int
    paths: dict[int, list[int]]
    edges: tuple[tuple[int, int], ...]


def covisibility(complete: NDArray[np.bool_]) -> IntArray:
    """(C, C) number of placements both cameras see completely, from a (P, C) mask."""
    as_float = complete.astype(np.float64)  # BLAS: exact for counts below 2^53, integer products are not vectorised
    return np.rint(as_float.T @ as_float).astype(np.int64)


def build_vision_graph(
    names: tuple[str, ...], complete: NDArray[np.bool_], *, reference: str | None = None, min_shared: int = 15
) -> VisionGraph:
    """The vision graph and the shortest paths from the reference camera.

    Args:
        names: camera names (axis 1 of ``complete``).
        complete: (P, C) True where a camera sees all three wand points.
        reference: the reference camera; default: the one with the most co-visibility.
        min_shared: fewest common placements for a pair to be calibrated.

    Raises:
        InsufficientDataError: a camera never sees the whole wand.
        DisconnectedRigError: the usable pairs do not connect every camera; the
            message names the groups and the placements shared across them.
    """
    shared = covisibility(complete)
    lonely = [names[i] for i in range(len(names)) if shared[i, i] == 0]
    if lonely:
        raise InsufficientDataError(f"camera(s) {', '.join(lonely)} never see the whole wand")
    linked = (shared >= min_shared) & ~np.eye(len(names), dtype=bool)
    groups = _components(linked)
    if len(groups) > 1 and len(names) == 2:
        raise DisconnectedRigError(
            f"cameras '{names[0]}' and '{names[1]}' both see the whole wand in only {shared[0, 1]} placements; "
            f"need at least {min_shared}"
        )
    if len(groups) > 1:
        raise DisconnectedRigError(_disconnected_message(names, shared, groups, min_shared))
    ref = reference_index(names, shared, reference)
    paths = _shortest_paths(linked, shared, ref)
    edges: list[tuple[int, int]] = []
    for target in sorted(paths, key=lambda t: (len(paths[t]), t)):
        path = paths[target]
        if len(path) > 1 and (path[-2], path[-1]) not in edges:
            edges.append((path[-2], path[-1]))
    return VisionGraph(names, shared, ref, {int(k): [int(x) for x in v] for k, v in paths.items()}, tuple(edges))


def reference_index(names: tuple[str, ...], shared: IntArray, reference: str | None) -> int:
    """The reference camera's index: the named one, else the one sharing the most placements with the
    others (the first on a tie), from the (C, C) :func:`covisibility`."""
    if reference is None:
        return int(np.argmax(shared.sum(axis=1) - np.diag(shared)))
    if reference in names:
        return names.index(reference)
    raise InsufficientDataError(f"reference camera '{reference}' is not in the rig ({', '.join(names)})")


def chained(linked: NDArray[np.bool_]) -> bool:
    """Whether a (C, C) adjacency links every camera to every other (directly or through others)."""
    return len(_components(linked & ~np.eye(linked.shape[0], dtype=bool))) == 1


def _components(linked: NDArray[np.bool_]) -> list[list[int]]:
    """The connected groups of cameras (ascending, ordered by their first camera) of a (C, C) adjacency."""
    unseen, groups = set(range(linked.shape[0])), []
    while unseen:
        group, frontier = set(), [min(unseen)]
        while frontier:
            camera = frontier.pop()
            if camera not in group:
                group.add(camera)
                frontier.extend(int(j) for j in np.flatnonzero(linked[camera]) if j not in group)
        unseen -= group
        groups.append(sorted(group))
    return groups


def _shortest_paths(linked: NDArray[np.bool_], shared: IntArray, source: int) -> dict[int, list[int]]:
    """Dijkstra's paths from ``source`` over the edges ``linked`` weighted 1 / shared (neighbours in
    ascending order, the first path found kept on a tie)."""
    distance, paths = {source: 0.0}, {source: [source]}
    done: set[int] = set()
    heap, pushed = [(0.0, 0, source)], 1
    while heap:
        dist, _, camera = heapq.heappop(heap)
        if camera in done:
            continue
        done.add(camera)
        for other in (int(j) for j in np.flatnonzero(linked[camera])):
            through = dist + 1.0 / float(shared[camera, other])
            if other not in done and (other not in distance or through < distance[other]):
                distance[other], paths[other] = through, [*paths[camera], other]
                heapq.heappush(heap, (through, pushed, other))
                pushed += 1
    return paths


def _disconnected_message(names: tuple[str, ...], shared: IntArray, groups: list[list[int]], min_shared: int) -> str:
    group_text = " | ".join("{" + ", ".join(names[i] for i in g) + "}" for g in groups)
    across = []
    for a, first in enumerate(groups):
        for second in groups[a + 1 :]:
            for i in first:
                for j in second:
                    if shared[i, j] > 0:
                        across.append(f"{names[i]}-{names[j]} {shared[i, j]}")
    across_text = ", ".join(across) if across else "none"
    return (
        f"the cameras form {len(groups)} groups that cannot be chained: {group_text}; placements seen "
        f"completely by cameras of different groups: {across_text} (a pair needs at least {min_shared}); "
        "wave the wand where the groups' views overlap"
    )
