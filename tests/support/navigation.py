"""A robot driven along a polyline through a navigation graph, passing doorways."""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np

from knowledge.navigation.doorways import Doorway
from knowledge.navigation.graph import DOORWAY, PLACE, GraphParams, NavigationGraph

Point = tuple[float, float]


def drive(
    g: NavigationGraph,
    points: Sequence[Point],
    *,
    label: str = "room",
    doors: Sequence[tuple[Point, float]] = (),
    step: float = 0.05,
) -> None:
    """Drive the polyline ``points``; a doorway ``(centre, normal)`` is reported (and the robot
    counts as in the opening within 0.2 m of it) where the path passes through it."""
    passed: set[int] = set()
    for (x0, y0), (x1, y1) in itertools.pairwise(points):
        n = max(1, int(math.hypot(x1 - x0, y1 - y0) / step))
        heading = math.atan2(y1 - y0, x1 - x0)
        for t in np.linspace(0.0, 1.0, n, endpoint=False):
            x, y = x0 + t * (x1 - x0), y0 + t * (y1 - y0)
            doorway, in_opening = None, False
            for i, ((cx, cy), normal) in enumerate(doors):
                d = math.hypot(x - cx, y - cy)
                in_opening = in_opening or d < 0.2
                if d < 0.2 and i not in passed:
                    passed.add(i)
                    # the normal points the way the robot passes
                    along = math.cos(heading - normal) >= 0
                    doorway = Doorway((cx, cy), 0.9, normal if along else normal + math.pi, 0.0)
                elif d >= 0.4:
                    passed.discard(i)
            g.update((x, y, heading), label, doorway, in_opening=in_opening)
    g.update((*points[-1], 0.0), label)


def small_map() -> NavigationGraph:
    """A corridor (0..3, 0), a door at (3, 1), a room (3..4, 2..3); the robot in the room."""
    g = NavigationGraph(GraphParams(node_distance=1.0))
    corridor = [g.add_node(PLACE, (float(x), 0.0), votes={"corridor": 5}).id for x in range(4)]
    for a, b in itertools.pairwise(corridor):
        g.add_edge(a, b)
    door = g.add_node(DOORWAY, (3.0, 1.0), width=0.9, orientation=math.pi / 2).id
    room = [g.add_node(PLACE, xy, votes={"room": 5}).id for xy in ((3.0, 2.0), (4.0, 2.0), (4.0, 3.0))]
    g.add_edge(corridor[-1], door)
    g.add_edge(door, room[0])
    g.add_edge(room[0], room[1])
    g.add_edge(room[1], room[2])
    g.current = room[2]
    return g
