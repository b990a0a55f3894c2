"""The layered map picture: real documents in, a PNG out, colours where the nodes are."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from agent.core.mapviz import LayeredMap, area_caption, class_colour, render_layered_map
from agent.core.pipeline import areas_message, graph_message
from knowledge.labels import CLASS_COLORS_BGR, CORRIDOR, DOORWAY, ROOM
from knowledge.navigation.graph import DOORWAY as DOORWAY_KIND
from knowledge.navigation.graph import PLACE, NavigationGraph
from knowledge.topology import persistence
from knowledge.topology.areas import AreaMap
from sim.tour import TourWorld, tour_world


@pytest.fixture(scope="module")
def tour() -> TourWorld:
    return tour_world(0)


def documents(tour: TourWorld) -> tuple[dict[str, Any], dict[str, Any], dict[str, int]]:
    """graph and areas messages of a hand-made graph on the tour: corridor nodes, the door,
    room nodes (one still unlabelled), as agent.core.pipeline makes them; and the key node ids."""
    g = NavigationGraph()
    corridor = [g.add_node(PLACE, (x, 1.5), votes={"corridor": 5}).id for x in (2.0, 4.0, 6.0, 8.0)]
    cx, cy = tour.doorway.center
    door = g.add_node(DOORWAY_KIND, (cx, cy), width=tour.doorway.width, orientation=math.pi / 2).id
    room = [g.add_node(PLACE, xy, votes={"room": 5}).id for xy in ((cx, 3.6), (11.3, 3.8), (11.3, 5.8))]
    bare = g.add_node(PLACE, (9.5, 6.3)).id
    for a, b in itertools.pairwise(corridor):
        g.add_edge(a, b)
    g.add_edge(corridor[-1], door)
    g.add_edge(door, room[0])
    g.add_edge(room[0], room[1])
    g.add_edge(room[1], room[2])
    g.add_edge(room[2], bare)
    areas = AreaMap()
    areas.update(g)
    doc = persistence.to_document(g, areas)
    return (
        graph_message(doc, 1.0),
        areas_message(doc, 1.0),
        {"corridor": corridor[1], "door": door, "room": room[1], "bare": bare},
    )


def at(lm: LayeredMap, xy: tuple[float, float], frame: str = "map") -> np.ndarray:
    c, r = lm.px(*xy, frame=frame)
    return lm.image[r, c].astype(int)


def test_the_picture_has_the_grid_the_nodes_in_their_class_colours_and_is_written(
    tour: TourWorld, tmp_path: Path
) -> None:
    graph, areas, ids = documents(tour)
    room_area = next(a["id"] for a in areas["areas"] if a["label"] == "room")
    concepts = {
        "areas": {
            str(room_area): {"id": room_area, "class": "room", "types": ["LivingRoom", "Room"], "names": []}
        },
        "version": 3,
    }
    out = tmp_path / "map.png"
    lm = render_layered_map(tour.grid, graph, areas, concepts, [], out, title="test", scale=4)
    assert lm.scale == 4
    disk = cv2.imread(str(out))
    assert disk is not None and disk.shape == lm.image.shape and np.array_equal(disk, lm.image)
    nodes = {n["id"]: n for n in graph["nodes"]}

    def node_colour(key: str) -> np.ndarray:
        n = nodes[ids[key]]
        return at(lm, (n["x"], n["y"]), "odom")

    assert np.array_equal(node_colour("corridor"), CLASS_COLORS_BGR[CORRIDOR])
    assert np.array_equal(node_colour("room"), CLASS_COLORS_BGR[ROOM])
    assert np.array_equal(node_colour("door"), CLASS_COLORS_BGR[DOORWAY])
    assert np.array_equal(node_colour("bare"), class_colour(None))
    # the grid underneath: a wall cell far from everything drawn is black, unknown space grey
    assert at(lm, (20.5 + 0.07, 1.5)).max() < 40  # the corridor's east end wall
    assert np.array_equal(at(lm, (0.1, 0.1)), [205, 205, 205])
    # the unvisited office is plain free space: white
    assert at(lm, (3.0, 5.0)).min() > 250
    # the room area is tinted towards the room colour between its nodes, the corridor's likewise
    tint = at(lm, (10.9, 4.6))
    room_c = np.array(CLASS_COLORS_BGR[ROOM])
    assert np.abs(tint - (0.28 * room_c + 0.72 * 254)).max() <= 3


def test_captions_come_from_the_concepts_and_objects_sit_at_their_nodes(tour: TourWorld) -> None:
    graph, areas, ids = documents(tour)
    room_area = next(a["id"] for a in areas["areas"] if a["label"] == "room")
    base = render_layered_map(tour.grid, graph, areas, None, [], None, scale=3)
    named = render_layered_map(
        tour.grid,
        graph,
        areas,
        {"areas": {room_area: {"class": "room", "types": ["LivingRoom"], "names": ["den"], "current": True}}},
        [
            {"name": "television", "kind": "Television", "node": ids["room"]},
            {"name": "couch", "kind": "Couch", "x": 11.3, "y": 6.6},
            {"name": "ghost", "kind": "Thing", "node": 999},  # an unknown node: left out
        ],
        None,
        scale=3,
    )
    diff = np.abs(named.image.astype(int) - base.image.astype(int)).sum(axis=2) > 30
    # something changed near the room node (the object's diamond and name) and at the couch
    for xy, frame in (((11.3, 3.8), "odom"), ((11.3, 6.6), "map")):
        c, r = named.px(*xy, frame=frame)
        assert diff[r - 12 : r + 12, c - 12 : c + 40].any()
    # the caption changed (room → den) but the corridor's did not
    corridor_xy = (5.0, 1.5)
    c, r = named.px(*corridor_xy)
    assert not diff[r - 20 : r + 20, c - 60 : c + 60].any()
    assert area_caption({"names": ["kitchen", "recreation room", "kitchen"]}) == "kitchen / recreation room"
    assert area_caption({"types": ["LivingRoom", "Room"], "class": "room"}) == "living room"
    assert area_caption({"types": ["Room"], "class": "room"}) == "room"
    assert area_caption(None, "corridor") == "corridor"
    assert area_caption(None) == "unknown"


def test_the_odometry_frame_is_placed_in_the_map_and_bad_documents_are_refused(tour: TourWorld) -> None:
    graph = {"nodes": [{"id": 1, "x": 0.0, "y": 0.0, "kind": "place", "label": "room"}], "edges": []}
    lm = render_layered_map(tour.grid, graph, None, None, [], None, odom_to_map=(11.0, 4.0, 0.5), scale=2)
    assert lm.px(0.0, 0.0, frame="odom") == lm.px(11.0, 4.0)
    assert lm.px(1.0, 0.0, frame="odom") == lm.px(11.0 + math.cos(0.5), 4.0 + math.sin(0.5))
    assert np.array_equal(at(lm, (11.0, 4.0)), CLASS_COLORS_BGR[ROOM])
    # the default scale makes the longer side about 1400 pixels
    auto = render_layered_map(tour.grid, graph, None, None, [], None)
    assert 1000 <= auto.image.shape[1] <= 1800
    with pytest.raises(ValueError, match=r"loci\.graph/1"):
        render_layered_map(tour.grid, {"nodes": []}, None, None, [], None)
    with pytest.raises(ValueError, match=r"loci\.areas/1"):
        render_layered_map(tour.grid, graph, {"areas": [{"id": 1}]}, None, [], None)
    with pytest.raises(ValueError, match="scale"):
        render_layered_map(tour.grid, graph, None, None, [], None, scale=0)
    with pytest.raises(ValueError, match="frame"):
        lm.px(0.0, 0.0, frame="base")
