"""A small office as a navigation graph and its areas (a corridor, a door, a room), and a settable clock."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

from knowledge.navigation.graph import DOORWAY, PLACE, GraphParams, NavigationGraph
from knowledge.topology.areas import AreaMap


@dataclass
class World:
    graph: NavigationGraph
    areas: AreaMap


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def office() -> tuple[World, list[int], int, list[int]]:
    """A corridor along y = 0 (x = 0..5), a door at (5, 1), a room of four nodes above it."""
    g = NavigationGraph(GraphParams(node_distance=1.0))
    corridor = [g.add_node(PLACE, (float(x), 0.0), votes={"corridor": 5}).id for x in range(6)]
    for a, b in itertools.pairwise(corridor):
        g.add_edge(a, b)
    door = g.add_node(DOORWAY, (5.0, 1.0), width=0.9, orientation=math.pi / 2).id
    room = [
        g.add_node(PLACE, xy, votes={"room": 5}).id for xy in ((5.0, 2.0), (6.0, 2.0), (5.0, 3.0), (6.0, 3.0))
    ]
    g.add_edge(corridor[-1], door)
    g.add_edge(door, room[0])
    for a, b in ((0, 1), (0, 2), (1, 3), (2, 3)):
        g.add_edge(room[a], room[b])
    areas = AreaMap()
    areas.update(g)
    return World(g, areas), corridor, door, room
