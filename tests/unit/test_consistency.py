"""False doorways (Sect. 7.4): a doorway that does not separate the two sides of its opening.

The graphs are grown the way the robot grows them (``NavigationGraph.update`` along a path,
doorways reported where the path crosses an opening), then checked.
"""

from __future__ import annotations

import math

import pytest
from support.navigation import drive

from knowledge.navigation.graph import DOORWAY, PLACE, GraphParams, NavigationGraph
from knowledge.topology.areas import AreaMap, AreaRemoved, AreasMerged
from knowledge.topology.consistency import false_doorways, remove_doorway, side_offset


def doorway_ids(g: NavigationGraph) -> list[int]:
    return sorted(n.id for n in g.doorway_nodes())


def test_a_doorway_passed_and_gone_round_is_reported_and_its_removal_keeps_one_area() -> None:
    g = NavigationGraph(GraphParams(node_distance=1.0))
    areas = AreaMap()
    # through the room, through the "doorway" between a bucket and a table at (3, 0)...
    drive(g, [(0.0, 0.0), (6.0, 0.0)], doors=[((3.0, 0.0), 0.0)])
    areas.update(g)
    assert len(doorway_ids(g)) == 1 and len(areas.areas) == 2  # the room looks like two areas
    assert false_doorways(g, areas) == []  # nothing contradicts the doorway yet
    # ... and back beside the table, to the node it started from, without passing the opening
    before = set(areas.areas)
    drive(g, [(6.0, 0.0), (6.0, 2.0), (0.0, 2.0), (0.0, 0.0)])
    events = areas.update(g)
    # coming back joins the two sides: the areas merge as the loop closes
    merged = [e for e in events if isinstance(e, AreasMerged)]
    assert len(merged) == 1 and {merged[0].area_id, *merged[0].absorbed} == before
    (found,) = false_doorways(g, areas)
    door = g.node(found.door)
    assert door.kind == DOORWAY and found.position == door.xy
    assert all(side_offset(door, g.node(k).xy) < 0 for k in found.sides[0])
    assert all(side_offset(door, g.node(k).xy) > 0 for k in found.sides[1])
    # the evidence: a chain of place nodes from one side to the other, each step an edge
    assert found.path[0] in found.sides[0] and found.path[-1] in found.sides[1]
    assert all(g.has_edge(a, b) for a, b in zip(found.path, found.path[1:], strict=False))
    assert all(g.node(k).kind == PLACE for k in found.path)
    assert found.area == merged[0].area_id
    about = found.as_dict()
    assert about["kind"] == "false_doorway" and about["node"] == found.door
    # "no, there was no door": the node goes, its neighbours are joined, the area stays
    neighbours = sorted(g.neighbours(found.door))
    events = remove_doorway(g, areas, found.door)
    assert found.door not in g and doorway_ids(g) == []
    assert all(g.has_edge(a, b) for a in neighbours for b in neighbours if a != b)
    assert not any(isinstance(e, AreasMerged | AreaRemoved) for e in events)
    assert len(areas.areas) == 1 and false_doorways(g, areas) == []


def test_a_real_doorway_is_not_reported() -> None:
    g = NavigationGraph(GraphParams(node_distance=1.0))
    # along the corridor, into the room through its door at (3, 0) (normal +y) and back out
    drive(
        g,
        [(0.0, -2.0), (3.0, -2.0), (3.0, 2.0), (4.0, 2.0), (3.0, 2.0), (3.0, -2.0), (6.0, -2.0)],
        doors=[((3.0, 0.0), math.pi / 2)],
        label="corridor",
    )
    areas = AreaMap()
    areas.update(g)
    assert len(doorway_ids(g)) == 1 and len(areas.areas) == 2
    assert false_doorways(g, areas) == []


def test_two_doors_into_the_same_room_are_not_reported() -> None:
    g = NavigationGraph(GraphParams(node_distance=1.0))
    # corridor at y = -2; the room above it has doors at x = 1 and x = 5: in one, out the other
    drive(
        g,
        [(-1.0, -2.0), (1.0, -2.0), (1.0, 2.0), (5.0, 2.0), (5.0, -2.0), (7.0, -2.0)],
        doors=[((1.0, 0.0), math.pi / 2), ((5.0, 0.0), math.pi / 2)],
    )
    # the corridor's two ends are far apart: join them as a walk back along it would
    drive(g, [(7.0, -2.0), (-1.0, -2.0)])
    areas = AreaMap()
    areas.update(g)
    assert len(doorway_ids(g)) == 2 and len(areas.areas) == 2
    assert false_doorways(g, areas) == []
    # without its second door the room would be reachable round the first one: then it is reported
    g2 = NavigationGraph(GraphParams(node_distance=1.0))
    drive(
        g2,
        [(-1.0, -2.0), (1.0, -2.0), (1.0, 2.0), (5.0, 2.0), (5.0, -2.0), (-1.0, -2.0)],
        doors=[((1.0, 0.0), math.pi / 2)],
    )
    assert [f.door for f in false_doorways(g2)] == doorway_ids(g2)


def test_a_doorway_entered_and_left_the_same_way_is_not_reported() -> None:
    g = NavigationGraph(GraphParams(node_distance=1.0))
    # into the opening and straight back: every neighbour of the doorway is on one side
    drive(g, [(0.0, 0.0), (2.95, 0.0), (0.0, 0.0)], doors=[((3.0, 0.0), 0.0)])
    assert false_doorways(g) == []


def test_ignored_doorways_and_bad_arguments() -> None:
    g = NavigationGraph(GraphParams(node_distance=1.0))
    drive(g, [(0.0, 0.0), (6.0, 0.0), (6.0, 2.0), (0.0, 2.0), (0.0, 0.0)], doors=[((3.0, 0.0), 0.0)])
    (found,) = false_doorways(g)
    assert false_doorways(g, ignore={found.door}) == []
    with pytest.raises(ValueError, match="margin"):
        false_doorways(g, margin=-1.0)
    with pytest.raises(ValueError, match="not a doorway"):
        remove_doorway(g, AreaMap(), found.path[0])
    with pytest.raises(KeyError):
        remove_doorway(g, AreaMap(), 999)
    # a doorway without an orientation has no sides: never reported
    g.node(found.door).orientation = None
    assert false_doorways(g) == []


def test_removing_a_doorway_between_two_areas_merges_them() -> None:
    g = NavigationGraph(GraphParams(node_distance=1.0))
    drive(g, [(0.0, 0.0), (6.0, 0.0)], doors=[((3.0, 0.0), 0.0)])
    areas = AreaMap()
    areas.update(g)
    assert len(areas.areas) == 2
    sizes = {a.id: len(a.nodes) for a in areas.areas.values()}
    (door,) = doorway_ids(g)
    events = remove_doorway(g, areas, door)
    (merged,) = [e for e in events if isinstance(e, AreasMerged)]
    # the larger area keeps its id and absorbs the other
    assert merged.area_id == max(sizes, key=lambda k: (sizes[k], -k))
    assert merged.absorbed == tuple(k for k in sizes if k != merged.area_id)
    assert AreaRemoved(merged.absorbed[0], "merged") in events
    assert list(areas.areas) == [merged.area_id]
    assert areas.areas[merged.area_id].nodes == frozenset(n.id for n in g.place_nodes())
