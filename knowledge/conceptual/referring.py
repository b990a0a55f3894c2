"""Referring expressions for the robot's answers: "a room", "the living room", "the room with the television".

Pure functions over the JSON the agent sends in the ``content`` of ``loci.say/1`` replies
(see ``docs/dialogue.md``). An AREA is a mapping::

    {"id": 3, "class": "room" | "corridor" | "hallway" | None,
     "types": ["LivingRoom", "Room"],            # most specific first (the reasoner's)
     "names": ["recreation room"],               # what people called it
     "objects": [{"name": "television", "kind": "Television"}],
     "current": True}

Every key is optional; unknown keys are ignored and wrong types are treated as missing, so a
half-filled AREA still gives a sentence. A TARGET is the ``loci.intent/1`` referring
expression ``{"head": "room", "determiner": "a", "with": ["couch"], "text": ...}``.

Which description wins (Dale and Reiter's incremental order, simplified): a name a person gave
("the kitchen", "Anna's office"), else the most specific type below the place class ("the
living room"), else the objects that distinguish it ("the room with the television"), else the
bare class ("the corridor", "a room", "a place").
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from typing import Any

from knowledge.conceptual.lexicon import GENERIC_TYPES, kind_words

#: Place classes that are usually one of a kind in a tour: "the corridor" rather than "a corridor".
UNIQUE_CLASSES = frozenset({"corridor", "hallway"})
#: Object kinds too vague to name an object by ("the room with the object").
_GENERIC_KINDS = frozenset({"thing", "object", "physicalobject", "item"})
#: At most this many objects in "the room with the television and the couch".
MAX_OBJECTS = 2

_VOWEL_SOUND = re.compile(r"[aeiou]|hour|honest|honou?r", re.IGNORECASE)
_NOT_VOWEL_SOUND = re.compile(r"uni|use|usu|eu|one|once", re.IGNORECASE)
_DETERMINED = re.compile(r"(the|a|an|this|that|my|your|his|her|our|their)\s", re.IGNORECASE)


def indefinite(noun: str) -> str:
    """ "a" or "an" before a noun phrase: "an office", "a unit", "an hour"."""
    if _NOT_VOWEL_SOUND.match(noun):
        return f"a {noun}"
    return f"an {noun}" if _VOWEL_SOUND.match(noun) else f"a {noun}"


def with_article(noun: str, *, definite: bool) -> str:
    """The noun with "the" or "a"/"an"; a phrase already determined or possessive stays as it is."""
    noun = " ".join(noun.split())
    if not noun:
        return noun
    if _DETERMINED.match(noun + " ") or "'s " in noun + " " or noun[0].isupper():
        return noun
    return f"the {noun}" if definite else indefinite(noun)


def join_words(items: Sequence[str], conjunction: str = "and") -> str:
    """ "a", "a and b", "a, b and c"."""
    items = [i for i in items if i]
    if len(items) <= 1:
        return items[0] if items else ""
    return f"{', '.join(items[:-1])} {conjunction} {items[-1]}"


def _strings(value: Any) -> list[str]:
    if not isinstance(value, list | tuple):
        return []
    return [v.strip() for v in value if isinstance(v, str) and v.strip()]


def object_words(obj: Any) -> str:
    """The words for one object of an AREA (``{"name", "kind"}``): its kind's words, else its name."""
    if isinstance(obj, str):
        return kind_words(obj) if " " not in obj else obj.lower()
    if not isinstance(obj, Mapping):
        return ""
    kind = obj.get("kind")
    if isinstance(kind, str) and kind.strip() and kind.strip().lower() not in _GENERIC_KINDS:
        return kind_words(kind)
    name = obj.get("name")
    if isinstance(name, str) and name.strip():
        return " ".join(name.replace("_", " ").split())
    return ""


def area_class(area: Mapping[str, Any]) -> str | None:
    """The AREA's place class word ("room", "corridor", ...), or None when unknown."""
    cls = area.get("class")
    if isinstance(cls, str) and cls.strip():
        return cls.strip().lower()
    return None


def specific_type(area: Mapping[str, Any]) -> str | None:
    """The words of the most specific type that says more than the place class, or None."""
    for t in _strings(area.get("types")):
        words = kind_words(t)
        if words and words.replace(" ", "") not in GENERIC_TYPES and words != area_class(area):
            return words
    return None


def area_objects(area: Mapping[str, Any], limit: int = MAX_OBJECTS) -> list[str]:
    """Distinct object words of an AREA, in the order given, at most ``limit``."""
    out: list[str] = []
    objects = area.get("objects")
    for obj in objects if isinstance(objects, list) else []:
        words = object_words(obj)
        if words and words not in out:
            out.append(words)
        if len(out) >= limit:
            break
    return out


def describe_area(
    area: Mapping[str, Any] | None, *, known_before: bool = True, definite: bool | None = None
) -> str:
    """A referring expression for an AREA.

    Args:
        area: the AREA mapping (see the module docstring); None gives "a place".
        known_before: the listener already knows this area (the default): descriptions that pick
            it out are definite ("the living room", "the room with the television"); False
            introduces it ("a living room", "a room with a television"). A bare room class stays
            "a room" either way: it does not tell one room from another. Names stay definite.
        definite: an alias of ``known_before`` (wins when given).

    Returns:
        "the kitchen" (a name), "the living room" (a type), "the room with the television"
        (objects), "the corridor" (a unique class), "a room", or "a place" (nothing known).
    """
    if definite is not None:
        known_before = definite
    if not isinstance(area, Mapping):
        return "a place"
    names = _strings(area.get("names"))
    if names:
        return with_article(names[0], definite=True)
    cls = area_class(area)
    typ = specific_type(area)
    if typ:
        return with_article(typ, definite=known_before)
    noun = cls or "place"
    objects = area_objects(area)
    if objects:
        things = join_words([with_article(o, definite=known_before) for o in objects])
        return f"{with_article(noun, definite=known_before)} with {things}"
    return with_article(noun, definite=known_before and noun in UNIQUE_CLASSES)


def describe_target(target: Any, *, definite: bool | None = None) -> str:
    """A TARGET (``{"head", "determiner", "with"}``) as words: "the television", "a room with a couch".

    ``definite`` forces the article; None keeps the TARGET's determiner (default "the").
    A plain string is taken as the head noun.
    """
    if isinstance(target, str):
        target = {"head": target}
    if not isinstance(target, Mapping):
        return "it"
    head = target.get("head")
    if not isinstance(head, str) or not head.strip():
        text = target.get("text")
        return text.strip() if isinstance(text, str) and text.strip() else "it"
    if definite is None:
        definite = target.get("determiner") != "a"
    phrase = with_article(kind_words(head) if " " not in head.strip() else head.strip(), definite=definite)
    things = [with_article(w, definite=definite) for w in _strings(target.get("with"))]
    return f"{phrase} with {join_words(things)}" if things else phrase


def _capitalise(text: str) -> str:
    return text[:1].upper() + text[1:] if text else text


def _sentence(text: str) -> str:
    text = _capitalise(text.strip())
    return text if not text or text[-1] in ".?!" else text + "."


def _metres(value: Any) -> str | None:
    if isinstance(value, bool) or not isinstance(value, int | float) or value != value or value < 0:
        return None
    return f"{value:.0f} metres" if value >= 10 else f"{value:.1f} metres"


def answer_text(intent: str, content: Mapping[str, Any]) -> str:
    """The English sentence(s) for a reply's ``content`` to an intent of kind ``intent``.

    Returns "" when the content does not carry what that kind's answer needs (the caller then
    uses the agent's own ``text``). Kinds and the content they read:

    - ``ask_place``: ``{"area"}`` → "I am in the living room."; with ``"certain": false`` (the
      tracked pose is not sure) → "I think I am in the living room, but I am not sure where I am."
    - ``ask_where``: ``{"target", "area", "node"}`` → "The television is in the living room."
    - ``go_to``: ``{"target", "distance"}`` → "I am going to the kitchen, 12 metres away.";
      ``{"reached": true}`` → "I have reached the kitchen." (``"certain": false``: "I think I
      have reached the kitchen, but I am not sure where I am.")
    - ``look_around``: ``{"objects", "area"}`` → "I see a television and a couch. I am in ...".
    - ``assert_type``/``assert_name``/``assert_object``: ``{"area"}`` (and ``"object"``) →
      "Thank you. Now I know this is the kitchen."
    - ``follow_me``: ``{"following": true}`` → "I am following you."; ``stop``: ``{"stopped":
      true}`` → "I stopped."; other follow-me reports (``{"state": "lost"}``) and ``answer``
      replies have no sentence here (the agent's text says it).
    """
    if not isinstance(content, Mapping):
        return ""
    area = content.get("area")
    if area is not None and not isinstance(area, Mapping):
        return ""  # malformed: the caller says the agent's text instead
    unsure = content.get("certain") is False
    if intent == "ask_place":
        if area is None:
            return "I do not know where I am." if "area" in content else ""
        if unsure:
            return _sentence(f"I think I am in {describe_area(area)}, but I am not sure where I am")
        return _sentence(f"I am in {describe_area(area)}")
    if intent == "ask_where":
        if "target" not in content and area is None:
            return ""
        what = describe_target(content.get("target"))
        if area is None:
            return _sentence(f"I do not know where {what} is")
        where = describe_area(area)
        if where == what:
            return _sentence(f"we are in {where}" if area.get("current") is True else f"I know {where}")
        if area.get("current") is True:
            return _sentence(f"{what} is here, in {where}")
        return _sentence(f"{what} is in {where}")
    if intent == "go_to":
        goal = describe_target(content.get("target")) if "target" in content else None
        if content.get("reached") is True:
            if unsure:
                return _sentence(
                    f"I think I have reached {goal}, but I am not sure where I am"
                    if goal
                    else "I think I am there, but I am not sure where I am"
                )
            return _sentence(f"I have reached {goal}" if goal else "I am there")
        if "reached" in content or goal is None:  # a failure report: the agent's text says why
            return ""
        far = _metres(content.get("distance"))
        return _sentence(f"I am going to {goal}, {far} away" if far else f"I am going to {goal}")
    if intent == "look_around":
        objects = content.get("objects")
        if not isinstance(objects, list) and area is None:
            return ""
        seen: list[str] = []
        for obj in objects if isinstance(objects, list) else []:
            words = object_words(obj)
            if words and words not in seen:
                seen.append(words)
        parts = [
            f"I see {join_words([with_article(w, definite=False) for w in seen])}."
            if seen
            else "I see nothing I know."
        ]
        if area is not None:
            parts.append(_sentence(f"I am in {describe_area(area)}"))
        return " ".join(parts)
    if intent in ("assert_type", "assert_name", "assert_object"):
        if intent == "assert_object":
            words = object_words(content.get("object"))
            return _sentence(f"thank you. This is {with_article(words, definite=True)}") if words else ""
        if area is None:
            return ""
        return _sentence(f"thank you. Now I know this is {describe_area(area)}")
    if intent == "follow_me" and content.get("following") is True:
        return "I am following you."
    if intent == "stop" and content.get("stopped") is True:
        return "I stopped."
    return ""
