"""Words ↔ ontology classes, from the classes' ``rdfs:label`` and ``skos:altLabel``.

"living room" ↔ LivingRoom, "tv" → Television. Words are normalised (lower case, no
punctuation, no leading article, single spaces); a plural falls back to its singular.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

_ARTICLES = ("the ", "a ", "an ", "this ", "that ", "my ", "our ", "your ")
_CAMEL = re.compile(r"(?<=[a-z0-9])(?=[A-Z])")


#: Ontology classes that say no more than the place class: never used as a description.
GENERIC_TYPES = frozenset(
    {"thing", "place", "area", "location", "room", "corridor", "hallway", "doorway", "space", "region"}
)
_WORD_OF_CLASS = re.compile(r"[A-Z]+(?=[A-Z][a-z])|[A-Z]?[a-z]+|[A-Z]+|\d+")


def kind_words(kind: str) -> str:
    """An ontology class name as lower-case words: "LivingRoom" → "living room".

    Underscores and hyphens separate words too ("coffee_machine" → "coffee machine"); text
    that already has spaces is only lower-cased; acronyms stay together ("TVSet" → "tv set").
    """
    text = kind.strip()
    if not text:
        return ""
    if " " in text:
        return " ".join(text.lower().split())
    words: list[str] = []
    for part in re.split(r"[_\-]+", text):
        words.extend(_WORD_OF_CLASS.findall(part) or [part])
    return " ".join(w.lower() for w in words if w)


def normalise(words: str) -> str:
    """Lower case, punctuation other than apostrophes dropped, leading articles removed."""
    w = re.sub(r"[^\w' ]+", " ", words.lower().replace("_", " "))
    w = " ".join(w.split())
    stripped = True
    while stripped:
        stripped = False
        for a in _ARTICLES:
            if w.startswith(a):
                w, stripped = w[len(a) :], True
    return w


def class_words(name: str) -> str:
    """A class name as words: "CoffeeMachine" → "coffee machine"."""
    return _CAMEL.sub(" ", name).lower()


@dataclass(frozen=True)
class ClassInfo:
    """An ontology class the map knows: local name, IRI, preferred word, area or object, depth."""

    name: str
    iri: str
    label: str
    is_area: bool
    ancestors: frozenset[str]  # local names of its named superclasses (itself included)

    @property
    def depth(self) -> int:
        return len(self.ancestors)


class Lexicon:
    """The classes under Area and Object and the words for them."""

    def __init__(
        self, classes: Iterable[ClassInfo], words: Mapping[str, str], disjoint: Iterable[frozenset[str]] = ()
    ) -> None:
        self.classes: dict[str, ClassInfo] = {c.name: c for c in classes}
        self._words = dict(words)  # normalised word -> class name
        self._disjoint = frozenset(disjoint)  # pairs of class names declared disjoint

    def lookup(self, words: str) -> ClassInfo | None:
        """The class a word names, or None ("living rooms" → LivingRoom)."""
        w = normalise(words)
        name = self._words.get(w)
        if name is None and w.endswith("s"):
            name = self._words.get(w[:-1])
        if name is None and w.endswith("es"):
            name = self._words.get(w[:-2])
        return self.classes.get(name) if name else None

    def word(self, name: str) -> str:
        """The preferred word for a class name (its label)."""
        c = self.classes.get(name)
        return c.label if c else class_words(name)

    def is_a(self, name: str, ancestor: str) -> bool:
        c = self.classes.get(name)
        return c is not None and ancestor in c.ancestors

    def disjoint(self, a: str, b: str) -> bool:
        """Whether classes ``a`` and ``b`` are declared disjoint (directly or through their ancestors)."""
        ca, cb = self.classes.get(a), self.classes.get(b)
        if ca is None or cb is None:
            return False
        return any(frozenset((x, y)) in self._disjoint for x in ca.ancestors for y in cb.ancestors)

    def most_specific_first(self, names: Iterable[str]) -> list[str]:
        """Class names sorted deepest first (ties by name)."""
        return sorted(set(names), key=lambda n: (-(self.classes[n].depth if n in self.classes else 0), n))

    def words(self) -> dict[str, str]:
        """Every known word → class name."""
        return dict(self._words)
