"""The guided-tour grammar: many phrasings of each intent, answers, refusals; intents validate."""

from __future__ import annotations

import pytest

from agent.bus.schemas import INTENT_KINDS, SCHEMAS
from agent.dialogue.grammar import NotUnderstood, Understood, normalise, parse, parse_answer, parse_target


def _intent(text: str, **kw: object) -> Understood:
    result = parse(text, **kw)  # type: ignore[arg-type]
    assert isinstance(result, Understood), f"{text!r} was not understood: {result}"
    # every understood utterance must make a valid loci.intent/1
    SCHEMAS.validate(
        {
            "schema": "loci.intent/1",
            "id": "t-1",
            "speaker": "tutor",
            "intent": result.intent,
            "args": result.args,
        }
    )
    return result


@pytest.mark.parametrize(
    ("text", "kind"),
    [
        ("You are in the corridor", "corridor"),
        ("you're in the corridor.", "corridor"),
        ("We are in a kitchen", "kitchen"),
        ("Now you are in the living room!", "living room"),
        ("This room is the kitchen", "kitchen"),
        ("This room is a kitchen", "kitchen"),
        ("This place is an office", "office"),
        ("This is an office", "office"),
        ("This is the kitchen.", "kitchen"),
        ("OK robot, this is a bedroom", "bedroom"),
        ("It's a meeting room", "meeting room"),
        ("This is a hallway", "hallway"),
        ("You are in the recreation room", "recreation room"),
        ("This room is a student office", "student office"),
        ("This room is a kind of library", "library"),
    ],
)
def test_assert_type(text: str, kind: str) -> None:
    result = _intent(text)
    assert result.intent == "assert_type"
    assert result.args == {"type": kind}


@pytest.mark.parametrize(
    ("text", "name"),
    [
        ("I call this room the recreation room", "recreation room"),
        ("We call this place the lounge", "lounge"),
        ("This room is called the Einstein room", "Einstein room"),
        ("This is called the lab", "lab"),
        ("Let's call this the quiet room", "quiet room"),
        ("Call it the den", "den"),
        ("The name of this room is kitchen two", "kitchen two"),
        ("This is Anna's office", "Anna's office"),
        ("This is my office", "my office"),
        ("You are in Peter's room", "Peter's room"),
    ],
)
def test_assert_name(text: str, name: str) -> None:
    result = _intent(text)
    assert result.intent == "assert_name"
    assert result.args == {"name": name}


@pytest.mark.parametrize(
    ("text", "obj"),
    [
        ("This is the charging station", "charging station"),
        ("This is a couch", "couch"),
        ("this is a television", "television"),
        ("That is the TV", "tv"),
        ("There is a couch here", "couch"),
        ("The television is here", "television"),
        ("You are at the charging station", "charging station"),
        ("Here is the coffee machine", "coffee machine"),
    ],
)
def test_assert_object(text: str, obj: str) -> None:
    result = _intent(text)
    assert result.intent == "assert_object"
    assert result.args == {"object": obj}


@pytest.mark.parametrize(
    "text",
    [
        "Where are you?",
        "Where am I?",
        "where are we now",
        "What is this place?",
        "What's this room?",
        "What room is this?",
        "Which room are we in?",
        "Do you know where you are?",
        "Robot, where are you?",
    ],
)
def test_ask_place(text: str) -> None:
    assert _intent(text).intent == "ask_place"


@pytest.mark.parametrize(
    ("text", "head", "determiner", "with_"),
    [
        ("Where is the television?", "television", "the", None),
        ("Where's the couch?", "couch", "the", None),
        ("Where can I find a coffee machine?", "coffee machine", "a", None),
        ("Do you know where the kitchen is?", "kitchen", "the", None),
        ("Where is a room with a couch?", "room", "a", ["couch"]),
        ("Where is Anna's office?", "Anna's office", None, None),
        ("where are the chairs", "chairs", "the", None),
    ],
)
def test_ask_where(text: str, head: str, determiner: str | None, with_: list[str] | None) -> None:
    result = _intent(text)
    assert result.intent == "ask_where"
    target = result.args["target"]
    assert target["head"] == head
    assert target.get("determiner") == determiner
    assert target.get("with") == with_


@pytest.mark.parametrize(
    ("text", "head", "determiner", "with_"),
    [
        ("Go to the television", "television", "the", None),
        ("Go to the kitchen", "kitchen", "the", None),
        ("Go to a room with a couch", "room", "a", ["couch"]),
        ("Go to the charging station", "charging station", "the", None),
        ("Please go back to the charging station.", "charging station", "the", None),
        ("Could you take me to the living room, please?", "living room", "the", None),
        ("Drive to a room that has a television and a couch", "room", "a", ["television", "couch"]),
        ("go to the room with the TV, the table and the bucket", "room", "the", ["tv", "table", "bucket"]),
        ("Let's go to the kitchen", "kitchen", "the", None),
        ("Navigate to Anna's office", "Anna's office", None, None),
        ("Bring me to the lab", "lab", "the", None),
        ("show me the way to the corridor", "corridor", "the", None),
    ],
)
def test_go_to(text: str, head: str, determiner: str | None, with_: list[str] | None) -> None:
    result = _intent(text)
    assert result.intent == "go_to"
    target = result.args["target"]
    assert (target["head"], target.get("determiner"), target.get("with")) == (head, determiner, with_)
    assert head.lower() in target["text"].lower()


@pytest.mark.parametrize(
    ("text", "kind"),
    [
        ("Follow me", "follow_me"),
        ("follow me, please", "follow_me"),
        ("Come with me!", "follow_me"),
        ("Can you follow me?", "follow_me"),
        ("Look around", "look_around"),
        ("Have a look around", "look_around"),
        ("What do you see?", "look_around"),
        ("Stop", "stop"),
        ("Stop!", "stop"),
        ("OK, stop.", "stop"),
        ("stop following me", "stop"),
        ("Wait", "stop"),
        ("Stay here", "stop"),
    ],
)
def test_commands(text: str, kind: str) -> None:
    result = _intent(text)
    assert result.intent == kind
    assert result.args == {}


@pytest.mark.parametrize(
    ("text", "choices", "answer"),
    [
        ("yes", ["yes", "no"], "yes"),
        ("Yes.", ["yes", "no"], "yes"),
        ("yeah, there was", ["yes", "no"], "yes"),
        ("No", ["yes", "no"], "no"),
        ("nope", ["yes", "no"], "no"),
        ("no, there wasn't", ["yes", "no"], "no"),
        ("the kitchen", ["kitchen", "office"], "kitchen"),
        ("Office", ["kitchen", "office"], "office"),
        ("I think it is the office", ["kitchen", "office"], "office"),
        ("Yes", ["Yes", "No"], "Yes"),
    ],
)
def test_answers_to_a_question(text: str, choices: list[str], answer: str) -> None:
    result = _intent(text, choices=choices)
    assert result.intent == "answer"
    assert result.args == {"answer": answer}


def test_yes_without_an_open_question_is_an_answer_to_the_latest() -> None:
    assert _intent("yes").args == {"answer": "yes"}
    assert _intent("No.").args == {"answer": "no"}


def test_an_open_question_does_not_swallow_commands() -> None:
    assert _intent("Go to the kitchen", choices=["yes", "no"]).intent == "go_to"
    assert _intent("Stop", choices=["kitchen", "office"]).intent == "stop"
    # "yes" is not an answer to a question whose choices are places
    assert parse_answer("yes", ["kitchen", "office"]) is None
    # two choices said: ambiguous
    assert parse_answer("kitchen or office", ["kitchen", "office"]) is None


@pytest.mark.parametrize(
    "text",
    [
        "",
        "   ",
        "blah blah",
        "The weather is nice today",
        "This is not the kitchen",
        "Go to",
        "Go to it",
        "Where is",
        "Sing me a song",
        "?!",
    ],
)
def test_not_understood(text: str) -> None:
    assert isinstance(parse(text), NotUnderstood)


def test_every_kind_is_reachable() -> None:
    samples = [
        "You are in the corridor",
        "I call this room the recreation room",
        "This is a couch",
        "Where am I?",
        "Where is the television?",
        "Follow me",
        "Look around",
        "Go to the kitchen",
        "Stop",
        "yes",
    ]
    assert {_intent(t).intent for t in samples} == set(INTENT_KINDS)


def test_normalise_keeps_names_and_drops_politeness() -> None:
    assert normalise("Please, could you go to Anna's office, please?") == "go to Anna's office"
    assert normalise("Where's the TV?") == "where is the TV"
    assert normalise("I call this the Einstein room") == "I call this the Einstein room"


def test_target_limits() -> None:
    assert parse_target("it") is None
    assert parse_target("a room with " + " and ".join(f"thing{i}" for i in range(9))) is None
    assert parse_target("x" * 201) is None
    assert parse_target("a room with a couch") == {
        "head": "room",
        "determiner": "a",
        "with": ["couch"],
        "text": "a room with a couch",
    }


def test_extra_place_words() -> None:
    assert _intent("This is the den").intent == "assert_object"
    assert _intent("This is the den", place_words=["den"]).intent == "assert_type"
