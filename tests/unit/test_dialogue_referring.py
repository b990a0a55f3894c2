"""Referring expressions for areas and targets, and the sentences of each reply kind."""

from __future__ import annotations

from typing import Any

import pytest

from knowledge.conceptual.lexicon import kind_words
from knowledge.conceptual.referring import (
    answer_text,
    describe_area,
    describe_target,
    indefinite,
    join_words,
)

TV = {"name": "tv-1", "kind": "Television"}
COUCH = {"name": "couch", "kind": "Couch"}


@pytest.mark.parametrize(
    ("kind", "words"),
    [
        ("LivingRoom", "living room"),
        ("CoffeeMachine", "coffee machine"),
        ("Television", "television"),
        ("ChargingStation", "charging station"),
        ("TVSet", "tv set"),
        ("coffee_machine", "coffee machine"),
        ("living room", "living room"),
        ("Room2", "room 2"),
        ("", ""),
    ],
)
def test_kind_words(kind: str, words: str) -> None:
    assert kind_words(kind) == words


@pytest.mark.parametrize(
    ("area", "known", "expected"),
    [
        # nothing known beyond the class
        ({"id": 1, "class": "room", "types": ["Room"], "names": [], "objects": []}, True, "a room"),
        ({"id": 1, "class": "room"}, False, "a room"),
        ({"id": 1, "class": None}, True, "a place"),
        ({}, True, "a place"),
        # corridors and hallways are one of a kind
        ({"id": 2, "class": "corridor", "types": ["Corridor"]}, True, "the corridor"),
        ({"id": 2, "class": "corridor"}, False, "a corridor"),
        ({"id": 2, "class": "hallway"}, True, "the hallway"),
        # a subtype from the reasoner
        ({"id": 3, "class": "room", "types": ["LivingRoom", "Room"]}, True, "the living room"),
        ({"id": 3, "class": "room", "types": ["LivingRoom", "Room"]}, False, "a living room"),
        ({"id": 3, "class": "room", "types": ["Office", "Room"]}, False, "an office"),
        ({"id": 3, "class": None, "types": ["Kitchen"]}, True, "the kitchen"),
        # a name a person gave wins over the type and the objects
        (
            {"class": "room", "types": ["LivingRoom"], "names": ["kitchen"], "objects": [TV]},
            True,
            "the kitchen",
        ),
        ({"class": "room", "names": ["recreation room"]}, False, "the recreation room"),
        ({"class": "room", "names": ["Anna's office"]}, True, "Anna's office"),
        # only objects distinguish it
        ({"class": "room", "types": ["Room"], "objects": [TV]}, True, "the room with the television"),
        ({"class": "room", "objects": [TV]}, False, "a room with a television"),
        ({"class": "room", "objects": [TV, COUCH]}, True, "the room with the television and the couch"),
        ({"class": None, "objects": [{"name": "coffee_machine"}]}, True, "the place with the coffee machine"),
        # malformed parts are ignored, not fatal
        ({"class": 5, "types": "Kitchen", "names": [3], "objects": [7, None]}, True, "a place"),
    ],
)
def test_describe_area(area: dict[str, Any], known: bool, expected: str) -> None:
    assert describe_area(area, known_before=known) == expected


def test_definite_is_an_alias_of_known_before() -> None:
    area = {"class": "room", "objects": [TV]}
    assert describe_area(area, definite=False) == describe_area(area, known_before=False)
    assert describe_area(area, known_before=False, definite=True) == "the room with the television"
    assert describe_area(None) == "a place"


def test_objects_are_limited_and_deduplicated() -> None:
    objects = [TV, {"name": "tv-2", "kind": "Television"}, COUCH, {"kind": "Table"}]
    assert (
        describe_area({"class": "room", "objects": objects}) == "the room with the television and the couch"
    )


@pytest.mark.parametrize(
    ("target", "expected"),
    [
        ({"head": "television", "determiner": "the"}, "the television"),
        ({"head": "room", "determiner": "a", "with": ["couch"]}, "a room with a couch"),
        (
            {"head": "room", "determiner": "the", "with": ["tv", "table"]},
            "the room with the tv and the table",
        ),
        ({"head": "Anna's office", "determiner": None}, "Anna's office"),
        ({"head": "office", "determiner": "a"}, "an office"),
        ("kitchen", "the kitchen"),
        ({"text": "that thing"}, "that thing"),
        (None, "it"),
    ],
)
def test_describe_target(target: Any, expected: str) -> None:
    assert describe_target(target) == expected


def test_articles_and_lists() -> None:
    assert indefinite("office") == "an office"
    assert indefinite("unit") == "a unit"
    assert indefinite("hour") == "an hour"
    assert indefinite("couch") == "a couch"
    assert join_words(["a"]) == "a"
    assert join_words(["a", "b", "c"]) == "a, b and c"
    assert join_words([]) == ""


LIVING = {
    "id": 3,
    "class": "room",
    "types": ["LivingRoom", "Room"],
    "names": [],
    "objects": [TV],
    "current": False,
}


@pytest.mark.parametrize(
    ("intent", "content", "expected"),
    [
        ("ask_place", {"area": {"id": 1, "class": "room", "current": True}}, "I am in a room."),
        ("ask_place", {"area": {**LIVING, "current": True}}, "I am in the living room."),
        ("ask_place", {"area": {"id": 2, "class": "corridor"}}, "I am in the corridor."),
        ("ask_place", {"area": None}, "I do not know where I am."),
        (
            "ask_where",
            {"target": {"head": "television", "determiner": "the"}, "area": LIVING, "node": 7},
            "The television is in the living room.",
        ),
        (
            "ask_where",
            {"target": {"head": "television", "determiner": "the"}, "area": {**LIVING, "current": True}},
            "The television is here, in the living room.",
        ),
        (
            "ask_where",
            {"target": {"head": "couch", "determiner": "the"}, "area": None, "node": None},
            "I do not know where the couch is.",
        ),
        (
            "ask_where",
            {"target": {"head": "television"}, "area": {"class": "room", "objects": [TV]}},
            "The television is in the room with the television.",
        ),
        (
            "go_to",
            {
                "target": {"head": "kitchen", "determiner": "the"},
                "node": 4,
                "path": [1, 2, 4],
                "distance": 12.4,
            },
            "I am going to the kitchen, 12 metres away.",
        ),
        (
            "go_to",
            {"target": {"head": "room", "determiner": "a", "with": ["couch"]}, "node": 4, "distance": 3.25},
            "I am going to a room with a couch, 3.2 metres away.",
        ),
        (
            "go_to",
            {"target": {"head": "kitchen", "determiner": "the"}, "reached": True, "node": 4},
            "I have reached the kitchen.",
        ),
        ("go_to", {"reached": True, "node": 4}, "I am there."),
        (
            "look_around",
            {"objects": [TV, COUCH], "area": LIVING},
            "I see a television and a couch. I am in the living room.",
        ),
        (
            "look_around",
            {"objects": [], "area": {"class": "corridor"}},
            "I see nothing I know. I am in the corridor.",
        ),
        (
            "assert_type",
            {"area": {"class": "room", "types": ["Kitchen"]}},
            "Thank you. Now I know this is the kitchen.",
        ),
        (
            "assert_name",
            {"area": {"class": "room", "names": ["recreation room"]}},
            "Thank you. Now I know this is the recreation room.",
        ),
        (
            "assert_object",
            {"object": {"name": "charging station", "kind": "ChargingStation"}},
            "Thank you. This is the charging station.",
        ),
        ("follow_me", {"following": True}, "I am following you."),
        ("stop", {"stopped": True}, "I stopped."),
    ],
)
def test_answer_text(intent: str, content: dict[str, Any], expected: str) -> None:
    assert answer_text(intent, content) == expected


@pytest.mark.parametrize(
    ("intent", "content"),
    [
        ("ask_place", {}),
        ("ask_where", {"node": 3}),
        ("go_to", {"node": 3}),
        ("assert_type", {}),
        ("assert_object", {"area": {"class": "room"}}),
        ("follow_me", {"state": "lost"}),
        ("stop", {"stopped": False}),
        ("answer", {"question": "q-1", "answer": "yes"}),
        ("go_to", {"target": {"head": "kitchen"}, "reached": False, "node": 3}),
        ("follow_me", {}),
        ("nonsense", {"a": 1}),
    ],
)
def test_answer_text_is_empty_when_content_lacks_the_answer(intent: str, content: dict[str, Any]) -> None:
    assert answer_text(intent, content) == ""


def test_known_before_changes_the_article_the_first_time() -> None:
    area = {"class": "room", "types": ["LivingRoom"]}
    first = describe_area(area, known_before=False)
    later = describe_area(area)
    assert first.startswith("a ") and later.startswith("the ")
    assert first.split(" ", 1)[1] == later.split(" ", 1)[1]
