"""The vision graph of Section III-B: which camera pairs to calibrate and how to chain them.

Vertices are cameras; an edge joins two cameras that both see the whole wand in
at least ``min_shared`` placements, with weight 1 / M_ij (M_ij = that count).
Dijkstra's shortest paths from the reference camera give, for every camera, the
chain of pairwise calibrations that places it in the reference frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import networkx as nx
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
    graph = nx.Graph()
    graph.add_nodes_from(range(len(names)))
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if shared[i, j] >= min_shared:
                graph.add_edge(i, j, weight=1.0 / shared[i, j])
    groups = sorted((sorted(g) for g in nx.connected_components(graph)), key=lambda g: g[0])
    if len(groups) > 1 and len(names) == 2:
        raise DisconnectedRigError(
            f"cameras '{names[0]}' and '{names[1]}' both see the whole wand in only {shared[0, 1]} placements; "
            f"need at least {min_shared}"
        )
    if len(groups) > 1:
        raise DisconnectedRigError(_disconnected_message(names, shared, groups, min_shared))
    if reference is None:
        off_diagonal = shared.sum(axis=1) - np.diag(shared)
        ref = int(np.argmax(off_diagonal))
    elif reference in names:
        ref = names.index(reference)
    else:
        raise InsufficientDataError(f"reference camera '{reference}' is not in the rig ({', '.join(names)})")
    paths = nx.single_source_dijkstra_path(graph, ref, weight="weight")
    edges: list[tuple[int, int]] = []
    for target in sorted(paths, key=lambda t: (len(paths[t]), t)):
        path = paths[target]
        if len(path) > 1 and (path[-2], path[-1]) not in edges:
            edges.append((path[-2], path[-1]))
    return VisionGraph(names, shared, ref, {int(k): [int(x) for x in v] for k, v in paths.items()}, tuple(edges))


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
