"""Vision graph: weights 1/M_ij, shortest paths from the reference, clear errors when disconnected."""

from __future__ import annotations

import numpy as np
import pytest

from wand_calib_ros.core.errors import InsufficientDataError
from wand_calib_ros.core.initialise.vision_graph import DisconnectedRigError, build_vision_graph, covisibility

NAMES = ("c0", "c1", "c2", "c3")


def _complete(pairs: dict[tuple[int, int], int], n_cameras: int = 4) -> np.ndarray:
    rows = []
    for (i, j), count in pairs.items():
        row = np.zeros(n_cameras, dtype=bool)
        row[[i, j]] = True
        rows.extend([row] * count)
    return np.array(rows)


def test_paths_follow_the_most_shared_placements() -> None:
    # c0-c2 share few placements, so c2 is reached through c1 (the paper's Fig. 8 situation).
    complete = _complete({(0, 1): 100, (1, 2): 80, (0, 2): 20, (2, 3): 50})
    graph = build_vision_graph(NAMES, complete, reference="c0")
    assert graph.paths[2] == [0, 1, 2] and graph.paths[3] == [0, 1, 2, 3]
    assert graph.edges == ((0, 1), (1, 2), (2, 3))
    assert covisibility(complete)[0, 1] == 100


def test_default_reference_has_the_most_co_visibility() -> None:
    complete = _complete({(0, 1): 30, (1, 2): 80, (1, 3): 60})
    assert build_vision_graph(NAMES, complete).reference == 1


def test_disconnected_rig_names_the_groups_and_shared_counts() -> None:
    complete = _complete({(0, 1): 100, (2, 3): 90, (1, 2): 4})
    with pytest.raises(DisconnectedRigError) as error:
        build_vision_graph(NAMES, complete, min_shared=15)
    message = str(error.value)
    assert "{c0, c1} | {c2, c3}" in message and "c1-c2 4" in message and "at least 15" in message


def test_camera_that_never_sees_the_wand_is_named() -> None:
    complete = _complete({(0, 1): 100, (1, 2): 100})
    with pytest.raises(InsufficientDataError, match="c3 never see the whole wand"):
        build_vision_graph(NAMES, complete)


def test_unknown_reference_is_an_error() -> None:
    with pytest.raises(InsufficientDataError, match="reference camera 'cX'"):
        build_vision_graph(NAMES, _complete({(0, 1): 50, (1, 2): 50, (2, 3): 50}), reference="cX")


def test_the_chains_are_networkx_shortest_paths_on_random_rigs() -> None:
    import networkx as nx

    rng = np.random.default_rng(8)
    tested = 0
    for _ in range(40):
        n = int(rng.integers(2, 12))
        complete = rng.random((200, n)) < rng.uniform(0.2, 0.9, n)
        complete[:, 0] |= complete.sum(axis=1) == 1  # every camera shares with camera 0 somewhere
        names = tuple(f"c{i}" for i in range(n))
        shared = covisibility(complete)
        graph = nx.Graph()
        graph.add_nodes_from(range(n))
        for i in range(n):
            for j in range(i + 1, n):
                if shared[i, j] >= 15:
                    graph.add_edge(i, j, weight=1.0 / shared[i, j])
        if not nx.is_connected(graph) or np.any(np.diag(shared) == 0):
            continue
        result = build_vision_graph(names, complete, min_shared=15)
        assert result.paths == nx.single_source_dijkstra_path(graph, result.reference, weight="weight")
        tested += 1
    assert tested >= 20
