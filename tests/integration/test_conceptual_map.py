"""The conceptual map with the real HermiT reasoner: layers, retraction, ambiguity, contradictions."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import owlready2  # type: ignore[import-untyped]
import pytest

from agent.bus.schemas import CONCEPTS
from knowledge.conceptual import ConceptualMap, InconsistentKnowledge, UnknownWord
from knowledge.conceptual.world import COMMONSENSE_IRI, CS
from knowledge.topology.areas import AreaClassChanged, AreaCreated, AreaRemoved, AreasMerged, AreaSplit


@pytest.fixture
def cmap() -> Iterator[ConceptualMap]:
    m = ConceptualMap()
    yield m
    m.close()


def types(m: ConceptualMap, area: int) -> list[str]:
    return list(m.snapshot()["areas"][str(area)]["types"])


def test_couch_makes_a_living_room_and_removing_it_retracts_that(cmap: ConceptualMap) -> None:
    cmap.set_area(1, "room")
    cmap.set_area(2, "corridor")
    cmap.add_object("couch", "couch", 1, node=4)
    cmap.add_object("charging station", "charging station", 2, node=1, source="tutor")
    assert types(cmap, 1) == ["Room"]  # nothing inferred before reasoning
    cmap.reason()
    snap = cmap.snapshot()
    assert snap["reasoned"] == snap["version"]
    assert snap["areas"]["1"]["types"] == ["LivingRoom", "Room"]
    assert snap["areas"]["1"]["inferred"] == ["LivingRoom"]
    # a corridor with a charging station has no more specific type (book Sect. 7.2.4.4)
    assert snap["areas"]["2"]["types"] == ["Corridor"] and snap["areas"]["2"]["inferred"] == []
    assert snap["objects"]["couch"] == {
        "name": "couch",
        "kind": "Couch",
        "area": 1,
        "node": 4,
        "source": "camera",
    }
    assert snap["objects"]["charging station"]["source"] == "tutor"
    CONCEPTS.validate({"schema": CONCEPTS.id, **snap})

    cmap.remove_object("couch")  # it was never there
    assert types(cmap, 1) == ["Room"], "an inference must go with the fact it came from"
    cmap.reason()
    assert types(cmap, 1) == ["Room"] and cmap.snapshot()["objects"].keys() == {"charging station"}
    assert cmap.reasonings == 2


def test_class_change_retypes_the_area(cmap: ConceptualMap) -> None:
    cmap.set_area(1, "room")
    cmap.add_object("tv", "Television", 1, node=2)
    cmap.reason()
    assert types(cmap, 1) == ["LivingRoom", "Room"]
    cmap.apply_area_events([AreaClassChanged(1, "room", "corridor")], {1: "corridor"})
    snap = cmap.snapshot()["areas"]["1"]
    assert snap["class"] == "corridor" and snap["types"] == ["Corridor"]
    cmap.reason()
    assert types(cmap, 1) == ["Corridor"], "a corridor with a TV is no living room"
    cmap.set_area(1, None)
    assert cmap.snapshot()["areas"]["1"]["class"] is None and types(cmap, 1) == []


def test_merge_and_split_move_objects_and_names(cmap: ConceptualMap) -> None:
    cmap.apply_area_events(
        [AreaCreated(1, "room", frozenset({1, 2})), AreaCreated(2, "room", frozenset({5, 6}))],
        {1: "room", 2: "room"},
    )
    cmap.add_object("tv", "television", 2, node=5)
    cmap.add_object("bookcase", "bookcase", 2, node=6)
    cmap.assert_name(2, "the den", "anna")
    v = cmap.version
    cmap.apply_area_events([AreasMerged(1, (2,)), AreaRemoved(2, "merged")], {1: "room"})
    snap = cmap.snapshot()
    assert snap["version"] > v
    assert list(snap["areas"]) == ["1"]
    assert {o["name"] for o in snap["areas"]["1"]["objects"]} == {"tv", "bookcase"}
    assert snap["areas"]["1"]["names"] == ["the den"]
    assert snap["objects"]["tv"]["area"] == 1
    # the area splits again: the piece holding node 6 takes the bookcase, the names stay
    cmap.apply_area_events(
        [AreaSplit(1, (3,)), AreaCreated(3, "room", frozenset({6}), "split")], {1: "room", 3: "room"}
    )
    snap = cmap.snapshot()
    assert snap["objects"]["bookcase"]["area"] == 3 and snap["objects"]["tv"]["area"] == 1
    assert snap["areas"]["3"]["names"] == [] and snap["areas"]["1"]["names"] == ["the den"]
    cmap.reason()
    assert types(cmap, 1) == ["LivingRoom", "Room"] and types(cmap, 3) == ["Library", "Room"]
    # an emptied area goes; its objects stay, with no area
    cmap.apply_area_events([AreaRemoved(3)], {1: "room"})
    snap = cmap.snapshot()
    assert "3" not in snap["areas"] and snap["objects"]["bookcase"]["area"] is None


def test_two_names_from_two_people_refer_to_one_area(cmap: ConceptualMap) -> None:
    cmap.set_area(7, "room")
    assert cmap.assert_type(7, "kitchen", "anna").accepted
    assert cmap.assert_type(7, "the recreation room", "bob").accepted
    cmap.assert_name(7, "Bob's corner", "bob")
    cmap.add_object("coffee machine", "coffee maker", 7, node=3)
    cmap.reason()
    area = cmap.snapshot()["areas"]["7"]
    assert area["types"][:2] == ["Kitchen", "RecreationRoom"] and "Room" in area["types"]
    assert area["names"] == ["kitchen", "recreation room", "Bob's corner"]
    assert {(s["speaker"], s["class"]) for s in area["asserted"]} >= {
        ("anna", "Kitchen"),
        ("bob", "RecreationRoom"),
    }
    for words in ("kitchen", "recreation room", "bob's corner", "the room with the coffee machine"):
        r = cmap.resolve(words)
        assert r.kind == "area" and r.areas == (7,), words
    where = cmap.resolve("coffee machine")
    assert where.kind == "object" and where.objects == ("coffee machine",) and where.areas == (7,)
    assert cmap.resolve("spaceship").kind == "unknown"
    assert cmap.retract(7, speaker="bob") == 2
    area = cmap.snapshot()["areas"]["7"]
    assert area["names"] == ["kitchen"] and "RecreationRoom" not in area["types"]
    assert "Kitchen" in area["types"], "anna's word and the coffee machine still hold"


def test_contradicting_assertions_are_reported_and_change_nothing(cmap: ConceptualMap) -> None:
    cmap.set_area(2, "corridor")
    cmap.set_area(3, None)
    assert cmap.assert_type(3, "corridor", "anna").accepted
    before, version = cmap.snapshot(), cmap.version
    said = cmap.assert_type(2, "kitchen", "bob")  # "this is the kitchen" in a corridor
    assert not said.accepted and said.cls == "Kitchen"
    assert [(c.layer, c.conflicts_with) for c in said.contradictions] == [("acquired", "Corridor")]
    said = cmap.assert_type(3, "room", "bob")  # anna said corridor
    assert not said.accepted
    assert [(c.layer, c.conflicts_with, c.speaker) for c in said.contradictions] == [
        ("asserted", "Corridor", "anna")
    ]
    assert cmap.snapshot() == before and cmap.version == version
    # the robot later classifies area 3 as a room: kept, reported; the tutor's word wins in reasoning
    found = cmap.set_area(3, "room")
    assert [(c.cls, c.conflicts_with, c.speaker) for c in found] == [("Room", "Corridor", "anna")]
    assert cmap.snapshot()["areas"]["3"]["conflicts"]
    cmap.reason()  # consistent: the acquired class is left out while contradicted
    assert cmap.snapshot()["areas"]["3"]["types"] == ["Corridor"]


def test_bad_words_and_arguments(cmap: ConceptualMap) -> None:
    with pytest.raises(ValueError, match="area class"):
        cmap.set_area(1, "kitchen")
    with pytest.raises(UnknownWord, match="object kind"):
        cmap.add_object("k", "kitchen", 1, None)
    with pytest.raises(UnknownWord, match="area type"):
        cmap.assert_type(1, "couch", "anna")
    with pytest.raises(UnknownWord, match="known"):
        cmap.assert_type(1, "spaceship", "anna")
    with pytest.raises(ValueError, match="no object"):
        cmap.remove_object("ghost")
    with pytest.raises(ValueError):
        cmap.merge_areas(1, 1)
    assert cmap.version == 0


def _disjoint_rooms(path: Path) -> Path:
    """A user ontology: living rooms are never kitchens; and a new room type, the sauna."""
    w = owlready2.World()
    onto = w.get_ontology("http://example.org/my-house.owl")
    cs = onto.get_namespace(CS)
    with onto:

        class LivingRoom(owlready2.Thing):
            namespace = cs

        class Kitchen(owlready2.Thing):
            namespace = cs

        class Room(owlready2.Thing):
            namespace = cs

        class Sauna(Room):
            pass

        Sauna.label = [owlready2.locstr("sauna", "en")]

        owlready2.AllDisjoint([LivingRoom, Kitchen])
    onto.save(str(path))
    w.close()
    return path


def test_reasoner_inconsistency_rolls_back_the_assertion(tmp_path: Path) -> None:
    with ConceptualMap(extra_ontologies=[_disjoint_rooms(tmp_path / "mine.owl")]) as m:
        sauna = m.lexicon.lookup("sauna")
        assert sauna is not None and sauna.name == "Sauna"
        m.set_area(1, "room")
        m.add_object("couch", "Couch", 1, node=1)
        said = m.assert_type(1, "kitchen", "anna")  # nothing inferred yet: looks fine
        assert said.accepted
        with pytest.raises(InconsistentKnowledge) as e:
            m.reason()
        assert any("assert_type" in d and "kitchen" in d for d in e.value.rolled_back)
        assert not any("add_object" in d for d in e.value.rolled_back), "the camera's couch stays"
        area = m.snapshot()["areas"]["1"]
        assert area["asserted"] == [] and area["types"] == ["LivingRoom", "Room"]
        assert [o["name"] for o in area["objects"]] == ["couch"]
        # now the contradiction is caught before the reasoner, from the inferred layer
        said = m.assert_type(1, "kitchen", "anna")
        assert not said.accepted and said.contradictions[0].layer == "inferred"
        assert m.world.get_ontology(COMMONSENSE_IRI).loaded
