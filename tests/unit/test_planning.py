"""Paths over the navigation graph (go-to): shortest paths against an independent oracle."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import shortest_path

from knowledge.navigation.graph import DOORWAY, PLACE, GraphParams, NavigationGraph
from knowledge.navigation.planning import distances, goal_in_area, nearest_reachable, plan, start_node


def random_graph(seed: int, n: int, p: float) -> NavigationGraph:
    rng = np.random.default_rng(seed)
    g = NavigationGraph()
    for _ in range(n):
        g.add_node(PLACE, (float(rng.uniform(0, 10)), float(rng.uniform(0, 10))))
    ids = sorted(g.nodes)
    for a, b in itertools.combinations(ids, 2):
        if rng.random() < p:
            g.add_edge(a, b)
    return g


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(2, 14), st.floats(0.1, 0.6))
def test_shortest_paths_match_scipy(seed: int, n: int, p: float) -> None:
    g = random_graph(seed, n, p)
    ids = sorted(g.nodes)
    index = {k: i for i, k in enumerate(ids)}
    m = np.zeros((n, n))
    for a, b, w in g.edges():
        m[index[a], index[b]] = m[index[b], index[a]] = w
    oracle = shortest_path(csr_matrix(m), method="D", directed=False)
    start = ids[0]
    dist = distances(g, start)
    for k in ids:
        expected = oracle[0, index[k]]
        if math.isinf(expected):
            assert k not in dist and plan(g, start, k) is None
            continue
        assert dist[k] == pytest.approx(expected)
        pl = plan(g, start, k)
        assert pl is not None and pl.start == start and pl.goal == k
        assert pl.distance == pytest.approx(expected)
        # the waypoints are the nodes' positions, consecutive nodes are joined by edges
        assert pl.waypoints == tuple(g.node(v).xy for v in pl.nodes)
        assert all(g.has_edge(a, b) for a, b in itertools.pairwise(pl.nodes))
    if len(dist) > 1:
        far = max(dist.values())
        assert set(distances(g, start, limit=far / 2)) == {k for k, d in dist.items() if d <= far / 2}


def corridor_and_room() -> tuple[NavigationGraph, list[int], int, list[int]]:
    """A corridor along y = 0 (x = 0..5), a door at (5, 1), a room of four nodes above it."""
    g = NavigationGraph(GraphParams(node_distance=1.0))
    corridor = [g.add_node(PLACE, (float(x), 0.0)).id for x in range(6)]
    for a, b in itertools.pairwise(corridor):
        g.add_edge(a, b)
    door = g.add_node(DOORWAY, (5.0, 1.0), width=0.9, orientation=math.pi / 2).id
    room = [g.add_node(PLACE, xy).id for xy in ((5.0, 2.0), (6.0, 2.0), (5.0, 3.0), (6.0, 3.0))]
    g.add_edge(corridor[-1], door)
    g.add_edge(door, room[0])
    for a, b in ((0, 1), (0, 2), (1, 3), (2, 3)):
        g.add_edge(room[a], room[b])
    return g, corridor, door, room


def test_a_path_into_the_room_passes_the_doorway() -> None:
    g, corridor, door, room = corridor_and_room()
    pl = plan(g, corridor[0], room[3])
    assert pl is not None
    assert pl.nodes[:7] == (*corridor, door) and pl.goal == room[3]
    assert pl.distance == pytest.approx(5.0 + 1.0 + 1.0 + 2.0)


def test_goal_in_an_area_is_its_middle_and_start_is_where_the_robot_is() -> None:
    g, corridor, _, room = corridor_and_room()
    # the room's centre is (5.5, 2.5): its four nodes are equally near, the nearest by path wins
    assert goal_in_area(g, corridor[0], room) == room[0]
    # the corridor's middle (x = 2.5): nodes 2 and 3 are equally near it; from the room, 3 is nearer
    assert goal_in_area(g, room[3], corridor) == corridor[3]
    assert goal_in_area(g, corridor[2], corridor) == corridor[2]  # already there
    assert goal_in_area(g, corridor[0], []) is None
    lone = g.add_node(PLACE, (20.0, 20.0)).id
    assert goal_in_area(g, corridor[0], [lone]) is None
    assert nearest_reachable(g, corridor[0], [room[3], corridor[4], lone]) == (corridor[4], 4.0)
    assert nearest_reachable(g, corridor[0], [lone]) is None
    # the start: the current node when the robot is near it, else the nearest node
    assert start_node(NavigationGraph()) is None and start_node(NavigationGraph(), (0.0, 0.0)) is None
    g.current = corridor[1]
    assert start_node(g) == corridor[1] and start_node(g, (1.2, 0.1)) == corridor[1]
    assert start_node(g, (4.1, 0.0)) == corridor[4]
    g.current = None
    assert start_node(g) is None and start_node(g, (5.9, 2.9)) == room[3]
    with pytest.raises(KeyError):
        distances(g, 999)
