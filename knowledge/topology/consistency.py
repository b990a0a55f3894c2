"""Inconsistencies of the navigation map: doorway nodes that do not separate two areas.

Doorways split the navigation graph into areas (Sect. 7.2.3). A doorway node that the
detector reported by mistake (the book's bucket near a table, Sect. 7.4) shows itself when
the robot, having passed it, comes back to a node of the area it left without crossing a
doorway again: the place nodes on the two sides of the opening are then connected by a
path that avoids the doorway node, so they are one area and the doorway separates nothing.
The robot should ask ("Was there a door here?") rather than decide alone.

:func:`false_doorways` finds such doorway nodes: a doorway node with place-node neighbours
on both sides of its opening (by the sign of their offset along the doorway's normal,
beyond ``margin`` metres) whose two sides are joined by a path of place nodes that does not
pass through it. Each one comes back as a :class:`FalseDoorway` with that path as evidence.
A doorway whose neighbours all lie on one side (the robot stepped into the opening and
turned back) is not reported: nothing contradicts it yet.

:func:`remove_doorway` is the correction when the tutor says there was no door: the node
goes (its neighbours joined pairwise, so the graph stays connected) and the areas are
recomputed; the area events (e.g. :class:`~knowledge.topology.areas.AreasMerged`) come back.

Pure functions of the graph: no I/O, no state.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Collection, Iterable
from dataclasses import dataclass

from knowledge.navigation.graph import DOORWAY, PLACE, NavigationGraph, Node
from knowledge.topology.areas import AreaEvent, AreaMap

__all__ = ["FalseDoorway", "false_doorways", "remove_doorway", "side_offset"]


@dataclass(frozen=True)
class FalseDoorway:
    """A doorway node whose two sides are one area.

    Attributes:
        door: the doorway node's id.
        position: its ``(x, y)``, metres, odometry frame.
        sides: the ids of its place-node neighbours on each side of the opening
            (``sides[0]`` behind the normal, ``sides[1]`` in front), sorted.
        path: place nodes from a node of ``sides[0]`` to a node of ``sides[1]`` that avoid
            the doorway (the evidence: the robot went round it).
        area: the id of the area both sides are in (None without an area map).
    """

    door: int
    position: tuple[float, float]
    sides: tuple[tuple[int, ...], tuple[int, ...]]
    path: tuple[int, ...]
    area: int | None = None

    def as_dict(self) -> dict[str, object]:
        """Plain JSON-able values (for a ``loci.ask/1`` message's ``about``)."""
        return {
            "kind": "false_doorway",
            "node": self.door,
            "x": round(self.position[0], 3),
            "y": round(self.position[1], 3),
            "sides": [list(self.sides[0]), list(self.sides[1])],
            "path": list(self.path),
            "area": self.area,
        }


def side_offset(door: Node, xy: tuple[float, float]) -> float:
    """Signed distance (metres) of ``xy`` from the doorway's opening along its normal.

    The normal is the doorway's ``orientation`` (the direction it was first passed in);
    without one, the offset is 0 (the side is unknown).
    """
    if door.orientation is None:
        return 0.0
    return (xy[0] - door.x) * math.cos(door.orientation) + (xy[1] - door.y) * math.sin(door.orientation)


def _path_avoiding(
    graph: NavigationGraph, sources: Iterable[int], targets: Collection[int]
) -> list[int] | None:
    """The fewest-hops path of place nodes from any source to any target (None: none)."""
    prev: dict[int, int | None] = {}
    queue: deque[int] = deque()
    for s in sources:
        prev[s] = None
        queue.append(s)
    while queue:
        u = queue.popleft()
        if u in targets:
            out = [u]
            while (p := prev[out[-1]]) is not None:
                out.append(p)
            return out[::-1]
        for v in sorted(graph.neighbours(u)):
            if v not in prev and graph.nodes[v].kind == PLACE:
                prev[v] = u
                queue.append(v)
    return None


def false_doorways(
    graph: NavigationGraph,
    areas: AreaMap | None = None,
    *,
    ignore: Collection[int] = (),
    margin: float = 0.05,
) -> list[FalseDoorway]:
    """Doorway nodes that do not separate the two sides of their opening (by id).

    Args:
        graph: the navigation graph.
        areas: its areas, to name the area of each finding (optional).
        ignore: doorway ids not to report (already asked about, or confirmed by the tutor).
        margin: metres; neighbours closer than this to the opening's line belong to neither side.
    """
    if not (math.isfinite(margin) and margin >= 0):
        raise ValueError(f"margin must be >= 0 metres, got {margin!r}")
    out: list[FalseDoorway] = []
    for door in sorted(graph.doorway_nodes(), key=lambda n: n.id):
        if door.id in ignore or door.kind != DOORWAY:
            continue
        behind: list[int] = []
        front: list[int] = []
        for k in sorted(graph.neighbours(door.id)):
            node = graph.nodes[k]
            if node.kind != PLACE:
                continue
            s = side_offset(door, node.xy)
            if s < -margin:
                behind.append(k)
            elif s > margin:
                front.append(k)
        if not behind or not front:
            continue
        path = _path_avoiding(graph, behind, set(front))
        if path is None:
            continue
        area = areas.area_of(path[0]) if areas is not None else None
        out.append(
            FalseDoorway(
                door=door.id,
                position=door.xy,
                sides=(tuple(behind), tuple(front)),
                path=tuple(path),
                area=area.id if area is not None else None,
            )
        )
    return out


def remove_doorway(graph: NavigationGraph, areas: AreaMap, door: int) -> list[AreaEvent]:
    """Delete a false doorway node and recompute the areas; returns the areas' events.

    The doorway's neighbours are joined pairwise (the robot did pass there), so the two
    sides become one area if they were not already.

    Raises:
        KeyError: no such node.
        ValueError: the node is not a doorway node.
    """
    node = graph.node(door)
    if node.kind != DOORWAY:
        raise ValueError(
            f"node {door} is a {node.kind} node, not a doorway; only doorways can be removed as false"
        )
    graph.remove_node(door, reconnect=True)
    return areas.update(graph)
