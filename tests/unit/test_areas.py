"""Topological areas (Sect. 7.2.3): split at doorway nodes, majority class, stable ids, events."""

from __future__ import annotations

import numpy as np

from knowledge.navigation.doorways import Doorway
from knowledge.navigation.graph import DOORWAY, PLACE, NavigationGraph
from knowledge.topology.areas import (
    Area,
    AreaClassChanged,
    AreaCreated,
    AreaMap,
    AreaRemoved,
    AreasMerged,
    AreaSplit,
    components,
    majority_label,
)


def chain(spec: str) -> NavigationGraph:
    """A path graph from a string: r = room node, c = corridor node, D = doorway node."""
    g = NavigationGraph()
    prev = None
    for i, ch in enumerate(spec):
        if ch == "D":
            n = g.add_node(DOORWAY, (float(i), 0.0), width=0.9, orientation=0.0)
        else:
            n = g.add_node(PLACE, (float(i), 0.0), votes={"r": {"room": 3}, "c": {"corridor": 3}}[ch])
        if prev is not None:
            g.add_edge(prev, n.id)
        prev = n.id
    return g


def test_areas_split_at_doorways_with_majority_class() -> None:
    g = chain("ccrcDrrcrDcc")
    comps = components(g)
    assert [sorted(c) for c in comps] == [[1, 2, 3, 4], [6, 7, 8, 9], [11, 12]]
    areas = AreaMap()
    events = areas.update(g)
    assert [type(e) for e in events] == [AreaCreated] * 3
    assert sorted(str(v) for v in areas.labels().values()) == ["corridor", "corridor", "room"]
    room, corridor = areas.area_of(8), areas.area_of(4)
    assert room is not None and room.label == "room"  # 3 room nodes, 1 corridor node
    assert corridor is not None and corridor.label == "corridor"
    assert areas.area_of(5) is None  # a doorway belongs to no area
    assert areas.doorway_links(g)[5] == tuple(sorted({corridor.id, room.id}))


def test_majority_ties() -> None:
    g = chain("rc")
    g.node(2).votes = {"corridor": 5}
    assert majority_label(g, [1, 2]) == "corridor"  # one node each; more votes for corridor
    g.node(2).votes = {"corridor": 3}
    assert majority_label(g, [1, 2], previous="room") == "room"  # a full tie keeps the class
    assert majority_label(g, [1, 2]) == "corridor"  # else the first name
    assert majority_label(g, []) is None


def test_ids_are_stable_as_the_graph_grows() -> None:
    g = NavigationGraph()
    areas = AreaMap()
    for x in np.arange(0.0, 4.0, 0.05):
        g.update((x, 0.0, 0.0), "corridor")
    ev = areas.update(g)
    assert len(ev) == 1 and isinstance(ev[0], AreaCreated) and ev[0].label == "corridor"
    corridor_id = ev[0].area_id
    g.update((4.3, 0.0, 0.0), "doorway", Doorway((4.3, 0.0), 0.9, 0.0, 0.0))
    for x in np.arange(4.6, 8.0, 0.05):
        g.update((x, 0.0, 0.0), "room")
        for e in areas.update(g):
            assert not isinstance(e, AreaRemoved | AreasMerged | AreaSplit)
    assert set(areas.areas) == {corridor_id, corridor_id + 1}
    assert areas.areas[corridor_id].label == "corridor" and areas.areas[corridor_id + 1].label == "room"
    # nothing changed: no events, and the same ids on a forced recomputation
    assert areas.update(g) == [] and areas.update(g, force=True) == []


def test_class_change_event() -> None:
    g = chain("rrc")
    areas = AreaMap()
    areas.update(g)
    (aid,) = areas.areas
    assert g.add_votes(1, {"corridor": 10})
    events = areas.update(g)
    assert events == [AreaClassChanged(aid, "room", "corridor")]


def test_merge_when_a_false_doorway_is_removed() -> None:
    g = chain("rrrDrrrr")
    areas = AreaMap()
    areas.update(g)
    first, second = areas.area_of(1), areas.area_of(5)
    assert first is not None and second is not None and first.id != second.id
    g.remove_node(4)  # the tutor: "there is no door here"
    events = areas.update(g)
    # the bigger part keeps its id and absorbs the other
    assert events == [AreasMerged(second.id, (first.id,)), AreaRemoved(first.id, "merged")]
    assert set(areas.areas) == {second.id}
    assert areas.areas[second.id].nodes == frozenset({1, 2, 3, 5, 6, 7, 8})


def test_split_when_a_doorway_appears_between_known_nodes() -> None:
    g = chain("ccccrrr")
    areas = AreaMap()
    areas.update(g)
    (aid,) = areas.areas
    assert areas.areas[aid].label == "corridor"
    # a doorway found between node 4 and node 5 (the edge is replaced by a doorway node)
    assert g.remove_edge(4, 5)
    d = g.add_node(DOORWAY, (4.5, 0.0), width=1.0, orientation=0.0)
    g.add_edge(4, d.id)
    g.add_edge(d.id, 5)
    events = areas.update(g)
    new_id = aid + 1
    assert events == [
        AreaSplit(aid, (new_id,)),
        AreaCreated(new_id, "room", frozenset({5, 6, 7}), "split"),
    ]
    assert areas.areas[aid] == Area(aid, "corridor", frozenset({1, 2, 3, 4}))


def test_removed_when_its_nodes_are_deleted() -> None:
    g = chain("ccDr")
    areas = AreaMap()
    areas.update(g)
    room = areas.area_of(4)
    assert room is not None
    g.remove_node(4)
    assert areas.update(g) == [AreaRemoved(room.id, "emptied")]


def test_restore_checks_ids() -> None:
    m = AreaMap.restore([Area(1, "room", frozenset({1})), Area(3, None, frozenset({2}))], next_id=4)
    assert m.next_id == 4
    for bad in ([Area(1, None, frozenset()), Area(1, None, frozenset())], [Area(5, None, frozenset())]):
        try:
            AreaMap.restore(bad, next_id=4)
        except ValueError as exc:
            assert "area id" in str(exc)
        else:
            raise AssertionError("restore accepted bad ids")
