"""The conceptual map (book Sect. 7.2.4): an OWL ontology of places and objects, and a reasoner.

:class:`ConceptualMap` keeps acquired (robot), asserted (people) and inferred (HermiT)
knowledge about the areas of a building apart, on top of the innate commonsense ontology in
``ontology/loci-commonsense.owl``. See docs/conceptual.md.

The names below load on first use (PEP 562), so a module that needs only the words
(:mod:`~knowledge.conceptual.lexicon`, :mod:`~knowledge.conceptual.referring`) does not
load owlready2.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from knowledge.conceptual.errors import InconsistentKnowledge, JavaNotFound, ReasonerError, UnknownWord
    from knowledge.conceptual.java import find_java
    from knowledge.conceptual.lexicon import Lexicon, normalise
    from knowledge.conceptual.map import AREA_CLASSES, Assertion, ConceptualMap, Contradiction
    from knowledge.conceptual.resolve import Resolution, resolve_words
    from knowledge.conceptual.world import default_ontology_path

_WHERE = {
    "InconsistentKnowledge": "errors",
    "JavaNotFound": "errors",
    "ReasonerError": "errors",
    "UnknownWord": "errors",
    "find_java": "java",
    "Lexicon": "lexicon",
    "normalise": "lexicon",
    "AREA_CLASSES": "map",
    "Assertion": "map",
    "ConceptualMap": "map",
    "Contradiction": "map",
    "Resolution": "resolve",
    "resolve_words": "resolve",
    "default_ontology_path": "world",
}

__all__ = [
    "AREA_CLASSES",
    "Assertion",
    "ConceptualMap",
    "Contradiction",
    "InconsistentKnowledge",
    "JavaNotFound",
    "Lexicon",
    "ReasonerError",
    "Resolution",
    "UnknownWord",
    "default_ontology_path",
    "find_java",
    "normalise",
    "resolve_words",
]


def __getattr__(name: str) -> Any:
    where = _WHERE.get(name)
    if where is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{where}"), name)
    globals()[name] = value
    return value
