"""Topological areas of the navigation graph (Sect. 7.2.3), with stable ids and change events.

An **area** is a connected component of the navigation graph's place nodes once the
doorway nodes are taken out: doorways split the graph into rooms and corridors. An area's
**class** is the majority of its nodes' labels (ties: the larger summed vote count, then
the class the area had, then the name).

:class:`AreaMap` recomputes the areas whenever it is given the graph and keeps their ids
stable: each new component is matched to the old areas by node overlap, the largest
overlaps first, each old id going to at most one component. What changed comes back as
events (plain frozen dataclasses) for the conceptual layer:

* :class:`AreaCreated` — a component that overlaps no old area (``cause="new"``) or a piece
  of a split (``cause="split"``);
* :class:`AreaClassChanged` — an area's majority class changed;
* :class:`AreasMerged` — a component covers several old areas; it keeps the id of the
  largest overlap and the others are *absorbed*, each also reported by
  :class:`AreaRemoved` with ``cause="merged"``;
* :class:`AreaSplit` — an old area's nodes fell into several components; the largest piece
  keeps the id, the others are new areas (each also reported by :class:`AreaCreated`
  with ``cause="split"``);
* :class:`AreaRemoved` — an area whose nodes are all gone (or absorbed by a merge).

Events of one update come in this order: merges and splits, removals, creations, class
changes, so a consumer can apply them one by one.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from knowledge.navigation.graph import PLACE, NavigationGraph

__all__ = [
    "Area",
    "AreaClassChanged",
    "AreaCreated",
    "AreaEvent",
    "AreaMap",
    "AreaRemoved",
    "AreaSplit",
    "AreasMerged",
    "components",
]


@dataclass(frozen=True)
class Area:
    """A topological area: its id, majority class (None if no node has a label yet) and nodes."""

    id: int
    label: str | None
    nodes: frozenset[int]


@dataclass(frozen=True)
class AreaCreated:
    """A new area. ``cause``: "new" (new nodes only) or "split" (a piece of :class:`AreaSplit`)."""

    area_id: int
    label: str | None
    nodes: frozenset[int]
    cause: str = "new"


@dataclass(frozen=True)
class AreaClassChanged:
    """An area's majority class changed from ``old`` to ``new``."""

    area_id: int
    old: str | None
    new: str | None


@dataclass(frozen=True)
class AreasMerged:
    """Areas ``absorbed`` joined area ``area_id`` (a doorway removed, a loop closed)."""

    area_id: int
    absorbed: tuple[int, ...]


@dataclass(frozen=True)
class AreaSplit:
    """Area ``area_id`` split: it keeps its largest piece; ``into`` are the new areas."""

    area_id: int
    into: tuple[int, ...]


@dataclass(frozen=True)
class AreaRemoved:
    """Area ``area_id`` is gone. ``cause``: "emptied" (its nodes were deleted) or "merged"."""

    area_id: int
    cause: str = "emptied"


AreaEvent = AreaCreated | AreaClassChanged | AreasMerged | AreaSplit | AreaRemoved


def components(graph: NavigationGraph) -> list[frozenset[int]]:
    """Connected components of the place nodes with the doorway nodes removed (sorted by smallest id)."""
    place = {k for k, n in graph.nodes.items() if n.kind == PLACE}
    seen: set[int] = set()
    out: list[frozenset[int]] = []
    for start in sorted(place):
        if start in seen:
            continue
        comp = {start}
        stack = [start]
        while stack:
            u = stack.pop()
            for v in graph.neighbours(u):
                if v in place and v not in comp:
                    comp.add(v)
                    stack.append(v)
        seen |= comp
        out.append(frozenset(comp))
    return out


def majority_label(graph: NavigationGraph, nodes: Iterable[int], previous: str | None = None) -> str | None:
    """The majority of the nodes' labels (see the module docstring for ties)."""
    count: Counter[str] = Counter()
    weight: Counter[str] = Counter()
    for k in nodes:
        n = graph.nodes[k]
        if n.label is not None:
            count[n.label] += 1
            weight[n.label] += sum(n.votes.values())
    if not count:
        return None
    return min(count, key=lambda c: (-count[c], -weight[c], c != previous, c))


class AreaMap:
    """The topological areas of a navigation graph, kept up to date by :meth:`update`."""

    def __init__(self) -> None:
        self.areas: dict[int, Area] = {}
        self._next_id = 1
        self._seen: tuple[int, int] | None = None  # (id of the graph, its revision) last computed

    @property
    def next_id(self) -> int:
        return self._next_id

    def area_of(self, node_id: int) -> Area | None:
        """The area holding a place node (None for doorway or unknown nodes)."""
        for a in self.areas.values():
            if node_id in a.nodes:
                return a
        return None

    def doorway_links(self, graph: NavigationGraph) -> dict[int, tuple[int, ...]]:
        """Doorway node id → the ids of the areas it connects (sorted)."""
        owner = {k: a.id for a in self.areas.values() for k in a.nodes}
        out: dict[int, tuple[int, ...]] = {}
        for n in graph.doorway_nodes():
            out[n.id] = tuple(sorted({owner[v] for v in graph.neighbours(n.id) if v in owner}))
        return out

    @classmethod
    def restore(cls, areas: Iterable[Area], next_id: int) -> AreaMap:
        """An area map with known areas (loading); ids must be unique and below ``next_id``."""
        m = cls()
        for a in areas:
            if a.id in m.areas or a.id >= next_id or a.id < 1:
                raise ValueError(f"area id {a.id} is repeated or not in 1..{next_id - 1}")
            m.areas[a.id] = a
        m._next_id = int(next_id)
        return m

    def update(self, graph: NavigationGraph, *, force: bool = False) -> list[AreaEvent]:
        """Recompute the areas of ``graph``; returns what changed (nothing if the graph did not)."""
        if not force and self._seen == (id(graph), graph.revision):
            return []
        self._seen = (id(graph), graph.revision)
        comps = components(graph)
        old = self.areas
        owner = {k: a.id for a in old.values() for k in a.nodes}
        # overlaps (component index, old id) -> shared nodes, largest first
        overlap: Counter[tuple[int, int]] = Counter()
        for ci, comp in enumerate(comps):
            for k in comp:
                if k in owner:
                    overlap[(ci, owner[k])] += 1
        pairs = sorted(overlap.items(), key=lambda kv: (-kv[1], kv[0][1], kv[0][0]))
        assigned: dict[int, int] = {}  # component -> id
        used: set[int] = set()
        for (ci, aid), _ in pairs:
            if ci not in assigned and aid not in used:
                assigned[ci] = aid
                used.add(aid)

        merges: list[AreasMerged] = []
        splits: list[AreaSplit] = []
        removed: list[AreaRemoved] = []
        created: list[AreaCreated] = []
        changed: list[AreaClassChanged] = []
        new_areas: dict[int, Area] = {}
        split_of: dict[int, int] = {}  # component -> the old area it split from
        for ci in range(len(comps)):
            if ci in assigned:
                continue
            mine = {aid: n for (c, aid), n in overlap.items() if c == ci}
            assigned[ci] = self._next_id
            self._next_id += 1
            if mine:
                # its nodes belonged to an area whose id went to a bigger piece: a split
                split_of[ci] = min(mine, key=lambda a: (-mine[a], a))
        # an old area whose id no component kept is absorbed by the one with most of its nodes
        kept = set(assigned.values())
        absorber: dict[int, int] = {}
        for (ci, aid), _ in pairs:
            if aid not in kept and aid not in absorber:
                absorber[aid] = ci
        for ci, comp in enumerate(comps):
            aid = assigned[ci]
            prev = old[aid].label if aid in old else None
            new_areas[aid] = Area(aid, majority_label(graph, comp, prev), comp)
            absorbed = sorted(a for a, c in absorber.items() if c == ci)
            if absorbed:
                merges.append(AreasMerged(aid, tuple(absorbed)))
                removed.extend(AreaRemoved(a, "merged") for a in absorbed)
        pieces: dict[int, list[int]] = {}
        for ci, src in split_of.items():
            pieces.setdefault(src, []).append(assigned[ci])
        for src, into in sorted(pieces.items()):
            splits.append(AreaSplit(src, tuple(sorted(into))))
        absorbed_ids = {r.area_id for r in removed}
        for aid in sorted(old):
            if aid not in new_areas and aid not in absorbed_ids:
                removed.append(AreaRemoved(aid, "emptied"))
        for ci in range(len(comps)):
            aid = assigned[ci]
            a = new_areas[aid]
            if aid in old:
                if old[aid].label != a.label:
                    changed.append(AreaClassChanged(aid, old[aid].label, a.label))
            else:
                created.append(AreaCreated(aid, a.label, a.nodes, "split" if ci in split_of else "new"))
        self.areas = dict(sorted(new_areas.items()))
        events: list[AreaEvent] = [*merges, *splits, *removed]
        events.extend(sorted(created, key=lambda e: e.area_id))
        events.extend(changed)
        return events

    def labels(self) -> Mapping[int, str | None]:
        """Area id → class."""
        return {k: a.label for k, a in self.areas.items()}
