"""The navigation graph (Sect. 7.2.2) and its JSON document (``loci.navgraph/1``)."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from knowledge.errors import ProtocolError
from knowledge.navigation.doorways import Doorway
from knowledge.navigation.graph import DOORWAY, PLACE, GraphParams, NavigationGraph
from knowledge.topology import persistence
from knowledge.topology.areas import AreaMap


def walk(
    g: NavigationGraph,
    xs: np.ndarray | list[float],
    y: float = 0.0,
    label: str | None = "room",
    theta: float = 0.0,
) -> None:
    for x in xs:
        g.update((float(x), y, theta), label)


def test_a_node_every_d_along_a_path() -> None:
    g = NavigationGraph(GraphParams(node_distance=1.0))
    walk(g, np.arange(0.0, 10.0, 0.05))
    xs = sorted(n.x for n in g.nodes.values())
    gaps = np.diff(xs)
    assert len(xs) == 10
    assert (gaps > 1.0).all() and (gaps <= 1.0 + 0.05 + 1e-9).all()
    # every position of the path is within d of a node
    path = np.arange(0.0, 10.0, 0.05)
    assert (np.abs(path[:, None] - np.array(xs)[None, :]).min(axis=1) <= 1.0 + 1e-9).all()


def test_no_node_while_standing_and_no_revote() -> None:
    g = NavigationGraph()
    for _ in range(200):
        upd = g.update((1.0, 2.0, 0.3), "corridor")
    assert len(g) == 1
    node = next(iter(g.nodes.values()))
    assert node.visits == 1 and sum(node.votes.values()) == 1  # voted once, with one label seen
    assert not upd.changed


def test_edges_follow_the_path() -> None:
    g = NavigationGraph()
    # an L: along x, then up along y
    for x in np.arange(0.0, 4.0, 0.05):
        g.update((x, 0.0, 0.0), "corridor")
    for y in np.arange(0.0, 4.0, 0.05):
        g.update((4.0, y, math.pi / 2), "corridor")
    order = sorted(g.nodes)  # ids are given in the order the nodes were dropped
    edges = {(a, b) for a, b, _ in g.edges()}
    assert edges == set(itertools.pairwise(order))
    for a, b, length in g.edges():
        na, nb = g.node(a), g.node(b)
        assert length == pytest.approx(math.hypot(na.x - nb.x, na.y - nb.y))


def test_majority_vote_and_revisits_flip_it() -> None:
    g = NavigationGraph(GraphParams(window=10))
    labels = ["room"] * 7 + ["corridor"] * 3
    for k, lab in enumerate(labels):
        g.update((0.002 * k, 0.0, 0.0), lab)
    # the node was dropped on the first scan: one vote, room
    node = g.node(1)
    assert node.label == "room" and node.votes == {"room": 1}
    # go away and come back twice seeing corridor: the window's labels are added each time
    for _ in range(2):
        walk(g, np.arange(0.0, 3.0, 0.05), label="corridor")
        walk(g, np.arange(3.0, -0.05, -0.05), label="corridor")
    assert node.visits == 3
    assert node.votes["corridor"] > node.votes["room"]
    assert node.label == "corridor"


def test_window_keeps_the_last_n_place_labels_and_ignores_doorway() -> None:
    g = NavigationGraph(GraphParams(window=4))
    for lab in ["room", "doorway", "corridor", "corridor", "doorway", "corridor", "room"]:
        g.update((0.0, 0.0, 0.0), lab)
    assert list(g.recent) == ["corridor", "corridor", "corridor", "room"]
    g2 = NavigationGraph(GraphParams(window=4))
    for lab in ["corridor"] * 3 + ["room"]:
        g2.update((5.0, 0.0, 0.0), lab)
    walk(g2, [6.2])  # a new node: votes of the window (room 1 + corridor 3 + the new room label)
    assert g2.node(2).votes == {"corridor": 2, "room": 2}
    assert g2.node(2).label == "corridor"  # a tie: the first in name order when new


def test_labels_of_mostly_guessed_scans_do_not_vote() -> None:
    # a front laser right after start-up: half of the 360° scan is interpolated
    g = NavigationGraph(GraphParams(window=4, min_coverage=0.75))
    for _ in range(5):
        g.update((0.0, 0.0, 0.0), "room", coverage=0.5)
    assert list(g.recent) == [None] * 4  # abstained, each in its slot of the window
    start = g.node(1)
    assert start.label is None and start.votes == {}  # a node, but no label yet
    for x in np.arange(0.1, 1.3, 0.1):
        g.update((float(x), 0.0, 0.0), "corridor", coverage=0.8)
    assert g.node(2).votes == {"corridor": 4} and g.node(2).label == "corridor"
    # coming back with the rear seen: the start node gets its first votes
    for x in np.arange(1.2, -0.05, -0.1):
        g.update((float(x), 0.0, math.pi), "corridor", coverage=0.9)
    assert start.label == "corridor"
    # exactly at the threshold votes; without a coverage every label votes
    g2 = NavigationGraph(GraphParams(min_coverage=0.75))
    g2.update((0.0, 0.0, 0.0), "room", coverage=0.75)
    g2.update((0.0, 0.0, 0.0), "hallway")
    assert list(g2.recent) == ["room", "hallway"]
    # 0: every label votes
    g3 = NavigationGraph(GraphParams(min_coverage=0.0))
    g3.update((0.0, 0.0, 0.0), "room", coverage=0.0)
    assert g3.node(1).label == "room"
    # abstaining scans push old labels out of the window: a node reached later does not get them
    g4 = NavigationGraph(GraphParams(window=4))
    for _ in range(4):
        g4.update((0.0, 0.0, 0.0), "room", coverage=0.9)
    for _ in range(2):
        g4.update((0.5, 0.0, 0.0), "corridor", coverage=0.3)
    g4.update((1.1, 0.0, 0.0), "corridor", coverage=0.3)  # a new node, the window: room + 3 abstained
    assert g4.node(2).votes == {"room": 1} and g4.node(2).label == "room"


@pytest.mark.parametrize("bad", [-0.1, 1.5, float("nan"), True])
def test_min_coverage_must_be_a_share(bad: object) -> None:
    with pytest.raises(ValueError, match="min_coverage"):
        GraphParams(min_coverage=bad)  # type: ignore[arg-type]


@pytest.mark.parametrize("bad", [-0.1, 1.01, float("nan"), float("inf")])
def test_a_coverage_outside_zero_one_is_an_error(bad: float) -> None:
    with pytest.raises(ValueError, match="coverage"):
        NavigationGraph().update((0.0, 0.0, 0.0), "room", coverage=bad)


def test_doorway_nodes_and_no_place_node_inside_an_opening() -> None:
    g = NavigationGraph()
    walk(g, np.arange(0.0, 3.0, 0.05), label="corridor")
    last = g.current
    # the robot passes an opening at x = 3.5: no place node while inside it
    for x in np.arange(3.0, 4.0, 0.05):
        upd = g.update((x, 0.0, 0.0), "doorway", in_opening=True)
        assert not upd.added
    door = Doorway(center=(3.5, 0.02), width=0.9, orientation=0.0, stamp=1.0)
    upd = g.update((4.0, 0.0, 0.0), "room", door)
    dn = g.doorway_nodes()
    assert len(dn) == 1 and dn[0].id in upd.added
    d = dn[0]
    assert d.kind == DOORWAY and d.label == "doorway" and d.width == 0.9 and d.orientation == 0.0
    assert last is not None and g.has_edge(last, d.id)
    walk(g, np.arange(4.0, 7.0, 0.05), label="room")
    after = [n for n in g.place_nodes() if n.x > 3.5]
    assert after and g.has_edge(d.id, min(after, key=lambda n: n.x).id)
    # passing again (the detector reports it 0.3 m off): the same node, visited twice
    g.update((4.0, 0.0, math.pi), "room", Doorway((3.6, -0.2), 1.0, math.pi, 2.0))
    assert len(g.doorway_nodes()) == 1 and d.visits == 2
    assert d.width == pytest.approx(0.95)


def test_doorway_nodes_are_not_reached_from_beside_them() -> None:
    g = NavigationGraph()
    g.add_node(DOORWAY, (1.0, 0.3), width=0.9, orientation=math.pi / 2)
    walk(g, np.arange(0.0, 3.0, 0.05))
    # the corridor nodes link to each other, not through the doorway beside the path
    assert g.neighbours(1) == {}
    assert len(g.place_nodes()) >= 2


def _door_round_trip(g: NavigationGraph, ranges: np.ndarray | None, known: np.ndarray | None = None) -> None:
    """Along a corridor (y = -1.2), up through a door at (3, 0.8) into a room, back out and
    diagonally away down the corridor, never coming within reach of the node below the door."""

    def go(points: list[tuple[float, float, float]], label: str, **kw: object) -> None:
        for x, y, th in points:
            g.update((x, y, th), label, ranges=ranges, known=known, **kw)  # type: ignore[arg-type]

    up, down = math.pi / 2, -math.pi / 2
    go([(x, -1.2, 0.0) for x in np.arange(0.0, 3.0, 0.05)], "corridor")
    go([(3.0, y, up) for y in np.arange(-1.2, 0.0, 0.05)], "corridor")
    go([(3.0, y, up) for y in np.arange(0.0, 1.4, 0.05)], "doorway", in_opening=True)
    g.update((3.0, 1.4, up), "room", Doorway((3.0, 0.8), 0.9, up, 0.0), ranges=ranges, known=known)
    go([(3.0, y, up) for y in np.arange(1.4, 4.0, 0.05)], "room")
    go([(3.0, y, down) for y in np.arange(4.0, 1.4, -0.05)], "room")
    go([(3.0, y, down) for y in np.arange(1.4, 0.0, -0.05)], "doorway", in_opening=True)
    g.update((3.0, 0.0, down), "corridor", Doorway((3.0, 0.8), 0.9, down, 0.0), ranges=ranges, known=known)
    go([(3.0 + t * 1.5, -t * 1.2, -0.67) for t in np.arange(0.0, 1.0, 0.02)], "corridor")
    go([(x, -1.2, 0.0) for x in np.arange(4.5, 8.0, 0.05)], "corridor")


def test_visible_links_join_a_path_that_comes_back_beside_itself() -> None:
    from knowledge.topology.areas import components

    along_path = NavigationGraph()
    _door_round_trip(along_path, None)
    with_scan = NavigationGraph()
    _door_round_trip(with_scan, np.full(360, 10.0))  # nothing in sight blocks
    (door,) = with_scan.doorway_nodes()
    # edges along the path only: the corridor before and after the door are linked only
    # through the doorway node, so without it they fall apart
    assert len(components(along_path)) == 3
    # seeing the corridor's last node on the way out joins the two stretches
    comps = components(with_scan)
    assert len(comps) == 2
    # and no link crosses the door: room and corridor meet only at the doorway node
    for a, b, _ in with_scan.edges():
        ya, yb = with_scan.node(a).y, with_scan.node(b).y
        if door.id not in (a, b):
            assert (ya > 0.8) == (yb > 0.8), (a, b)
    # a wall in the way (every beam 0.3 m) links nothing beyond the path
    walled = NavigationGraph()
    _door_round_trip(walled, np.full(360, 0.3))
    assert sorted(walled.edges()) == sorted(along_path.edges())
    # long beams that were interpolated, not measured (a front laser's rear half with an
    # empty local map), see nothing: they would see through walls
    guessed = NavigationGraph()
    _door_round_trip(guessed, np.full(360, 10.0), known=np.zeros(360, dtype=bool))
    assert sorted(guessed.edges()) == sorted(along_path.edges())


def test_nearest_and_shortest_path() -> None:
    g = NavigationGraph()
    pts = {1: (0, 0), 2: (1, 0), 3: (2, 0), 4: (2, 1), 5: (1, 1.2), 6: (0, 1)}
    for k, xy in pts.items():
        g.add_node(PLACE, xy, node_id=k)
    for a, b in [(1, 2), (2, 3), (3, 4), (4, 5), (5, 6), (6, 1)]:
        g.add_edge(a, b)
    near = g.nearest((1.9, 0.9))
    assert near is not None and near[0] == 4 and near[1] == pytest.approx(math.hypot(0.1, 0.1))
    assert g.path(1, 4) == [1, 2, 3, 4]  # 3 m, against 1 + 1.02 + 1.02 the other way round
    assert g.path(1, 5) == [1, 6, 5]
    assert g.path_length([1, 6, 5]) == pytest.approx(1 + math.hypot(1, 0.2))
    g.add_node(PLACE, (10, 10), node_id=7)
    assert g.path(1, 7) is None
    assert g.path(3, 3) == [3]
    with pytest.raises(KeyError, match="no navigation node 99"):
        g.path(1, 99)


def test_remove_node_reconnects_its_neighbours() -> None:
    g = NavigationGraph()
    for k, xy in {1: (0, 0), 2: (1, 0), 3: (2, 0)}.items():
        g.add_node(PLACE if k != 2 else DOORWAY, xy, node_id=k)
    g.add_edge(1, 2)
    g.add_edge(2, 3)
    assert g.nearest((1.0, 0.1)) == (2, 0.1)
    g.remove_node(2)
    assert list(g.edges()) == [(1, 3, 2.0)]
    assert 2 not in g
    assert g.nearest((1.0, 0.1), kind=PLACE) == (1, math.hypot(1.0, 0.1))
    assert g.nearest((1.0, 0.1), kind=DOORWAY) is None
    g.add_node(PLACE, (5, 5))
    assert max(g.nodes) == 4  # ids are never reused


# ---------------------------------------------------------------------------- persistence


def built_graph() -> tuple[NavigationGraph, AreaMap]:
    g = NavigationGraph()
    walk(g, np.arange(0.0, 3.0, 0.05), label="corridor")
    g.update((3.5, 0.0, 0.0), "doorway", Doorway((3.4, 0.0), 0.9, 0.1, 1.0))
    walk(g, np.arange(3.6, 6.0, 0.05), label="room")
    areas = AreaMap()
    areas.update(g)
    return g, areas


def test_round_trip(tmp_path: Path) -> None:
    g, areas = built_graph()
    path = persistence.save(tmp_path / "nav" / "graph.json", g, areas, meta={"robot": "r1"})
    g2, areas2 = persistence.load(path)
    assert areas2 is not None
    assert persistence.to_document(g2, areas2, meta={"robot": "r1"}) == persistence.to_document(
        g, areas, meta={"robot": "r1"}
    )
    assert json.loads(path.read_text())["schema"] == "loci.navgraph/1"
    # the reloaded graph carries on where the old one stopped
    assert g2.next_id == g.next_id and g2.current == g.current and list(g2.recent) == list(g.recent)
    assert areas2.update(g2) == []  # same areas, nothing to report
    g2.update((8.0, 0.0, 0.0), "room")
    assert max(g2.nodes) == g.next_id
    # written atomically: nothing but the file itself is left in the folder
    assert sorted(p.name for p in path.parent.iterdir()) == ["graph.json"]


def test_min_coverage_is_saved_and_old_documents_load_with_every_label_voting(tmp_path: Path) -> None:
    g, areas = built_graph()
    g.params = GraphParams(min_coverage=0.6)
    doc = persistence.to_document(g, areas)
    assert persistence.from_document(doc)[0].params.min_coverage == 0.6
    del doc["params"]["min_coverage"]  # written before the key existed
    assert persistence.from_document(doc)[0].params.min_coverage == 0.0
    doc["params"]["min_coverage"] = 2.0
    with pytest.raises(ProtocolError, match="min_coverage"):
        persistence.from_document(doc)


def test_graph_without_areas(tmp_path: Path) -> None:
    g, _ = built_graph()
    g2, areas = persistence.loads(persistence.dumps(persistence.to_document(g)))
    assert areas is None and len(g2) == len(g)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda d: d.update(schema="loci.navgraph/2"), "newer than this genius-loci"),
        (lambda d: d.update(schema="loci.topomap/1"), "not a navigation graph"),
        (lambda d: d.pop("nodes"), "missing required field 'nodes'"),
        (lambda d: d["nodes"][0].update(kind="kitchen"), r"nodes\[0\].kind"),
        (lambda d: d["nodes"][0].update(x="far"), r"nodes\[0\].x: expected a number"),
        (lambda d: d["nodes"][1].update(id=d["nodes"][0]["id"]), "repeated"),
        (lambda d: d["edges"].append({"source": 1, "target": 999, "length": 1.0}), "unknown"),
        (lambda d: d["areas"]["areas"][0]["nodes"].append(999), "not place nodes"),
        (lambda d: d.update(next_node_id=1), "not below next_node_id"),
        (lambda d: d["params"].update(node_distance=-1), "node_distance"),
        (lambda d: d.update(current=999), "current node"),
    ],
)
def test_bad_documents_are_rejected_clearly(tmp_path: Path, mutate: object, message: str) -> None:
    g, areas = built_graph()
    doc = persistence.to_document(g, areas)
    mutate(doc)  # type: ignore[operator]
    path = tmp_path / "graph.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(ProtocolError, match=message):
        persistence.load(path)


def test_corrupt_files(tmp_path: Path) -> None:
    g, areas = built_graph()
    path = persistence.save(tmp_path / "graph.json", g, areas)
    text = path.read_text()
    path.write_text(text[: len(text) // 2])  # a torn write (what the atomic write prevents)
    with pytest.raises(ProtocolError, match=r"invalid JSON.*move it aside"):
        persistence.load(path)
    path.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ProtocolError):
        persistence.load(path)
    path.write_text("[1, 2]")
    with pytest.raises(ProtocolError, match="expected a JSON object"):
        persistence.load(path)
    with pytest.raises(FileNotFoundError, match="starts empty"):
        persistence.load(tmp_path / "missing.json")
