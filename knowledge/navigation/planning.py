"""Paths over the navigation graph: "go to the television" becomes a list of waypoints.

The robot only drives where it has been: a goal is a navigation node, the path is the
shortest chain of graph edges to it (by edge length, metres), and the waypoints are the
nodes' positions in the odometry frame. Doorway nodes on the way are waypoints too, so the
robot passes a door through its middle.

* :func:`distances` — Dijkstra from one node: metres to every reachable node.
* :func:`plan` — the shortest path between two nodes as a :class:`Plan`.
* :func:`start_node` — where a path starts for a robot at a position: the node it is at
  (``graph.current``) when that is within reach, else the nearest node.
* :func:`goal_in_area` — the node to drive to when the goal is a whole area: the reachable
  node of the area nearest to the area's centre (the middle of the room, not its door).
* :func:`nearest_reachable` — among candidate nodes, the one with the shortest path.

Positions are those of the graph, i.e. of the laser in the odometry frame; a laser mounted
off the robot's centre puts the waypoints that far off the robot's reference point.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Collection, Iterable
from dataclasses import dataclass

from knowledge.navigation.graph import NavigationGraph

__all__ = ["Plan", "distances", "goal_in_area", "nearest_reachable", "plan", "start_node"]


@dataclass(frozen=True)
class Plan:
    """A path over the graph.

    Attributes:
        nodes: node ids from the start to the goal (one id when start is the goal).
        waypoints: ``(x, y)`` of each node, metres, odometry frame.
        distance: metres along the edges.
    """

    nodes: tuple[int, ...]
    waypoints: tuple[tuple[float, float], ...]
    distance: float

    @property
    def start(self) -> int:
        return self.nodes[0]

    @property
    def goal(self) -> int:
        return self.nodes[-1]


def distances(graph: NavigationGraph, start: int, *, limit: float = math.inf) -> dict[int, float]:
    """Metres along the edges from ``start`` to every node reachable from it (``start``: 0).

    Nodes farther than ``limit`` metres are left out.

    Raises:
        KeyError: ``start`` is not a node.
    """
    graph.node(start)
    dist = {start: 0.0}
    heap = [(0.0, start)]
    done: set[int] = set()
    while heap:
        d, u = heapq.heappop(heap)
        if u in done:
            continue
        done.add(u)
        for v, w in graph.neighbours(u).items():
            nd = d + w
            if nd <= limit and nd < dist.get(v, math.inf):
                dist[v] = nd
                heapq.heappush(heap, (nd, v))
    return dist


def plan(graph: NavigationGraph, start: int, goal: int) -> Plan | None:
    """The shortest path from ``start`` to ``goal`` (None: the graph does not connect them).

    Raises:
        KeyError: either node is not in the graph.
    """
    path = graph.path(start, goal)
    if path is None:
        return None
    return Plan(
        nodes=tuple(path),
        waypoints=tuple(graph.node(k).xy for k in path),
        distance=graph.path_length(path),
    )


def start_node(graph: NavigationGraph, xy: tuple[float, float] | None = None) -> int | None:
    """The node a path starts from for a robot at ``xy`` (metres, odometry frame).

    ``graph.current`` (the node the robot was last at) when it exists and, given ``xy``, lies
    within ``node_distance`` of it; else the node nearest to ``xy``; None for an empty graph
    (or no current node and no ``xy``).
    """
    cur = graph.current
    if cur is not None and cur in graph:
        if xy is None:
            return cur
        n = graph.node(cur)
        if math.hypot(n.x - xy[0], n.y - xy[1]) <= graph.params.node_distance:
            return cur
    if xy is None:
        return None
    near = graph.nearest(xy)
    return near[0] if near is not None else None


def nearest_reachable(
    graph: NavigationGraph, start: int, candidates: Iterable[int]
) -> tuple[int, float] | None:
    """Of ``candidates``, the node with the shortest path from ``start`` and its length
    (ties: the smaller id); None when none is reachable."""
    dist = distances(graph, start)
    best = [(dist[k], k) for k in candidates if k in dist]
    if not best:
        return None
    d, k = min(best)
    return k, d


def goal_in_area(graph: NavigationGraph, start: int, area_nodes: Collection[int]) -> int | None:
    """The node to drive to for "go to <area>": of the area's nodes reachable from ``start``,
    the one nearest to the centroid of all the area's nodes (ties: the shorter path, then the
    smaller id). ``start`` itself when it is in the area. None when none is reachable."""
    nodes = [k for k in area_nodes if k in graph]
    if not nodes:
        return None
    if start in nodes:
        return start
    dist = distances(graph, start)
    reachable = [k for k in nodes if k in dist]
    if not reachable:
        return None
    cx = sum(graph.node(k).x for k in nodes) / len(nodes)
    cy = sum(graph.node(k).y for k in nodes) / len(nodes)
    return min(reachable, key=lambda k: (math.hypot(graph.node(k).x - cx, graph.node(k).y - cy), dist[k], k))
