"""The guided-tour language: a tutor's utterance → the kind and ``args`` of a ``loci.intent/1``.

A small grammar of sentence patterns over normalised text (lower-cased first letter,
contractions expanded, punctuation and politeness words removed). What it understands
(``docs/dialogue.md`` has the full list):

- assert_type: "You are in the corridor", "This room is the kitchen", "This is an office"
- assert_name: "I call this room the recreation room", "This room is called the lab", "This is Anna's office"
- assert_object: "This is the charging station", "This is a couch", "There is a couch here"
- ask_place: "Where are you?", "Where am I?", "What is this place?", "Which room is this?"
- ask_where: "Where is the television?", "Where can I find a couch?", "Do you know where the kitchen is?"
- go_to: "Go to the television", "Take me to the kitchen", "Go to a room with a couch"
- follow_me / look_around / stop: "Follow me", "Look around", "Stop"
- answer: "yes", "no", or one of the choices of the question asked last (see :func:`parse`)

Whether "This is the X" names a place type or an object is decided by the head noun: the
words of :data:`PLACE_WORDS` (and nouns ending in one of :data:`PLACE_SUFFIXES`) are place
types, anything else is an object. A possessive ("Anna's office") is a name.

Pure functions; no I/O.
"""

from __future__ import annotations

import re
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from typing import Any

#: Place types a tutor may assert with "This is a ..." (the ontology's room types and classes).
PLACE_WORDS = frozenset(
    {
        "room",
        "corridor",
        "hallway",
        "hall",
        "doorway",
        "door",
        "kitchen",
        "office",
        "living room",
        "bedroom",
        "bathroom",
        "toilet",
        "restroom",
        "washroom",
        "lab",
        "laboratory",
        "lobby",
        "foyer",
        "entrance",
        "library",
        "classroom",
        "lecture room",
        "meeting room",
        "conference room",
        "seminar room",
        "dining room",
        "storage room",
        "storeroom",
        "printer room",
        "copy room",
        "server room",
        "workshop",
        "staircase",
        "stairwell",
        "corridor end",
        "cafeteria",
        "canteen",
        "recreation room",
        "common room",
        "waiting room",
    }
)
#: A noun ending in one of these words is a place type ("recreation room", "student office").
PLACE_SUFFIXES = ("room", "office", "corridor", "hallway", "hall", "kitchen", "lab", "laboratory", "area")

YES_WORDS = frozenset(
    {"yes", "yeah", "yep", "yup", "sure", "correct", "right", "indeed", "affirmative", "of course", "true"}
)
NO_WORDS = frozenset({"no", "nope", "nah", "not really", "negative", "wrong", "false", "no way"})

_CONTRACTIONS = (
    (r"\bwhere's\b", "where is"),
    (r"\bwhat's\b", "what is"),
    (r"\bthat's\b", "that is"),
    (r"\bit's\b", "it is"),
    (r"\bthere's\b", "there is"),
    (r"\bhere's\b", "here is"),
    (r"\byou're\b", "you are"),
    (r"\bwe're\b", "we are"),
    (r"\bi'm\b", "i am"),
    (r"\blet's\b", "let us"),
    (r"\bdon't\b", "do not"),
    (r"\bisn't\b", "is not"),
    (r"\bwasn't\b", "was not"),
    (r"\bcan't\b", "cannot"),
)
_LEADING = re.compile(
    r"^(?:(?:please|ok|okay|so|now|hey|hello|hi|robot|well|and|then|alright|all right|good|great|"
    r"thanks|thank you)(?:\s*,\s*|\s+)|(?:can|could|would|will) you(?: please)?\s+|"
    r"i (?:want|would like|need) you to\s+|(?:please )?try to\s+)+",
    re.IGNORECASE,
)
_TRAILING = re.compile(
    r"(?:(?:\s*,\s*|\s+)(?:please|now|for me|robot|then|again|thanks|thank you))+$", re.IGNORECASE
)
_DETERMINERS = {"the": "the", "this": "the", "that": "the", "a": "a", "an": "a", "some": "a", "any": "a"}
_WITH = re.compile(
    r"\s+(?:with|that has|which has|that have|which have|that contains|containing|having|"
    r"where there is|where there are)\s+",
    re.IGNORECASE,
)
_LIST = re.compile(r"\s*,\s*(?:and\s+|or\s+)?|\s+and\s+|\s+or\s+", re.IGNORECASE)
_PRONOUNS = frozenset({"you", "i", "we", "it", "this", "that", "here", "there", "me", "us", "they", "one"})
_NP = r"(?P<np>.+)"
_SUBJECT = r"(?:this (?:room|place|area|corridor|hallway|one)|this|it|that|here)"
_AREA_SUBJECT = r"(?:this|the) (?:room|place|area|corridor|hallway)"


def _rx(pattern: str) -> re.Pattern[str]:
    return re.compile(pattern, re.IGNORECASE)


_STOP = _rx(
    r"(?:stop|halt|freeze|wait|abort|hold on|hold it|never mind|cancel(?: that| it)?|stay(?: here| there)?|"
    r"stop (?:moving|following(?: me)?|it|there|here|now)|do not move|stand still)"
)
_FOLLOW = _rx(r"(?:follow(?: me)?(?: around)?|come (?:with|along with|after) me|come along|walk with me)")
_LOOK = _rx(
    r"(?:(?:have|take) a look around(?: you| here)?|look around(?: you| here| the room| a bit)?|"
    r"what (?:do|can) you see(?: here| around you)?|what is around (?:you|here|us))"
)
_ASK_PLACE = _rx(
    r"(?:where (?:are|am) (?:you|i|we)(?: now| right now)?|"
    r"what (?:is|was) this(?: (?:place|room|area))?|what (?:place|room|area|kind of (?:place|room)) is this|"
    r"which (?:room|place|area) is this|which (?:room|place|area) are (?:you|we) in|"
    r"where is this|do you know where (?:you|we) are|do you know where i am|what is here)"
)
_ASK_WHERE = (
    _rx(r"do you know where " + _NP + r" (?:is|are)"),
    _rx(r"where (?:is|are) " + _NP),
    _rx(r"where (?:can|do|could|would|might|should) (?:i|we|one) find " + _NP),
    _rx(r"(?:can|could) you (?:find|show me) " + _NP),
)
_GO_TO = (
    _rx(
        r"(?:go|drive|move|navigate|head|walk|return|come|get|run)(?: back)?(?: over)? "
        r"(?:to|into|towards|toward|inside) " + _NP
    ),
    _rx(r"(?:take|bring|lead|guide|show) (?:me|us) (?:the way )?(?:to|into) " + _NP),
    _rx(r"let us go (?:to|into) " + _NP),
    _rx(r"show me the way to " + _NP),
)
_ASSERT_NAME = (
    _rx(r"(?:i|we) (?:call|name|have named|named) (?:" + _AREA_SUBJECT + r"|" + _SUBJECT + r") (?P<name>.+)"),
    _rx(r"(?:" + _AREA_SUBJECT + r"|" + _SUBJECT + r") is (?:called|named|known as) (?P<name>.+)"),
    _rx(r"(?:let us |please )?call (?:" + _AREA_SUBJECT + r"|" + _SUBJECT + r") (?P<name>.+)"),
    _rx(r"(?:the|its) name(?: of (?:" + _AREA_SUBJECT + r"|" + _SUBJECT + r"))? is (?P<name>.+)"),
)
#: "You are in X": X is a place type (an object when said with "at": "You are at the charging station").
_ASSERT_IN = _rx(
    r"(?:you are|we are|i am|you have arrived|we have arrived)(?: now)? (?P<prep>in|inside|at) " + _NP
)
#: "This room is X": X is a place type.
_ASSERT_AREA = _rx(_AREA_SUBJECT + r" is (?:a kind of |a sort of )?" + _NP)
#: "This is X": X is a place type or an object, by its head noun.
_ASSERT_THIS = (
    _rx(_SUBJECT + r" is (?:a kind of |a sort of )?" + _NP),
    _rx(_NP + r" is (?:here|over here|right here|this one)"),
)
_THERE_IS = _rx(r"there (?:is|are) " + _NP + r" (?:here|in here|in this room|over here)")


@dataclass(frozen=True)
class Understood:
    """What an utterance asks of the agent: a ``loci.intent/1`` kind and its ``args``."""

    intent: str
    args: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class NotUnderstood:
    """An utterance outside the grammar; ``reason`` says which part failed (for logs)."""

    text: str
    reason: str = "no rule matches"


Parse = Understood | NotUnderstood


def normalise(text: str) -> str:
    """Words of an utterance joined by single spaces: punctuation, contractions and politeness removed.

    The case of the words is kept (names keep their capitals) except that a sentence-initial
    capital is lowered ("Go to ..." → "go to ..."). Apostrophes of possessives stay ("Anna's").
    """
    text = text.replace("’", "'").replace("‘", "'")
    text = re.sub(r"[^\w', -]+", " ", text)
    text = re.sub(r"(?<!\w)'|'(?!\w)", " ", text)
    text = " ".join(text.replace("_", " ").split())
    text = re.sub(r"\s*,[\s,]*", ", ", text).strip(" ,")
    for pattern, repl in _CONTRACTIONS:
        text = re.sub(pattern, repl, text, flags=re.IGNORECASE)
    previous = None
    while previous != text:
        previous = text
        text = _LEADING.sub("", text).strip(" ,")
        text = _TRAILING.sub("", text).strip(" ,")
    if text[:1].isupper() and not (len(text) > 1 and text[1].isupper()) and not text.startswith(("I ", "I'")):
        first, _, rest = text.partition(" ")
        if "'" not in first:
            text = (first.lower() + " " + rest).strip()
    return text


def _lower_keep_possessive(words: str) -> str:
    """Lower-case a noun phrase except possessive proper names ("Anna's office" stays)."""
    return " ".join(w if w.endswith("'s") and w[:1].isupper() else w.lower() for w in words.split())


def _split_determiner(phrase: str) -> tuple[str | None, str]:
    first, _, rest = phrase.partition(" ")
    det = _DETERMINERS.get(first.lower())
    if det is not None and rest:
        return det, rest
    return None, phrase


def bare_noun(phrase: str) -> str:
    """The phrase without its leading determiner, lower-cased: "the Kitchen" → "kitchen"."""
    return _lower_keep_possessive(_split_determiner(phrase.strip())[1])


def is_possessive(phrase: str) -> bool:
    return bool(re.search(r"\w's\b|\b(?:my|our|your|his|her|their)\s", phrase, re.IGNORECASE))


def is_place_word(noun: str, extra: Collection[str] = ()) -> bool:
    """True when a bare noun names a place type ("kitchen", "recreation room"), not an object."""
    noun = noun.lower()
    if noun in PLACE_WORDS or noun in extra:
        return True
    last = noun.rsplit(" ", 1)[-1]
    return last in PLACE_SUFFIXES


def parse_target(phrase: str) -> dict[str, Any] | None:
    """A referring expression → a TARGET ``{"head", "determiner", "with", "text"}``; None if unusable.

    "a room with a couch and a television" → ``{"head": "room", "determiner": "a", "with":
    ["couch", "television"], "text": ...}``. Pronouns ("it", "here") are refused.
    """
    phrase = " ".join(phrase.split()).strip(" ,")
    if not phrase:
        return None
    parts = _WITH.split(phrase, maxsplit=1)
    det, head = _split_determiner(parts[0])
    head = _lower_keep_possessive(head)
    if not head or head in _PRONOUNS or head.startswith("not ") or len(head) > 200:
        return None
    target: dict[str, Any] = {"head": head, "determiner": det}
    if len(parts) == 2:
        objects = [bare_noun(o) for o in _LIST.split(parts[1]) if o.strip()]
        objects = [o for o in objects if o and o not in _PRONOUNS]
        if not objects or len(objects) > 8 or any(len(o) > 200 for o in objects):
            return None
        target["with"] = objects
    target["text"] = phrase[:400]
    return target


def _answer(text: str, choices: Sequence[str]) -> str | None:
    """The choice an answer picks: "yes"/"no" from their synonyms, or a choice said (unambiguous)."""
    words = " ".join(re.sub(r"[^\w' ]+", " ", text.lower()).split())
    words = re.sub(r"^(?:(?:well|ok|okay|hmm|uh|um|i think|i guess)\s+)+", "", words)
    lowered = {c.lower(): c for c in choices}
    if words in lowered:
        return lowered[words]
    bare = bare_noun(words).lower() if words else words
    if bare in lowered:
        return lowered[bare]
    first = words.split(" ", 1)[0] if words else ""
    head = re.sub(
        r"\s+(?:it|there|that|this|is|was|there was|there is|it is|it was|i am sure)\b.*$", "", words
    )
    for group, canonical in ((YES_WORDS, "yes"), (NO_WORDS, "no")):
        if (words in group or head in group or first in group) and (not lowered or canonical in lowered):
            return lowered.get(canonical, canonical)
    hits = [c for low, c in lowered.items() if re.search(rf"\b{re.escape(low)}\b", words)]
    return hits[0] if len(hits) == 1 else None


def parse_answer(text: str, choices: Sequence[str] = ()) -> str | None:
    """The answer an utterance gives to a question with ``choices`` ("yes"/"no" when none), or None."""
    return _answer(text, choices)


def parse(
    text: str,
    *,
    choices: Sequence[str] | None = None,
    place_words: Collection[str] = (),
) -> Parse:
    """Understand one utterance.

    Args:
        text: what was said (any case and punctuation).
        choices: the choices of the question the robot asked last and that is still open;
            None when no question is open. An utterance that answers it ("yes", "yeah, there
            was", or one of the choices) becomes an ``answer``; without an open question a bare
            "yes"/"no" is still an ``answer`` (to the agent's latest question).
        place_words: more nouns to treat as place types (besides :data:`PLACE_WORDS`).

    Returns:
        :class:`Understood` (intent kind and args; ``answer`` args lack the question id, which
        the caller adds) or :class:`NotUnderstood`.
    """
    if choices is not None:
        picked = _answer(text, choices)
        if picked is not None:
            return Understood("answer", {"answer": picked})
    said = normalise(text)
    if not said:
        return NotUnderstood(text, "nothing to understand")
    if choices is None and said.lower() in YES_WORDS | NO_WORDS:
        return Understood("answer", {"answer": "yes" if said.lower() in YES_WORDS else "no"})
    if _STOP.fullmatch(said):
        return Understood("stop")
    if _FOLLOW.fullmatch(said):
        return Understood("follow_me")
    if _LOOK.fullmatch(said):
        return Understood("look_around")
    if _ASK_PLACE.fullmatch(said):
        return Understood("ask_place")
    for rx in _ASK_WHERE:
        m = rx.fullmatch(said)
        if m:
            target = parse_target(m["np"])
            if target is None:
                return Understood("ask_place") if bare_noun(m["np"]) in _PRONOUNS else NotUnderstood(text)
            return Understood("ask_where", {"target": target})
    for rx in _GO_TO:
        m = rx.fullmatch(said)
        if m:
            target = parse_target(m["np"])
            return Understood("go_to", {"target": target}) if target else NotUnderstood(text, "no goal")
    for rx in _ASSERT_NAME:
        m = rx.fullmatch(said)
        if m:
            return _name(text, m["name"])
    m = _ASSERT_IN.fullmatch(said)
    if m:
        return _assertion(text, m["np"], place=m["prep"].lower() != "at", place_words=place_words)
    m = _ASSERT_AREA.fullmatch(said)
    if m:
        return _assertion(text, m["np"], place=True, place_words=place_words)
    m = _THERE_IS.fullmatch(said)
    if m:
        return _assertion(text, m["np"], place=False, place_words=place_words)
    for rx in _ASSERT_THIS:
        m = rx.fullmatch(said)
        if m:
            return _assertion(text, m["np"], place=None, place_words=place_words)
    return NotUnderstood(text)


def _name(text: str, phrase: str) -> Parse:
    _, name = _split_determiner(" ".join(phrase.split()))
    if not name or name.lower() in _PRONOUNS or name.lower().startswith("not ") or len(name) > 200:
        return NotUnderstood(text, "no name")
    return Understood("assert_name", {"name": name})


def _assertion(text: str, phrase: str, *, place: bool | None, place_words: Collection[str]) -> Parse:
    """An assertion about "here": a type, a name (possessive) or an object, from its noun phrase."""
    phrase = " ".join(phrase.split())
    if is_possessive(phrase):
        return _name(text, phrase)
    if _WITH.search(phrase):
        return NotUnderstood(text, "an assertion names one type or object")
    noun = bare_noun(phrase)
    if not noun or noun in _PRONOUNS or noun.startswith("not ") or len(noun) > 200:
        return NotUnderstood(text, "no type or object")
    if place is None:
        place = is_place_word(noun, place_words)
    if place:
        return Understood("assert_type", {"type": noun})
    return Understood("assert_object", {"object": noun})
